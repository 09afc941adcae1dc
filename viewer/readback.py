"""Reading a recording back through rerun's own API (tests, benchmarks, and `topside export` later)."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import rerun as rr
from rerun.error_utils import RerunWarning


def chunks_by_entity(rrd: Path) -> dict[str, list[rr.chunk.Chunk]]:
    """All chunks of the recording in an .rrd file, grouped by entity path."""
    out: dict[str, list[rr.chunk.Chunk]] = {}
    with warnings.catch_warnings():  # a file without footer (cut, or still being written) reads on: what it holds
        warnings.simplefilter("ignore", RerunWarning)  # counts, and a caller names a cut file in its own words
        reader = rr.chunk.RrdReader(rrd)
    for chunk in reader.store().stream().to_chunks():
        out.setdefault(chunk.entity_path, []).append(chunk)
    return out


def component_rows(chunks: list[rr.chunk.Chunk], component: str, timeline: str = "capture_time"
                   ) -> tuple[np.ndarray, list]:
    """(times, values) of one component ('Scalars:scalars', ...) over the chunks of an entity, sorted by time."""
    times: list = []
    values: list = []
    for chunk in chunks:
        rb = chunk.to_record_batch()
        names = rb.schema.names
        if component not in names:
            continue
        col = rb.column(names.index(component)).to_pylist()
        if timeline in names:
            t = rb.column(names.index(timeline)).cast("int64").to_numpy() / 1e9
        else:
            t = np.full(len(col), np.nan)
        times.extend(t)
        values.extend(col)
    order = np.argsort(np.asarray(times), kind="stable")
    return np.asarray(times)[order], [values[i] for i in order]
