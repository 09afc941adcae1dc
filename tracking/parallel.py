"""Offline tracking on every core, or on a Ray cluster: each camera's video cut into chunks that start at keyframes,
decoded, searched and posed in worker processes (or Ray tasks), put back in capture-time order on the main process.

The chunks depend on the videos and CHUNK_FRAMES only, never on how many workers run them, so the output is the same
for every number of workers. A chunk is decoded on its own from its keyframe; a detector with state (MarkerTracker)
starts afresh at each chunk. The main process replays every decoded frame's presentation time through one
VideoHealth per camera, in order, so frame numbers, dropped frames and the video's health (and the warnings made from
them) are those of one pass over the whole video. A video that cannot be cut safely (no timestamps, damaged packets,
B-frames, not a file) is one chunk.
"""

from __future__ import annotations

import heapq
import importlib.util
import math
import os
import re
import resource
import socket
import sys
import tempfile
import threading
import time
from collections import deque
from collections.abc import Callable, Iterator
from concurrent.futures import Future, ProcessPoolExecutor
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Protocol

from tracking.camera import load_camera
from tracking.detection import DEFAULT_REFINEMENT, Refinement
from tracking.errors import InputError
from tracking.frame_times import FrameClock
from tracking.images import VideoHealth, decoded_frames, frames, is_image, open_video
from tracking.pipeline import CameraTracker, FrameResult, TrackStats
from tracking.rig import CameraEntry, Rig, load_rig

CHUNK_FRAMES = 150  # a chunk starts at the first keyframe this many frames or more after the previous chunk's start
# (10 s at 15 FPS): long enough that the overhead of a chunk and of a Ray task is amortised, short enough that the
# workers share the last chunks of a video evenly (benchmarks/results/scale.md)
RAY_INSTALL = "pip install 'topside[cluster]'"  # what `--ray` says when Ray is not installed
RAY_CLIENT_INSTALL = "pip install 'ray[client]'"  # what a ray:// address says when Ray's client is not installed
RAY_ADDRESS = re.compile(r"(?P<client>ray://)?(?P<host>[A-Za-z0-9._-]+|\[[0-9A-Fa-f:.]+\])(:(?P<port>[0-9]{1,5}))?")
RAY_CLIENT_PORT = 10001  # Ray's client server: ray://HOST without a port
RAY_PROBE_TIMEOUT_S = 5.0  # a cluster's head accepts a TCP connection within this, or the address is refused at once
# Connecting to a port that answers but is no Ray head: Ray's client gives up after 30 s by itself, its connection to
# a cluster's GCS (HOST:PORT) retries for ever; topside gives up after this (the environment variable overrides it).
RAY_CONNECT_TIMEOUT_S = 60.0
RAY_CONNECT_TIMEOUT_ENV = "TOPSIDE_RAY_CONNECT_TIMEOUT_S"
RAY_EXPECTED = "expected a Ray cluster's head: ray://HOST:10001 for Ray's client, HOST:6379 for its GCS"


@dataclass(frozen=True)
class Chunk:
    """One part of one camera's video: from a keyframe, a number of packets (None: to the end, or all of it)."""

    camera: str
    number: int  # within the camera, from 0
    start_pts: int | None  # the keyframe's presentation time in stream ticks (None: from the start, no seek)
    packets: int | None  # packets to decode (None: to the end)
    packets_before: int  # the video's packets before the keyframe
    start_time: float  # capture time of the keyframe, s (the order chunks are handed out in)


@dataclass(frozen=True)
class VideoPlan:
    """How one camera's video is cut, and its declared size and nominal interval (a VideoHealth, declared)."""

    camera: str
    chunks: tuple[Chunk, ...]
    health: VideoHealth
    frames: int  # packets, for progress bars
    whole_reason: str = ""  # why the video is one chunk ('' when it was cut at its keyframes or is too short)


@dataclass(frozen=True)
class ChunkTask:
    """What a worker needs to track one chunk: everything by value or by path (every node sees the videos)."""

    rig_path: Path
    chunk: Chunk
    refinement: Refinement = DEFAULT_REFINEMENT
    packets: bool = False  # keep each frame's H.264 packet (a recording or an archive is written)
    keep_gray: bool = False  # send the pixels back (a recording of a source without H.264)
    roi_tracking: bool = False
    lean: bool = False  # send back each frame without its detections and poses (FrameResult.lean: no sink shows them)
    threads: str = "SLICE"  # the decoder's threading (SLICE: one thread for cameras' H.264): a worker is one core


