"""Writing offsets as CSV: a row per timestamp and cone."""

from __future__ import annotations

import csv
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from tracking.filtering import ConeEstimate

OFFSET_COLUMNS = ("time", "cone", "dx", "dy", "dz", "cameras", "sdx", "sdy", "sdz")  # sd*: 1σ, m


def write_offsets_csv(path: str | Path, estimates: Iterable[ConeEstimate]) -> int:
    """Stream estimates to CSV (flushed row by row, so an interrupted run keeps what it measured)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    n = 0
    with path.open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(OFFSET_COLUMNS)
        for e in estimates:
            sd = np.sqrt(np.diag(e.covariance)) if e.covariance is not None else np.full(3, np.nan)
            writer.writerow([f"{e.time:.6f}", e.cone, *(f"{v:.5f}" for v in e.offset), " ".join(e.cameras),
                             *(f"{v:.5f}" for v in sd)])
            n += 1
            if n % 100 == 0:
                f.flush()
    return n
