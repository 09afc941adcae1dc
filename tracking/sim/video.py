"""H.264 video writing with PyAV: libx264, yuv420p, a constant rate factor, capture times as PTS."""

from __future__ import annotations

from fractions import Fraction
from pathlib import Path

import av
import numpy as np

TIME_BASE = Fraction(1, 90000)  # the MPEG clock: PTS ticks of 1/90000 s
X264_PARAMS = "bframes=0:threads=1:mbtree=0"  # no B-frames (cameras stream I and P); one thread and no
# macroblock-tree rate control, so that the same frames give the same bytes: with mbtree, 1-3 % of 0.4 s
# renders came out different (a few P-frames, up to 8 levels) from identical frames


def pts_of(seconds: float) -> int:
    """PTS ticks of a time relative to the first frame."""
    return round(seconds / TIME_BASE)


class VideoWriter:
    """Writes BGR frames with explicit PTS to an mp4 file."""

    def __init__(self, path: Path, width: int, height: int, fps: float, crf: int, preset: str) -> None:
        self.container = av.open(str(path), mode="w")
        self.stream = self.container.add_stream("libx264", rate=Fraction(fps).limit_denominator(1000))
        self.stream.width = width
        self.stream.height = height
        self.stream.pix_fmt = "yuv420p"
        self.stream.time_base = TIME_BASE
        self.stream.codec_context.time_base = TIME_BASE
        self.stream.options = {"crf": str(crf), "preset": preset, "x264-params": X264_PARAMS}
        self.last_pts = -1

    def write(self, bgr: np.ndarray, pts: int) -> None:
        """Encode one frame captured pts ticks after the first."""
        if pts <= self.last_pts:
            raise ValueError(f"PTS must increase ({pts} after {self.last_pts})")
        frame = av.VideoFrame.from_ndarray(bgr, format="bgr24")
        frame.pts = pts
        frame.time_base = TIME_BASE
        for packet in self.stream.encode(frame):
            self.container.mux(packet)
        self.last_pts = pts

    def close(self) -> None:
        """Flush the encoder and close the file."""
        for packet in self.stream.encode():
            self.container.mux(packet)
        self.container.close()


def read_pts(path: Path) -> list[float]:
    """Presentation times (s) of every frame of a video, in order."""
    with av.open(str(path)) as container:
        stream = container.streams.video[0]
        return [float(f.pts * stream.time_base) for f in container.decode(stream)]