@dataclass
class ChunkResult:
    """A chunk's frames, tracked, and every decoded frame's presentation time as the decoder stamped it."""

    chunk: Chunk
    stamps: list[tuple[float | None, bool, int]] = field(default_factory=list)  # (pts s, damaged, packets read)
    results: dict[int, FrameResult] = field(default_factory=dict)  # stamp number -> its frame, tracked
    packets_read: int = 0
    error: tuple[str, str, str | None] | None = None  # an InputError met (source, message, field)
    seconds: float = 0.0  # wall time the chunk took in its worker
    cpu_seconds: float = 0.0
    max_rss_mb: float = 0.0  # the worker's peak resident memory so far
    worker: str = ""  # host:pid
    still: bool = False  # a still image: one frame, no decoder (its result as it is)


@dataclass
class StampLog(VideoHealth):
    """A VideoHealth that also keeps every decoded frame's presentation time, whether damaged, and the packets read
    by then, for the main process to replay (its copies share the list)."""

    stamps: list[tuple[float | None, bool, int]] = field(default_factory=list)

    def stamp(self, pts: float | None, damaged: bool = False) -> float | None:
        self.stamps.append((pts, damaged, self.packets))
        return super().stamp(pts, damaged)


def source_path(rig: Rig, entry: CameraEntry) -> Path | str:
    """A camera's source as CameraTracker.run opens it: a path, or a URL as it is."""
    path = rig.resolve(entry.source)
    return path if path.exists() or not entry.source.startswith(("rtsp:", "http:", "https:")) else entry.source


def plan_video(rig: Rig, entry: CameraEntry, chunk_frames: int = CHUNK_FRAMES) -> VideoPlan:
    """Cut one camera's video at keyframes (reads its packets, decodes nothing); a video that cannot be cut safely, a
    still image or a stream is one chunk."""
    src = source_path(rig, entry)
    health = VideoHealth()
    clock = rig.clock(entry)

    def whole(reason: str, count: int | None = None) -> VideoPlan:
        return VideoPlan(entry.name, (Chunk(entry.name, 0, None, None, 0, clock.capture(0, 0.0)),), health,
                         count or 0, reason)

    if isinstance(src, str) or is_image(src) or not Path(src).is_file():
        return whole("not a video file")
    with open_video(src) as container:
        stream = container.streams.video[0]
        health.declare(container, src)
        if stream.codec_context.has_b_frames:
            return whole("B-frames")
        base = stream.time_base
        keys: list[tuple[int, int]] = []  # (packets before, pts)
        n = 0
        last_key_pts = None
        try:
            for packet in container.demux(stream):
                if not packet.size:
                    continue
                if packet.pts is None or packet.is_corrupt:
                    return whole("packets without timestamps" if packet.pts is None else "damaged packets")
                if packet.is_keyframe:
                    if last_key_pts is not None and packet.pts <= last_key_pts:
                        return whole("keyframe timestamps not increasing")
                    keys.append((n, packet.pts))
                    last_key_pts = packet.pts
                n += 1
        except Exception:  # the decoder says what is wrong with it, once it gets there
            return whole("unreadable packets")
    if not keys or keys[0][0] != 0 or base is None:
        return whole("does not start with a keyframe", n)
    starts = [keys[0]]
    for before, pts in keys[1:]:
        if before - starts[-1][0] >= chunk_frames:
            starts.append((before, pts))
    chunks = []
    for k, (before, pts) in enumerate(starts):
        count = starts[k + 1][0] - before if k + 1 < len(starts) else None
        chunks.append(Chunk(entry.name, k, pts if k else None, count, before, clock.capture(before, float(pts * base))))
    return VideoPlan(entry.name, tuple(chunks), health, n)


EXIT_ORPHANED = 70  # a worker whose parent died ends with this status (nobody reads it)
_RIGS: dict[tuple[str, float], Rig] = {}


def worker_rig(path: Path) -> Rig:
    """A worker's rig, loaded once per process (and again when its file changed)."""
    key = (str(path), Path(path).stat().st_mtime)
    if key not in _RIGS:
        _RIGS[key] = load_rig(path)
    return _RIGS[key]


