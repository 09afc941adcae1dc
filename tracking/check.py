"""Pre-lift check of a rig against a few seconds of every camera: what each camera sees, whether its clock keeps its
frame rate, how well each cone will be measured, and which markers disagree with the rig.

One CheckReport gathers it (check_rig builds it; the CLI prints it and may record it):

- per camera, its clock: frame intervals against the stream's declared rate (the rate its clock keeps, frames dropped,
  intervals off the frame grid) and what its video reported (timestamps back, jumps, damaged packets);
- per camera and marker: frames seen, distance, angle off the marker's normal, pixels per code cell and the pose's
  reprojection error;
- marker disagreements (tracking/disagreements.py). Per camera frame, each marker's pose is predicted from the other
  markers of its body that the frame shows (the rig fixes where they are relative to each other) and compared with its
  own detected pose: a wrong id shows as a marker far from where the rig puts it, a wrong face as a normal 90° off, a
  centre 0.3 m off as a residual of 0.3 m, a marker turned otherwise than the rig says as a turn about its normal. The
  residuals' medians over the frames are tested against their σ (corner noise through both poses, the frames' own
  spread and the survey's). A camera that sees one marker of each body is checked by the topside's tilt against the
  jacket (it hangs near level): a marker whose face or turn is wrong tilts it. With two markers of a body only, both
  are named: either may be the wrong one.
- per cone, its σ as the fusion filter (tracking.estimator.TopsideFilter) has it after those seconds, and a verdict:
  ``blind`` (no camera sees a topside marker at it and its σ exceeds the report limit: it would show NO DATA),
  ``weak`` (σ above READY_MAX_SIGMA_M, or above the report limit although seen, or measured by one camera only) or
  ``ready``;
- per camera the filter never placed, why (tracking.estimator: no jacket marker in view, an ambiguous view nothing has
  settled yet, corners that do not fit) and so what would let it be placed;
- the markers' size against marker_size (tracking.scale), from cameras that see two markers of one body or have a
  surveyed position; a warning when nothing fixes the scale; an offset that puts the topside through its cones.

Exit status of `topside check`: 0 when every cone is ready and nothing disagrees (CheckReport.ready), 1 otherwise
(a weak or blind cone, a marker that disagrees with the rig, a camera that sees no marker of the rig or is never
placed, a clock off its rate, a survey its markers refute, markers that do not look their stated size, the topside
through its cones, or an id the rig does not list while a rig marker is never seen), 2 for bad input.
"""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from typing import Literal

import numpy as np

from tracking.camera import RMS_KEY, UNSTATED_RMS_PX, CameraModel
from tracking.detection import DEFAULT_REFINEMENT, Refinement
from tracking.disagreements import (
    Disagreement,
    cone_readings,
    cross_camera_disagreements,
    relative_disagreements,
    tilt_disagreements,
)
from tracking.errors import InputError
from tracking.estimate import WITHHELD_BELOW, ConeEstimate, axes_withheld
from tracking.estimator import TopsideFilter, cone_points, filter_frame, point_offset_matrix
from tracking.estimator.disagreement import lens_sigmas
from tracking.estimator.filter import misread_warning
from tracking.estimator.noise import (
    MOUNT_MISMATCH,
    REPORT_MAX_SIGMA_M,
    STATE,
    TILT_BASELINE_SIDES,
    TILT_FLOOR_RAD,
    lens_px,
)
from tracking.estimator.state import topside_pose, untold_turn
from tracking.geometry import skew
from tracking.images import Frame, VideoHealth
from tracking.mirror import seen_only_mirrored
from tracking.offsets import BodyObservation, PairOffset
from tracking.pipeline import CameraTracker, FrameResult
from tracking.rig import Rig
from tracking.scale import ScaleEvidence
from tracking.sources import Pacer, camera_frames

