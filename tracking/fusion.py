"""Fusion of every camera into the topside's rigid pose relative to the jacket, over time.

One Kalman filter for the whole installation. Its state holds the topside (12,): translation t and
small rotation ω of the topside frame in the jacket frame, and their rates; and every camera (12,
each): its pose in the jacket frame as an error about a nominal T_jacket_camera (rotation δθ, position
δp) and its rates, with a motion prior from the rig's mount (fixed, vessel, drone). A camera's rates
revert to zero within CAMERA_RATE_TAU_S, and a camera on a rigid mount gets only the process noise its
own images show: the jacket markers' image motion measures how much it moves (a vessel in calm water,
barely), so a still camera's pose, and with it the swing about its one far marker that the corners
hardly see, is averaged over many seconds instead of a fraction of one.

A camera frame is measured by its markers' corners: each marker's four undistorted corners against
their projection through T_camera_jacket (jacket markers) or T_camera_jacket · T_jacket_topside
(topside markers); the camera first, from its jacket corners, then the topside. A far camera's
poorly seen marker tilt is thus averaged into the camera's pose over time instead of turning depth
into height and sideways offset at every frame, and the markers' precise bearings do the measuring.
Body poses (pose.estimate_body_pose) only place a camera or the topside at first sight.

Pair offsets (topside marker S displaced from its mated position, jacket frame) are accepted too:
to first order in ω, o = (R - I) r_S + t ≈ t - [r_S]× ω, linear in the state.

A marker's corners seen by one camera carry, besides white noise, an error that stays while the marker's image
stays: the sub-pixel phase of its edges, the blur of its own data cells into the border, and the stream's coding
of a still picture do not change from frame to frame. Each view (camera, marker) therefore has 8 bias states, one
per corner coordinate, which renew as the marker's image moves (VIEW_BIAS_RENEW_PX). A still camera's view of a
still jacket marker then tells the filter its pose to the bias's σ, however long it looks, instead of averaging
a fixed error away as if it were noise (which left a still camera's swing 7σ off, and an offset 48 mm off).

What the rig states but footage is not trusted to tell widens σ rather than hiding in it. Each marker's survey
error (survey_sigma) is a consider state (ConsiderStates): never estimated, its prior kept, its cross-covariance
carried, so a marker's error stays in σ however many frames see it. A camera's clock σ (time_offset_sigma) widens
its topside corners' noise by their motion over it, and every estimate's σ by the topside's motion over the largest
clock σ of the cameras it rests on (clock_bound).

Measurements are applied at their capture times (cameras need no synchronisation), and the offset
at every cone follows from the topside pose, including cones no camera sees. Corners far off are
down-weighted (Huber-like), markers and pair offsets gated by their Mahalanobis distance. Offline,
a Rauch-Tung-Striebel pass smooths the run.
"""

from __future__ import annotations

import bisect
from collections import deque
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from statistics import NormalDist

import cv2
import numpy as np

from tracking.filtering import (
    WITHHELD_BELOW,
    WITHHELD_CLOCKS,
    WITHHELD_SCALE,
    WITHHELD_SIGMA,
    ConeEstimate,
    paper_filter,
    raw_estimates,
)
from tracking.offsets import MAX_PAIR_TILT_RAD, BodyObservation, PairOffset, body_geometry
from tracking.placement import (
    DECISIVE_CHI2,
    EVIDENCE_CAP,
    LEVEL_SIGMA_RAD,
    ONE_OPTION_WAIT_S,
    SAME_OPTION_CHI2,
    Hypotheses,
    between,
    rotation_angle,
)
from tracking.pose import BodyPose, Choice, body_object_points
from tracking.rig import Rig
from tracking.scale import ScaleEvidence, below_cones, survey_sample

STATE = 12  # per body: pose (6) and rates (6)
GATE_CHI2 = {3: 16.27, 6: 22.46}  # by degrees of freedom, 99.9 %
REINIT_AFTER_REJECTS = 15  # consecutive gated measurements before the filter reopens a covariance
CONTRIBUTION_WINDOW_S = 0.5  # a camera counts as contributing when it was accepted this recently
AMBIGUOUS_VARIANCE_GAIN = 25.0  # σ × 5 for poses IPPE could not settle: their error is bimodal, not Gaussian
MEASUREMENT_FLOOR_M = 0.01  # σ added to every measured position: biases corner noise does not explain (far markers'
# tilt, first-order rotation, timing); evidence in docs/method.md#the-filters-constants, as for the constants below
ROTATION_FLOOR_RAD = 1e-3  # σ added to every measured body rotation, for the same reasons
REPORT_MAX_SIGMA_M = 0.05  # a cone whose offset σ exceeds this on any axis is reported as unknown (NaN): 3σ must fit
# in the 150 mm concentricity tolerance for a number to be worth showing
REPORT_WARMUP_S = 4.0  # for this long after the topside is placed, a cone is reported only when its σ is below
REPORT_WARMUP_SIGMA_M = 0.025  # this: the first seconds' camera poses are poorly known and not Gaussian
SMOOTHER_SPAN_S = 30.0  # recorded runs are smoothed this much at a time, each time with SMOOTHER_LAG_S of the
SMOOTHER_LAG_S = 45.0  # future after it: memory holds both, not the whole run; a still camera gains from the far future
JACOBIAN_STEP = 1e-6  # rad or m, numeric Jacobians of the body measurements
CORNER_NOISE_PX = 0.15  # σ of a corner coordinate from frame to frame (edge-fit corners in fog and rain: 0.1 px median)
VIEW = 8  # bias states per view (camera, marker): one per corner coordinate
VIEW_BIAS_PX = 0.08  # σ of the part of a corner's error that stays while its marker's image stays
VIEW_BIAS_RENEW_PX = 0.5  # that part renews as the marker's image moves: exp(-travel / this) of it stays from one
# frame of the view to the next (travel: the mean shift of its predicted corners, the filter's own corrections included)
VIEW_BIAS_TAU_S = 0.5  # ... but no faster than with this time constant, however far the image travels (a drone's
# marker cells and the stream's coding move with the marker, not the pixel grid)
CORNER_HUBER_CHI2 = 5.99  # 2 degrees of freedom, 95 %: beyond it a corner's variance grows with its residual (rain's
# heavy tail)
CAMERA_RATE_TAU_S = 0.5  # a camera's rates revert to zero with this time constant: a drone's jitter and a vessel's
# wave motion turn within a second or two
MOTION_LAG_S = 1.0  # lag of the second differences of jacket-marker image positions that measure a camera's motion
MOTION_SAMPLES = 60  # second differences (per marker and image axis) whose median gives the camera's motion level
MOTION_MIN_SAMPLES = 12  # until then the mount's motion prior is used as it stands
MOTION_UPDATE_EVERY = 5  # frames with new samples between two medians (the level changes over seconds)
MOTION_FLOOR = 1e-4  # the least share of its mount's process noise a camera keeps
GAUSSIAN_MEDIAN_CHI2_1 = 0.4549  # median of a χ² variable with 1 degree of freedom: variance from a median of squares
PLACEMENT_GAIN = 25.0  # σ × 5 on the pose that first places a camera: it only linearises; the same frame's corners,
# applied right after, carry its information (else counted twice)
CORNER_GATE_CHI2 = 26.12  # 8 degrees of freedom (a marker's four corners), 99.9 %
TOPSIDE_PLACEMENT_M = 1.0  # σ of the topside's position when a single view first places it
PLACEMENT_FIT_P = 0.99  # a view places a camera or the topside only if its pose fits its corners as well as
# CORNER_NOISE_PX would at this probability (χ² of the RMS over 8 N - 6 degrees of freedom, N markers)
SURVEY_GATE_CHI2 = GATE_CHI2[3]  # a camera's surveyed position (rig: position, position_sigma) is applied when its
# first view places it, unless it lies beyond this from that placement: then reported (survey_conflicts), not trusted


@dataclass(frozen=True)
class CameraMotion:
    """How a camera on one kind of mount may move: its pose's process noise and the prior of its rates."""

    mount: str
    angular_accel_psd: float  # rad²/s³, white-noise angular acceleration
    accel_psd: float  # m²/s³, white-noise acceleration
    prior_rate_radps: float
    prior_speed_mps: float
    adapts: bool = True  # its process noise follows the motion its images show (below); a hovering drone's
    # jitter is fast at every scale (its 1 s level understates its frame-to-frame motion), so it keeps its prior