def run_chunk(task: ChunkTask) -> ChunkResult:
    """Track one chunk (in a worker process, a Ray task or in place): a fresh detector, a decoder of its own."""
    import cv2

    t0, c0 = time.perf_counter(), time.process_time()
    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)  # a worker is one core: N workers, N cores (in place: given back after the chunk)
    try:
        return _run_chunk(task, t0, c0)
    finally:
        cv2.setNumThreads(threads)


def _run_chunk(task: ChunkTask, t0: float, c0: float) -> ChunkResult:
    out = ChunkResult(task.chunk)
    log = StampLog()
    chunk = task.chunk
    src: Path | str = ""
    try:  # bad input comes back as data: Ray would wrap the exception in its own, with a traceback in its text
        rig = worker_rig(task.rig_path)
        entry = next(c for c in rig.cameras if c.name == task.chunk.camera)
        tracker = CameraTracker.from_rig(rig, entry, task.refinement, packets=task.packets,
                                         roi_tracking=task.roi_tracking)
        src = source_path(rig, entry)
        if chunk.start_pts is None and chunk.packets is None:  # the whole video (or image, or stream) in one
            source = frames(src, rig.clock(entry), packets=task.packets, health=log)
        else:
            container = open_video(src)
            source = _closing(container, decoded_frames(container, src, rig.clock(entry), packets=task.packets,
                                                        health=log, chunk=(chunk.start_pts, chunk.packets),
                                                        threads=task.threads, first_index=chunk.packets_before))
        for frame in source:
            result = tracker.process(frame)
            keep = task.keep_gray and frame.packet is None
            result = replace(result, frame=replace(frame, gray=frame.gray if keep else None, bgr=None, video=None))
            out.results[len(log.stamps) - 1] = result.lean() if task.lean else result
    except InputError as exc:
        out.error = (exc.source, exc.message, exc.field)
    out.stamps = log.stamps
    out.still = bool(src) and is_image(src)
    out.packets_read = log.packets
    out.seconds = time.perf_counter() - t0
    out.cpu_seconds = time.process_time() - c0
    out.max_rss_mb = peak_rss_mb()
    out.worker = f"{os.uname().nodename}:{os.getpid()}"
    return out


def peak_rss_mb() -> float:
    """This process's peak resident memory, MB: VmHWM (its own, since it was started), else getrusage's (which a
    spawned worker inherits from the process it was forked from)."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    except (OSError, ValueError, IndexError):
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def _closing(container: Any, items: Iterator[Any]) -> Iterator[Any]:
    """items, then the container closed."""
    with container:
        yield from items


class Runner(Protocol):
    """Runs tasks somewhere: submit a chunk (or call a module-level function on one argument, both picklable) returns
    a handle, wait its result (a ChunkResult for a chunk)."""

    def submit(self, task: ChunkTask) -> Any: ...

    def call(self, fn: Callable[[Any], Any], arg: Any) -> Any: ...

    def wait(self, handle: Any) -> Any: ...

    workers: int


class InPlace:
    """Runs each task in this process when its result is wanted (--workers 1)."""

    workers = 1

    def submit(self, task: ChunkTask) -> Any:
        return run_chunk, task

    def call(self, fn: Callable[[Any], Any], arg: Any) -> Any:
        return fn, arg

    def wait(self, handle: Any) -> Any:
        fn, arg = handle
        return fn(arg)

    def close(self) -> None:
        pass


def ready(_: object = None) -> str:
    """A worker's host:pid once it has imported the tracker (benchmarks warm the workers with it)."""
    return f"{os.uname().nodename}:{os.getpid()}"


def _worker_init() -> None:
    """A worker process: one thread for OpenCV, and it ends with its parent."""
    import multiprocessing as mp
    import threading

    import cv2

    cv2.setNumThreads(1)
    parent = mp.parent_process()
    if parent is not None:
        threading.Thread(target=_end_with, args=(parent,), daemon=True, name="end-with-parent").start()


def _end_with(parent: Any) -> None:
    """Wait on the parent's sentinel; once it is gone (killed: nobody will read the results), end this worker."""
    parent.join()
    os._exit(EXIT_ORPHANED)


