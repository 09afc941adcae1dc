"""The tracking pipeline: frames -> detections -> poses -> pair offsets, per camera, merged by capture time."""

from __future__ import annotations

import heapq
from collections import Counter
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Protocol

import numpy as np

from tracking.camera import CameraModel, load_camera
from tracking.detection import DEFAULT_REFINEMENT, Detections, MarkerDetector, Refinement
from tracking.errors import InputError
from tracking.estimate import ConeEstimate
from tracking.images import Frame, VideoHealth, frames, to_the_end
from tracking.marker_tracker import MarkerTracker
from tracking.mirror import drop_mirrored, mirror_ambiguous, mirror_turns, seen_only_mirrored
from tracking.offsets import (
    BodyGeometry,
    BodyObservation,
    PairGeometry,
    PairOffset,
    body_geometry,
    frame_offsets,
    observe_bodies,
    pair_geometries,
)
from tracking.pose import Choice, MarkerPose, estimate_pose
from tracking.rig import CameraEntry, Marker, Rig


@dataclass
class FrameResult:
    """Everything the tracker found in one frame of one camera."""

    camera: str
    frame: Frame
    detections: Detections
    poses: dict[int, MarkerPose]  # rig markers only, by id
    offsets: list[PairOffset]
    unknown_ids: list[int]  # detected ids that the rig does not list
    observation: BodyObservation | None = None  # both bodies' poses and all rig markers' corners, for fusion
    tracked: bool = True  # False: recorded only (not searched, or not fused), to keep up in real time
    warnings: tuple[str, ...] = ()  # one line each, for the command to print: the calibration's size taken from this
    # (the camera's first) frame
    mirrored: tuple[int, ...] = ()  # ids detected that may be mirrored and that nothing confirmed: dropped
    # (tracking.mirror)
    posed: int | None = None  # len(poses) where the detections and poses were dropped (lean)

    @property
    def time(self) -> float:
        """Capture time, s."""
        return self.frame.time

    @property
    def marker_count(self) -> int:
        """Rig markers posed in the frame."""
        return len(self.poses) if self.posed is None else self.posed

    def lean(self) -> FrameResult:
        """The frame without its detections and marker poses (their count kept): what the offsets CSV and the run's
        summary need, a third of the size a worker sends back (benchmarks/results/scale.md)."""
        return replace(self, detections=Detections([]), poses={}, posed=self.marker_count)

    @property
    def measurements(self) -> list[PairOffset | BodyObservation]:
        """What the frame gives the estimators: its pair offsets, then its body observation (the fusion filter takes
        the observation, which holds the pairs, when there is one: tracking.estimator.preferred)."""
        return [*self.offsets, *([self.observation] if self.observation is not None else [])]


class Sink(Protocol):
    """What takes a run's stream of frames and estimates (viewer.session.Recorder, viewer.archive.ArchiveSink, the live
    Foxglove stream): each frame as it is tracked, each estimate as the estimator gives it, then close once."""

    def on_frame(self, result: FrameResult) -> None: ...

    def on_estimate(self, estimate: ConeEstimate) -> None: ...

    def close(self, stopped: str = "") -> None:
        """Finish; stopped: why the run ended before the end of its sources (empty: it ran to its end)."""


@dataclass
class TrackStats:
    """Counts for the run summary, per camera."""

    frames: Counter = field(default_factory=Counter)
    markers: Counter = field(default_factory=Counter)
    pair_offsets: Counter = field(default_factory=Counter)
    ambiguous: Counter = field(default_factory=Counter)
    unknown_ids: Counter = field(default_factory=Counter)  # id -> detections
    mirrored: Counter = field(default_factory=Counter)  # (camera, id) -> detections dropped as possibly mirrored
    videos: dict[str, VideoHealth] = field(default_factory=dict)  # camera -> its video's health: as of its newest
    # frame (the last carries the health at the video's end), or as track_rig(stats=) keeps it (frames or not)

    def add(self, r: FrameResult) -> None:
        """Count one frame's results."""
        self.frames[r.camera] += 1
        self.markers[r.camera] += r.marker_count
        self.pair_offsets[r.camera] += len(r.offsets)
        self.ambiguous[r.camera] += sum(o.choice == Choice.AMBIGUOUS for o in r.offsets)
        self.unknown_ids.update(r.unknown_ids)
        self.mirrored.update((r.camera, i) for i in r.mirrored)
        if r.frame.video is not None:
            self.videos[r.camera] = r.frame.video

    def never_placed(self, camera: str, why: str) -> str:
        """Why the filter never placed a camera (its CameraState.waiting), said better where it had none of its frames
        because every rig marker it showed was dropped as seen mirrored."""
        from tracking.estimator.state import NOT_SEEN

        mirrored = sorted(i for (cam, i) in self.mirrored if cam == camera)
        if not mirrored or why != NOT_SEEN:
            return why
        return seen_only_mirrored(mirrored)

    def warnings(self, cameras: Iterable[str] = ()) -> list[str]:
        """One line per camera whose video ended early, or whose timestamps went backwards, repeated, jumped or were
        missing, or that gave no frame at all; cameras: the names expected (a camera never heard of is reported)."""
        lines = []
        for camera in dict.fromkeys([*self.videos, *cameras]):
            video = self.videos.get(camera)
            if video is not None and video.troubled():
                lines.append(f"{camera}: {video.summary()}")
            elif not self.frames[camera]:
                lines.append(f"{camera}: no frame could be read" + (f" from {video.source}" if video else ""))
        return lines


