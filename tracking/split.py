"""Fusion split over time: a long run's measurements cut into segments fused independently, in worker processes or
Ray tasks (tracking.parallel's runners), then joined.

The filter applies every measurement in capture-time order, so one pass over a run takes the run's frames times the
filter's step however many cores detect (benchmarks/results/scale.md). Split, segment k keeps the estimates of the
frames in [t0 + k S, t0 + (k + 1) S) (S = segment_s, t0 the run's first measurement) and is fused from LEAD_IN_S
before its start: a fresh filter places the cameras (an ambiguous view waits for the evidence that settles it), places
the topside and warms up (REPORT_WARMUP_S) inside that lead-in, whose estimates are dropped. The smoothed mode also
reads TRAIL_S past the segment's end, so that its last estimates are smoothed by as much of the future as the one
pass's (SMOOTHER_LAG_S at least). Segment 0 is fused on this process as the measurements arrive, as the one pass
does (a run no longer than S is the one pass); the later ones go to the runner as soon as their measurements are in.

The segments depend on the measurements' times, segment_s and the overlaps only, never on how many workers run them:
the output is the same for every number of workers and on Ray. A segment's filter knows less than the one pass's
at its start (the lead-in against all the run before it): after the lead-in its shown offsets lie within 0.5σ of
the one pass's, where the one pass shows one too (measured in benchmarks/results/scale.md, whence LEAD_IN_S). A
segment's frames before its filter accepted anything are given as withheld rows (σ too large) once anything was
shown before, as the one pass gives a row for every frame from its first.

What the filter found over the run (tracking.estimator.FilterReport) is joined from the segments': a camera never
placed in any of them is reported unplaced; the markers' size evidence is summed, each segment's in proportion to the
share of its span it keeps (the overlaps are not counted twice); the offsets withheld as the topside through its
cones are counted among the rows kept.
"""

from __future__ import annotations

import math
import os
import time
from collections import deque
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from tracking.estimate import WITHHELD_BELOW, WITHHELD_SIGMA, ConeEstimate
from tracking.estimator import ESTIMATORS, FilterReport, Measurement, cone_points, frames
from tracking.estimator.noise import SMOOTHER_LAG_S
from tracking.parallel import Runner, worker_rig
from tracking.rig import Rig
from tracking.scale import ScaleEvidence

SPLIT_MODES = ("fused", "smoothed")  # the modes with a filter; paper and raw cost nothing worth splitting
SEGMENT_S = 300.0  # s of capture kept per segment: the lead-in is LEAD_IN_S / SEGMENT_S (7 %) more filter work, and
# six hours are 72 segments, fused on as many cores while the others detect (benchmarks/results/scale.md); a run no
# longer than this is fused in one pass, as before
LEAD_IN_S = 20.0  # s fused before a segment's start and dropped: the cameras placed (an ambiguous far view waits
# for the evidence), the topside placed and warmed up (REPORT_WARMUP_S), the cameras' poses and biases settled to
# within 0.5σ of the one pass's (benchmarks/results/scale.md: with 10 s offsets stayed up to 0.7σ off for 9 s
# after a segment's start, with 20 s none was beyond 0.37σ)
TRAIL_S = {"fused": 0.0, "smoothed": SMOOTHER_LAG_S}  # s read past a segment's end: the smoother's look-ahead (the
# one pass smooths every step with SMOOTHER_LAG_S of the future at least)


@dataclass(frozen=True)
class Segment:
    """Which estimates a segment keeps: those at capture times in [start, stop)."""

    number: int
    start: float
    stop: float


@dataclass(frozen=True)
class SegmentTask:
    """What a worker needs to fuse one segment: the rig by path (every node sees it), the mode, the measurements from
    its lead-in to its trail, and whether to send back the cameras' poses (a recording or an archive shows them)."""

    rig_path: Path
    mode: str
    segment: Segment
    measurements: tuple[Measurement, ...]
    poses: bool = False


@dataclass
class SegmentResult:
    """A segment's kept estimates and what its filter found (FilterReport), with its timings."""

    segment: Segment
    estimates: list[ConeEstimate] = field(default_factory=list)
    first_shown: float = math.inf  # capture time of its first estimate from the filter (rows before it: withheld)
    report: FilterReport = field(default_factory=FilterReport)
    share: float = 1.0  # the part of its measurements' span it keeps (its report's evidence counts this much)
    measurements: int = 0
    seconds: float = 0.0
    cpu_seconds: float = 0.0
    worker: str = ""

    def __getstate__(self) -> dict[str, Any]:
        """Pickled with its estimates as columns (without the cameras' poses): a third of the driver's time to take
        them back as objects, four a frame (benchmarks/results/scale.md)."""
        return {**self.__dict__, "estimates": pack(self.estimates)}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state, estimates=unpack(state["estimates"]))


