"""The filter's state: what each entry of x (n,) and P (n, n) is, and the operations every stage of the filter shares.

x holds, in order: the topside (12: translation t and small rotation ω of the topside frame in the jacket frame, then
their rates); every camera of the rig (12 each: its pose error (δθ, δp) about a nominal T_jacket_camera, jacket frame,
then its rates); the markers' survey errors as consider states (ConsiderStates); then the views' corner biases (16 per
(camera, marker), appended as views first appear: 8 that renew as the marker's image travels, 8 as its shape
changes). A camera's nominal pose absorbs its error at every prediction (FilterState.fold_cameras), so within a step
every error is about the predicted nominal.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field

import numpy as np
from scipy.linalg.lapack import dtrtrs
from threadpoolctl import threadpool_limits

from tracking.estimator.hypotheses import Hypotheses
from tracking.estimator.noise import (
    STATE,
    TILT_BASELINE_SIDES,
    TILT_FLOOR_RAD,
    VIEW_PRIOR,
    VIEW_STATES,
    CornerNoise,
    FilterTuning,
    prior_covariance,
)
from tracking.estimator.process import CameraMotionLevel, PoseMotionLevel
from tracking.geometry import rotation, skew
from tracking.offsets import body_geometry
from tracking.pose import body_object_points
from tracking.rig import Rig
from tracking.scale import ScaleEvidence

BLAS_THREADS = 1  # the filter's products are of a few hundred rows: on a busy 2-core machine one took 35 µs on one
# thread and 2.4 ms on OpenBLAS's two (threads spinning for work this small), which made the filter 2-3× slower
_blas_limited = False


def one_blas_thread() -> None:
    """Limit this process's BLAS to BLAS_THREADS, once (a context per frame would cost 0.3 ms)."""
    global _blas_limited
    if not _blas_limited:
        threadpool_limits(BLAS_THREADS, user_api="blas")
        _blas_limited = True


_EYE4 = np.eye(4)  # copied: cheaper than a new identity, per frame and camera


def point_offset_matrix(r: np.ndarray) -> np.ndarray:
    """(3, 12) H: offset of a topside point at r (3,) from the topside state, o = t - [r]× ω."""
    H = np.zeros((3, STATE))
    H[:, :3] = np.eye(3)
    H[:, 3:6] = -skew(r)
    return H


def untold_turn(points: np.ndarray, baseline: float) -> tuple[np.ndarray, np.ndarray]:
    """The centre (3,) of some topside points (n, 3) and the axes (3, k) about which their positions do not tell the
    topside's turn: those they spread less than baseline (m) across (RMS distance from the axis through the centre).
    One cone's markers leave every axis; two cones', the line through them; three cones', none."""
    c = points.mean(axis=0)
    d = points - c
    M = d.T @ d / len(points)
    w, V = np.linalg.eigh(np.trace(M) * np.eye(3) - M)  # the spread² across each axis
    return c, V[:, w < baseline**2]


@dataclass
class ViewBias:
    """The persistent corner errors of one marker seen by one camera: where their VIEW_STATES states sit, the marker's
    corners (8,) predicted at its last frame (ideal pixels), from which the next frame's image travel is measured, and
    the shape its image had when the shape's part was last reset, from which the shape's change is measured."""

    index: int
    corners: np.ndarray
    time: float
    shape: np.ndarray = field(init=False)  # (4, 2) the corners about their centre at the last reset, px
    departure: float = 0.0  # the largest departure from that shape since, over its size
    misread: np.ndarray = field(init=False)  # (2,) px, its corners' departure from every affine image of the square
    # its pose predicts, weighted over VIEW_MISREAD_TAU_S from zero weight (measurements.misread)
    misread_weight: float = 0.0  # the sum of those weights (1 once the view has been seen for several τ)
    misread_weight2: float = 0.0  # the sum of their squares: the share of one frame's white noise left in the sum
    misread_pose_px: np.ndarray = field(init=False)  # (2,) px, the weighted sum of the σ the pose's own uncertainty
    # puts there (near markers: a perspective the pose errs in is not affine)
    misread_time: float | None = None  # capture time of its last frame in that average
    misread_px: float = 0.0  # the largest such average that widened its shape bias, px (0: never)

    def __post_init__(self) -> None:
        self.shape = centred(self.corners)
        self.restart_misread()

    def restart_misread(self) -> None:
        """The misread average back to nothing weighed (a widening already made stays in the filter's renewal)."""
        self.misread = np.zeros(2)
        self.misread_pose_px = np.zeros(2)
        self.misread_weight = self.misread_weight2 = 0.0
        self.misread_time = None


