"""Capture times recorded beside a video: a sidecar file per camera, so the clocks need not be guessed.

A recorder on site writes each frame's capture time as it grabs it (a sidecar CSV, a timecode track converted to one,
a drone's telemetry): those are the times the tracker uses when the rig names the file (`cameras[].times`), in place
of the container's presentation times, which many recorders write as nominal k / fps. The file is a CSV with a header
and two columns:

    frame,time
    0,123.3379
    1,123.5047

`frame` is the frame's number in the video in decode order (0 = the first frame the video gives), `time` its capture
time in seconds on the clock all the rig's cameras share (the camera's `time_offset` is still added). Frames the file
does not list are not tracked (and said so once); times must increase with the frame number.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tracking.errors import InputError

COLUMNS = ("frame", "time")
MAX_FRAMES = 10_000_000  # a sidecar frame number beyond this is a typo (six hours at 60 fps is 1.3 million)


def read_frame_times(path: Path) -> np.ndarray:
    """(N,) capture times, s, by frame number (NaN where the file lists no time) from a sidecar CSV."""
    import pandas as pd  # here, not at the top: every command loads rigs, few have times files (0.5 s at start)

    try:
        df = pd.read_csv(path)
    except FileNotFoundError:
        raise InputError(path, "times file not found") from None
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        raise InputError(path, f"not a CSV file ({' '.join(str(exc).split())})") from None
    missing = [c for c in COLUMNS if c not in df.columns]
    if missing:
        raise InputError(path, f"missing column {missing[0]!r} (expected a header with columns frame,time)")
    frame = pd.to_numeric(df["frame"], errors="coerce").to_numpy()
    time = pd.to_numeric(df["time"], errors="coerce").to_numpy(dtype=float)
    bad = ~np.isfinite(frame) | (frame != np.round(frame)) | (frame < 0) | (frame > MAX_FRAMES)
    if len(df) == 0 or bad.any():
        row = int(np.argmax(bad)) + 2 if bad.any() else 2
        raise InputError(path, f"line {row}: frame: expected a frame number 0, 1, 2, ...", "frame")
    if not np.isfinite(time).all():
        raise InputError(path, f"line {int(np.argmax(~np.isfinite(time))) + 2}: time: expected seconds", "time")
    index = frame.astype(int)
    if len(np.unique(index)) != len(index):
        raise InputError(path, f"frame {int(index[np.argmax(np.bincount(index))])} is listed twice", "frame")
    order = np.argsort(index)
    if np.any(np.diff(time[order]) <= 0):
        k = int(np.argmax(np.diff(time[order]) <= 0)) + 1
        raise InputError(path, f"frame {int(index[order][k])}: time does not increase with the frame number", "time")
    times = np.full(int(index.max()) + 1, np.nan)
    times[index] = time
    return times


@dataclass(frozen=True)
class FrameClock:
    """A camera's clock: capture time of frame `index` shown at presentation time `pts_s`, on the common clock."""

    offset: float = 0.0  # s, the camera's time_offset
    times: np.ndarray | None = None  # (N,) sidecar capture times by frame number, s (None: presentation times)

    def capture(self, index: int, pts_s: float) -> float:
        """Capture time, s: the sidecar's time of the frame (NaN when it lists none) or its presentation time, plus
        the offset."""
        if self.times is None:
            return pts_s + self.offset
        return float(self.times[index]) + self.offset if index < len(self.times) else float("nan")


def as_clock(clock: float | FrameClock) -> FrameClock:
    """A FrameClock from a time offset (s) or a FrameClock."""
    return clock if isinstance(clock, FrameClock) else FrameClock(float(clock))