def pack(estimates: list[ConeEstimate]) -> Any:
    """Estimates as columns: times, names and reasons by index, offsets and covariances stacked (NaN: none); as they
    are when they hold the cameras' poses."""
    if any(e.T_jacket_cameras is not None for e in estimates):
        return estimates
    names: dict[Any, int] = {}
    index = np.array([[names.setdefault(v, len(names)) for v in (e.cone, e.cameras, e.withheld)] for e in estimates],
                     dtype=np.int32).reshape(-1, 3)
    covariance = np.array([np.full((3, 3), np.nan) if e.covariance is None else e.covariance for e in estimates])
    return (np.array([e.time for e in estimates]), list(names), index, np.array([e.offset for e in estimates]),
            covariance.reshape(-1, 3, 3))


def unpack(packed: Any) -> list[ConeEstimate]:
    """The estimates of pack's columns."""
    if isinstance(packed, list):
        return packed
    times, names, index, offsets, covariance = packed
    known = ~np.isnan(covariance[:, 0, 0])
    return [ConeEstimate(t, names[i], offsets[k], names[c], covariance[k] if known[k] else None, None, names[w])
            for k, (t, (i, c, w)) in enumerate(zip(times.tolist(), index.tolist(), strict=True))]


@dataclass
class SplitInfo:
    """What a split run did, for the command's summary and the benchmarks."""

    segments: int = 0  # 1: the run was fused in one pass
    results: list[SegmentResult] = field(default_factory=list)  # the segments fused by the runner (not segment 0)


def fuse_segment(task: SegmentTask) -> SegmentResult:
    """Fuse one segment (in a worker process, a Ray task or in place)."""
    t0, c0 = time.perf_counter(), time.process_time()
    out = fuse(worker_rig(task.rig_path), task.mode, task.measurements, task.segment, task.poses)
    out.seconds, out.cpu_seconds = time.perf_counter() - t0, time.process_time() - c0
    out.worker = f"{os.uname().nodename}:{os.getpid()}"
    return out


def fuse(rig: Rig, mode: str, measurements: Iterable[Measurement], segment: Segment, poses: bool = True
         ) -> SegmentResult:
    """One segment's estimates from its measurements (lead-in and trail included): those it keeps, each frame it keeps
    before its filter's first estimate given as withheld rows."""
    measurements = list(measurements)
    out = SegmentResult(segment, measurements=len(measurements))
    kept = [e for e in ESTIMATORS[mode](rig, iter(measurements), report=out.report)
            if segment.start <= e.time < segment.stop]
    out.first_shown = kept[0].time if kept else math.inf
    cones = sorted(cone_points(rig))
    times = [g[0].time for g in frames(measurements) if segment.start <= g[0].time < min(segment.stop,
                                                                                         out.first_shown)]
    pending = [ConeEstimate(t, cone, np.full(3, np.nan), (), withheld=WITHHELD_SIGMA)
               for t in dict.fromkeys(times) for cone in cones]
    out.estimates = pending + (kept if poses else [replace(e, T_jacket_cameras=None) for e in kept])
    if measurements:
        span = measurements[-1].time - measurements[0].time
        keeps = min(measurements[-1].time, segment.stop) - max(measurements[0].time, segment.start)
        out.share = min(1.0, max(0.0, keeps) / span) if span > 0 else 1.0
    return out


def join_reports(reports: list[tuple[FilterReport, float]], below: int) -> FilterReport:
    """The run's FilterReport from its segments' (each with the share of its span it keeps): cameras never placed in
    any, the size evidence summed by share, `below` rows withheld as through the cones at the deepest any found, the
    views any found misread (at the largest departure)."""
    out = FilterReport()
    if not reports:
        return out
    unplaced = set.intersection(*(set(r.unplaced) for r, _ in reports))
    out.unplaced = {name: next(r.unplaced[name] for r, _ in reversed(reports) if name in r.unplaced)
                    for name in reports[-1][0].unplaced if name in unplaced}
    scale = ScaleEvidence()
    for r, share in reports:
        scale.information += share * r.scale.information
        scale.weighted += share * r.scale.weighted
        scale.samples += round(share * r.scale.samples)
        if r.scale.example is not None and (scale.example is None or r.scale.example.sigma < scale.example.sigma):
            scale.example = r.scale.example
    if scale.samples == 0 and any(r.scale.samples for r, _ in reports):
        scale.samples = 1  # something measured the scale, if only in an overlap
    out.scale = scale
    deepest = min((r.below[1] for r, _ in reports if r.below[0]), default=0.0)
    out.below = (below, deepest) if below else (0, 0.0)
    for r, _ in reports:
        for key, px in r.misread.items():
            out.misread[key] = max(px, out.misread.get(key, 0.0))
    return out