def centred(corners: np.ndarray) -> np.ndarray:
    """(4, 2) a marker's corners (8,) about their centre."""
    c = corners.reshape(4, 2)
    return c - c.mean(axis=0)


NOT_SEEN = "no rig marker in any of its frames"  # why a camera is not placed that the filter never had a frame of (it
# gets a camera's frames only where they show rig markers)


@dataclass
class CameraState:
    """The nominal pose of one camera in the jacket frame, about which the filter holds its error."""

    index: int  # first index of the camera's block in the state
    mount: str  # the rig's camera mount: its motion prior
    name: str  # the rig's camera name: its views' key
    T_jacket_camera: np.ndarray | None = None  # (4, 4), None until a jacket view places the camera
    consecutive_rejects: int = 0
    motion: CameraMotionLevel = field(default_factory=lambda: CameraMotionLevel())
    turns: PoseMotionLevel = field(default_factory=lambda: PoseMotionLevel())  # its turns about its jacket markers
    lone_turns: PoseMotionLevel = field(default_factory=lambda: PoseMotionLevel())  # the same from one marker's fits
    # (their rotations are looser: apart, so they do not raise the noise median of the fits of several)
    corner_noise: CornerNoise = field(default_factory=lambda: CornerNoise())  # its corners' σ, measured
    model_px: float = 0.0  # its calibration's RMS reprojection error, px (BodyObservation.model_px)
    motion_scale: float = 1.0  # share of its mount's process noise the camera gets (1 until its level is known)
    centre: np.ndarray | None = None  # (3,) the centre of its last jacket view's marker when it saw one alone, jacket
    # frame: what it may orbit unseen (estimator.process.orbit_psd); None when it saw several
    hypotheses: Hypotheses | None = None  # while an ambiguous jacket view waits: its options and their evidence
    waiting: str = NOT_SEEN  # why it is not placed (empty once placed)
    placed_at: float | None = None  # capture time of its (last) placement, s

    @property
    def level(self) -> float | None:
        """How much the camera moves, rad²/s³: the larger of its images' level and its turns' (None until the images'
        is measured)."""
        return None if self.motion.level is None else max(self.motion.level, self.turned or 0.0)

    @property
    def turned(self) -> float | None:
        """How fast its own fits say it turns, rad²/s³: the larger of its two turn levels (None where neither reads
        one)."""
        levels = [level for level in (self.turns.level, self.lone_turns.level) if level is not None]
        return max(levels) if levels else None



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
        markers: dict[int, int] = {}
        prior: list[float] = []
        for marker in rig.markers:
            sigma = rig.marker_sigma(marker)
            if sigma is not None and (sigma.tilt_rad().any() or sigma.position().any()):
                markers[marker.id] = first + len(prior)
                prior.extend(np.concatenate([sigma.tilt_rad(), sigma.position()]) ** 2)
        return cls(markers, np.array(prior), first)

    @property
    def indices(self) -> slice:
        return slice(self.first, self.first + self.prior.size)



def camera_pose(nominal: np.ndarray, index: int, x: np.ndarray) -> np.ndarray:
    """(4, 4) T_jacket_camera of a camera at nominal T_jacket_camera (4, 4) whose error states start at index in x."""
    T = _EYE4.copy()
    T[:3, :3] = rotation(x[index:index + 3]) @ nominal[:3, :3]
    T[:3, 3] = nominal[:3, 3] + x[index + 3:index + 6]
    return T


