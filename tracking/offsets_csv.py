"""Writing offsets as CSV: a row per timestamp and cone."""

from __future__ import annotations

import csv
from collections.abc import Iterable
from pathlib import Path

from tracking.estimate import ConeEstimate

OFFSET_COLUMNS = ("time", "cone", "dx", "dy", "dz", "cameras", "sdx", "sdy", "sdz", "withheld")  # sd*: 1σ, m;
# withheld: why dx, dy, dz are empty, where the estimator says (tracking.estimate.WITHHELD_*)
FLUSH_ROWS = 100  # rows between flushes: a killed run keeps all but the last few


class OffsetsWriter:
    """An offsets CSV written row by row and flushed every FLUSH_ROWS, so an interrupted run keeps what it measured;
    `rows` counts what is in the file, however the run ends."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file = self.path.open("w", newline="")
        self._writer = csv.writer(self._file)
        self._writer.writerow(OFFSET_COLUMNS)
        self.rows = 0

    def write(self, e: ConeEstimate) -> None:
        """One estimate as a row (numbers as Python floats: formatting numpy's costs twice as much, and a split
        run's driver writes every row: benchmarks/results/scale.md)."""
        dx, dy, dz = e.offset.tolist()
        sd = e.sigma.tolist()
        self._writer.writerow((f"{e.time:.6f}", e.cone, f"{dx:.5f}", f"{dy:.5f}", f"{dz:.5f}", " ".join(e.cameras),
                               f"{sd[0]:.5f}", f"{sd[1]:.5f}", f"{sd[2]:.5f}", e.withheld))
        self.rows += 1
        if self.rows % FLUSH_ROWS == 0:
            self._file.flush()

    def close(self) -> None:
        """Flush and close the file."""
        self._file.close()

    def __enter__(self) -> OffsetsWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def write_offsets_csv(path: str | Path, estimates: Iterable[ConeEstimate]) -> int:
    """Stream estimates to CSV; returns the number of rows."""
    with OffsetsWriter(path) as writer:
        for e in estimates:
            writer.write(e)
    return writer.rows
