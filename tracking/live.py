"""Live tracking: a worker process per camera (decode, detect, poses), one fusion filter, camera health.

Each camera runs in its own process, so decoding and detection use every core and a camera that stops does
not stop the others. Workers send their FrameResults (pixels dropped when the H.264 packet carries them) and
state changes through one queue. The main process puts the results back in capture-time order (waiting at
most REORDER_S for a slower camera), applies them to the topside filter, and keeps every camera's health.
"""

from __future__ import annotations

import heapq
import multiprocessing as mp
import os
import queue
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path

import cv2

from tracking.detection import DEFAULT_REFINEMENT, Refinement
from tracking.errors import InputError
from tracking.estimate import ConeEstimate
from tracking.estimator import FilterTuning, TopsideFilter, filter_frame
from tracking.images import Frame
from tracking.pipeline import CameraTracker, FrameResult
from tracking.rig import Rig, load_rig
from tracking.sources import (
    CameraState,
    FreezeDetector,
    Pacer,
    SourceEvent,
    SourceKind,
    camera_frames,
    first_capture_time,
    source_kind,
    uses_wall_clock,
)

REORDER_S = 0.15  # longest wait for a slower camera before a frame is fused out of order
LOST_AFTER_S = 1.0  # wall-clock seconds without a frame before a camera counts as lost
RECONNECT_S = 2.0  # wait between attempts to reopen a lost device or stream
STALE_S = 0.5  # an estimate whose newest measurement is older than this is shown as NO DATA
LATE_S = 0.1  # a frame this far behind the live clock is recorded but not searched, so the worker catches up
WORKER_NICE = 5  # workers yield the cores to the main process, which then never falls behind them
QUEUE_FRAMES = 64  # frames a worker may have in flight; in real time, newer frames replace what does not fit
WAIT_S = 0.2  # a worker waiting for a credit or for room in the queue checks this often whether it should stop
START_DELAY_S = 0.5  # replay starts this long after every worker is ready
EMA = 0.1  # smoothing of the frame-rate estimate


@dataclass
class CameraHealth:
    """What the main process knows of one camera."""

    name: str
    state: CameraState = CameraState.STARTING
    detail: str = ""
    frames: int = 0
    markers: int = 0  # markers found in the newest frame
    last_capture: float | None = None  # capture time of the newest frame
    last_wall: float | None = None  # wall time it arrived
    fps: float = 0.0
    skipped: int = 0  # frames recorded only (not searched, or not fused), to stay in real time


@dataclass
class LiveUpdate:
    """What happened since the previous update."""

    now: float  # the live clock: capture time that is due now
    results: list[FrameResult] = field(default_factory=list)
    estimates: list[ConeEstimate] = field(default_factory=list)
    events: list[SourceEvent] = field(default_factory=list)
    cameras: dict[str, CameraHealth] = field(default_factory=dict)
    last_measurement: float | None = None  # capture time of the newest measurement the filter accepted

    def in_capture_order(self) -> list[FrameResult | ConeEstimate]:
        """Frames and estimates by capture time, each frame before the estimates of its time."""
        order = sorted([(r.time, 0, k) for k, r in enumerate(self.results)]
                       + [(e.time, 1, k) for k, e in enumerate(self.estimates)])
        return [self.results[k] if kind == 0 else self.estimates[k] for _, kind, k in order]


@dataclass
class _Channel:
    """A camera worker's line to the main process: its queue, the stop event, and whether the main process lives."""

    out: mp.Queue
    stop: mp.Event
    parent: object | None = field(default_factory=mp.parent_process)

    def done(self) -> bool:
        """Stop asked for, or the main process died without asking (killed): an orphan must not run on."""
        if self.parent is not None and not self.parent.is_alive():
            self.out.cancel_join_thread()  # nobody reads the queue any more: exit without waiting to flush it
            return True
        return self.stop.is_set()

    def send(self, item: object, credit: mp.Semaphore | None = None) -> bool:
        """Put an item on the queue, first taking a credit when given, waiting for either (a slower camera, a slow
        main process) but not for a main process that is gone; False when the worker should stop."""
        while credit is not None and not credit.acquire(timeout=WAIT_S):
            if self.done():
                return False
        while True:
            try:
                self.out.put(item, timeout=WAIT_S)
                return True
            except queue.Full:
                if self.done():
                    return False