@dataclass
class CameraTracker:
    """Detection and poses for one camera of a rig."""

    rig: Rig
    entry: CameraEntry
    camera: CameraModel
    detector: MarkerDetector | MarkerTracker
    keep_color: bool = False
    packets: bool = False  # keep each frame's H.264 packet for recording
    geometries: list[PairGeometry] = field(default_factory=list)
    markers: dict[int, Marker] = field(default_factory=dict)
    bodies: BodyGeometry | None = None
    ambiguous: frozenset[int] = frozenset()  # rig ids a mirror image can read as (tracking.mirror)
    turns: dict[int, np.ndarray] = field(default_factory=dict)  # self-mirroring ids -> how a mirror turns their reading

    def __post_init__(self) -> None:
        self.geometries = pair_geometries(self.rig)
        self.markers = self.rig.marker_by_id
        self.bodies = body_geometry(self.rig)
        self.ambiguous = mirror_ambiguous(self.rig)
        self.turns = mirror_turns(self.rig)

    @classmethod
    def from_rig(cls, rig: Rig, entry: CameraEntry, refinement: Refinement, keep_color: bool = False,
                 packets: bool = False, roi_tracking: bool = False) -> CameraTracker:
        """Load the camera's calibration and build its detector (stateful MarkerTracker with roi_tracking)."""
        camera = load_camera(rig.resolve(entry.calibration))
        detector = MarkerDetector(rig.dictionary, refinement, camera, inverted=rig.inverted)
        return cls(rig, entry, camera, MarkerTracker(detector) if roi_tracking else detector, keep_color, packets)

    def process(self, frame: Frame) -> FrameResult:
        """Detect, estimate poses and the pair offsets of one frame; a calibration without a size takes the first
        frame's (the result carries the warning that says so)."""
        width, height = frame.gray.shape[1], frame.gray.shape[0]
        warnings: tuple[str, ...] = ()
        if not self.camera.sized:
            self.camera, warning = self.camera.sized_from(width, height, self.rig.resolve(self.entry.calibration),
                                                          self.entry.source)
            warnings = (warning,)
        problem = self.camera.size_problem(width, height)
        if problem:
            raise InputError(self.entry.source, problem, "image size")
        result = self.measure(frame, self.detector.detect(frame.gray, keep_rejected=self.keep_color))
        return replace(result, warnings=warnings) if warnings else result

    def measure(self, frame: Frame, detections: Detections) -> FrameResult:
        """Poses, pair offsets and the body observation of one frame's detections."""
        poses = {d.id: estimate_pose(d, self.camera, self.rig.marker_size) for d in detections.markers
                 if d.id in self.markers}
        poses, mirrored = drop_mirrored(poses, self.markers, self.ambiguous, self.rig.marker_size, self.camera,
                                          self.turns)
        unknown = [d.id for d in detections.markers if d.id not in self.markers]
        offsets = frame_offsets(self.geometries, poses, self.entry.name, frame.time)
        assert self.bodies is not None
        observation = observe_bodies(self.bodies, poses, self.camera, self.entry.name, frame.time,
                                     self.rig.marker_size)
        return FrameResult(self.entry.name, frame, detections, poses, offsets, unknown, observation,
                           mirrored=tuple(mirrored))

    def skip(self, frame: Frame) -> FrameResult:
        """A frame recorded but not searched for markers (the tracker is behind real time)."""
        return FrameResult(self.entry.name, frame, Detections([]), {}, [], [], tracked=False)

    def run(self, health: VideoHealth | None = None) -> Iterator[FrameResult]:
        """Every frame of the camera's source, processed; the last one carries the video's health at its end
        (health: filled as the frames go)."""
        source = self.entry.source
        path = self.rig.resolve(source)
        src = path if path.exists() or not source.startswith(("rtsp:", "http:", "https:")) else source
        health = health if health is not None else VideoHealth()
        for frame in to_the_end(frames(src, self.rig.clock(self.entry), keep_color=self.keep_color,
                                       packets=self.packets, health=health), health):
            yield self.process(frame)


def track_rig(rig: Rig, refinement: Refinement = DEFAULT_REFINEMENT, cameras: list[str] | None = None,
              keep_color: bool = False, on_frame: Callable[[FrameResult], None] | None = None,
              packets: bool = False, roi_tracking: bool = False, stats: TrackStats | None = None
              ) -> Iterator[FrameResult]:
    """All cameras of a rig, merged into one stream ordered by capture time (roi_tracking: see MarkerTracker).

    stats: keeps every camera's video health from the start, so that a video giving no frame at all is reported
    with its counts too (the results are not counted in it: TrackStats.add does that)."""
    entries = [c for c in rig.cameras if cameras is None or c.name in cameras]
    if not entries:
        raise InputError(rig.path, "no cameras to track (expected at least one)", "cameras")
    trackers = [CameraTracker.from_rig(rig, e, refinement, keep_color, packets, roi_tracking) for e in entries]
    healths = [VideoHealth() for _ in trackers]
    if stats is not None:
        stats.videos.update({t.entry.name: h for t, h in zip(trackers, healths, strict=True)})
    # merge needs each camera's times in order: the decoder drops (and counts) a frame not after its predecessor
    for result in heapq.merge(*(t.run(h) for t, h in zip(trackers, healths, strict=True)), key=lambda r: r.time):
        if on_frame is not None:
            on_frame(result)
        yield result


def source_frame_count(path: Path) -> int | None:
    """Number of frames a video declares, for progress bars (None when unknown)."""
    import av

    try:
        with av.open(str(path)) as c:
            n = c.streams.video[0].frames
            return int(n) if n else None
    except Exception:
        return None
