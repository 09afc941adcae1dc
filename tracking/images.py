"""Reading still images and videos into grayscale frames stamped with their capture time."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import av
import cv2
import numpy as np

from tracking.errors import InputError

IMAGE_SUFFIXES = {".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".webp", ".pgm", ".ppm"}


@dataclass(frozen=True)
class Frame:
    """One grayscale frame and when it was captured."""

    index: int  # frame number within its source, from 0
    time: float  # capture time on the common clock, s
    gray: np.ndarray  # (H, W) uint8
    bgr: np.ndarray | None = None  # (H, W, 3) uint8, kept only when asked for


def is_image(path: str | Path) -> bool:
    """True when the path looks like a still image file."""
    return Path(path).suffix.lower() in IMAGE_SUFFIXES


def read_gray(path: str | Path) -> np.ndarray:
    """A still image as grayscale (H, W) uint8; a one-line error when it cannot be read."""
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "image not found")
    image = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    if image is None:
        raise InputError(path, "cannot be read as an image (expected PNG, JPEG, BMP or TIFF)")
    return image


def video_frames(source: str | Path, time_offset: float = 0.0, keep_color: bool = False) -> Iterator[Frame]:
    """Decode a video (file or URL) with PyAV; capture time = presentation time + time_offset."""
    try:
        container = av.open(str(source))
    except (av.error.FFmpegError, OSError) as exc:
        raise InputError(source, f"cannot be opened as a video ({exc.strerror or exc})") from None
    with container:
        if not container.streams.video:
            raise InputError(source, "holds no video stream")
        stream = container.streams.video[0]
        stream.thread_type = "AUTO"
        fallback_dt = 1.0 / float(stream.average_rate or 15)
        try:
            for index, frame in enumerate(container.decode(stream)):
                t = float(frame.time) if frame.time is not None else index * fallback_dt
                gray = frame.to_ndarray(format="gray")
                bgr = frame.to_ndarray(format="bgr24") if keep_color else None
                yield Frame(index=index, time=t + time_offset, gray=gray, bgr=bgr)
        except av.error.FFmpegError as exc:
            raise InputError(source, f"video is damaged after frame {index} ({exc.strerror or exc})") from None


def frames(source: str | Path, time_offset: float = 0.0, keep_color: bool = False) -> Iterator[Frame]:
    """Frames of an image file (one frame at time_offset) or a video."""
    if is_image(source):
        gray = read_gray(source)
        bgr = cv2.imread(str(source), cv2.IMREAD_COLOR) if keep_color else None
        yield Frame(index=0, time=time_offset, gray=gray, bgr=bgr)
        return
    if not str(source).startswith(("rtsp:", "http:", "https:")) and not Path(source).is_file():
        raise InputError(source, "image or video not found")
    yield from video_frames(source, time_offset, keep_color)