DEFAULT_SECONDS = 5.0  # a few seconds of each camera: enough for the filter to settle a still installation's σ
READY_MAX_SIGMA_M = 0.025  # a ready cone's 2σ (50 mm) takes at most a third of the 150 mm concentricity tolerance
MIN_CAMERAS = 2  # a cone measured by one camera goes blind when that camera fails: weak
TILT_NOTE_LEVER_M = 10.0  # a cone this far off the point or line the seen topside markers span is told how the
# topside's tilt reaches it: a milliradian misread there moves it 10 mm, a fifth of the report limit
SEEN_SHARE = 0.5  # a camera counts for a marker (and its cone) when it detects it in at least this share of its frames
CLOCK_RATE_TOLERANCE = 0.005  # a clock 0.5 % off its declared rate drifts 50 ms in 10 s against the common clock: 12 mm
# of topside travel at the crane's 0.25 m/s
CLOCK_GRID_TOLERANCE = 0.25  # an interval more than this share of a frame interval off a whole number of them is
# irregular (jitter a stamped device clock shows is far below it)
CLOCK_MAX_SHARE = 0.05  # more than this share of frames dropped, or of intervals irregular, is a clock problem
Verdict = Literal["ready", "weak", "blind"]


@dataclass(frozen=True)
class MarkerSight:
    """One camera's view of one rig marker over the check (medians over the frames it was detected in)."""

    camera: str
    marker: int
    frames: int  # frames it was detected in
    share: float  # of the camera's frames
    distance_m: float  # camera to marker centre
    angle_deg: float  # between the marker's normal and its line of sight to the camera
    cell_px: float  # pixels per code cell along the marker's shortest side (foreshortened)
    reprojection_px: float  # RMS reprojection error of its chosen pose

    @property
    def counts(self) -> bool:
        """True when the camera sees it often enough to count on (SEEN_SHARE)."""
        return self.share >= SEEN_SHARE


@dataclass(frozen=True)
class CameraClock:
    """Whether a camera's frames come at the rate its stream declares."""

    camera: str
    frames: int
    seconds: float  # capture time from its first frame to its last
    declared_fps: float  # the stream's (or device's) rate
    measured_fps: float  # the rate its clock keeps: frames per second on the frame grid (dropped frames aside); NaN
    # with fewer than two frames
    dropped: int  # frames missing: intervals spanning k frame intervals count k - 1
    irregular: int  # intervals more than CLOCK_GRID_TOLERANCE of an interval off the frame grid
    video: tuple[str, ...] = ()  # what the video reported (timestamps back or repeated, jumps, damaged packets)

    @property
    def problems(self) -> list[str]:
        """One phrase per problem (empty: the clock keeps its rate)."""
        out = []
        if self.frames < 2:
            out.append(f"{self.frames} frame{'' if self.frames == 1 else 's'}: no interval to measure")
            return out + list(self.video)
        if abs(self.measured_fps / self.declared_fps - 1) > CLOCK_RATE_TOLERANCE:
            out.append(f"runs at {self.measured_fps:.3f} fps, not the {self.declared_fps:.3f} it declares")
        if self.dropped > CLOCK_MAX_SHARE * (self.frames + self.dropped):
            out.append(f"{self.dropped} of {self.frames + self.dropped} frames dropped")
        if self.irregular > CLOCK_MAX_SHARE * (self.frames - 1):
            out.append(f"{self.irregular} of {self.frames - 1} intervals off its frame grid")
        return out + list(self.video)


@dataclass(frozen=True)
class ConeCheck:
    """A cone's predicted σ and verdict."""

    cone: str
    sigma_m: np.ndarray  # (3,) σ of dx, dy, dz after the check's seconds, m
    cameras: tuple[str, ...]  # cameras that see a topside marker at it (or, for a cone without markers, the topside)
    verdict: Verdict
    reason: str