class LocalPool:
    """Worker processes on this machine (spawned: no state inherited from the parent)."""

    def __init__(self, workers: int) -> None:
        import multiprocessing as mp

        self.workers = workers
        self.pool = ProcessPoolExecutor(workers, mp_context=mp.get_context("spawn"), initializer=_worker_init)

    def submit(self, task: ChunkTask) -> Future:
        return self.pool.submit(run_chunk, task)

    def call(self, fn: Callable[[Any], Any], arg: Any) -> Future:
        return self.pool.submit(fn, arg)

    def warm(self) -> set[str]:
        """Start every worker and import the tracker in it; the workers' host:pid."""
        return set(self.pool.map(ready, range(4 * self.workers), chunksize=1))

    def wait(self, handle: Future) -> Any:
        return handle.result()

    def close(self) -> None:
        self.pool.shutdown(wait=True, cancel_futures=True)


class RayRunner:
    """Chunks as Ray tasks: a cluster at address (ray://host:10001, or 'auto'), or a local Ray with `workers` CPUs
    when address is '' (or 'local')."""

    def __init__(self, address: str = "", workers: int | None = None) -> None:
        ray = import_ray()
        self.ray = ray
        self.started = False
        if not ray.is_initialized():
            if address in ("", "local"):
                ray.init(address=None, num_cpus=workers, include_dashboard=False, log_to_driver=False,
                         configure_logging=False)
            else:
                connect_ray(ray, address)
            self.started = True
        self.workers = int(ray.cluster_resources().get("CPU", 1))
        self.remote = ray.remote(num_cpus=1, max_retries=2)(run_chunk)
        self.remotes: dict[Callable[[Any], Any], Any] = {}

    def submit(self, task: ChunkTask) -> Any:
        return self.remote.remote(task)

    def call(self, fn: Callable[[Any], Any], arg: Any) -> Any:
        if fn not in self.remotes:
            self.remotes[fn] = self.ray.remote(num_cpus=1, max_retries=2)(fn)
        return self.remotes[fn].remote(arg)

    def warm(self) -> set[str]:
        """Start the Ray workers and import the tracker in them; their host:pid."""
        remote = self.ray.remote(num_cpus=1)(ready)
        return set(self.ray.get([remote.remote(k) for k in range(4 * self.workers)]))

    def wait(self, handle: Any) -> Any:
        return self.ray.get(handle)

    def close(self) -> None:
        if self.started:
            self.ray.shutdown()


def check_ray_address(address: str) -> None:
    """A one-line InputError unless address is one Ray can take: '' or 'local' (a Ray started here), 'auto',
    ray://HOST[:PORT] (a cluster through Ray's client, which needs ray[client]) or HOST:PORT (a cluster's GCS)."""
    if address in ("", "local", "auto"):
        return
    match = RAY_ADDRESS.fullmatch(address)
    port = match and match["port"]
    if not match or (port and not 1 <= int(port) <= 65535) or (not match["client"] and not port):
        raise InputError("--ray", f"{address!r} is not a Ray address (expected ray://HOST:PORT, HOST:PORT, auto, "
                                  "or nothing for a Ray started here)")
    if match["client"] and importlib.util.find_spec("grpc") is None:  # Ray's own test of its client's dependencies
        raise InputError("--ray", f"{address} needs Ray's client, which is not installed (install it with: "
                                  f"{RAY_CLIENT_INSTALL})")


def ray_endpoint(address: str) -> tuple[str, int] | None:
    """The host and port a cluster's address names (ray://HOST[:PORT] or HOST:PORT); None for a Ray found by Ray
    ('auto') or started here."""
    match = RAY_ADDRESS.fullmatch(address)
    if address in ("", "local", "auto") or match is None:
        return None
    return match["host"].strip("[]"), int(match["port"] or RAY_CLIENT_PORT)


def probe_ray(address: str, timeout: float = RAY_PROBE_TIMEOUT_S) -> None:
    """A one-line InputError when the cluster's head does not accept a TCP connection within timeout."""
    endpoint = ray_endpoint(address)
    if endpoint is None:
        return
    try:
        socket.create_connection(endpoint, timeout=timeout).close()
    except OSError as exc:
        why = f"no answer within {timeout:.0f} s" if isinstance(exc, TimeoutError) else \
            exc.strerror or type(exc).__name__
        raise InputError("--ray", f"{address} does not answer ({why}; {RAY_EXPECTED})") from None