@dataclass(frozen=True)
class FilterTuning:
    """Process and prior noise of the filter."""

    accel_psd: float = 0.05  # m²/s³: white-noise acceleration of the translation (crane and waves)
    angular_accel_psd: float = 1e-6  # rad²/s³: a topside hanging from cranes yaws and rolls slowly
    prior_position_m: float = 20.0
    prior_rotation_rad: float = 0.05
    prior_speed_mps: float = 1.0
    prior_rate_radps: float = 0.01
    camera_motion: tuple[CameraMotion, ...] = (
        CameraMotion("fixed", 1e-8, 1e-6, 1e-4, 1e-3),  # bolted to the jacket or a platform
        CameraMotion("vessel", 1e-5, 0.1, 0.005, 0.3),  # on the crane vessel: metres and milliradians in waves
        CameraMotion("drone", 1e-3, 0.5, 0.05, 1.0,  # flying: 0.3 m/s and 0.01 rad/s, changing within seconds
                     adapts=False))

    def motion(self, mount: str) -> CameraMotion:
        """The motion prior of a camera mount."""
        return next(m for m in self.camera_motion if m.mount == mount)


def skew(v: np.ndarray) -> np.ndarray:
    """(3, 3) matrix of v× ."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def rate_decay(dt: float, tau: float) -> tuple[float, float]:
    """(a, b) of a rate that reverts to zero with time constant tau (inf: constant velocity) over dt:
    rate' = a rate, pose' = pose + b rate."""
    if not np.isfinite(tau):
        return 1.0, dt
    a = float(np.exp(-dt / tau))
    return a, tau * (1.0 - a)


def _body_rows(M: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """F M as a new array for M (n, k): F = [[I, B], [0, A]] per body on the first 12 B rows (rates' decay a (B, 6)
    and their weight b (B, 6) on the pose), identity on the rest. O(n k), where a dense F would cost O(n² k)."""
    out = np.array(M, order="C")
    rows = out[:a.size * 2].reshape(len(a), 2, 6, -1)  # a view: rows of contiguous memory
    rows[:, 0] += b[:, :, None] * rows[:, 1]
    rows[:, 1] *= a[:, :, None]
    return out


def _body_columns(M: np.ndarray, a: np.ndarray, b: np.ndarray) -> None:
    """M Fᵀ in place for a C-ordered M (k, n), F as in _body_rows."""
    cols = M[:, :a.size * 2].reshape(len(M), len(a), 2, 6)  # a view: each row's first 12 B entries are contiguous
    cols[:, :, 0] += cols[:, :, 1] * b[None]
    cols[:, :, 1] *= a[None]


@dataclass(frozen=True)
class Transition:
    """One prediction of the state (n,): bodies first (12 each), then consider states and view biases.

    Per body, its rates' decay a (B, 6), their weight b (B, 6) on the pose and its process noise (B, 12, 12); per
    state after the bodies, the share of it that stays (V,), the rest renewed with VIEW_BIAS_PX (consider states:
    all of it stays).
    """

    a: np.ndarray
    b: np.ndarray
    noise: np.ndarray
    keep: np.ndarray

    def apply(self, M: np.ndarray) -> np.ndarray:
        """F M for M (n, k)."""
        out = _body_rows(M, self.a, self.b)
        out[self.a.size * 2:] *= self.keep[:, None]
        return out

    def covariance(self, P: np.ndarray) -> np.ndarray:
        """F P Fᵀ + Q for a covariance P (n, n)."""
        out = self.apply(P)
        _body_columns(out, self.a, self.b)
        out[:, self.a.size * 2:] *= self.keep[None, :]
        for k, Q in enumerate(self.noise):
            out[STATE * k:STATE * (k + 1), STATE * k:STATE * (k + 1)] += Q
        nb = self.a.size * 2
        out[nb:, nb:] += np.diag((1.0 - self.keep**2) * VIEW_BIAS_PX**2)
        return out


def _block_noise(dt: float, psds: list[float]) -> np.ndarray:
    """(12, 12) white-noise-acceleration process noise of one body, psds (6,) per pose axis."""
    Q = np.zeros((STATE, STATE))
    for i, q in enumerate(psds):
        Q[i, i] = q * dt**3 / 3
        Q[i, i + 6] = Q[i + 6, i] = q * dt**2 / 2
        Q[i + 6, i + 6] = q * dt
    return Q


def process_noise(dt: float, tuning: FilterTuning) -> np.ndarray:
    """(12, 12) white-noise-acceleration process noise of the topside over dt seconds."""
    return _block_noise(dt, [tuning.accel_psd] * 3 + [tuning.angular_accel_psd] * 3)


def camera_process_noise(dt: float, tuning: FilterTuning, mount: str, scale: float = 1.0) -> np.ndarray:
    """(12, 12) process noise of one camera on a mount over dt seconds (rotation first, then position),
    scaled by the share of the mount's motion the camera shows (1: all of it)."""
    m = tuning.motion(mount)
    return _block_noise(dt, [scale * m.angular_accel_psd] * 3 + [scale * m.accel_psd] * 3)


def prior_covariance(tuning: FilterTuning) -> np.ndarray:
    """(12, 12) initial covariance of the topside: anywhere near, barely rotated."""
    sd = [tuning.prior_position_m] * 3 + [tuning.prior_rotation_rad] * 3 + \
         [tuning.prior_speed_mps] * 3 + [tuning.prior_rate_radps] * 3
    return np.diag(np.square(sd))


def point_offset_matrix(r: np.ndarray) -> np.ndarray:
    """(3, 12) H: offset of a topside point at r (3,) from the topside state, o = t - [r]× ω."""
    H = np.zeros((3, STATE))
    H[:, :3] = np.eye(3)
    H[:, 3:6] = -skew(r)
    return H


def fits_its_corners(pose: BodyPose) -> bool:
    """Whether a pose's reprojection RMS is what corner noise of CORNER_NOISE_PX leaves at PLACEMENT_FIT_P
    over the corners its fit kept (Wilson-Hilferty's χ² quantile, within 1 % from 2 degrees of freedom up)."""
    points = 8 * len(pose.marker_ids) - 2 * pose.outliers  # coordinates of the corners the fit kept
    dof = points - 6
    z = NormalDist().inv_cdf(PLACEMENT_FIT_P)
    quantile = dof * (1.0 - 2.0 / (9 * dof) + z * np.sqrt(2.0 / (9 * dof))) ** 3
    return pose.reprojection_error**2 * points <= quantile * CORNER_NOISE_PX**2


def rotvec(R: np.ndarray) -> np.ndarray:
    """(3,) rotation vector of a rotation matrix, exact for small angles too.

    cv2.Rodrigues returns zero below 1e-5 rad, which would blind numeric Jacobians; below 90° the angle
    comes from atan2(sin, cos) of the skew and symmetric parts instead.
    """
    c = (np.trace(R) - 1.0) / 2.0
    if c < 0.0:  # beyond 90°: OpenCV is exact there
        return cv2.Rodrigues(R)[0].reshape(3)
    v = 0.5 * np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    s = float(np.linalg.norm(v))
    return v if s < 1e-12 else v * (np.arctan2(s, c) / s)


def rotation(v: np.ndarray) -> np.ndarray:
    """(3, 3) rotation matrix of a rotation vector."""
    return cv2.Rodrigues(np.asarray(v, dtype=np.float64).reshape(3))[0]


def pose_residual(T_measured: np.ndarray, T_predicted: np.ndarray) -> np.ndarray:
    """(6,) measured minus predicted (4, 4) pose: rotation vector of R_m R_pᵀ, then translation difference."""
    return np.concatenate([rotvec(T_measured[:3, :3] @ T_predicted[:3, :3].T),
                           T_measured[:3, 3] - T_predicted[:3, 3]])


def inverse(T: np.ndarray) -> np.ndarray:
    """(4, 4) inverse of a rigid transform."""
    out = np.eye(4)
    out[:3, :3] = T[:3, :3].T
    out[:3, 3] = -T[:3, :3].T @ T[:3, 3]
    return out


