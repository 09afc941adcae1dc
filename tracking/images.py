"""Reading still images and videos into grayscale frames stamped with their capture time."""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING

import cv2
import numpy as np

from tracking.errors import InputError
from tracking.frame_times import FrameClock, as_clock

if TYPE_CHECKING:  # PyAV is imported where a video is opened: at every command's start it would cost 0.1 s
    import av

LUMA_FIRST_FORMATS = {"yuv420p", "yuvj420p", "yuv422p", "yuvj422p", "yuv444p", "yuvj444p", "nv12", "nv21", "gray"}
IMAGE_SUFFIXES = {".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".webp", ".pgm", ".ppm"}
DEFAULT_FPS = 15.0  # nominal frame rate of a stream that does not give one
JUMP_S = 0.5  # a gap this long would leave a camera's cones stale on its own (live.STALE_S): worth a look
JUMP_INTERVALS = 2.5  # ... and it must exceed a dropped frame's gap (2 intervals; cameras and the simulator drop)
END_SLACK_INTERVALS = 2.5  # a video declared by its duration ends early when its frames stop more than this many
# intervals before that duration: the last frame's own interval, one dropped frame, rounding
DECLARED_DURATION_FORMATS = {"matroska,webm"}  # duration is a header field written when the file was finished (and
# absent when it was not); MPEG-TS, raw H.264 and streams estimate it from the data they hold, or from the bitrate


@dataclass(frozen=True)
class Frame:
    """One grayscale frame and when it was captured."""

    index: int  # frame number within its source, from 0
    time: float  # capture time on the common clock, s
    gray: np.ndarray | None  # (H, W) uint8; None once tracked when the packet carries the image on
    bgr: np.ndarray | None = None  # (H, W, 3) uint8, kept only when asked for
    packet: bytes | None = None  # the frame as the camera encoded it: one H.264 access unit, Annex B
    keyframe: bool = False  # the packet decodes on its own (IDR)
    video: VideoHealth | None = None  # its source's health up to this frame (None: a still image)


@dataclass
class VideoHealth:
    """What a video source delivered against what its container declares, and the presentation times that went
    wrong; the decoder fills it frame by frame (O(1) each), and each Frame carries a copy as of itself."""

    source: str = ""  # the file's name, or the URL
    declared_frames: int | None = None  # frames the container declares (MP4, AVI: from its index)
    declared_s: float | None = None  # duration it declares when it gives no frame count (Matroska), s
    interval_s: float = 1.0 / DEFAULT_FPS  # nominal frame interval, s
    packets: int = 0  # video packets read from the container
    decoded: int = 0  # frames out of the decoder, dropped ones included
    untimed: int = 0  # frames without a presentation time: stamped one nominal interval after the one before
    backwards: int = 0  # frames whose time is before the previous frame's: dropped
    repeated: int = 0  # frames whose time equals the previous frame's: dropped
    damaged: int = 0  # frames decoded from a packet cut short or broken: dropped
    unlisted: int = 0  # frames the camera's times file gives no capture time: dropped
    jumps: int = 0  # gaps longer than jump_s() between consecutive frames
    largest_jump_s: float = 0.0
    largest_jump_at_s: float = 0.0  # where the largest jump starts, s after the first frame
    first_s: float | None = None  # presentation time of the first frame kept, s
    last_s: float | None = None  # ... and of the newest, s
    ended: bool = False  # the source was read to its end
    news: tuple[str, ...] = ()  # problems first seen since the previous frame's copy (the recording logs them)
    _anchor: tuple[float, int] = field(default=(0.0, 0), repr=False)  # last timed frame kept: (time, its number)
    _kept: int = field(default=0, repr=False)

    def declare(self, container: av.container.InputContainer, source: str | Path) -> None:
        """Take the source's name, nominal interval, and the frames or duration its container declares."""
        import av

        stream = container.streams.video[0]
        rate = stream.guessed_rate or stream.average_rate  # the camera's rate; the average one counts gaps in
        self.source = str(source) if "://" in str(source) else Path(source).name
        self.interval_s = 1.0 / float(rate) if rate else 1.0 / DEFAULT_FPS
        if stream.frames:
            self.declared_frames = int(stream.frames)
        elif container.format.name in DECLARED_DURATION_FORMATS and container.duration:
            self.declared_s = container.duration / av.time_base

    def jump_s(self) -> float:
        """The gap between two frames above which it counts as a jump, s."""
        return max(JUMP_S, JUMP_INTERVALS * self.interval_s)

    def stamp(self, pts: float | None, damaged: bool = False) -> float | None:
        """Count one decoded frame; its presentation time, or None when it is to be dropped: damaged (decoded from a
        packet the demuxer found cut short or broken, its missing parts concealed with other frames' pixels), or not
        after the previous frame's time (the tracker merges cameras by capture time and fusion applies each frame
        at its time, so a frame from the past would be fused as if it were now; a repeated time, one instant twice).
        """
        self.decoded += 1
        if damaged:
            self.damaged += 1
            if self.damaged == 1:
                self._note(f"frame {self.decoded - 1} decoded from a damaged packet: dropped")
            return None
        if pts is None:
            self.untimed += 1
            if self.untimed == 1:
                self._note(f"frame {self.decoded - 1} has no timestamp: stamped at the nominal "
                           f"{1 / self.interval_s:.4g} fps")
        t = pts if pts is not None else self._anchor[0] + (self._kept - self._anchor[1]) * self.interval_s
        if self.last_s is not None and t <= self.last_s:
            if t < self.last_s:
                self.backwards += 1
                if self.backwards == 1:
                    self._note(f"timestamp went back {self.last_s - t:.3g} s after {self._position()}: frame dropped")
            else:
                self.repeated += 1
                if self.repeated == 1:
                    self._note(f"timestamp repeated after {self._position()}: frame dropped")
            return None
        if self.last_s is not None and t - self.last_s > self.jump_s():
            self.jumps += 1
            if t - self.last_s > self.largest_jump_s:
                self.largest_jump_s, self.largest_jump_at_s = t - self.last_s, self.last_s - (self.first_s or 0.0)
            self._note(f"jump of {t - self.last_s:.3g} s after {self._position()}")
        if pts is not None:
            self._anchor = (t, self._kept)
        self.first_s = t if self.first_s is None else self.first_s
        self.last_s = t
        self._kept += 1
        return t

    def unlisted_frame(self, index: int) -> None:
        """Count a frame the times file lists no capture time for (said once)."""
        self.unlisted += 1
        if self.unlisted == 1:
            self._note(f"frame {index} has no capture time in the camera's times file: frames without one are dropped")

    def finish(self) -> None:
        """The source has no more frames."""
        self.ended = True
        if self.short():
            self._note(self.ending())

    def report(self) -> VideoHealth:
        """A copy as of now, for the frame about to go out; the news goes with it."""
        copy = replace(self)
        self.news = ()
        return copy

    def short(self) -> bool:
        """True when the source ended before the frames (or the duration) its container declares."""
        if not self.ended:
            return False
        if self.declared_frames is not None:
            return self.decoded < self.declared_frames
        if self.declared_s is not None:
            end = (self.last_s if self.last_s is not None else 0.0) + self.interval_s
            return end < self.declared_s - END_SLACK_INTERVALS * self.interval_s
        return False

    def ending(self) -> str:
        """How a short source ended, against what its container declares."""
        if self.declared_frames is not None:
            cause = (f"{counted(self.packets, 'packet')} read: the file may be cut short"
                     if self.packets < self.declared_frames
                     else f"{self.declared_frames - self.decoded} did not decode")
            return f"ended after {self.decoded} of {self.declared_frames} frames ({cause})"
        assert self.declared_s is not None
        stop = (self.last_s if self.last_s is not None else 0.0) + self.interval_s
        expected = round((self.declared_s - (self.first_s or 0.0)) / self.interval_s)  # Matroska times run from 0
        return (f"ended after {self.decoded} of about {expected} frames (its frames stop at {stop:.1f} s of the "
                f"{self.declared_s:.1f} s it declares: the file may be cut short)")

    def problems(self) -> list[str]:
        """Everything that went wrong, one phrase each (empty for a sound source)."""
        out = [f"{self.source} {self.ending()}"] if self.short() else []
        if self.backwards or self.repeated:
            phrases = ([f"{counted(self.backwards, 'timestamp')} went backwards"] if self.backwards else []) + (
                [f"{self.repeated if self.backwards else counted(self.repeated, 'timestamp')} repeated"]
                if self.repeated else [])
            out.append(f"{', '.join(phrases)} (frames dropped)")
        if self.damaged:
            out.append(f"{counted(self.damaged, 'frame')} from damaged packets dropped")
        if self.jumps:
            out.append(f"{counted(self.jumps, 'jump')} over {self.jump_s():.2g} s (largest {self.largest_jump_s:.3g} "
                       f"s, after {self.largest_jump_at_s:.1f} s)")
        if self.untimed:
            out.append(f"{counted(self.untimed, 'frame')} had no timestamp (stamped at the nominal "
                       f"{1 / self.interval_s:.4g} fps)")
        if self.unlisted:
            out.append(f"{counted(self.unlisted, 'frame')} without a time in the times file dropped")
        return out

    def troubled(self) -> bool:
        """True when anything went wrong (cheap: no text)."""
        return bool(self.backwards or self.repeated or self.damaged or self.jumps or self.untimed or self.unlisted
                    or self.short())

    def summary(self) -> str:
        """The problems as one line ('' for a sound source)."""
        return "; ".join(self.problems())

    def _position(self) -> str:
        """Where the newest frame kept is: seconds after the first."""
        return f"{(self.last_s or 0.0) - (self.first_s or 0.0):.1f} s"

    def _note(self, text: str) -> None:
        """Add a problem to the news."""
        self.news = (*self.news, text)


def counted(n: int, noun: str) -> str:
    """'1 frame', '3 frames'."""
    return f"{n} {noun}{'' if n == 1 else 's'}"


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
    import av

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


def decoded_frames(container: av.container.InputContainer, source: str | Path, time_offset: float | FrameClock = 0.0,
                   keep_color: bool = False, packets: bool = False, health: VideoHealth | None = None,
                   chunk: tuple[int | None, int | None] | None = None, threads: str = "AUTO",
                   first_index: int = 0) -> Iterator[Frame]:
    """Frames of an open container; capture time = presentation time + time_offset, or with a FrameClock that has a
    times file, the file's time of the frame (frame number first_index + the frames decoded here) + its offset.

    With packets=True, each frame also carries its H.264 packet in Annex B (when the stream passes through).
    health: filled as the frames go (see VideoHealth); a frame whose time is not after the previous one, or decoded
    from a damaged packet, is dropped. chunk: (pts of a keyframe, None for the first; packets to decode from it, None
    for all): only that part, decoded on its own; frame numbers count from the keyframe (tracking.parallel puts them
    back)."""
    import av

    clock = as_clock(time_offset)
    stream = container.streams.video[0]
    stream.thread_type = threads
    health = health if health is not None else VideoHealth()
    health.declare(container, source)
    annexb = (av.bitstream.BitStreamFilterContext("h264_mp4toannexb", stream)
              if packets and passes_through(stream) else None)
    pending: dict[int | None, list[tuple[bytes, bool]]] = {}  # pts -> packets (FIFO) until their frames come out
    index = 0
    cut = False  # a packet cut short (a truncated file's last) or damaged went to the decoder
    damaged: set[int] = set()  # pts of such packets whose frames have not come out
    try:
        for packet in chunk_packets(container, stream, chunk):
            pts, key = packet.pts, packet.is_keyframe
            health.packets += packet.size > 0  # the last one, empty, only flushes the decoder
            if packet.is_corrupt:
                cut = True
                if pts is not None:
                    damaged.add(pts)
            try:
                decoded = packet.decode()
            except av.error.InvalidDataError:
                if not cut:
                    raise
                decoded = []  # its frame is lost, not the video: threaded decoders mostly drop it unsaid (or say so
                # with a later packet), one core raises at once; the frames against the declared ones tell
            if annexb is not None and packet.size and not packet.is_corrupt:  # before the frames go out: a decoder
                # without delay (one thread, one core) returns the packet's own frame at once. After decoding: the
                # filter takes the data
                pending.setdefault(pts, []).append((b"".join(bytes(p) for p in annexb.filter(packet)), key))
            for frame in decoded:
                t = health.stamp(frame.time, frame.pts in damaged)
                damaged.discard(frame.pts)
                waiting = pending.get(frame.pts)
                own = waiting.pop(0) if waiting else None
                if waiting == []:
                    del pending[frame.pts]
                capture = clock.capture(first_index + index, t) if t is not None else None
                if capture is not None and math.isnan(capture):
                    health.unlisted_frame(first_index + index)
                elif capture is not None:
                    yield _frame(frame, index, capture, keep_color, own, health.report())
                index += 1
    except av.error.FFmpegError as exc:
        raise InputError(source, f"video is damaged after frame {index} ({exc.strerror or exc})") from None
    health.finish()


def chunk_packets(container: av.container.InputContainer, stream: av.video.stream.VideoStream,
                  chunk: tuple[int | None, int | None] | None) -> Iterator[av.Packet]:
    """The stream's packets: all of them, or a chunk's (keyframe pts or None for the first, packet count or None)
    then an empty packet that flushes the decoder. A seek that does not land on the keyframe raises ValueError."""
    import av

    if chunk is None:
        yield from container.demux(stream)
        return
    start, count = chunk
    if start is not None:
        container.seek(start, stream=stream, backward=True, any_frame=False)
    n = 0
    for packet in container.demux(stream):
        if start is not None and n == 0 and packet.size and (packet.pts != start or not packet.is_keyframe):
            raise ValueError(f"seeking to the keyframe at pts {start} landed on pts {packet.pts}")
        if count is not None and n >= count and packet.size:
            break
        size = packet.size  # the Annex B filter takes a packet's data once decoded
        n += size > 0
        yield packet
        if not size:
            return  # the demuxer's own flush: the end of the video
    flush = av.Packet()
    flush.stream = stream
    flush.time_base = stream.time_base  # the frames it flushes out take their time base from it
    yield flush


def luma(frame: av.VideoFrame) -> np.ndarray:
    """(H, W) uint8 grey of a decoded frame: its luma plane as it is when it has one (no colour conversion:
    half the decoding cost at 920×600), else converted."""
    if frame.format.name not in LUMA_FIRST_FORMATS:
        return frame.to_ndarray(format="gray")
    plane = frame.planes[0]
    rows = np.frombuffer(plane, np.uint8).reshape(-1, plane.line_size)
    return np.ascontiguousarray(rows[:frame.height, :frame.width])


def quarter_turns(frame: av.VideoFrame) -> int:
    """Quarter turns counterclockwise (0-3) that present the frame upright: its container's display rotation (a
    phone filming in portrait stores landscape pixels and this), as players and OpenCV show it; 0 for an angle that
    is not a quarter turn."""
    turns, rest = divmod(frame.rotation, 90)
    return int(turns) % 4 if rest == 0 else 0


def turned(container: av.container.InputContainer) -> bool:
    """True when the video's first frame has a display rotation (its frames are then recorded as images)."""
    import av

    try:
        frame = next(container.decode(video=0), None)
    except av.error.FFmpegError:
        return False
    return frame is not None and quarter_turns(frame) != 0


def upright(image: np.ndarray, turns: int) -> np.ndarray:
    """The image (H, W[, 3]) turned counterclockwise by turns quarter turns (np.rot90), contiguous."""
    return image if turns == 0 else np.ascontiguousarray(np.rot90(image, turns))


def _frame(frame: av.VideoFrame, index: int, time: float, keep_color: bool, packet: tuple[bytes, bool] | None,
           video: VideoHealth) -> Frame:
    """One decoded frame as a Frame, at its capture time, upright as players show it (a calibration made from the
    same camera's photos or frames is too). A turned frame keeps no packet: the recording's video decoder would show
    its pixels unturned, so it is recorded as an image."""
    turns = quarter_turns(frame)
    packet = packet if turns == 0 else None
    return Frame(index=index, time=time, gray=upright(luma(frame), turns),
                 bgr=upright(frame.to_ndarray(format="bgr24"), turns) if keep_color else None,
                 packet=packet[0] if packet else None, keyframe=packet[1] if packet else False, video=video)


def video_frames(source: str | Path, time_offset: float | FrameClock = 0.0, keep_color: bool = False,
                 packets: bool = False, health: VideoHealth | None = None) -> Iterator[Frame]:
    """Decode a video (file or URL) with PyAV; capture time = presentation time + time_offset."""
    with open_video(source) as container:
        yield from decoded_frames(container, source, time_offset, keep_color, packets, health)


def to_the_end(frames: Iterable[Frame], health: VideoHealth) -> Iterator[Frame]:
    """The frames, one behind the decoder, so that the last carries its source's health at the end (whether a video
    ended early is known only after its last frame)."""
    held: Frame | None = None
    for frame in frames:
        if held is not None:
            yield held
        held = frame
    if held is not None:
        if held.video is not None:
            end = health.report()
            held = replace(held, video=replace(end, news=held.video.news + end.news))
        yield held


def frames(source: str | Path, time_offset: float | FrameClock = 0.0, keep_color: bool = False, packets: bool = False,
           health: VideoHealth | None = None) -> Iterator[Frame]:
    """Frames of an image file (one frame at time_offset) or a video (health: see decoded_frames)."""
    if is_image(source):
        gray = read_gray(source)
        bgr = cv2.imread(str(source), cv2.IMREAD_COLOR) if keep_color else None
        yield Frame(index=0, time=as_clock(time_offset).offset, gray=gray, bgr=bgr)
        return
    if not str(source).startswith(("rtsp:", "http:", "https:")) and not Path(source).is_file():
        raise InputError(source, "image or video not found")
    yield from video_frames(source, time_offset, keep_color, packets, health)
