"""Live camera sources: a device index, an RTSP/HTTP stream, or a video file replayed at its own frame rate.

Capture times: a replayed file keeps its presentation times plus the camera's time_offset (the same clock as
`topside track`), paced against the wall clock; devices and streams are stamped on the Unix wall clock when a
frame arrives (streams: their presentation times anchored to the wall clock at the first frame, so network
jitter does not move them), plus time_offset. One rig does not mix the two clocks.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, replace
from enum import StrEnum
from fractions import Fraction
from pathlib import Path

import av
import cv2
import numpy as np

from tracking.errors import InputError
from tracking.frame_times import FrameClock
from tracking.images import (
    Frame,
    VideoHealth,
    decoded_frames,
    frames,
    is_image,
    open_video,
    passes_through,
    to_the_end,
    turned,
)
from tracking.rig import CameraEntry, Rig

STREAM_PREFIXES = ("rtsp:", "rtsps:", "http:", "https:", "udp:", "tcp:", "srt:")
STREAM_OPTIONS = {"rtsp_transport": "tcp", "timeout": "5000000"}  # µs: a dead stream raises instead of hanging
ENCODE_BITRATE = 2_000_000  # bit/s of H.264 made from raw device frames: 0.9 GB per camera-hour
STREAM_ASSUMED_BITRATE = 8_000_000  # bit/s of a network camera's stream when nothing says: the upper end of what
# docs/field-guide.md asks of a 920×600 camera (well above 2 Mbit/s; 4.4-4.9 met every target)
ENCODE_KEYFRAME_S = 2.0  # a recording segment or a late viewer waits at most this for a decodable frame
FROZEN_AFTER_S = 1.0  # identical frames for this long: the camera is frozen
FINGERPRINT_STEP = 8  # px between the samples that fingerprint a frame


class SourceKind(StrEnum):
    """Where a camera's frames come from."""

    DEVICE = "device"
    STREAM = "stream"
    FILE = "file"


class CameraState(StrEnum):
    """A camera's condition as the live tracker sees it."""

    STARTING = "starting"
    LIVE = "live"
    FROZEN = "frozen"  # frames arrive but do not change
    LOST = "lost"  # no frames (unplugged, stream down); retried
    ENDED = "ended"  # a replayed file reached its end


@dataclass(frozen=True)
class SourceEvent:
    """A change of a camera's state, with the wall-clock time it was seen."""

    camera: str
    state: CameraState
    wall_time: float
    detail: str = ""
    first_time: float | None = None  # with "ready" from a file: the capture time of its first frame


def source_kind(source: str) -> SourceKind:
    """A device index (digits), a stream URL, or a file path."""
    if source.strip().isdigit():
        return SourceKind.DEVICE
    if source.lower().startswith(STREAM_PREFIXES):
        return SourceKind.STREAM
    return SourceKind.FILE


def uses_wall_clock(rig: Rig) -> bool:
    """True when the rig's cameras are live (Unix time); a one-line error when live and files are mixed."""
    kinds = {source_kind(c.source) != SourceKind.FILE for c in rig.cameras}
    if len(kinds) > 1:
        raise InputError(rig.path, "mixes video files with live devices or streams (their clocks differ; "
                                   "expected all files or all live)", "cameras.source")
    return kinds == {True}


def check_sources(rig: Rig) -> None:
    """Before a live session writes anything: live and file sources not mixed, and every file a readable image or
    video (a one-line error naming it), as `track` requires."""
    uses_wall_clock(rig)
    for entry in rig.cameras:
        if source_kind(entry.source) != SourceKind.FILE:
            continue
        path = rig.resolve(entry.source)
        if not path.is_file():
            raise InputError(path, "image or video not found")
        if not is_image(path):
            open_video(path).close()


@dataclass
class Pacer:
    """Replays capture times against the wall clock: time t is due at t0 + (t - origin) / speed (inf: no waiting)."""

    t0: float  # wall time at which capture time `origin` is due
    speed: float = 1.0
    origin: float = 0.0

    def wait(self, t: float) -> None:
        """Sleep until capture time t is due."""
        if np.isfinite(self.speed):
            delay = self.t0 + (t - self.origin) / self.speed - time.time()
            if delay > 0:
                time.sleep(delay)

    def now(self) -> float:
        """The capture time that is due now."""
        return self.origin + (time.time() - self.t0) * self.speed


class H264Encoder:
    """Encodes raw frames into H.264 packets (Annex B, no B-frames) so raw sources record as video too."""

    def __init__(self, width: int, height: int, fps: float = 30.0, bitrate: int = ENCODE_BITRATE) -> None:
        self.codec = av.CodecContext.create("libx264", "w")
        self.codec.width, self.codec.height = width, height
        self.codec.pix_fmt = "yuv420p"
        self.codec.time_base = Fraction(1, 1000)
        self.codec.bit_rate = bitrate
        keyint = max(1, round(fps * ENCODE_KEYFRAME_S))
        self.codec.options = {"preset": "ultrafast", "tune": "zerolatency",
                              "x264-params": f"keyint={keyint}:bframes=0:repeat-headers=1"}
        self._n = 0

    def encode(self, image: np.ndarray) -> tuple[bytes, bool]:
        """(packet, keyframe) of one (H, W) grey or (H, W, 3) BGR frame."""
        fmt = "gray" if image.ndim == 2 else "bgr24"
        frame = av.VideoFrame.from_ndarray(image, format=fmt).reformat(format="yuv420p")
        frame.pts = self._n
        self._n += 1
        packets = self.codec.encode(frame)
        return b"".join(bytes(p) for p in packets), any(p.is_keyframe for p in packets)