@dataclass(frozen=True)
class CameraCheck:
    """What one camera showed over the check."""

    camera: str
    clock: CameraClock
    sights: tuple[MarkerSight, ...]
    unknown_ids: dict[int, int]  # detected ids the rig does not list -> frames
    T_jacket_camera: np.ndarray | None  # (4, 4) where the filter has it at the end (else where its own markers place
    # it in its median frame), None without a jacket view
    T_jacket_markers: dict[int, np.ndarray] = field(default_factory=dict)  # (4, 4) each marker of that frame as the
    # camera so placed sees it (where the crew can compare it with the rig's)
    survey_m: float | None = None  # distance from its surveyed position to where the filter placed it, m
    survey_conflict: bool = False  # the filter refused the survey as beyond its σ
    first_frame: Frame | None = None  # its first frame (for the recording)
    model: CameraModel | None = None  # its calibration (sized by the first frame when the file gave no size)
    unplaced: str = ""  # why the fusion filter never placed it (tracking.estimator CameraState.waiting); empty: placed
    moves: str = ""  # its mount, where its images show it moving far more than the mount allows: the mount it needs
    mirrored: tuple[int, ...] = ()  # rig ids it detected and dropped as possibly seen mirrored (tracking.mirror)

    @property
    def problems(self) -> list[str]:
        """One line per problem of this camera."""
        out = [f"{self.camera}: clock {p}" for p in self.clock.problems]
        if not self.sights and self.mirrored:
            out.append(f"{self.camera}: never placed, so none of its frames is used: "
                       f"{seen_only_mirrored(list(self.mirrored))}")
        elif not self.sights:
            out.append(f"{self.camera}: sees no marker of the rig in {self.clock.frames} frames")
        elif self.unplaced:
            out.append(f"{self.camera}: never placed, so none of its frames is used: {self.unplaced}")
        if self.moves:
            out.append(f"{self.camera}: {self.moves}")
        if self.survey_conflict:
            out.append(f"{self.camera}: its surveyed position is {self.survey_m:.2f} m from where its markers place "
                       "it, beyond the survey's σ (position or position_sigma wrong?); not used")
        return out


@dataclass
class CheckReport:
    """Everything `topside check` found: cameras, marker disagreements, cones."""

    rig: Rig
    seconds: float
    cameras: list[CameraCheck]
    disagreements: list[Disagreement]
    cones: list[ConeCheck]
    warnings: list[str] = field(default_factory=list)  # one line each (a calibration's size taken from a frame)
    T_jacket_topside: np.ndarray | None = None  # (4, 4) where the filter has the topside at the end
    scale: ScaleEvidence = field(default_factory=ScaleEvidence)  # whether the markers look their stated size
    below: dict[str, float] = field(default_factory=dict)  # cone -> Δz (m) of an offset that puts the topside
    # through its cones (a rig error: tracking.scale.below_cones)

    @property
    def unseen_markers(self) -> list[int]:
        """Rig markers no camera detected."""
        seen = {s.marker for c in self.cameras for s in c.sights}
        return sorted(m.id for m in self.rig.markers if m.id not in seen)

    @property
    def unknown_ids(self) -> dict[int, list[str]]:
        """Detected ids the rig does not list -> the cameras that saw them."""
        out: dict[int, list[str]] = {}
        for c in self.cameras:
            for i in sorted(c.unknown_ids):
                out.setdefault(i, []).append(c.camera)
        return out

    @property
    def disagreeing_markers(self) -> list[int]:
        """Every marker a disagreement names."""
        return sorted({m for d in self.disagreements for m in d.markers})

    def rig_errors(self) -> list[str]:
        """One line per rig error the footage shows: markers that do not look their stated size, the topside through
        its cones."""
        out = [f"marker_size: {self.scale.message()}"] if self.scale.mismatch else []
        return out + [f"cone {cone}: the offset puts the topside {-dz:.2f} m below its cone tip, where no set-down can "
                      "be: marker_size, a marker's centre or a pair's mated offset is wrong"
                      for cone, dz in self.below.items()]

    def problems(self) -> list[str]:
        """One line per finding that makes the rig not ready (empty: ready)."""
        out = self.rig_errors()
        out += [p for c in self.cameras for p in c.problems]
        out += [f"{d.camera}: {d.reason}" for d in self.disagreements]
        if self.unseen_markers and self.unknown_ids:
            ids = ", ".join(f"{i} ({', '.join(cams)})" for i, cams in self.unknown_ids.items())
            out.append(f"markers {', '.join(map(str, self.unseen_markers))} of the rig are never seen, while ids "
                       f"the rig does not list are: {ids}; an id entered wrongly?")
        out += [f"cone {c.cone}: {c.verdict}: {c.reason}" for c in self.cones if c.verdict != "ready"]
        return out

    @property
    def ready(self) -> bool:
        """True when every cone is ready and nothing disagrees: `topside check` exits 0."""
        return not self.problems()