class CameraPoses(Mapping[str, np.ndarray]):
    """T_jacket_camera (4, 4) of the placed cameras in one state, each taken when first read: the filter gives them
    with every frame's estimates, and few readers (the recording's frusta, check) look at them."""

    def __init__(self, nominals: dict[str, tuple[np.ndarray, int]], x: np.ndarray) -> None:
        self._nominals = nominals  # camera -> nominal T_jacket_camera (4, 4) (never written in place) and index
        self._x = x  # (n,) the state's bodies, a copy
        self._poses: dict[str, np.ndarray] = {}

    def __getitem__(self, name: str) -> np.ndarray:
        if name not in self._poses:
            nominal, index = self._nominals[name]
            self._poses[name] = camera_pose(nominal, index, self._x)
        return self._poses[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self._nominals)

    def __len__(self) -> int:
        return len(self._nominals)


def topside_pose(x: np.ndarray) -> np.ndarray:
    """(4, 4) T_jacket_topside of a state."""
    T = _EYE4.copy()
    T[:3, :3] = rotation(x[3:6])
    T[:3, 3] = x[:3]
    return T


@dataclass
class FilterState:
    """The state and covariance of one installation's filter, the rig's geometry they refer to, and what the filter
    keeps between frames (counters, placements, findings)."""

    rig: Rig
    tuning: FilterTuning = field(default_factory=FilterTuning)
    x: np.ndarray = field(init=False)  # (n,)
    P: np.ndarray = field(init=False)  # (n, n)
    time: float | None = field(default=None, init=False)  # capture time of the state, s (None before the first)
    cameras: dict[str, CameraState] = field(init=False)  # rig order
    body_size: int = field(init=False)  # entries of the bodies: the topside's and the cameras'
    consider: ConsiderStates = field(init=False)  # after the bodies; view biases after them
    views: dict[tuple[str, int], ViewBias] = field(init=False)  # (camera, marker) -> its bias states
    renewal: np.ndarray = field(init=False)  # (n - body_size,) variance a state after the bodies is renewed with (its
    # prior; consider states are never renewed)
    topside_placed: bool = field(default=False, init=False)
    placed_at: float | None = field(default=None, init=False)  # capture time the topside was (last) placed, or
    # first measured
    rejected: int = field(default=0, init=False)  # total gated measurements
    consecutive_rejects: int = field(default=0, init=False)  # of the topside
    jolts: int = field(default=0, init=False)  # frames whose jacket corners widened their camera's covariance
    replacements: int = field(default=0, init=False)  # cameras placed again at a view that showed them moved beyond
    # their prior (TopsideFilter._jumped)
    last_accepted: dict[str, float] = field(init=False)  # camera -> capture time of its last topside view used
    survey_conflicts: dict[str, float] = field(init=False)  # camera -> distance, m, between its surveyed position
    # and where its first view placed it, for a survey beyond SURVEY_GATE_CHI2 (not applied)
    scale: ScaleEvidence = field(init=False)  # whether the markers look the size the rig states (tracking.scale)
    below: tuple[int, float] = field(default=(0, 0.0), init=False)  # estimates withheld for putting the topside
    # through its cones, and the deepest of their Δz (m)
    jacket_corners: dict[int, np.ndarray] = field(init=False)  # marker id -> its corners (4, 3), jacket frame
    topside_corners: dict[int, np.ndarray] = field(init=False)  # marker id -> its corners (4, 3), topside frame
    centres: dict[int, np.ndarray] = field(init=False)  # marker id -> its centre (3,), its body's frame
    cones: dict[str, np.ndarray] = field(init=False)  # cone -> the point (3,) whose offset is the cone's
    pair_ids: tuple[tuple[str, int, int], ...] = field(init=False)  # (cone, jacket id, topside id) of every pair (the
    # other cones' offsets come through the topside)
    pair_seen: dict[str, float] = field(init=False)  # cone -> capture time a camera's frame last measured its pair
    topside_seen: dict[int, float] = field(init=False)  # topside marker id -> capture time it was last measured
    _levers: dict[frozenset[int], tuple[np.ndarray, np.ndarray]] = field(init=False)  # seen topside markers -> the
    # axes their positions do not tell (3, k) and each cone's lever from their centre as a turn's offset (C, 3, 3)
    cone_rows: tuple[list[str], np.ndarray] = field(init=False)  # the cones in name order and their offsets' (C, 3,
    # 12) point_offset_matrix
    clock_sigma: dict[str, float] = field(init=False)  # camera -> its clock's σ, s (rig: time_offset_sigma)
    surveys: dict[str, tuple[np.ndarray, float]] = field(init=False)  # camera -> surveyed position (3,), σ m

    def __post_init__(self) -> None:
        one_blas_thread()
        self.cameras = {c.name: CameraState(STATE * (1 + k), c.mount, c.name) for k, c in enumerate(self.rig.cameras)}
        self.body_size = STATE * (1 + len(self.cameras))
        self.consider = ConsiderStates.of(self.rig, self.body_size)
        self.views = {}
        n = self.consider.indices.stop
        self.renewal = np.zeros(n - self.body_size)
        self.x = np.zeros(n)
        self.P = np.zeros((n, n))
        self.P[:STATE, :STATE] = prior_covariance(self.tuning)
        self.P[self.consider.indices, self.consider.indices] = np.diag(self.consider.prior)
        for cam in self.cameras.values():
            self.reset_camera(cam)
        self.last_accepted, self.survey_conflicts, self.scale = {}, {}, ScaleEvidence()
        geometry = body_geometry(self.rig)
        self.jacket_corners = {i: body_object_points([T], self.rig.marker_size) for i, T in geometry.jacket.items()}
        self.topside_corners = {i: body_object_points([T], self.rig.marker_size)
                                for i, T in geometry.topside.items()}
        self.centres = {m.id: np.array(m.center, dtype=float) for m in self.rig.markers}
        self.cones = cone_points(self.rig)
        self.pair_ids = tuple((p.cone, p.jacket, p.topside) for p in self.rig.all_pairs())
        self.pair_seen, self.topside_seen, self._levers = {}, {}, {}
        names = sorted(self.cones)
        self.cone_rows = (names, np.array([point_offset_matrix(self.cones[c]) for c in names]).reshape(-1, 3, STATE))
        self.clock_sigma = {c.name: float(c.time_offset_sigma or 0.0) for c in self.rig.cameras}
        self.surveys = {c.name: (np.array(c.position, dtype=float), float(c.position_sigma)) for c in self.rig.cameras
                        if c.position is not None and c.position_sigma is not None}

    @property
    def size(self) -> int:
        """Length of the state: the bodies', the consider states' and the views' biases so far."""
        return self.x.size

    def tilt_floor(self, seen: frozenset[int], P_turn: np.ndarray) -> np.ndarray | None:
        """(C, 3, 3) the variance the cones' offsets (cone_rows' order) gain when the topside's turn about the axes the
        seen topside markers' positions do not tell (untold_turn over TILT_BASELINE_SIDES) is held to σ ≥
        TILT_FLOOR_RAD, from the turn's covariance P_turn (3, 3): about those axes only their orientation tells it, and
        a marker's orientation from its corners errs beyond what its corners' σ says (docs/method.md). Each cone moves
        by its lever from the markers' centre; None when nothing is seen or the turn already has that σ about every
        such axis."""
        if not seen:
            return None
        if seen not in self._levers:
            c, U = untold_turn(np.array([self.centres[i] for i in sorted(seen)]),
                               TILT_BASELINE_SIDES * self.rig.marker_size)
            self._levers[seen] = (U, -np.array([skew(self.cones[name] - c) for name in self.cone_rows[0]]))
        U, A = self._levers[seen]
        if not U.shape[1]:
            return None
        w, V = np.linalg.eigh(TILT_FLOOR_RAD**2 * np.eye(U.shape[1]) - U.T @ P_turn @ U)
        if w.max() <= 0.0:
            return None
        B = U @ V
        added = (B * np.fmax(w, 0.0)) @ B.T  # (3, 3) the turn's variance raised to the floor about the untold axes
        return A @ added @ A.transpose(0, 2, 1)

    def camera_pose(self, cam: CameraState, x: np.ndarray | None = None) -> np.ndarray:
        """(4, 4) T_jacket_camera of a placed camera in a state (default: the current one)."""
        assert cam.T_jacket_camera is not None, f"camera {cam.name} is not placed"
        return camera_pose(cam.T_jacket_camera, cam.index, self.x if x is None else x)

    def reset_camera(self, cam: CameraState, covariance: np.ndarray | None = None) -> None:
        """Forget a camera: its block decoupled, its pose covariance given (or unit), its rates' prior."""
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
                self.forget_view(view)

    def forget_view(self, view: ViewBias) -> None:
        """A view's bias states back to their prior, decoupled from the rest."""
        v = slice(view.index, view.index + VIEW_STATES)
        self.P[v, :] = 0.0
        self.P[:, v] = 0.0
        self.P[v, v] = np.diag(self.renewal[view.index - self.body_size:view.index - self.body_size + VIEW_STATES])
        self.x[v] = 0.0
        view.restart_misread()

    def append_view(self, key: tuple[str, int], corners: np.ndarray, time: float) -> ViewBias:
        """A new view's bias states appended to the state with their prior; its marker's corners (8,) predicted now."""
        n = self.size
        view = ViewBias(n, corners, time)
        self.x = np.concatenate([self.x, np.zeros(VIEW_STATES)])
        P = np.zeros((n + VIEW_STATES, n + VIEW_STATES))
        P[:n, :n] = self.P
        P[n:, n:] = np.diag(VIEW_PRIOR)
        self.P = P
        self.renewal = np.concatenate([self.renewal, VIEW_PRIOR])  # a new array: transitions hold the old
        self.views[key] = view
        return view

    def fold_cameras(self) -> None:
        """Move the cameras' pose errors (and the motion their rates imply) into their nominal poses.

        Done once per step, at the prediction: within a step every error is about the predicted nominal,
        which keeps the smoother's differences between steps consistent.
        """
        for cam in self.cameras.values():
            if cam.T_jacket_camera is not None:
                cam.T_jacket_camera = self.camera_pose(cam)
                self.x[cam.index:cam.index + 6] = 0.0

    def apply(self, H: np.ndarray, y: np.ndarray, R: np.ndarray, columns: list[int] | None = None) -> None:
        """Kalman update with H (M, n), innovation y (M,) and measurement covariance R (M, M); with columns (C,), H is
        (M, C): the state entries it measures (the rest of its row is zero).

        P - P Hᵀ S⁻¹ H P as P - W Wᵀ, W = P Hᵀ L⁻ᵀ (S = L Lᵀ): symmetric by construction, O(n² M) where the Joseph
        form would cost O(n³) for n = 12 per body."""
        PHt = self.P @ H.T if columns is None else self.P[:, columns] @ H.T  # (n, M)
        S = (H @ PHt if columns is None else H @ PHt[columns]) + R
        try:
            L = np.linalg.cholesky(S)
            Wt, _ = dtrtrs(L, PHt.T, lower=1)  # (M, n): LAPACK's triangular solves, without numpy's per-call checks
            K = dtrtrs(L, Wt, lower=1, trans=1)[0].T  # (n, M): P Hᵀ S⁻¹
            P = self.P - Wt.T @ Wt
        except np.linalg.LinAlgError:  # S not positive definite (P lost it to rounding): symmetrised instead
            K = np.linalg.solve(S, PHt.T).T
            P = self.P - K @ PHt.T
            P = (P + P.T) / 2
        c = self.consider.indices  # consider states are not estimated (Schmidt): the others' update, their covariance
        K[c] = 0.0  # and cross-covariance are as with them, their own is kept
        P[c, c] = self.P[c, c]
        self.x = self.x + K @ y
        self.P = P