def connect_ray(ray: Any, address: str) -> None:
    """ray.init to the cluster at address, or a one-line InputError within a bounded time: the head is probed first
    (an unreachable one is refused within RAY_PROBE_TIMEOUT_S), then Ray connects in a thread of its own, given
    RAY_CONNECT_TIMEOUT_S (a port that answers and is no Ray head: Ray would retry for ever). What Ray writes to
    stderr meanwhile (its core's retries, every 5 s) goes to a file dropped after, so a failure is one line."""
    probe_ray(address)
    outcome: list[BaseException | None] = []

    def init() -> None:
        try:
            ray.init(address=address, include_dashboard=False, log_to_driver=False, configure_logging=False)
            outcome.append(None)
        except Exception as exc:  # Ray's ConnectionError, RuntimeError, ...: named in the line
            outcome.append(exc)

    timeout = _env_seconds(RAY_CONNECT_TIMEOUT_ENV, RAY_CONNECT_TIMEOUT_S)
    with _stderr_to_file():
        thread = threading.Thread(target=init, name="ray-connect", daemon=True)  # not its SIGTERM handler either
        thread.start()
        thread.join(timeout)
    if not outcome:
        raise InputError("--ray", f"{address} answers, and no Ray cluster connected within {timeout:g} s "
                                  f"({RAY_EXPECTED})")
    if outcome[0] is not None:
        raise InputError("--ray", f"{address}: could not connect: {outcome[0]} ({RAY_EXPECTED})")


def _env_seconds(name: str, default: float) -> float:
    """A positive number of seconds from the environment, else default."""
    try:
        value = float(os.environ.get(name, ""))
    except ValueError:
        return default
    return value if math.isfinite(value) and value > 0 else default


@contextmanager
def _stderr_to_file() -> Iterator[None]:
    """File descriptor 2 (Python's and Ray's C++ core's stderr) into a temporary file for the block."""
    sys.stderr.flush()
    saved = os.dup(2)
    try:
        with tempfile.TemporaryFile() as sink:
            os.dup2(sink.fileno(), 2)
            try:
                yield
            finally:
                sys.stderr.flush()
                os.dup2(saved, 2)
    finally:
        os.close(saved)


def import_ray() -> Any:
    """The ray module, or a one-line InputError saying how to install it."""
    try:
        import ray
    except ImportError:
        raise InputError("--ray", f"needs Ray, which is not installed (install it with: {RAY_INSTALL})") from None
    return ray


def runner(workers: int | None = None, ray_address: str | None = None) -> InPlace | LocalPool | RayRunner:
    """Where the chunks run: Ray when an address is given ('' for a local Ray), else `workers` local processes (None:
    every core; 1: this process)."""
    if ray_address is not None:
        check_ray_address(ray_address)
        return RayRunner(ray_address, workers)
    workers = workers or os.cpu_count() or 1
    return InPlace() if workers == 1 else LocalPool(workers)


class Scheduler:
    """Hands chunks out in capture-time order, keeping at most `window` submitted and not yet taken, and gives each
    back when asked for (submitting up to it first when needed)."""

    def __init__(self, run: Runner, tasks: list[ChunkTask], window: int) -> None:
        self.run = run
        self.todo = deque(sorted(tasks, key=lambda t: (t.chunk.start_time, t.chunk.number)))
        self.window = max(window, 1)
        self.handles: dict[tuple[str, int], Any] = {}
        self.done: list[ChunkResult] = []  # for benchmarks: every result, its timings
        self._fill()

    def _submit(self) -> None:
        task = self.todo.popleft()
        self.handles[(task.chunk.camera, task.chunk.number)] = self.run.submit(task)

    def _fill(self) -> None:
        while self.todo and len(self.handles) < self.window:
            self._submit()

    def take(self, chunk: Chunk) -> ChunkResult:
        key = (chunk.camera, chunk.number)
        while key not in self.handles:
            self._submit()
        handle = self.handles.pop(key)
        self._fill()
        result = self.run.wait(handle)
        self.done.append(result)
        self._fill()
        return result