def _send_frames(channel: _Channel, name: str, frames: Iterable[Frame], tracker: CameraTracker,
                 late: Callable[[float], bool], credits: mp.Semaphore | None) -> bool:
    """Track and send one pass of a camera's frames (a frozen image announced, not measured; a frame late for the live
    clock only recorded); False when the worker should stop."""
    freeze = FreezeDetector()
    state = CameraState.STARTING
    for frame in frames:
        if channel.done():
            return False
        frozen = freeze.frozen(frame)
        if frozen != (state == CameraState.FROZEN) or state == CameraState.STARTING:
            state = CameraState.FROZEN if frozen else CameraState.LIVE
            if not channel.send(SourceEvent(name, state, time.time(), "the image does not change" if frozen else "")):
                return False
        if frozen:
            continue  # a frozen image re-stamped with new times would be a false measurement
        result = tracker.skip(frame) if late(frame.time) else tracker.process(frame)
        if frame.packet is not None:  # the packet carries the image: do not ship the pixels
            result = replace(result, frame=replace(frame, gray=None, bgr=None))
        if not channel.send(result, credits):
            return False
    return True


def camera_worker(rig_path: Path, name: str, out: mp.Queue, stop: mp.Event, t0: mp.Value, origin: mp.Value,
                  speed: float, refinement: Refinement, realtime: bool, loop_until: float | None = None,
                  credits: mp.Semaphore | None = None) -> None:
    """Process entry: track one camera until its source ends, stop is set or the main process is gone; reconnect
    lost live sources. With credits (a replay flat out), each frame sent takes one, which the main process gives
    back when it has fused the frame: a camera cannot run ahead of the slowest by more than its credits."""
    channel = _Channel(out, stop)
    rig = load_rig(rig_path)
    entry = next(c for c in rig.cameras if c.name == name)
    cv2.setNumThreads(1)  # one process per camera already uses every core
    if hasattr(os, "nice"):
        os.nice(WORKER_NICE)  # when the cores are short, the main process (fusion, the live view) goes first
    tracker = CameraTracker.from_rig(rig, entry, refinement, packets=True, roi_tracking=True)
    if not channel.send(SourceEvent(name, CameraState.STARTING, time.time(), "ready", first_capture_time(rig, entry))):
        return
    while t0.value == 0.0 and not channel.done():
        time.sleep(0.01)
    pacer = Pacer(t0.value, speed, origin.value)
    live_source = source_kind(entry.source) != SourceKind.FILE

    def late(t: float) -> bool:
        """A frame's capture time is too far behind the live clock to search it in real time."""
        behind = (time.time() + entry.time_offset - t) if live_source else pacer.now() - t
        return realtime and behind > LATE_S

    while not channel.done():
        try:
            if not _send_frames(channel, name, camera_frames(rig, entry, pacer, loop_until), tracker, late, credits):
                return
            if not live_source:
                channel.send(SourceEvent(name, CameraState.ENDED, time.time(), "end of file"))
                return
            if not channel.send(SourceEvent(name, CameraState.LOST, time.time(), "stream ended; reconnecting")):
                return
        except InputError as exc:
            if not channel.send(SourceEvent(name, CameraState.LOST, time.time(), f"{exc}; reconnecting")):
                return
            if not live_source:
                channel.send(SourceEvent(name, CameraState.ENDED, time.time(), str(exc)))
                return
        stop.wait(RECONNECT_S)


