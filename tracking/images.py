"""Reading still images and videos into grayscale frames stamped with their capture time."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import av
import cv2
import numpy as np

from tracking.errors import InputError

LUMA_FIRST_FORMATS = {"yuv420p", "yuvj420p", "yuv422p", "yuvj422p", "yuv444p", "yuvj444p", "nv12", "nv21", "gray"}
IMAGE_SUFFIXES = {".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".webp", ".pgm", ".ppm"}


@dataclass(frozen=True)
class Frame:
    """One grayscale frame and when it was captured."""

    index: int  # frame number within its source, from 0
    time: float  # capture time on the common clock, s
    gray: np.ndarray | None  # (H, W) uint8; None once tracked when the packet carries the image on
    bgr: np.ndarray | None = None  # (H, W, 3) uint8, kept only when asked for
    packet: bytes | None = None  # the frame as the camera encoded it: one H.264 access unit, Annex B
    keyframe: bool = False  # the packet decodes on its own (IDR)


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


def open_video(source: str | Path, options: dict[str, str] | None = None) -> av.container.InputContainer:
    """A video container opened with PyAV; a one-line error when it cannot be."""
    try:
        container = av.open(str(source), options=options or {})
    except (av.error.FFmpegError, OSError) as exc:
        raise InputError(source, f"cannot be opened as a video ({exc.strerror or exc})") from None
    if not container.streams.video:
        container.close()
        raise InputError(source, "holds no video stream")
    return container


def passes_through(stream: av.video.stream.VideoStream) -> bool:
    """True when the stream's packets can be recorded as they are: H.264 without B-frames."""
    return stream.codec_context.name == "h264" and not stream.codec_context.has_b_frames


def decoded_frames(container: av.container.InputContainer, source: str | Path, time_offset: float = 0.0,
                   keep_color: bool = False, packets: bool = False) -> Iterator[Frame]:
    """Frames of an open container; capture time = presentation time + time_offset.

    With packets=True, each frame also carries its H.264 packet in Annex B (when the stream passes through).
    """
    stream = container.streams.video[0]
    stream.thread_type = "AUTO"
    fallback_dt = 1.0 / float(stream.average_rate or 15)
    annexb = (av.bitstream.BitStreamFilterContext("h264_mp4toannexb", stream)
              if packets and passes_through(stream) else None)
    pending: dict[int | None, tuple[bytes, bool]] = {}  # pts -> packet, until its frame leaves the decoder
    index = 0
    try:
        for packet in container.demux(stream):
            pts, key = packet.pts, packet.is_keyframe
            decoded = packet.decode()
            if annexb is not None and packet.size:  # before the frames go out: a decoder without delay (one
                # thread, one core) returns the packet's own frame at once. After decoding: the filter takes the data
                pending[pts] = (b"".join(bytes(p) for p in annexb.filter(packet)), key)
            for frame in decoded:
                yield _frame(frame, index, fallback_dt, time_offset, keep_color, pending.pop(frame.pts, None))
                index += 1
    except av.error.FFmpegError as exc:
        raise InputError(source, f"video is damaged after frame {index} ({exc.strerror or exc})") from None


def luma(frame: av.VideoFrame) -> np.ndarray:
    """(H, W) uint8 grey of a decoded frame: its luma plane as it is when it has one (no colour conversion:
    half the decoding cost at 920×600), else converted."""
    if frame.format.name not in LUMA_FIRST_FORMATS:
        return frame.to_ndarray(format="gray")
    plane = frame.planes[0]
    rows = np.frombuffer(plane, np.uint8).reshape(-1, plane.line_size)
    return np.ascontiguousarray(rows[:frame.height, :frame.width])


def _frame(frame: av.VideoFrame, index: int, fallback_dt: float, time_offset: float, keep_color: bool,
           packet: tuple[bytes, bool] | None) -> Frame:
    """One decoded frame as a Frame."""
    t = float(frame.time) if frame.time is not None else index * fallback_dt
    return Frame(index=index, time=t + time_offset, gray=luma(frame),
                 bgr=frame.to_ndarray(format="bgr24") if keep_color else None,
                 packet=packet[0] if packet else None, keyframe=packet[1] if packet else False)


def video_frames(source: str | Path, time_offset: float = 0.0, keep_color: bool = False,
                 packets: bool = False) -> Iterator[Frame]:
    """Decode a video (file or URL) with PyAV; capture time = presentation time + time_offset."""
    with open_video(source) as container:
        yield from decoded_frames(container, source, time_offset, keep_color, packets)


def frames(source: str | Path, time_offset: float = 0.0, keep_color: bool = False, packets: bool = False
           ) -> Iterator[Frame]:
    """Frames of an image file (one frame at time_offset) or a video."""
    if is_image(source):
        gray = read_gray(source)
        bgr = cv2.imread(str(source), cv2.IMREAD_COLOR) if keep_color else None
        yield Frame(index=0, time=time_offset, gray=gray, bgr=bgr)
        return
    if not str(source).startswith(("rtsp:", "http:", "https:")) and not Path(source).is_file():
        raise InputError(source, "image or video not found")
    yield from video_frames(source, time_offset, keep_color, packets)