class _Segments:
    """The segments after the first: their measurements gathered as they arrive, each sent to the runner once its
    last measurement is in, their results taken back in order (at most `limit` sent and not taken)."""

    def __init__(self, run: Runner, rig_path: Path, mode: str, t0: float, segment_s: float, lead_in_s: float,
                 trail_s: float, poses: bool, limit: int) -> None:
        self.run, self.rig_path, self.mode, self.poses = run, rig_path, mode, poses
        self.t0, self.size, self.lead, self.trail = t0, segment_s, lead_in_s, trail_s
        self.limit = max(1, limit)
        self.open: dict[int, list[Measurement]] = {}
        self.sent: deque[Any] = deque()
        self.done: deque[SegmentResult] = deque()
        self.count = 0
        self.last = t0  # capture time of the newest frame added

    def start(self, k: int) -> float:
        return self.t0 + k * self.size

    def add(self, group: list[Measurement]) -> float:
        """One camera frame's measurements into every segment it belongs to (its own, the next ones' lead-in, the
        previous ones' trail); the segments it completes sent. Its capture time."""
        t = self.last = group[0].time
        first = max(1, math.floor((t - self.trail - self.t0) / self.size))
        last = math.floor((t + self.lead - self.t0) / self.size)
        for k in range(first, last + 1):
            if t < self.start(k + 1) + self.trail:
                self.open.setdefault(k, []).extend(group)
        for k in sorted(self.open):
            if self.start(k + 1) + self.trail > t:
                break
            self._send(k)
        return t

    def finish(self) -> None:
        """The run has ended: every segment with frames of its own sent, the others dropped."""
        for k in sorted(self.open):
            if self.start(k) <= self.last:
                self._send(k)
        self.open.clear()

    def _send(self, k: int) -> None:
        segment = Segment(k, self.start(k), self.start(k + 1))
        task = SegmentTask(self.rig_path, self.mode, segment, tuple(self.open.pop(k)), self.poses)
        self.sent.append(self.run.call(fuse_segment, task))
        self.count += 1
        while len(self.sent) > self.limit:
            self.done.append(self.run.wait(self.sent.popleft()))

    def taken(self, everything: bool = False) -> Iterator[SegmentResult]:
        """The results back so far (everything: waiting for the rest), in order."""
        while self.done:
            yield self.done.popleft()
        while everything and self.sent:
            yield self.run.wait(self.sent.popleft())


@dataclass
class _Joined:
    """The segments' estimates as they join: rows before anything was shown dropped (the one pass has none), the
    rows withheld as through the cones counted, each segment's report kept with its share."""

    info: SplitInfo
    reports: list[tuple[FilterReport, float]] = field(default_factory=list)
    below: int = 0
    shown: bool = False

    def keep(self, e: ConeEstimate, first_shown: float = -math.inf) -> bool:
        """Whether a segment's row joins the run's (first_shown: the segment filter's first estimate)."""
        if not (self.shown or e.time >= first_shown):
            return False
        self.shown, self.below = True, self.below + (e.withheld == WITHHELD_BELOW)
        return True

    def results(self, results: Iterable[SegmentResult]) -> Iterator[ConeEstimate]:
        for r in results:
            self.info.results.append(r)
            self.reports.append((r.report, r.share))
            yield from (e for e in r.estimates if self.keep(e, r.first_shown))


def split_estimates(rig: Rig, measurements: Iterable[Measurement], mode: str, run: Runner,
                    segment_s: float = SEGMENT_S, lead_in_s: float = LEAD_IN_S, trail_s: float | None = None,
                    poses: bool = True, report: FilterReport | None = None, info: SplitInfo | None = None
                    ) -> Iterator[ConeEstimate]:
    """The estimates of `mode` (fused or smoothed) over a run, fused in segments of segment_s each read from
    lead_in_s before its start to trail_s (default TRAIL_S[mode]) after its end; segment 0 here, the others by `run`.
    In time order; report, when given, gets the joined findings at the end (join_reports). poses: keep the cameras'
    poses in the estimates (a recording or an archive shows them)."""
    if rig.path is None:
        raise ValueError("the rig has no file (the workers read it)")
    trail = TRAIL_S[mode] if trail_s is None else trail_s
    source = frames(measurements)  # by camera frame, a frame's body observation in place of its pair offsets (as
    first = next(source, None)  # the filter takes them): the segments carry no more than the filter reads
    if first is None:
        yield from ESTIMATORS[mode](rig, iter(()), report=report)
        return
    t0 = first[0].time
    later = _Segments(run, Path(rig.path).resolve(), mode, t0, segment_s, lead_in_s, trail, poses, run.workers)
    head_end = t0 + segment_s + trail
    joined = _Joined(info if info is not None else SplitInfo())

    def head() -> Iterator[Measurement]:  # segment 0, here: the run until its end and trail
        group: list[Measurement] | None = first
        while group is not None and later.add(group) < head_end:
            yield from group
            group = next(source, None)

    head_report = FilterReport()
    yield from (e for e in ESTIMATORS[mode](rig, head(), report=head_report) if e.time < t0 + segment_s and
                joined.keep(e))
    joined.reports.append((head_report, segment_s / (segment_s + trail) if later.last >= head_end else 1.0))
    for group in source:
        later.add(group)
        yield from joined.results(later.taken())
    later.finish()
    yield from joined.results(later.taken(everything=True))
    joined.info.segments = 1 + later.count
    if report is not None:
        joint = join_reports(joined.reports, joined.below)
        report.unplaced, report.scale, report.below = joint.unplaced, joint.scale, joint.below