def replay(plan: VideoPlan, take: Callable[[Chunk], ChunkResult], clock: FrameClock, health: VideoHealth,
           first_warning: bool = True) -> Iterator[FrameResult]:
    """One camera's frames from its chunks' results, as one pass over the video gives them: frame numbers, dropped
    frames and health replayed through `health` (declared as the plan's), the last frame carrying the health at the
    video's end, a chunk's InputError raised where it was met."""
    held: FrameResult | None = None
    seen_first = not first_warning
    for chunk in plan.chunks:
        result = take(chunk)
        if result.still:
            yield from result.results.values()
            continue
        for k, (pts, damaged, read) in enumerate(result.stamps):
            health.packets = chunk.packets_before + read
            t = health.stamp(pts, damaged)
            if t is None:
                continue  # dropped here (the chunk's own pass may have kept it: it did not see the frames before)
            capture = clock.capture(health.decoded - 1, t)
            if math.isnan(capture):
                health.unlisted_frame(health.decoded - 1)
                continue
            r = result.results.get(k)
            if r is None and result.error is not None:
                raise InputError(*result.error)  # met on this frame (its size, say): where one pass meets it
            if r is None or r.frame.time != capture:
                raise RuntimeError(f"{plan.camera}: chunk {chunk.number} disagrees with its video at frame {k}")
            warnings = r.warnings if not seen_first else ()
            seen_first = True
            r = replace(r, frame=replace(r.frame, index=health.decoded - 1, video=health.report()), warnings=warnings)
            if held is not None:
                yield held
            held = r
        if result.error is not None:
            raise InputError(*result.error)
        health.packets = chunk.packets_before + result.packets_read
    health.finish()
    if held is not None:
        end = health.report()
        assert held.frame.video is not None
        yield replace(held, frame=replace(held.frame, video=replace(end, news=held.frame.video.news + end.news)))


def plan_rig(rig: Rig, cameras: list[str] | None = None, chunk_frames: int = CHUNK_FRAMES) -> list[VideoPlan]:
    """Every camera's plan (one line of error for a camera that cannot be read)."""
    entries = [c for c in rig.cameras if cameras is None or c.name in cameras]
    if not entries:
        raise InputError(rig.path, "no cameras to track (expected at least one)", "cameras")
    for e in entries:  # what the workers read, checked here before any work, in track_rig's order
        load_camera(rig.resolve(e.calibration))
    for e in entries:
        src = source_path(rig, e)
        if not isinstance(src, str) and not Path(src).is_file():
            raise InputError(src, "image or video not found")
    return [plan_video(rig, e, chunk_frames) for e in entries]


def track_chunks(rig: Rig, run: Runner, refinement: Refinement = DEFAULT_REFINEMENT, packets: bool = False,
                 keep_gray: bool = False, roi_tracking: bool = False, stats: TrackStats | None = None,
                 plans: list[VideoPlan] | None = None, chunk_frames: int = CHUNK_FRAMES,
                 window: int | None = None, scheduler: list[Scheduler] | None = None, lean: bool = False
                 ) -> Iterator[FrameResult]:
    """All cameras of a rig, tracked chunk by chunk by `run`, merged into one stream ordered by capture time (as
    pipeline.track_rig gives it). stats: as track_rig's. scheduler: a list that gets the Scheduler (benchmarks).
    lean: each frame without its detections and poses (FrameResult.lean)."""
    if rig.path is None:
        raise InputError("rig", "has no file (the workers read it)")
    plans = plans if plans is not None else plan_rig(rig, chunk_frames=chunk_frames)
    entries = {c.name: c for c in rig.cameras}
    healths = {p.camera: replace(p.health) for p in plans}
    if stats is not None:
        stats.videos.update(healths)
    tasks = [ChunkTask(Path(rig.path).resolve(), c, refinement, packets, keep_gray, roi_tracking,  # any node, any cwd
                       lean) for p in plans for c in p.chunks]
    sched = Scheduler(run, tasks, window or max(2 * run.workers, run.workers + len(plans)))
    if scheduler is not None:
        scheduler.append(sched)
    streams = [replay(p, sched.take, rig.clock(entries[p.camera]), healths[p.camera]) for p in plans]
    yield from heapq.merge(*streams, key=lambda r: r.time)