# --- reading a few seconds of every camera ------------------------------------------------------------------------

@dataclass
class CameraRun:
    """One camera's processed frames over the check (their pixels dropped but the first frame's)."""

    tracker: CameraTracker
    results: list[FrameResult]
    health: VideoHealth | None
    first_frame: Frame | None
    warnings: list[str]


def first_seconds(frames: Iterable[Frame], seconds: float) -> Iterator[Frame]:
    """The frames up to `seconds` of capture time after the first one."""
    start = None
    for frame in frames:
        start = frame.time if start is None else start
        if frame.time - start > seconds:
            return
        yield frame


def run_camera(rig: Rig, name: str, seconds: float, refinement: Refinement = DEFAULT_REFINEMENT,
               on_frame: Callable[[], None] | None = None) -> CameraRun:
    """Detect and estimate poses in the first `seconds` of one camera's source (a file is read flat out)."""
    entry = next(c for c in rig.cameras if c.name == name)
    tracker = CameraTracker.from_rig(rig, entry, refinement)
    results, warnings = [], []
    health, first = None, None
    frames = camera_frames(rig, entry, Pacer(time.time(), speed=float("inf")))
    try:
        for frame in first_seconds(frames, seconds):
            result = tracker.process(frame)
            warnings += result.warnings
            first = replace(frame, packet=None) if first is None else first  # its pixels, for the recording
            health = frame.video if frame.video is not None else health
            results.append(replace(result, frame=replace(frame, gray=None, bgr=None, packet=None)))
            if on_frame is not None:
                on_frame()
    finally:
        close = getattr(frames, "close", None)
        if close is not None:
            close()
    return CameraRun(tracker, results, health, first, warnings)


def run_cameras(rig: Rig, seconds: float, refinement: Refinement = DEFAULT_REFINEMENT,
                on_frame: Callable[[], None] | None = None) -> dict[str, CameraRun]:
    """Every camera's first `seconds`, read side by side (live sources then overlap in time)."""
    if not rig.cameras:
        raise InputError(rig.path, "no cameras to check (expected at least one)", "cameras")
    with ThreadPoolExecutor(max_workers=len(rig.cameras)) as pool:
        futures = {c.name: pool.submit(run_camera, rig, c.name, seconds, refinement, on_frame) for c in rig.cameras}
        return {name: future.result() for name, future in futures.items()}


# --- what each camera sees, and its clock ---------------------------------------------------------------------------

def marker_sights(rig: Rig, camera: str, results: list[FrameResult]) -> list[MarkerSight]:
    """Per rig marker the camera detected: frames, median distance, angle, pixels per cell, reprojection error."""
    cells = rig.code_cells
    per: dict[int, list[tuple[float, float, float, float]]] = {}
    for r in results:
        for i, pose in r.poses.items():
            T = pose.T_camera_marker
            distance = float(np.linalg.norm(T[:3, 3]))
            cos = float(-T[:3, 2] @ T[:3, 3]) / max(distance, 1e-9)
            sides = np.linalg.norm(np.roll(pose.corners, -1, axis=0) - pose.corners, axis=1)
            per.setdefault(i, []).append((distance, float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))),
                                          float(sides.min()) / cells, pose.reprojection_error))
    frames = max(len(results), 1)
    return [MarkerSight(camera, i, len(v), len(v) / frames, *(float(x) for x in np.median(np.array(v), axis=0)))
            for i, v in sorted(per.items())]