def device_frames(index: int, time_offset: float, clock: Callable[[], float] = time.time, encode: bool = True
                  ) -> Iterator[Frame]:
    """Frames of a local camera, stamped on the wall clock as they are grabbed, with H.264 packets (unless not
    encode) and the health of their times (a wall clock stepped back drops the frame; a stall over
    VideoHealth.jump_s counts as a jump)."""
    quiet = cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_ERROR)  # no warnings of a missing device:
    try:  # the one line below says it, and a lost camera is retried every 2 s
        capture = cv2.VideoCapture(index)
    finally:
        cv2.utils.logging.setLogLevel(quiet)
    if not capture.isOpened():
        raise InputError(f"device {index}", "cannot be opened (expected a connected camera)")
    encoder = None
    health = VideoHealth(f"device {index}")
    n = 0
    try:
        while True:
            ok = capture.grab()
            grabbed = clock()
            ok, bgr = capture.retrieve() if ok else (False, None)
            if not ok:
                return
            n += 1
            if n == 1:
                fps = capture.get(cv2.CAP_PROP_FPS) or 30.0
                encoder = H264Encoder(bgr.shape[1], bgr.shape[0], fps) if encode else None
                health.interval_s = 1.0 / fps
            t = health.stamp(grabbed)
            if t is None:  # not encoded either, so the recorded H.264 never refers to it
                continue
            packet, key = encoder.encode(bgr) if encoder is not None else (b"", False)
            yield Frame(index=n - 1, time=t + time_offset, gray=cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY),
                        packet=packet or None, keyframe=key, video=health.report())
    finally:
        capture.release()


def stream_frames(url: str, time_offset: float, clock: Callable[[], float] = time.time) -> Iterator[Frame]:
    """Frames of a network stream: presentation times anchored to the wall clock at the first frame."""
    with open_video(url, STREAM_OPTIONS) as container:
        anchor = None
        for frame in decoded_frames(container, url, 0.0, packets=True):
            anchor = clock() - frame.time if anchor is None else anchor
            yield Frame(index=frame.index, time=anchor + frame.time + time_offset, gray=frame.gray,
                        packet=frame.packet, keyframe=frame.keyframe, video=frame.video)


def file_frames(path: Path, time_offset: float | FrameClock, pacer: Pacer, loop_until: float | None = None
                ) -> Iterator[Frame]:
    """A video file replayed at its own frame rate (or faster): each frame waits until it is due.

    loop_until: replay the file again and again, capture times running on, up to this capture time (soak tests).
    """
    shift, index = 0.0, 0
    while True:
        first = last = None
        health = VideoHealth()  # the last frame carries whether the file ended early
        for frame in to_the_end(frames(path, time_offset, packets=True, health=health), health):
            first = frame if first is None else first
            t = frame.time + shift
            if loop_until is not None and t > loop_until:
                return
            pacer.wait(t)
            yield replace(frame, index=index, time=t) if shift else frame
            last, index = frame, index + 1
        if loop_until is None or first is None or last is None or last.index == 0:
            return
        shift += (last.time - first.time) * (1 + 1 / last.index)  # one frame interval after the clip's end


def camera_frames(rig: Rig, entry: CameraEntry, pacer: Pacer, loop_until: float | None = None) -> Iterator[Frame]:
    """The frames of one camera of the rig, whatever its source."""
    kind = source_kind(entry.source)
    if kind == SourceKind.DEVICE:
        return device_frames(int(entry.source), entry.time_offset)
    if kind == SourceKind.STREAM:
        return stream_frames(entry.source, entry.time_offset)
    return file_frames(rig.resolve(entry.source), rig.clock(entry), pacer, loop_until)


def byte_rate(rig: Rig, entry: CameraEntry) -> float:
    """Bytes per second of a camera's video as the recording and a live viewer get it: a file whose H.264 passes
    through, its size over its duration; a device, its encoding (ENCODE_BITRATE); a stream, or a file re-coded as a
    JPEG a frame (about as much at 920×600 and 15 FPS) or unreadable, STREAM_ASSUMED_BITRATE."""
    kind = source_kind(entry.source)
    if kind == SourceKind.DEVICE:
        return ENCODE_BITRATE / 8
    assumed = STREAM_ASSUMED_BITRATE / 8
    if kind == SourceKind.STREAM:
        return assumed
    path = rig.resolve(entry.source)
    try:
        with open_video(path) as container:
            duration = (container.duration or 0) / av.time_base
            if not passes_through(container.streams.video[0]) or turned(container):
                return assumed
        return path.stat().st_size / duration if duration > 0 else assumed
    except (InputError, OSError):
        return assumed


def first_capture_time(rig: Rig, entry: CameraEntry) -> float | None:
    """Capture time of a file's first frame (None for live sources or an unreadable file)."""
    if source_kind(entry.source) != SourceKind.FILE:
        return None
    try:
        return next(iter(frames(rig.resolve(entry.source), rig.clock(entry)))).time
    except (InputError, StopIteration):
        return None


def fingerprint(gray: np.ndarray) -> bytes:
    """A cheap signature of a frame's content: equal for repeated (frozen) frames."""
    return gray[::FINGERPRINT_STEP, ::FINGERPRINT_STEP].tobytes()


@dataclass
class FreezeDetector:
    """Tells when a camera keeps delivering the same image."""

    last: bytes = b""
    since: float | None = None  # capture time the current image first appeared

    def frozen(self, frame: Frame) -> bool:
        """True while the frame repeats the previous image for FROZEN_AFTER_S or more."""
        assert frame.gray is not None
        fp = fingerprint(frame.gray)
        if fp != self.last or self.since is None:
            self.last, self.since = fp, frame.time
            return False
        return frame.time - self.since >= FROZEN_AFTER_S