def _pose_params(T: np.ndarray) -> np.ndarray:
    return np.concatenate([rotvec(T[:3, :3]), T[:3, 3]])


def _from_params(p: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = rotation(p[:3])
    T[:3, 3] = p[3:]
    return T


def _numeric_jacobian(f: Callable[[np.ndarray], np.ndarray], x0: np.ndarray) -> np.ndarray:
    """(M, N) forward-difference Jacobian of f at x0 (N,)."""
    base = f(x0)
    J = np.empty((base.size, x0.size))
    for k in range(x0.size):
        step = np.zeros(x0.size)
        step[k] = JACOBIAN_STEP
        J[:, k] = (f(x0 + step) - base) / JACOBIAN_STEP
    return J


def measured_covariance(T_measured: np.ndarray, covariance: np.ndarray, T_predicted: np.ndarray) -> np.ndarray:
    """(6, 6) covariance of pose_residual from a PnP pose's (rvec, tvec) covariance (6, 6)."""
    J = _numeric_jacobian(lambda p: pose_residual(_from_params(p), T_predicted), _pose_params(T_measured))
    return J @ covariance @ J.T


@dataclass
class FilterStep:
    """One time step of the filter, kept for the smoother (its predicted covariance follows from the previous step's P
    and F: not kept, it would double the memory)."""

    time: float
    x_pred: np.ndarray
    x: np.ndarray
    P: np.ndarray
    F: Transition
    cameras: tuple[str, ...]
    warming: bool  # within REPORT_WARMUP_S of the topside's (last) placement


@dataclass
class ViewBias:
    """The persistent corner errors of one marker seen by one camera: where their 8 states sit, and the marker's corners
    (8,) predicted at its last frame (ideal pixels), from which the next frame's image travel is measured."""

    index: int
    corners: np.ndarray
    time: float


@dataclass
class CameraState:
    """The nominal pose of one camera in the jacket frame, about which the filter holds its error."""

    index: int  # first index of the camera's block in the state
    mount: str  # the rig's camera mount: its motion prior
    name: str  # the rig's camera name: its views' key
    T_jacket_camera: np.ndarray | None = None  # (4, 4), None until a jacket view places the camera
    consecutive_rejects: int = 0
    motion: CameraMotionLevel = field(default_factory=lambda: CameraMotionLevel())
    motion_scale: float = 1.0  # share of its mount's process noise the camera gets (1 until its level is known)
    hypotheses: Hypotheses | None = None  # while an ambiguous jacket view waits: its options and their evidence
    waiting: str = "no frame of it yet"  # why it is not placed (empty once placed)
    placed_at: float | None = None  # capture time of its (last) placement, s


@dataclass
class CameraMotionLevel:
    """How much a camera moves, from the image motion of the jacket markers it sees (fixed in the world).

    Each frame gives, per jacket marker and image axis, the second divided difference a of the marker
    centre over MOTION_LAG_S (three samples about that far apart). Under white-noise angular acceleration
    of psd q, Var(a) = (2/3) q f² / Δ px²/s⁴, so each a² (3/2) Δ / f² estimates q; the median of the last
    MOTION_SAMPLES (robust to rain-struck corners) over the χ²₁ median gives the camera's level. Corner
    noise alone reads as about 1e-8 rad²/s³: a still camera's level, below every mount's prior.
    """

    tracks: dict[int, tuple[list[float], list[tuple[float, float]]]] = field(default_factory=dict)  # jacket
    # marker id -> times and centres (px) of its last 2.5 lags
    samples: deque = field(default_factory=lambda: deque(maxlen=MOTION_SAMPLES))  # q estimates, rad²/s³
    level: float | None = None  # angular acceleration psd the camera shows, rad²/s³ (None until enough samples)
    pending: int = 0  # frames with new samples since the level was last taken

    def add(self, time: float, corners: dict[int, np.ndarray], focal_px: float) -> None:
        """One frame's jacket-marker corners (4, 2), undistorted pixels."""
        added = False
        for marker, z in corners.items():
            times, centres = self.tracks.setdefault(marker, ([], []))
            cx, cy = z.reshape(4, 2).sum(axis=0).tolist()
            times.append(time)
            centres.append((cx / 4, cy / 4))
            old = bisect.bisect_left(times, time - 2.5 * MOTION_LAG_S)
            if old:
                del times[:old], centres[:old]
            if times[0] > time - 1.75 * MOTION_LAG_S:
                continue  # not yet two lags of history
            i1, i0 = (self._nearest(times, time - k * MOTION_LAG_S) for k in (1, 2))
            t0, t1 = times[i0], times[i1]
            if not (t0 < t1 < time) or abs(t1 - (time - MOTION_LAG_S)) > 0.25 * MOTION_LAG_S:
                continue
            weight = 3.0 / ((time - t0) * focal_px**2)  # a² (3/2) Δ / f², a = 2 Δv / (2 Δ)
            for k in range(2):
                c0, c1, c2 = centres[i0][k], centres[i1][k], centres[-1][k]
                self.samples.append(weight * ((c2 - c1) / (time - t1) - (c1 - c0) / (t1 - t0)) ** 2)
            added = True
        self.pending += added
        if self.pending >= MOTION_UPDATE_EVERY and len(self.samples) >= MOTION_MIN_SAMPLES:
            self.level = float(np.median(self.samples)) / GAUSSIAN_MEDIAN_CHI2_1
            self.pending = 0

    @staticmethod
    def _nearest(times: list[float], t: float) -> int:
        k = bisect.bisect_left(times, t)
        return k if k == 0 or (k < len(times) and times[k] - t < t - times[k - 1]) else k - 1


def cone_points(rig: Rig) -> dict[str, np.ndarray]:
    """The point (3,) whose offset is each cone's: its tip in the rig, else the centre of its pair's topside marker
    (topside frame, which is the jacket frame when mated)."""
    points = {c: np.array(p, dtype=float) for c, p in rig.cones.items()}
    markers = rig.marker_by_id
    for pair in rig.all_pairs():
        if pair.cone not in points:
            points[pair.cone] = np.array(markers[pair.topside].center, dtype=float)
    return points


@dataclass(frozen=True)
class ConsiderStates:
    """The markers' survey errors, which the rig states (survey_sigma) but footage is not trusted to measure, carried
    as consider (Schmidt) states: each marker's rotation δθ and centre δp in its body's frame. They sit in the state
    after the bodies with their prior covariance, which no update changes, and stay zero; the updates carry their
    cross-covariances, so a cone's σ holds them as the geometry passes them on (a survey error stays while the markers
    stay: averaging frames does not shrink it)."""

    markers: dict[int, int]  # marker id -> index of its (δθ, δp) (6,)
    prior: np.ndarray  # (C,) variances, in index order from the first
    first: int  # index of the first

    @classmethod
    def of(cls, rig: Rig, first: int) -> ConsiderStates:
        """The rig's survey σ of its markers that are not references, from index first."""
        markers, prior = {}, []
        for marker in rig.markers:
            sigma = rig.marker_sigma(marker)
            if sigma is not None and (sigma.tilt_rad().any() or sigma.position().any()):
                markers[marker.id] = first + len(prior)
                prior.extend(np.concatenate([sigma.tilt_rad(), sigma.position()]) ** 2)
        return cls(markers, np.array(prior), first)

    @property
    def indices(self) -> slice:
        return slice(self.first, self.first + self.prior.size)


@dataclass
class TopsideFilter:
    """The Kalman filter of one installation: the topside and every camera of the rig."""

    rig: Rig
    tuning: FilterTuning = field(default_factory=FilterTuning)
    x: np.ndarray | None = None
    P: np.ndarray | None = None
    time: float | None = None
    rejected: int = 0  # total gated measurements
    consecutive_rejects: int = 0
    last_accepted: dict[str, float] = field(default_factory=dict)  # camera -> capture time of its topside view
    survey_conflicts: dict[str, float] = field(default_factory=dict)  # camera -> distance, m, between its surveyed
    # position and where its first view placed it, for a survey beyond SURVEY_GATE_CHI2 (not applied)

    def __post_init__(self) -> None:
        self.cameras = {c.name: CameraState(STATE * (1 + k), c.mount, c.name) for k, c in enumerate(self.rig.cameras)}
        self.body_size = STATE * (1 + len(self.cameras))
        self.consider = ConsiderStates.of(self.rig, self.body_size)  # after the bodies; view biases after them
        self.views: dict[tuple[str, int], ViewBias] = {}  # (camera, marker) -> its bias states, from its first corners
        n = self.consider.indices.stop
        self.x = np.zeros(n) if self.x is None else self.x
        if self.P is None:
            self.P = np.zeros((n, n))
            self.P[:STATE, :STATE] = prior_covariance(self.tuning)
            self.P[self.consider.indices, self.consider.indices] = np.diag(self.consider.prior)
            for cam in self.cameras.values():
                self._reset_camera(cam)
        self.topside_placed = False
        self.placed_at: float | None = None  # capture time the topside was (last) placed, or first measured
        geometry = body_geometry(self.rig)
        self.jacket_corners = {i: body_object_points([T], self.rig.marker_size) for i, T in geometry.jacket.items()}
        self.topside_corners = {i: body_object_points([T], self.rig.marker_size)
                                for i, T in geometry.topside.items()}
        self.centres = {m.id: np.array(m.center, dtype=float) for m in self.rig.markers}
        self.cones = cone_points(self.rig)
        self.clock_sigma = {c.name: float(c.time_offset_sigma or 0.0) for c in self.rig.cameras}  # s, from the rig
        self.surveys = {c.name: (np.array(c.position, dtype=float), float(c.position_sigma)) for c in self.rig.cameras
                        if c.position is not None and c.position_sigma is not None}  # camera -> (position (3,), σ m)
        self.scale = ScaleEvidence()  # whether the markers look the size the rig states (tracking.scale)
        self.below: tuple[int, float] = (0, 0.0)  # estimates withheld for putting the topside through its cones, and
        # the deepest of their Δz (m)

    @property
    def size(self) -> int:
        """Length of the state: the bodies' and the views' biases so far."""
        assert self.x is not None
        return self.x.size

    def _reset_camera(self, cam: CameraState, covariance: np.ndarray | None = None) -> None:
        """Forget a camera: its block decoupled, its pose covariance given (or unit), its rates' prior."""
        assert self.P is not None and self.x is not None
        b = slice(cam.index, cam.index + STATE)
        self.P[b, :] = 0.0
        self.P[:, b] = 0.0
        motion = self.tuning.motion(cam.mount)
        sd = [1.0] * 6 + [motion.prior_rate_radps] * 3 + [motion.prior_speed_mps] * 3
        self.P[b, b] = np.diag(np.square(sd))
        if covariance is not None:
            self.P[cam.index:cam.index + 6, cam.index:cam.index + 6] = covariance
        self.x[b] = 0.0
        cam.consecutive_rejects = 0
        for (name, _), view in self.views.items():  # its views' biases: unknown again, and about nothing
            if name == cam.name:
                self._forget_view(view)

    def _forget_view(self, view: ViewBias) -> None:
        """A view's bias states back to their prior, decoupled from the rest."""
        assert self.P is not None and self.x is not None
        v = slice(view.index, view.index + VIEW)
        self.P[v, :] = 0.0
        self.P[:, v] = 0.0
        self.P[v, v] = VIEW_BIAS_PX**2 * np.eye(VIEW)
        self.x[v] = 0.0

    def predict(self, time: float, frame: Sequence[Measurement] = ()) -> Transition:
        """Move the state to a capture time and renew the corner biases of the views a frame's body observations will
        measure, by how far their markers' images moved; returns the transition used."""
        assert self.P is not None and self.x is not None
        dt = 0.0 if self.time is None else max(0.0, time - self.time)
        blocks = 1 + len(self.cameras)
        a_cam, b_cam = rate_decay(dt, CAMERA_RATE_TAU_S)  # the topside keeps its speed, cameras' rates revert
        a, b = np.full((blocks, 6), a_cam), np.full((blocks, 6), b_cam)
        a[0], b[0] = 1.0, dt
        noise = np.zeros((blocks, STATE, STATE))
        noise[0] = process_noise(dt, self.tuning)
        for k, cam in enumerate(self.cameras.values()):
            if cam.T_jacket_camera is not None:
                noise[1 + k] = camera_process_noise(dt, self.tuning, cam.mount, cam.motion_scale)
        bodies = Transition(a, b, noise, np.ones(self.size - self.body_size))
        self.x = bodies.apply(self.x[:, None])[:, 0]
        self.P = bodies.covariance(self.P)
        self._fold_cameras()
        self.time = time if self.time is None else max(self.time, time)
        keep = self._renew([o for o in frame if isinstance(o, BodyObservation)])
        return Transition(a, b, noise, keep)

    def _renew(self, frame: list[BodyObservation]) -> np.ndarray:
        """Renew the biases of a frame's views not yet renewed for it; the share of each bias state that stayed (V,)."""
        assert self.x is not None and self.P is not None
        nb = self.body_size
        keep = np.ones(self.size - nb)
        for o in frame:
            for view, share in self._renewed(o):
                keep[view.index - nb:view.index - nb + VIEW] = share
        if (keep < 1.0).any():  # as Transition.covariance does for the views, in place: predict and _apply leave
            self.x[nb:] *= keep  # arrays that nothing else holds
            self.P[nb:, :] *= keep[:, None]
            self.P[:, nb:] *= keep
            self.P[nb:, nb:] += np.diag((1.0 - keep**2) * VIEW_BIAS_PX**2)
        return keep

    def _renewed(self, o: BodyObservation) -> list[tuple[ViewBias, float]]:
        """The views of a camera frame not yet renewed for it, each with the share of its bias that stays: exp(-travel /
        VIEW_BIAS_RENEW_PX), travel the mean shift of its marker's predicted corners since its last frame, but at least
        exp(-dt / VIEW_BIAS_TAU_S), dt the time since then."""
        cam = self.cameras.get(o.camera)
        if cam is None or cam.T_jacket_camera is None:
            return []
        assert self.x is not None
        out = []
        for marker in o.corners:
            view = self.views.get((o.camera, marker))
            if view is None or view.time == o.time or (marker in self.topside_corners and not self.topside_placed):
                continue
            h = self._predict_corners(cam, marker, self.x, o.K)
            travel = float(np.linalg.norm((h - view.corners).reshape(4, 2), axis=1).mean())
            by_travel, by_time = np.exp(-travel / VIEW_BIAS_RENEW_PX), np.exp(-(o.time - view.time) / VIEW_BIAS_TAU_S)
            view.corners, view.time = h, o.time
            out.append((view, float(max(by_travel, by_time))))
        return out

    def _view(self, cam: CameraState, marker: int, K: np.ndarray, time: float) -> ViewBias:
        """The bias states of a camera's view of a marker; a new view's appended to the state with its prior."""
        assert self.P is not None and self.x is not None
        key = (cam.name, marker)
        if key not in self.views:
            n = self.size
            self.x = np.concatenate([self.x, np.zeros(VIEW)])
            P = np.zeros((n + VIEW, n + VIEW))
            P[:n, :n] = self.P
            P[n:, n:] = VIEW_BIAS_PX**2 * np.eye(VIEW)
            self.P = P
            self.views[key] = ViewBias(n, self._predict_corners(cam, marker, self.x, K), time)
        return self.views[key]

    def _measure_motion(self, cam: CameraState, time: float, jacket: dict[int, np.ndarray], K: np.ndarray) -> None:
        """A frame's jacket corners into the camera's motion level; its process noise scaled to that level."""
        prior = self.tuning.motion(cam.mount)
        if not prior.adapts or not jacket:
            return
        cam.motion.add(time, jacket, float(K[0, 0] + K[1, 1]) / 2)
        if cam.motion.level is not None:
            cam.motion_scale = float(np.clip(cam.motion.level / prior.angular_accel_psd, MOTION_FLOOR, 1.0))

    def _fold_cameras(self) -> None:
        """Move the cameras' pose errors (and the motion their rates imply) into their nominal poses.

        Done once per step, at the prediction: within a step every error is about the predicted nominal,
        which keeps the smoother's differences between steps consistent.
        """
        assert self.x is not None
        for cam in self.cameras.values():
            if cam.T_jacket_camera is None:
                continue
            i = cam.index
            T = np.eye(4)
            T[:3, :3] = rotation(self.x[i:i + 3]) @ cam.T_jacket_camera[:3, :3]
            T[:3, 3] = cam.T_jacket_camera[:3, 3] + self.x[i + 3:i + 6]
            cam.T_jacket_camera = T
            self.x[i:i + 6] = 0.0

    def _camera_pose(self, cam: CameraState, x: np.ndarray) -> np.ndarray:
        """(4, 4) T_jacket_camera of a state."""
        assert cam.T_jacket_camera is not None
        i = cam.index
        T = np.eye(4)
        T[:3, :3] = rotation(x[i:i + 3]) @ cam.T_jacket_camera[:3, :3]
        T[:3, 3] = cam.T_jacket_camera[:3, 3] + x[i + 3:i + 6]
        return T

    @staticmethod
    def _topside_pose(x: np.ndarray) -> np.ndarray:
        """(4, 4) T_jacket_topside of a state."""
        T = np.eye(4)
        T[:3, :3] = rotation(x[3:6])
        T[:3, 3] = x[:3]
        return T

    def _apply(self, H: np.ndarray, y: np.ndarray, R: np.ndarray) -> None:
        """Kalman update with H (M, n), innovation y (M,) and measurement covariance R (M, M)."""
        assert self.P is not None and self.x is not None
        PHt = self.P @ H.T  # (n, M): O(n² M), where the Joseph form would cost O(n³) for n = 12 per body
        S = H @ PHt + R
        K = np.linalg.solve(S, PHt.T).T
        P = self.P - K @ PHt.T
        c = self.consider.indices  # consider states are not estimated (Schmidt): the others' update, their covariance
        K[c] = 0.0  # and cross-covariance are as with them, their own is kept
        P[c, c] = self.P[c, c]
        self.x = self.x + K @ y
        self.P = (P + P.T) / 2  # stays symmetric

    def _best(self, candidates: list[tuple[np.ndarray, np.ndarray]], H: np.ndarray, gain: float,
              floor: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
        """The candidate (innovation, covariance) nearest the prediction: (d², y, R)."""
        assert self.P is not None
        HPH = H @ self.P @ H.T
        scored = []
        for y_k, cov in candidates:
            R_k = cov + floor
            scored.append((float(y_k @ np.linalg.solve(HPH + R_k, y_k)), y_k, cov))
        scored.sort(key=lambda c: c[0])
        d2, y, cov = scored[0]
        gate = GATE_CHI2[H.shape[0]]
        if gain != 1.0 and not (d2 <= gate and all(c[0] > gate for c in scored[1:])):  # the prediction did
            R = gain * cov + floor  # not settle the ambiguity either: inflate
            return float(y @ np.linalg.solve(HPH + R, y)), y, R
        return d2, y, cov + floor

    def _gated(self, d2: float, dof: int) -> bool:
        return not np.isfinite(d2) or d2 > GATE_CHI2[dof]

    def _topside_rejected(self) -> None:
        assert self.P is not None
        self.rejected += 1
        self.consecutive_rejects += 1
        if self.consecutive_rejects >= REINIT_AFTER_REJECTS:  # lost: reopen, keep the state
            self.P[:STATE, :STATE] += prior_covariance(self.tuning)
            self.consecutive_rejects = 0

    def update(self, m: PairOffset | BodyObservation) -> bool:
        """Apply one measurement; False when (its topside part) was gated out or could not be used."""
        if isinstance(m, BodyObservation):
            return self.observe(m)
        assert self.x is not None
        if not self.last_accepted and m.choice == Choice.AMBIGUOUS:
            return False  # never start from a pose IPPE could not settle: nothing could gate it
        H = np.zeros((3, self.size))
        H[:, :STATE] = point_offset_matrix(self.centres[m.topside_id])
        self._pair_consider(H, m)
        gain = AMBIGUOUS_VARIANCE_GAIN if m.choice == Choice.AMBIGUOUS else 1.0
        candidates = [(o - H @ self.x, c) for o, c in ((m.offset, m.covariance), *m.alternatives)]
        d2, y, R = self._best(candidates, H, gain, MEASUREMENT_FLOOR_M**2 * np.eye(3))
        if self._gated(d2, 3):
            self._topside_rejected()
            return False
        self._apply(H, y, R)
        self.consecutive_rejects = 0
        self.last_accepted[m.camera] = m.time
        if self.placed_at is None:
            self.placed_at = m.time
        return True

    def _pair_consider(self, H: np.ndarray, m: PairOffset) -> None:
        """H's columns (3, ·) of a pair offset's consider states, given its topside columns: its markers off by
        (δθ_W, δp_W) and (δθ_S, δp_S) put it off by δp_S - δp_W - δθ_W × (p_S - c_W), p_S where the state has the
        topside marker now (a jacket marker's tilt turns the whole distance, 20 m while the topside comes in)."""
        assert self.x is not None
        w, s = self.consider.markers.get(m.jacket_id), self.consider.markers.get(m.topside_id)
        if w is not None:
            p_s = self.centres[m.topside_id] + H[:, :STATE] @ self.x[:STATE]
            H[:, w:w + 3] = skew(p_s - self.centres[m.jacket_id])
            H[:, w + 3:w + 6] = -np.eye(3)
        if s is not None:
            H[:, s + 3:s + 6] = np.eye(3)

    def _place_camera(self, cam: CameraState, o: BodyObservation) -> bool:
        """First view of the jacket: the camera's pose from it; an ambiguous one settled by the evidence (placement)."""
        jb = o.jacket
        assert jb is not None
        assert self.x is not None
        if not fits_its_corners(jb):
            cam.waiting = "its jacket view does not fit its corners (a corner off by rain or glare?)"
            return False  # a corner off: wait for a clean view
        options = [(jb.T_camera_body, jb.covariance), *jb.alternatives]
        gain = 1.0
        if jb.choice != Choice.UNIQUE and len(options) > 1:
            T_jc = self._settle(cam, o, options)
            if T_jc is None:
                return False
            options = [(inverse(T_jc), options[0][1])]
            gain = AMBIGUOUS_VARIANCE_GAIN
        T_cj, cov = options[0]
        cov_jc = self._camera_covariance(T_cj, cov)
        cam.T_jacket_camera = inverse(T_cj)
        floor = np.diag([ROTATION_FLOOR_RAD**2] * 3 + [MEASUREMENT_FLOOR_M**2] * 3)
        self._reset_camera(cam, gain * PLACEMENT_GAIN * cov_jc + floor)
        self._apply_survey(cam, gain * cov_jc[3:, 3:] + floor[3:, 3:])
        cam.hypotheses, cam.waiting, cam.placed_at = None, "", o.time
        return True

    def _one_option(self, options: list[tuple[np.ndarray, np.ndarray]]) -> bool:
        """Whether an ambiguous view's options place the camera within each other's σ (a view near square on): then
        either places it, and its covariance (AMBIGUOUS_VARIANCE_GAIN) holds the other."""
        (T_0, cov_0), rest = options[0], options[1:]
        p_0, S_0 = inverse(T_0)[:3, 3], self._camera_covariance(T_0, cov_0)[3:, 3:]
        for T, cov in rest:
            d = inverse(T)[:3, 3] - p_0
            if float(d @ np.linalg.solve(S_0 + self._camera_covariance(T, cov)[3:, 3:], d)) > SAME_OPTION_CHI2:
                return False
        return True

    @staticmethod
    def _camera_covariance(T_cj: np.ndarray, cov: np.ndarray) -> np.ndarray:
        """(6, 6) covariance of a camera's error state (δθ, δp, jacket frame) placed by T_camera_jacket (4, 4) with the
        covariance (6, 6) of its (rvec, tvec)."""
        T_jc = inverse(T_cj)

        def camera_error(p: np.ndarray) -> np.ndarray:
            return pose_residual(inverse(_from_params(p)), T_jc)

        J = _numeric_jacobian(camera_error, _pose_params(T_cj))
        return J @ cov @ J.T

    def _settle(self, cam: CameraState, o: BodyObservation, options: list[tuple[np.ndarray, np.ndarray]]
                ) -> np.ndarray | None:
        """The pose (4, 4) T_jacket_camera that places a camera whose jacket view is ambiguous, once the evidence
        decides between its options, or they are one (tracking.placement); None until then, with the reason in
        cam.waiting."""
        assert self.x is not None and self.P is not None
        positions = [inverse(T)[:3, 3] for T, _ in options]
        h = cam.hypotheses
        order = h.match(positions) if h is not None else None
        if h is None or order is None:  # the first ambiguous view
            h = cam.hypotheses = Hypotheses.start(positions, o.time)
            order = list(range(len(options)))
        for j, k in enumerate(order):
            h.positions[k] = positions[j]
        sigma2 = CORNER_NOISE_PX**2 + VIEW_BIAS_PX**2  # a corner's error in one frame, noise and view bias

        def chi2(values: list[float]) -> np.ndarray:  # per hypothesis, from per frame option
            out = np.zeros(len(h.positions))
            for j, v in enumerate(values):
                out[order[j]] = v
            return out

        zero = self.x.copy()
        zero[cam.index:cam.index + 6] = 0.0
        jacket = [i for i in o.corners if i in self.jacket_corners]
        topside = [i for i in o.corners if i in self.topside_corners] if self.topside_placed else []
        candidates = [*options, (inverse(between([inverse(T) for T, _ in options])), options[0][1])]
        misfits, distances = [], []
        for n, (T_cj, cov) in enumerate(candidates):
            cam.T_jacket_camera = inverse(T_cj)
            if n < len(options):
                misfits.append(sum(float(np.sum((self._predict_corners(cam, i, zero, o.K) -
                                                 o.corners[i].reshape(-1)) ** 2)) for i in jacket) / sigma2)
            distances.append(self._topside_distance(cam, o, topside, self._camera_covariance(T_cj, cov), sigma2)
                             if topside else np.nan)
        cam.T_jacket_camera = None
        for j, k in enumerate(order):
            h.poses[k].append((distances[j], inverse(options[j][0])))
        h.between.append((distances[-1], inverse(candidates[-1][0])))
        h.add(chi2(misfits), o.time, "its jacket corners")
        gate = CORNER_GATE_CHI2 * len(topside)  # the topside's corners fit no option: the topside's state is off, and
        if topside and min(distances[:len(options)]) <= gate:  # the frame tells nothing of which option is right
            h.add(chi2([min(d, EVIDENCE_CAP * gate) for d in distances[:len(options)]]), o.time,
                  "the topside's corners")
        elif o.topside is not None and not self.topside_placed:  # the topside hangs near level under the right one
            tilts = [min(float(np.linalg.norm(rotvec(T[:3, :3].T @ T_ct[:3, :3]))) for T_ct in
                         [o.topside.T_camera_body, *(a for a, _ in o.topside.alternatives)]) for T, _ in options]
            h.add(chi2([(t / LEVEL_SIGMA_RAD) ** 2 for t in tilts]), o.time, "the topside's tilt")
        if cam.name in self.surveys and not h.surveyed:  # once, and only when it fits one option and rules out another:
            position, sigma = self.surveys[cam.name]  # a survey off by metres must not choose (it is refused later)
            survey = [float((p - position) @ np.linalg.solve(sigma**2 * np.eye(3) +
                                                             self._camera_covariance(T, cov)[3:, 3:], p - position))
                      for p, (T, cov) in zip(positions, options, strict=True)]
            if min(survey) <= SURVEY_GATE_CHI2 and max(survey) - min(survey) >= DECISIVE_CHI2:
                h.add(chi2(survey), o.time, "its surveyed position", once=True)
            h.surveyed = True
        h.step(o.time)
        k = h.decided()
        if k is not None:
            return h.pose(k)
        if self._one_option(options) and h.span >= ONE_OPTION_WAIT_S:  # near square on: between them
            return h.one()
        apart = np.degrees(rotation_angle(options[0][0][:3, :3], options[1][0][:3, :3]))
        marker = o.jacket.marker_ids[0] if o.jacket is not None else "?"
        cam.waiting = (f"its view of jacket marker {marker} is ambiguous (two poses {apart:.0f}° apart fit its corners "
                       f"alike); {', '.join(sorted(h.sources))} tell them apart by χ² {h.margin:.1f} of "
                       f"{DECISIVE_CHI2:g} so far")
        return None

    def _topside_distance(self, cam: CameraState, o: BodyObservation, markers: list[int], camera_cov: np.ndarray,
                          sigma2: float) -> float:
        """Mahalanobis distance of a frame's topside corners from their prediction through a tentatively placed camera
        (cam.T_jacket_camera, its error state zero, covariance (6, 6) camera_cov) and the topside's state."""
        assert self.x is not None and self.P is not None
        saved = self.x[cam.index:cam.index + 6].copy()
        self.x[cam.index:cam.index + 6] = 0.0
        columns = [*range(6), *range(cam.index, cam.index + 6)]
        ys, Js = [], []
        for i in markers:
            h_i, J_i = self.corner_jacobian(cam, i, o.K, columns)
            ys.append(o.corners[i].reshape(-1) - h_i)
            Js.append(J_i)
        self.x[cam.index:cam.index + 6] = saved
        y, J = np.concatenate(ys), np.vstack(Js)
        P = np.zeros((12, 12))
        P[:6, :6] = self.P[:6, :6]
        P[6:, 6:] = camera_cov
        S = J @ P @ J.T + sigma2 * np.eye(len(y))
        return float(y @ np.linalg.solve(S, y))

    def _apply_survey(self, cam: CameraState, placed: np.ndarray) -> None:
        """The camera's surveyed position as a measurement of its just placed pose, gated against the placement's own
        (3, 3) position covariance (placed, without PLACEMENT_GAIN); a conflict is kept in survey_conflicts."""
        if cam.name not in self.surveys:
            return
        assert self.x is not None and cam.T_jacket_camera is not None
        position, sigma = self.surveys[cam.name]
        y = position - (cam.T_jacket_camera[:3, 3] + self.x[cam.index + 3:cam.index + 6])
        R = sigma**2 * np.eye(3)
        if float(y @ np.linalg.solve(placed + R, y)) > SURVEY_GATE_CHI2:
            self.survey_conflicts[cam.name] = float(np.linalg.norm(y))
            return
        self.survey_conflicts.pop(cam.name, None)
        H = np.zeros((3, self.size))
        H[:, cam.index + 3:cam.index + 6] = np.eye(3)
        self._apply(H, y, R)

    def _place_topside(self, cam: CameraState, topside: BodyPose) -> bool:
        """First view of the topside: its pose from the placed camera (the option hanging nearest level)."""
        assert self.x is not None and self.P is not None
        if not fits_its_corners(topside):
            return False
        T_jc = self._camera_pose(cam, self.x)
        options = [T @ np.eye(4) for T, _ in [(topside.T_camera_body, None), *topside.alternatives]]
        poses = [T_jc @ T for T in options]
        tilts = [float(np.linalg.norm(rotvec(T[:3, :3]))) for T in poses]
        k = int(np.argmin(tilts)) if topside.choice != Choice.UNIQUE else 0
        if tilts[k] > MAX_PAIR_TILT_RAD:
            return False
        self.x[:STATE] = 0.0  # level, as the prior: one far marker's tilt is worth less than the prior's 0.05 rad
        self.x[:3] = poses[k][:3, 3]
        self.P[:STATE, :] = 0.0
        self.P[:, :STATE] = 0.0
        self.P[:STATE, :STATE] = prior_covariance(self.tuning)
        self.P[:3, :3] = np.eye(3) * TOPSIDE_PLACEMENT_M**2
        self.topside_placed = True
        self.placed_at = self.time
        return True

    def _predict_corners(self, cam: CameraState, marker: int, x: np.ndarray, K: np.ndarray) -> np.ndarray:
        """(8,) ideal pixels of a marker's corners predicted from a state."""
        T = inverse(self._camera_pose(cam, x))
        if marker in self.topside_corners:
            T = T @ self._topside_pose(x)
            X = self.topside_corners[marker]
        else:
            X = self.jacket_corners[marker]
        i = self.consider.markers.get(marker)
        if i is not None and x[i:i + 6].any():  # the marker turned by δθ about its centre and moved by δp
            c = self.centres[marker]
            X = c + (X - c) @ rotation(x[i:i + 3]).T + x[i + 3:i + 6]
        pc = X @ T[:3, :3].T + T[:3, 3]
        uv = pc @ K.T
        return (uv[:, :2] / uv[:, 2:3]).reshape(-1)

    def corner_jacobian(self, cam: CameraState, marker: int, K: np.ndarray, columns: list[int]
                        ) -> tuple[np.ndarray, np.ndarray]:
        """A marker's corners predicted from the current state, (8,) ideal pixels, and their (8, C) forward-difference
        Jacobian with respect to the state's entries at columns (C,)."""
        assert self.x is not None
        h = self._predict_corners(cam, marker, self.x, K)
        J = np.empty((8, len(columns)))
        for j, k in enumerate(columns):
            x1 = self.x.copy()
            x1[k] += JACOBIAN_STEP
            J[:, j] = (self._predict_corners(cam, marker, x1, K) - h) / JACOBIAN_STEP
        return h, J

    def _corner_update(self, cam: CameraState, corners: dict[int, np.ndarray], K: np.ndarray,
                       topside: bool, time: float) -> bool:
        """One Kalman update with the corners (4, 2) of some markers of one body, each with its view's bias; False when
        none was used."""
        assert self.x is not None and self.P is not None
        columns = [*(range(6) if topside else ()), *range(cam.index, cam.index + 6)]
        views = {marker: self._view(cam, marker, K, time).index for marker in sorted(corners)}
        Hs, ys, Rs = [], [], []
        sigma = CORNER_NOISE_PX
        for marker, z in sorted(corners.items()):
            i = self.consider.markers.get(marker)
            cols = columns if i is None else [*columns, *range(i, i + 6)]
            h, J = self.corner_jacobian(cam, marker, K, cols)
            v = slice(views[marker], views[marker] + VIEW)
            H = np.zeros((8, self.size))
            H[:, cols] = J
            H[:, v] = np.eye(VIEW)
            y = z.reshape(-1) - h - self.x[v]
            HPH = H @ self.P @ H.T
            R = sigma**2 * np.eye(8)
            if topside and self.clock_sigma.get(cam.name):  # a clock known to σ_t: the topside seen up to σ_t early
                moved = J[:, :6] @ self.x[6:12] * self.clock_sigma[cam.name]  # or late, (8,) px along its motion
                R += np.outer(moved, moved)  # (cone_estimates adds what the cameras' clocks share)
            for j in range(4):  # robust: a corner far off (rain, glare) counts as if at the threshold
                b = slice(2 * j, 2 * j + 2)
                d2_j = float(y[b] @ np.linalg.solve(HPH[b, b] + R[b, b], y[b]))
                if d2_j > CORNER_HUBER_CHI2:
                    R[b, b] *= d2_j / CORNER_HUBER_CHI2
            if float(y @ np.linalg.solve(HPH + R, y)) > CORNER_GATE_CHI2:
                self.rejected += 1
                continue
            Hs.append(H)
            ys.append(y)
            Rs.append(R)
        if not Hs:
            return False
        H = np.vstack(Hs)
        R = np.zeros((H.shape[0], H.shape[0]))
        for k, R_k in enumerate(Rs):
            R[8 * k:8 * k + 8, 8 * k:8 * k + 8] = R_k
        self._apply(H, np.concatenate(ys), R)
        return True

    def _measure_scale(self, o: BodyObservation) -> None:
        """A frame's evidence of the markers' size: two markers of one body in it, and a surveyed camera's distance to
        its jacket marker (the same for both IPPE options)."""
        for sample in o.scale:
            self.scale.add(sample, o.time)
        if o.camera not in self.surveys or o.jacket is None:
            return
        position, sigma = self.surveys[o.camera]
        T, cov = o.jacket.T_camera_body, o.jacket.covariance
        for i in o.jacket.marker_ids:
            c = self.centres[i]

            def distance(p: np.ndarray, c: np.ndarray = c) -> np.ndarray:
                return np.array([np.linalg.norm(rotation(p[:3]) @ c + p[3:])])

            p0 = _pose_params(T)
            J = _numeric_jacobian(distance, p0)
            sample = survey_sample(o.camera, i, float(distance(p0)[0]), float(np.sqrt(J @ cov @ J.T)[0, 0]),
                                   float(np.linalg.norm(position - c)), sigma)
            if sample is not None:
                self.scale.add(sample, o.time)

    def clock_bound(self, cameras: tuple[str, ...]) -> float:
        """σ, s, of the time an estimate resting on these cameras (all when none) is the topside's: the largest of their
        clocks' (rig: time_offset_sigma), a bound whatever their weights and signs. Weighing each camera by its share
        of the topside's information instead left errors outside 2σ where a synced drone's share was large."""
        return max((self.clock_sigma.get(c, 0.0) for c in cameras or self.clock_sigma), default=0.0)

    def observe(self, o: BodyObservation) -> bool:
        """Apply one camera frame's marker corners; False when no topside corner of it was used.

        The corners are measured directly: each marker's four corners (8 pixel coordinates) against
        their projection through the camera's and the topside's poses in the state. The IPPE
        ambiguity of a lone marker never arises; poses only place a camera or the topside at first sight.
        """
        assert self.x is not None and self.P is not None
        cam = self.cameras.get(o.camera)
        if cam is None:
            return False
        self._measure_scale(o)
        if cam.T_jacket_camera is None:
            if o.jacket is None:
                cam.waiting = "no jacket marker of the rig in its view (a camera is placed by the jacket's markers)"
                return False
            if not self._place_camera(cam, o):
                return False
        if not self.topside_placed:
            if o.topside is None or not self._place_topside(cam, o.topside):
                o = BodyObservation(o.time, o.camera, o.jacket, None,
                                    {i: c for i, c in o.corners.items() if i in self.jacket_corners}, o.K)
        jacket = {i: z for i, z in o.corners.items() if i in self.jacket_corners}
        self._measure_motion(cam, o.time, jacket, o.K)
        topside = {i: z for i, z in o.corners.items() if i in self.topside_corners and self.topside_placed}
        self._renew([o])  # when predict was not given the frame
        used_jacket = self._corner_update(cam, jacket, o.K, False, o.time)  # the camera first, then the topside
        used_topside = self._corner_update(cam, topside, o.K, True, o.time)  # through the camera just refined
        if o.jacket is not None:
            cam.consecutive_rejects = 0 if used_jacket else cam.consecutive_rejects + 1
            if cam.consecutive_rejects >= REINIT_AFTER_REJECTS:  # lost: place it again at its next view
                cam.T_jacket_camera = None
                cam.waiting = f"lost: its jacket corners were refused {REINIT_AFTER_REJECTS} frames in a row"
                self._reset_camera(cam)
        if o.topside is not None and self.topside_placed and not used_topside:
            self.consecutive_rejects += 1
            if self.consecutive_rejects >= REINIT_AFTER_REJECTS:  # lost: place it again at its next view
                self.topside_placed = False
                self.consecutive_rejects = 0
        if used_topside:
            self.consecutive_rejects = 0
            self.last_accepted[o.camera] = o.time
        return used_topside

    def contributing(self) -> tuple[str, ...]:
        """Cameras accepted within CONTRIBUTION_WINDOW_S of the current time."""
        assert self.time is not None
        return tuple(sorted(c for c, t in self.last_accepted.items() if self.time - t <= CONTRIBUTION_WINDOW_S))

    def warming(self) -> bool:
        """Whether the filter is within REPORT_WARMUP_S of the topside's (last) placement."""
        assert self.time is not None
        return self.placed_at is None or self.time - self.placed_at < REPORT_WARMUP_S

    def cone_estimates(self, x: np.ndarray | None = None, P: np.ndarray | None = None,
                       time: float | None = None, cameras: tuple[str, ...] | None = None,
                       warming: bool | None = None) -> list[ConeEstimate]:
        """Offset and covariance at every cone from a state (default: the current one), withholding cones whose σ
        exceeds REPORT_MAX_SIGMA_M, or REPORT_WARMUP_SIGMA_M while warming (default: whether the filter is now); from
        the current state, with the placed cameras' poses (a past state's are relative to nominals since moved)."""
        poses = None if x is not None else {name: self._camera_pose(cam, self.x) for name, cam in self.cameras.items()
                                            if cam.T_jacket_camera is not None}
        x = self.x if x is None else x
        P = self.P if P is None else P
        assert x is not None and P is not None
        time = self.time if time is None else time
        cameras = self.contributing() if cameras is None else cameras
        warming = self.warming() if warming is None else warming
        limit = REPORT_WARMUP_SIGMA_M if warming else REPORT_MAX_SIGMA_M
        clock = self.clock_bound(cameras)
        out = []
        for cone, r in sorted(self.cones.items()):
            H = point_offset_matrix(r)
            cov = timed = H @ P[:STATE, :STATE] @ H.T
            if clock:  # the estimate is the topside's at a time its cameras' clocks hold to σ: its motion over it
                speed, rates = H[:, :6] @ x[6:STATE], H[:, :6] @ P[6:STATE, 6:STATE] @ H[:, :6].T
                cov = cov + clock**2 * (np.outer(speed, speed) + rates)
            withheld = ""
            offset = H @ x[:STATE]
            if self.scale.mismatch:  # a rig error: every offset scaled
                withheld = WITHHELD_SCALE
            elif below_cones(float(offset[2]), float(np.sqrt(cov[2, 2]))):  # no set-down can be there: a rig error
                withheld = WITHHELD_BELOW
                self.below = (self.below[0] + 1, min(self.below[1], float(offset[2])))
            elif np.sqrt(np.diag(cov)).max() > limit:  # the clocks' fault when exact clocks would have shown it
                withheld = WITHHELD_CLOCKS if np.sqrt(np.diag(timed)).max() <= limit else WITHHELD_SIGMA
            offset = np.full(3, np.nan) if withheld else offset
            out.append(ConeEstimate(time, cone, offset, cameras, cov, poses, withheld))
        return out


Measurement = PairOffset | BodyObservation


def _frames(measurements: Iterable[Measurement]) -> Iterator[list[Measurement]]:
    """Group time-ordered measurements by camera frame; a frame's body observation replaces its pair offsets."""
    group: list[Measurement] = []
    for m in measurements:
        if group and (m.time != group[0].time or m.camera != group[0].camera):
            yield preferred(group)
            group = []
        group.append(m)
    if group:
        yield preferred(group)


def preferred(group: list[Measurement]) -> list[Measurement]:
    """A camera frame's body observations if it has any (they hold its pair offsets), else its pair offsets."""
    observations: list[Measurement] = [m for m in group if isinstance(m, BodyObservation)]
    return observations or group


@dataclass
class FilterReport:
    """What a run of the filter found besides its estimates, taken when the run ends: the cameras it never placed and
    why (each camera's CameraState.waiting), the markers' size against the rig's (tracking.scale), and the offsets it
    withheld for putting the topside through its cones."""

    unplaced: dict[str, str] = field(default_factory=dict)
    scale: ScaleEvidence = field(default_factory=ScaleEvidence)
    below: tuple[int, float] = (0, 0.0)  # estimates withheld as the topside through its cones, and the deepest Δz, m

    def take(self, kf: TopsideFilter) -> None:
        """The findings of a filter at the end of its run."""
        self.unplaced = {name: cam.waiting for name, cam in kf.cameras.items() if cam.placed_at is None}
        self.scale = kf.scale
        self.below = kf.below


def fused_estimates(rig: Rig, measurements: Iterable[Measurement], tuning: FilterTuning | None = None,
                    report: FilterReport | None = None) -> Iterator[ConeEstimate]:
    """Live: after each frame with measurements, the filtered offset at every cone; report, when given, gets the
    run's findings at its end."""
    kf = TopsideFilter(rig, tuning or FilterTuning())
    for group in _frames(measurements):
        yield from filter_frame(kf, group)
    if report is not None:
        report.take(kf)


def filter_frame(kf: TopsideFilter, group: list[Measurement]) -> list[ConeEstimate]:
    """One camera frame's measurements applied at its capture time; the estimate at every cone after it
    (none until something was accepted; from then on, every frame gives one)."""
    kf.predict(group[0].time, group)
    for m in preferred(group):
        kf.update(m)
    return kf.cone_estimates() if kf.last_accepted else []


def smoothed_estimates(rig: Rig, measurements: Iterable[Measurement], tuning: FilterTuning | None = None,
                       span_s: float = SMOOTHER_SPAN_S, lag_s: float = SMOOTHER_LAG_S,
                       report: FilterReport | None = None) -> Iterator[ConeEstimate]:
    """Recorded: the filter forward, then Rauch-Tung-Striebel passes backward; the offset at every cone, in time order.

    The backward pass runs whenever the kept steps span span_s + lag_s: from the newest step back, it gives the steps
    older than lag_s before the newest and lets them go, so memory holds span_s + lag_s of the run, not all of it.
    The cameras' nominal poses move as the filter runs; the backward pass treats their errors about
    the nominal of each step as the state, which holds to first order. A cone is shown where the live filter showed
    it at that step (its σ limit and warm-up), with the live filter's covariance: the smoothed covariance counts the
    frames after a step as independent of those before it, but a view's persistent corner errors are in both, so it
    claimed σ of 30-45 mm at cones far from every marker (offsets resting on the topside's rotation) that were
    100-200 mm off, and cones the live filter withheld were shown.
    """
    kf = TopsideFilter(rig, tuning or FilterTuning())
    steps: list[FilterStep] = []
    for group in _frames(measurements):
        F = kf.predict(group[0].time, group)
        assert kf.x is not None and kf.P is not None
        x_pred = kf.x.copy()
        for m in group:
            kf.update(m)
        if kf.last_accepted:
            steps.append(FilterStep(kf.time, x_pred, kf.x.copy(), kf.P.copy(), F, kf.contributing(), kf.warming()))
            if steps[-1].time - steps[0].time >= span_s + lag_s:
                yield from _smooth_back(kf, steps, steps[-1].time - lag_s)
    yield from _smooth_back(kf, steps, np.inf)
    if report is not None:
        report.take(kf)


def _smooth_back(kf: TopsideFilter, steps: list[FilterStep], until: float) -> Iterator[ConeEstimate]:
    """One backward (RTS) pass from the newest of steps: the estimates of the steps before until, which leave steps;
    each with its step's forward covariance (smoothed_estimates says why), so the smoothed covariance is not kept."""
    if not steps:
        return
    nxt = steps[-1]
    x_s = nxt.x
    out = [kf.cone_estimates(x_s, nxt.P, nxt.time, nxt.cameras, nxt.warming)] if nxt.time < until else []
    for step in reversed(steps[:-1]):
        n = step.x.size  # views first seen after this step are independent of it: their states drop out
        P_pred = nxt.F.covariance(step.P)
        C = np.linalg.solve(P_pred, nxt.F.apply(step.P)).T  # P Fᵀ P_pred⁻¹ (P_pred symmetric)
        x_s = step.x + C @ (x_s[:n] - nxt.x_pred)
        x_s[kf.consider.indices] = 0.0  # considered, not estimated (TopsideFilter._apply)
        if step.time < until:
            out.append(kf.cone_estimates(x_s, step.P, step.time, step.cameras, step.warming))
        nxt = step
    del steps[:len(out)]  # the smoothed ones are the oldest: the rest waits for more of the future
    for estimates in reversed(out):
        yield from estimates


def _pair_offsets(measurements: Iterable[Measurement]) -> Iterator[PairOffset]:
    return (m for m in measurements if isinstance(m, PairOffset))


ESTIMATORS: dict[str, Callable[..., Iterable[ConeEstimate]]] = {  # (rig, measurements, report=None)
    "fused": fused_estimates,  # live, the default
    "smoothed": smoothed_estimates,  # recorded runs
    "paper": lambda rig, measurements, report=None: paper_filter(rig, _pair_offsets(measurements)),  # the paper's
    "raw": lambda rig, measurements, report=None: raw_estimates(_pair_offsets(measurements)),  # each pair offset
}