class LiveTracker:
    """Runs every camera of a rig live and fuses them; iterate `updates()` inside a `with` block."""

    def __init__(self, rig: Rig, speed: float = 1.0, refinement: Refinement = DEFAULT_REFINEMENT,
                 cameras: list[str] | None = None, tuning: FilterTuning | None = None,
                 reorder_s: float = REORDER_S, loop_until: float | None = None, ahead_frames: int = QUEUE_FRAMES
                 ) -> None:
        if rig.path is None:
            raise InputError("rig", "has no file (the workers read it)")
        self.rig = rig
        self.wall_clock = uses_wall_clock(rig)
        self.speed = 1.0 if self.wall_clock else speed
        self.realtime = self.wall_clock or self.speed == 1.0
        self.refinement = refinement
        self.names = [c.name for c in rig.cameras if cameras is None or c.name in cameras]
        if not self.names:
            raise InputError(rig.path, "no cameras to track (expected at least one)", "cameras")
        self.loop_until = loop_until  # replay files in a loop up to this capture time (soak tests)
        self.reorder_s = reorder_s if self.realtime else float("inf")  # flat out: strict capture-time order
        self.kf = TopsideFilter(rig, tuning or FilterTuning())
        self.health = {n: CameraHealth(n) for n in self.names}
        self._ctx = mp.get_context("spawn")
        self._queue = self._ctx.Queue(maxsize=QUEUE_FRAMES * len(self.names))
        self._stop = self._ctx.Event()
        self._t0 = self._ctx.Value("d", 0.0)
        self._origin = self._ctx.Value("d", 0.0)  # capture time at which a replay starts
        self._first_times: dict[str, float] = {}
        # flat out, fusion waits for the slowest camera: the others get ahead_frames credits each, so the frames
        # waiting for it stay bounded (in real time a frame waits at most reorder_s; a live source cannot wait)
        self._credits = None if self.realtime else {n: self._ctx.Semaphore(ahead_frames) for n in self.names}
        self._workers: list[mp.process.BaseProcess] = []
        self._pending: list[tuple[float, int, FrameResult, float]] = []  # (time, seq, result, wall arrival)
        self._seq = 0
        self._newest = 0.0  # newest capture time released

    def __enter__(self) -> LiveTracker:
        for name in self.names:
            p = self._ctx.Process(target=camera_worker, name=f"camera-{name}", daemon=True,
                                  args=(self.rig.path, name, self._queue, self._stop, self._t0, self._origin,
                                        self.speed, self.refinement, self.realtime, self.loop_until,
                                        self._credits[name] if self._credits else None))
            p.start()
            self._workers.append(p)
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._t0.value = self._t0.value or time.time()
        deadline = time.time() + 5.0
        while any(p.is_alive() for p in self._workers) and time.time() < deadline:
            self._drain(0.05)  # a worker blocked on a full queue must be able to finish
        for p in self._workers:
            if p.is_alive():
                p.terminate()
            p.join(1.0)
        self._queue.close()
        self._queue.cancel_join_thread()

    def now(self) -> float:
        """The live clock: Unix time for live sources, the replay's capture time for files."""
        if self.wall_clock:
            return time.time()
        if not self._t0.value:
            return 0.0
        if not self.speed < float("inf"):
            return self._newest  # as fast as possible: the newest frame is "now"
        return Pacer(self._t0.value, self.speed, self._origin.value).now()  # the workers' clock

    def _drain(self, timeout: float) -> list[object]:
        """Messages from the workers, waiting up to timeout for the first."""
        items: list[object] = []
        try:
            items.append(self._queue.get(timeout=timeout))
            while True:
                items.append(self._queue.get_nowait())
        except queue.Empty:
            pass
        return items

    def _start_clock_when_ready(self) -> None:
        """Start the replay once every worker has loaded, at the earliest first frame of the files."""
        if self._t0.value == 0.0 and all(h.detail == "ready" or h.state != CameraState.STARTING
                                         for h in self.health.values()):
            self._origin.value = min(self._first_times.values(), default=0.0)
            self._t0.value = time.time() + START_DELAY_S

    def _handle(self, item: object, update: LiveUpdate, wall: float) -> None:
        """One message of a worker."""
        if isinstance(item, SourceEvent):
            h = self.health[item.camera]
            h.state, h.detail = item.state, item.detail
            if item.first_time is not None:
                self._first_times[item.camera] = item.first_time
            update.events.append(item)
        elif isinstance(item, FrameResult):
            h = self.health[item.camera]
            if h.last_capture is not None and item.time > h.last_capture:
                rate = 1.0 / (item.time - h.last_capture)
                h.fps = (1 - EMA) * h.fps + EMA * rate if h.fps else rate
            h.frames += 1
            if not item.tracked:
                h.skipped += 1
            else:
                h.markers = len(item.poses)
            h.last_capture, h.last_wall = item.time, wall
            if h.state in (CameraState.LOST, CameraState.STARTING):
                h.state, h.detail = CameraState.LIVE, ""
            heapq.heappush(self._pending, (item.time, self._seq, item, wall))
            self._seq += 1

    def _watermark(self) -> float:
        """Capture time up to which every running camera has delivered its frames."""
        running = [h.last_capture for h in self.health.values() if h.state in (CameraState.LIVE, CameraState.STARTING)]
        if not running:
            return float("inf")
        return -float("inf") if any(t is None for t in running) else min(running)

    def _release(self, update: LiveUpdate, wall: float, flush: bool = False) -> None:
        """Fuse the frames that are due, in capture-time order."""
        mark = self._watermark()
        while self._pending and (flush or self._pending[0][0] <= mark or wall - self._pending[0][3] >= self.reorder_s):
            t, _, result, _ = heapq.heappop(self._pending)
            if self._credits is not None:
                self._credits[result.camera].release()
            self._newest = max(self._newest, t)
            if self.realtime and result.tracked and self.now() - t > STALE_S:  # too old to show: the main process
                result = replace(result, tracked=False)  # is behind; record the frame, skip its fusion, catch up
                self.health[result.camera].skipped += 1
            update.results.append(result)
            if not result.tracked:
                continue
            measurements = result.measurements
            if measurements:
                update.estimates.extend(filter_frame(self.kf, measurements))

    def _check_lost(self, wall: float, update: LiveUpdate) -> None:
        """A live camera silent for LOST_AFTER_S is lost (a hung stream sends no event)."""
        waiting = {r.camera for _, _, r, _ in self._pending} if self._credits is not None else set()
        for h in self.health.values():
            if h.name in waiting:
                continue  # silent because its frames wait here for a slower camera, and it for their credits
            if h.state == CameraState.LIVE and h.last_wall is not None and wall - h.last_wall > LOST_AFTER_S * (
                    1.0 if self.realtime else 10.0):
                h.state, h.detail = CameraState.LOST, f"no frame for {wall - h.last_wall:.1f} s"
                update.events.append(SourceEvent(h.name, h.state, wall, h.detail))

    def updates(self, period_s: float = 0.1) -> Iterator[LiveUpdate]:
        """One update per period (or sooner when frames arrive), until every source has ended."""
        while True:
            update = LiveUpdate(now=0.0)
            for item in self._drain(period_s):
                self._handle(item, update, time.time())
            self._start_clock_when_ready()
            wall = time.time()
            done = all(h.state == CameraState.ENDED for h in self.health.values()) or (
                not any(p.is_alive() for p in self._workers) and self._queue.empty())
            self._release(update, wall, flush=done)
            self._check_lost(wall, update)
            update.now = self.now()
            update.cameras = self.health
            update.last_measurement = max(self.kf.last_accepted.values(), default=None)
            yield update
            if done and not self._pending:
                return