def camera_clock(camera: str, times: np.ndarray, health: VideoHealth | None) -> CameraClock:
    """A camera's clock from its frames' capture times (N,) and its video's health (declared rate, problems)."""
    interval = health.interval_s if health is not None else 1.0 / 15.0
    video = tuple(health.problems()) if health is not None else ()
    if len(times) < 2:
        return CameraClock(camera, len(times), 0.0, 1.0 / interval, float("nan"), 0, 0, video)
    dt = np.diff(np.asarray(times, dtype=float))
    steps = np.maximum(np.round(dt / interval), 1.0)
    irregular = int(np.sum(np.abs(dt / interval - steps) > CLOCK_GRID_TOLERANCE))
    measured = 1.0 / float(np.median(dt / steps))
    return CameraClock(camera, len(times), float(times[-1] - times[0]), 1.0 / interval, measured,
                       int(np.sum(steps - 1)), irregular, video)


# --- placement, fusion, verdicts ------------------------------------------------------------------------------------

def camera_placement(results: list[FrameResult], T_jacket_camera: np.ndarray | None = None
                     ) -> tuple[np.ndarray | None, dict[int, np.ndarray]]:
    """T_jacket_camera (4, 4): the one given (the filter's), else as the camera's own jacket markers place it in its
    median frame with a jacket view; and every marker of that frame in the jacket frame (4, 4 each) as the camera so
    placed sees it. One far marker places a camera poorly (its tilt is barely seen, and the camera swings about it);
    the filter's pose, from many frames and the other cameras, is far better."""
    views = [r for r in results if r.observation is not None and r.observation.jacket is not None]
    if not views:
        return T_jacket_camera, {}
    median = views[len(views) // 2]
    assert median.observation is not None and median.observation.jacket is not None
    T = np.linalg.inv(median.observation.jacket.T_camera_body) if T_jacket_camera is None else T_jacket_camera
    return T, {i: T @ pose.T_camera_marker for i, pose in sorted(median.poses.items())}


def measurements(results: Iterable[FrameResult]) -> Iterator[list[BodyObservation | PairOffset]]:
    """Each processed frame's measurements for the filter (its body observation, else its pair offsets)."""
    for r in results:
        group = r.measurements
        if group:
            yield group


def fuse(rig: Rig, results: list[FrameResult]) -> tuple[TopsideFilter, list[ConeEstimate]]:
    """The fusion filter over every camera's frames in capture-time order; its cone estimates at the end."""
    kf = TopsideFilter(rig)
    last: list[ConeEstimate] = []
    for group in measurements(sorted(results, key=lambda r: r.time)):
        last = filter_frame(kf, group) or last
    return kf, last


def cone_checks(rig: Rig, estimates: list[ConeEstimate], sights: list[MarkerSight],
                lens: Callable[[str, float], str] = lambda cone, worst: "") -> list[ConeCheck]:
    """A verdict per cone from its σ (the filter's covariance) and the cameras that see a topside marker at it; lens
    names a camera whose calibration error holds a cone's σ up (lens_reason)."""
    by_id = rig.marker_by_id
    topside = [s for s in sights if s.counts and by_id[s.marker].body == "topside"]
    everyone = tuple(sorted({s.camera for s in topside}))
    cones = rig.all_cones()
    by_cone = {e.cone: e for e in estimates}
    out = []
    for cone in cones:
        e = by_cone.get(cone)
        sigma = np.sqrt(np.diag(e.covariance)) if e is not None and e.covariance is not None else np.full(3, np.inf)
        worst = float(sigma.max())
        has_markers = any(m.cone == cone and m.body == "topside" for m in rig.markers)
        cameras = tuple(sorted({s.camera for s in topside if by_id[s.marker].cone == cone})) if has_markers \
            else everyone
        mm = f"σ {worst * 1000:.0f} mm"
        source = (f"seen by {', '.join(cameras)}" if has_markers and cameras else
                  f"no camera sees a topside marker at {cone}" if has_markers else
                  f"no marker at {cone}: from the topside's rigid pose through {', '.join(everyone) or 'no camera'}")
        why = depth_reason(e, cameras, rig, cone) + lens(cone, worst) if e is not None and \
            worst > READY_MAX_SIGMA_M else ""
        if not has_markers:
            why += tilt_reason(rig, cone, {c for s in topside if (c := by_id[s.marker].cone) is not None})
        if not np.isfinite(worst):
            verdict: Verdict = "weak" if has_markers and cameras else "blind"
            reason = f"{source}; the filter gave no estimate in these seconds: it would show NO DATA{why}"
        elif worst > REPORT_MAX_SIGMA_M:
            verdict = "weak" if has_markers and cameras else "blind"
            partly = (f" on {axes_withheld(e.offset)} (its other axes alone)"  # as the filter gave it
                      if e is not None and np.isfinite(e.offset).any() else "")
            reason = (f"{source}; {mm} is above the {REPORT_MAX_SIGMA_M * 1000:.0f} mm report limit: it would show "
                      f"NO DATA{partly}{why}")
        elif worst > READY_MAX_SIGMA_M:
            verdict, reason = "weak", (f"{source}; {mm} is above the {READY_MAX_SIGMA_M * 1000:.0f} mm a ready cone "
                                       f"has{why}")
        elif len(cameras) < MIN_CAMERAS:
            verdict, reason = "weak", f"{source}; {mm}, but from one camera only: it goes blind if that camera fails"
        else:
            verdict, reason = "ready", f"{source}; {mm}"
        out.append(ConeCheck(cone, sigma, cameras, verdict, reason))
    return out


def tilt_reason(rig: Rig, cone: str, seen: set[str]) -> str:
    """'; it turns with the topside's tilt about ...' for a cone without topside markers when the topside markers the
    cameras see (at the cones seen) leave the topside's tilt about some axis to their own orientation (untold_turn, as
    the filter finds it: one cone's markers, or two cones' line): the cone, d m off them across those axes, moves d mm
    a milliradian, its σ about d × TILT_FLOOR_RAD; else ''."""
    points = np.array([m.center for m in rig.markers if m.body == "topside" and m.cone in seen], dtype=float)
    if not len(points):
        return ""
    centre, axes = untold_turn(points, TILT_BASELINE_SIDES * rig.marker_size)
    if not axes.shape[1]:
        return ""
    d = float(np.linalg.norm(skew(cone_points(rig)[cone] - centre) @ axes, 2))  # the most a unit turn moves it
    if d < TILT_NOTE_LEVER_M:
        return ""
    names = sorted(seen)
    about = f"its topside marker at {names[0]}" if len(names) == 1 else \
        f"the line through its topside markers at {' and '.join(names)}"
    return (f"; it turns with the topside's tilt about {about}, which only their own orientation tells (a topside "
            f"marker at another cone would tell it by positions): {d:.0f} m off, each milliradian misread moves it "
            f"{d:.0f} mm; the tracker allows that tilt {TILT_FLOOR_RAD * 1000:g} mrad at least: σ about "
            f"{d * TILT_FLOOR_RAD * 1000:.0f} mm there")


DEPTH_ALIGNED_DEG = 30.0  # a cone's least known direction within this of a camera's line of sight is its depth


def depth_reason(e: ConeEstimate, cameras: tuple[str, ...], rig: Rig, cone: str) -> str:
    """'; the σ lies along CAM's line of sight ...' when a cone's least known direction is the depth of the one
    camera that measures it (a camera measures depth from the markers' size alone, far worse than across its view),
    else ''."""
    if e.covariance is None or not e.T_jacket_cameras or len(cameras) != 1 or cameras[0] not in e.T_jacket_cameras:
        return ""
    _, vectors = np.linalg.eigh(e.covariance)
    axis = vectors[:, -1]
    point = cone_points(rig)[cone]
    sight = point - np.asarray(e.T_jacket_cameras[cameras[0]])[:3, 3]
    cos = abs(float(axis @ sight)) / float(np.linalg.norm(sight))
    if np.degrees(np.arccos(min(cos, 1.0))) > DEPTH_ALIGNED_DEG:
        return ""
    return (f"; it lies along {cameras[0]}'s line of sight, {np.linalg.norm(sight):.0f} m: one camera measures depth "
            "from the markers' size alone, so a second camera at an angle to it (ideally square), or nearer, would "
            "measure that axis")


LENS_NOTE_SHARE = 0.5  # a camera's calibration is named when what its error alone leaves is this much of σ


def lens_reason(lens: dict[str, np.ndarray], calibrations: dict[str, CameraModel], worst: float,
                used: dict[str, float] | None = None) -> str:
    """'; CAM's calibration states ... px ...' when the σ one camera's calibration error (CameraModel.model_px: the
    stated RMS, or UNSTATED_RMS_PX where it states none) alone gives a cone's estimate (lens: camera -> (3,) m, in its
    weight, tracking.estimator.disagreement.lens_sigmas) is LENS_NOTE_SHARE of its worst σ or more, else ''; used:
    camera -> the model error taken, px, where its own fits of the markers leave more (estimator.noise.lens_px)."""
    if not lens:
        return ""
    camera, sigma = max(lens.items(), key=lambda item: float(item[1].max()))
    if not float(sigma.max()) >= LENS_NOTE_SHARE * worst:
        return ""
    model = calibrations[camera]
    states = "states no error, taken as" if model.rms is None else "states"
    taken = (used or {}).get(camera, model.model_px)
    fits = f" and its fits of the markers leave {taken:.2f} px" if taken > model.model_px + 0.005 else ""
    return (f"; {camera}'s calibration {states} {model.model_px:.2f} px RMS error{fits}, which alone leaves "
            f"σ {float(sigma.max()) * 1000:.0f} mm in the estimate (across its line of sight, and along it, as the "
            "markers' size reads their depth, while no second camera is compared; no number of frames averages it "
            "away): a better calibration, a longer lens or a second camera at an angle would lower it")


def unstated_errors(rig: Rig, runs: dict[str, CameraRun]) -> list[str]:
    """One line per camera whose calibration states no RMS reprojection error: its lens model's own error is then
    taken as UNSTATED_RMS_PX (camera.CameraModel.model_px): in its corners' noise and the σ floor."""
    return [f"{rig.resolve(c.calibration)}: {RMS_KEY}: not stated, so {c.name}'s lens model error is taken as "
            f"{UNSTATED_RMS_PX:g} px, the top of what a sound calibration leaves (a calibration by `topside calibrate` "
            "states its own; a better one lowers every σ that camera's view gives)"
            for c in rig.cameras if c.name in runs and runs[c.name].tracker.camera.rms is None]


def misread_markers(kf: TopsideFilter) -> list[str]:
    """One line per view the filter found misread beyond its corners' prior (measurements.misread)."""
    return [misread_warning(camera, marker, v.misread_px) for (camera, marker), v in sorted(kf.views.items())
            if v.misread_px > 0.0]


def mount_mismatch(kf: TopsideFilter, name: str) -> str:
    """What a camera's measured motion says of its rig mount (empty: nothing): a level MOUNT_MISMATCH times its
    mount's prior, and the first mount whose prior holds it (the filter follows the level either way)."""
    cam = kf.cameras[name]
    prior = kf.tuning.motion(cam.mount).angular_accel_psd
    if cam.level is None or cam.level <= MOUNT_MISMATCH * prior:
        return ""
    fits = [m.mount for m in sorted(kf.tuning.camera_motion, key=lambda m: m.angular_accel_psd)
            if m.angular_accel_psd >= cam.level]
    return (f"mount: {cam.mount} allows turns of {prior:.0e} rad²/s³, its images show {cam.level:.0e} (it, or what it "
            f"films, moves): mount: {fits[0] if fits else 'moving'}")


def check_rig(rig: Rig, seconds: float = DEFAULT_SECONDS, refinement: Refinement = DEFAULT_REFINEMENT,
              on_frame: Callable[[], None] | None = None) -> CheckReport:
    """Check a rig against the first `seconds` of each of its cameras (see the module); on_frame is called after each
    frame is processed (from the cameras' threads)."""
    return check_runs(rig, run_cameras(rig, seconds, refinement, on_frame), seconds)


def check_runs(rig: Rig, runs: dict[str, CameraRun], seconds: float) -> CheckReport:
    """The report on every camera's processed frames (run_cameras)."""
    everything = [r for run in runs.values() for r in run.results]
    kf, estimates = fuse(rig, everything)
    placed = estimates[0].T_jacket_cameras if estimates and estimates[0].T_jacket_cameras else {}
    cameras, disagreements, sights = [], [], []
    for name, run in runs.items():
        seen = marker_sights(rig, name, run.results)
        sights += seen
        unknown = Counter(i for r in run.results for i in set(r.unknown_ids))
        survey = next(c for c in rig.cameras if c.name == name).position
        survey_m = None
        if survey is not None and name in placed:
            survey_m = float(np.linalg.norm(np.asarray(placed[name])[:3, 3] - np.array(survey)))
        if name in kf.survey_conflicts:
            survey_m = kf.survey_conflicts[name]
        clock = camera_clock(name, np.array([r.time for r in run.results]), run.health)
        filtered = placed.get(name)
        T_jacket_camera, T_jacket_markers = camera_placement(run.results, None if filtered is None
                                                             else np.asarray(filtered))
        unplaced = kf.cameras[name].waiting if kf.cameras[name].T_jacket_camera is None else ""
        cameras.append(CameraCheck(name, clock, tuple(seen), dict(unknown), T_jacket_camera, T_jacket_markers,
                                   survey_m, name in kf.survey_conflicts, run.first_frame, run.tracker.camera,
                                   unplaced, mount_mismatch(kf, name),
                                   tuple(sorted({i for r in run.results for i in r.mirrored}))))
        disagreements += relative_disagreements(rig, name, run.results, run.tracker.camera)
        disagreements += tilt_disagreements(rig, name, run.results)
    points = cone_points(rig)
    omega = kf.x[3:6] if kf.x is not None and kf.topside_placed else np.zeros(3)
    readings = [r for name, run in runs.items() for r in cone_readings(rig, name, run.results, points, omega)]
    disagreements += cross_camera_disagreements(rig, readings)
    warnings = [w for run in runs.values() for w in run.warnings] + misread_markers(kf) + unstated_errors(rig, runs)
    if not kf.scale.fixed:
        warnings.append(f"{rig.path}: marker_size: {kf.scale.message()}")
    below = {e.cone: float((point_offset_matrix(cone_points(rig)[e.cone]) @ kf.x[:STATE])[2]) for e in estimates
             if e.withheld == WITHHELD_BELOW}  # the offset the filter withheld, at the end
    topside = topside_pose(kf.x) if kf.topside_placed else None
    calibrations = {name: run.tracker.camera for name, run in runs.items()}
    used = {name: lens_px(model.model_px, kf.cameras[name].corner_noise) for name, model in calibrations.items()
            if name in kf.cameras}
    checks = cone_checks(rig, estimates, sights,
                         lambda cone, worst: lens_reason(lens_sigmas(kf.disagreement, cone, kf.time or 0.0),
                                                         calibrations, worst, used))
    return CheckReport(rig, seconds, cameras, disagreements, checks, warnings, topside, kf.scale, below)
