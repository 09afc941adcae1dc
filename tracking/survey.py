"""Marker poses from the footage: a bundle adjustment of every marker's pose in its body's frame.

Markers are mounted by riggers and surveyed to a centimetre or two and a degree or so; a jacket marker's centre off by
20 mm puts every offset measured through it 20 mm off. The footage itself measures the markers' poses where cameras see
them together with other markers of the same body, or see the topside move: all cameras' frames of a stretch of
footage are fitted at once to

- every marker's pose in its body's frame: a correction (rotation δθ about the body's axes at the marker's centre,
  displacement δp) to the rig's pose, with the rig's survey σ as its prior;
- the topside's rigid motion relative to the jacket: translation and small rotation as cubic B-splines of capture time
  (the clocks must be synchronised first: `topside sync`);
- every camera frame's pose T_camera_jacket (vessels and drones move; each frame is free);

by the markers' corners (undistorted pixels, σ FIT_NOISE_PX, soft-L1 per corner beyond SOFT_L1_PX against
rain-struck corners), with tracking/least_squares.py's solver (Levenberg-Marquardt on the sparse normal equations). The
topside's motion starts from tracking/motion_model.py's fit of the pair offsets.

Gauge: the jacket frame is defined by its markers as surveyed, the topside frame by its own: either one marker per body
named `reference: true` in the rig (held where the rig has it), or, without one, by every marker's survey prior at once
(a correction common to all markers of a body is then as uncertain as the survey: no footage can tell it). What the
footage cannot tell stays where the survey put it, with the survey's σ: a camera that sees one jacket and one topside
marker and nothing else cannot tell both moved together (its offsets are the same either way), and a topside moving
along one line cannot tell a rotation about that line. The σ written for each marker says what was learnt, widened
to hold what its error shares with other markers' (the fusion filter takes each marker's as independent).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
from scipy.sparse import csr_matrix

from tracking.clocks import SPLINE_MARGIN_S, UNKNOWN_SIGMA_S
from tracking.errors import InputError
from tracking.estimator.noise import CORNER_NOISE_PX, VIEW_BIAS_PX
from tracking.geometry import rotations
from tracking.least_squares import SoftL1, Triplets, information_columns, minimise
from tracking.motion_model import (
    KNOT_S,
    ROTATION_KNOT_S,
    OffsetModel,
    Spline,
    motion_prior,
    motion_prior_rows,
    pair_samples,
)
from tracking.offsets import BodyObservation, PairOffset
from tracking.pose import Choice, marker_object_points
from tracking.rig import Marker, Pair, Rig, SurveyCorrection, SurveySigma

CORRELATED_FRAMES = 15  # a view's corner errors last about this many frames (a second at 15 FPS: the sub-pixel phase
# of a marker's edges and the stream's coding of a still picture; tracking.estimator's view biases): its frames count
# as one in this many, else a far camera's frames overstate what it tells (evidence in
# docs/method.md#clocks-and-the-marker-survey-sync-survey)
FIT_NOISE_PX = CORNER_NOISE_PX * float(np.sqrt(CORRELATED_FRAMES))  # the corners' σ in the fit (CORNER_NOISE_PX:
# the fusion filter's frame-to-frame σ; each view (camera, marker) also carries a bias per corner coordinate of the
# filter's VIEW_BIAS_PX: at 34 m a 1 m marker spans 37 px, so 0.08 px is 0.2 % of its scale, 70 mm of its depth, which
# no number of frames averages away)
SOFT_L1_PX = 0.5  # corners further than this from their prediction count linearly (rain, glare)
MAX_ITERATIONS = 40  # Levenberg-Marquardt steps (it stops sooner when the cost no longer falls)
DIFF_STEP = 1e-6  # rad or m: forward differences of one observation's corners
DEFAULT_TOLERANCE_SIGMAS = 3.0  # without the rig's survey_tolerance, a correction beyond this many prior σ is flagged
BISECTIONS = 40  # independent_sigmas' search for its scale, in ratios (to 1e-6 of a factor of up to 1e6)
MIN_VIEWS = 10  # a marker seen in fewer frames keeps its survey pose
MIN_FORESHORTENING = 0.4  # a marker seen more than 66° off its normal is left out: its corners are biased by up to a
# pixel there (evidence in docs/method.md#clocks-and-the-marker-survey-sync-survey)


@dataclass(frozen=True)
class MarkerSurvey:
    """One marker's pose as the footage places it: its correction to the rig's pose and what is left of its σ."""

    id: int
    body: str
    position_m: np.ndarray  # (3,) centre moved by, body frame, m
    rotation_rad: np.ndarray  # (3,) rotation vector applied at the centre, body frame, rad
    sigma_m: np.ndarray  # (3,) σ of the corrected centre, body frame, m
    sigma_rad: np.ndarray  # (3,) σ of the corrected rotation about the body's axes, rad
    prior_m: np.ndarray  # (3,) σ the survey gave the centre, m
    prior_rad: np.ndarray  # (3,) σ the survey gave the rotation, rad
    views: int  # camera frames that saw it
    held_m: np.ndarray  # (3,) σ of the centre the rig is given: sigma_m widened where markers' errors are correlated
    # (independent_sigmas), as the fusion filter takes each marker's as independent, m
    held_rad: np.ndarray  # (3,) ... of its rotation, rad
    reference: bool = False  # held as its body's datum
    flagged: bool = False  # moved beyond the survey's tolerance

    @property
    def learnt(self) -> float:
        """Share of the survey's position σ the footage removed, as the rig is given it (held_m), along the best-seen
        axis (0: nothing learnt)."""
        if self.reference or not np.any(self.prior_m > 0):
            return 0.0
        return float(max(np.max(1.0 - self.held_m / np.maximum(self.prior_m, 1e-12)), 0.0))


@dataclass(frozen=True)
class SurveyFit:
    """The survey of one stretch of footage: every marker, and how well the corners fitted."""

    markers: list[MarkerSurvey]
    frames: int  # camera frames used
    corners: int  # corners fitted
    rms_px: float  # RMS corner residual, px
    iterations: int


rodrigues = rotations  # (N, 3, 3) rotation matrices of rotation vectors (N, 3): the name the survey's callers know


@dataclass
class _Views:
    """Every (frame, marker) the survey fits, as arrays of V views over F frames."""

    frame: np.ndarray  # (V,) frame index
    marker: np.ndarray  # (V,) index into the rig's markers
    corners: np.ndarray  # (V, 8) undistorted pixels
    K: np.ndarray  # (V, 4) fx, fy, cx, cy
    time: np.ndarray  # (V,) capture time
    topside: np.ndarray  # (V,) bool
    T_camera_jacket: np.ndarray  # (F, 4, 4) each frame's first pose
    frame_camera: list[str]


def _first_pose(o: BodyObservation, near: np.ndarray | None) -> np.ndarray | None:
    """A frame's T_camera_jacket to start from: its jacket pose, the IPPE option whose camera sits nearest `near`
    (the camera's typical position, jacket frame) when ambiguous."""
    if o.jacket is None:
        return None
    options = [o.jacket.T_camera_body, *(T for T, _ in o.jacket.alternatives)]
    if near is None or o.jacket.choice == Choice.UNIQUE:
        return options[0]
    return min(options, key=lambda T: float(np.linalg.norm(-T[:3, :3].T @ T[:3, 3] - near)))


def foreshortening(corners: np.ndarray) -> float:
    """A marker's shortest side over its longest, from its corners (4, 2): 1 face-on, cos(angle off its normal)."""
    q = np.asarray(corners, dtype=float).reshape(4, 2)
    sides = np.linalg.norm(q - np.roll(q, -1, axis=0), axis=1)
    return float(sides.min() / max(sides.max(), 1e-9))


def untimed_cameras(rig: Rig) -> set[str]:
    """Cameras whose clock is not measured (no time_offset_sigma, or one beyond UNKNOWN_SIGMA_S) while another's is:
    their views of the moving topside would be fitted at the wrong instants. None when no clock is measured (the
    survey then takes the rig's clocks as they are, and says so)."""
    measured = {c.name for c in rig.cameras if c.time_offset_sigma is not None
                and c.time_offset_sigma <= UNKNOWN_SIGMA_S}
    return set() if not measured else {c.name for c in rig.cameras} - measured


def _views(rig: Rig, observations: list[BodyObservation]) -> _Views:
    """The views of the observations with a jacket pose to start from; a camera of untimed_cameras gives its jacket
    markers only."""
    index = {m.id: k for k, m in enumerate(rig.markers)}
    untimed = untimed_cameras(rig)
    centres: dict[str, list[np.ndarray]] = {}
    for o in observations:
        if o.jacket is not None and o.jacket.choice == Choice.UNIQUE:
            T = o.jacket.T_camera_body
            centres.setdefault(o.camera, []).append(-T[:3, :3].T @ T[:3, 3])
    typical = {c: np.median(np.array(p), axis=0) for c, p in centres.items()}
    frame, marker, corners, K, time, topside, poses, cams = [], [], [], [], [], [], [], []
    for o in observations:
        T = _first_pose(o, typical.get(o.camera))
        if T is None:
            continue
        f = len(poses)
        poses.append(T)
        cams.append(o.camera)
        for mid, z in sorted(o.corners.items()):
            if mid not in index or (o.camera in untimed and rig.markers[index[mid]].body == "topside") \
                    or foreshortening(z) < MIN_FORESHORTENING:
                continue
            frame.append(f)
            marker.append(index[mid])
            corners.append(np.asarray(z, dtype=float).reshape(8))
            K.append([o.K[0, 0], o.K[1, 1], o.K[0, 2], o.K[1, 2]])
            time.append(o.time)
            topside.append(rig.markers[index[mid]].body == "topside")
    if not frame:
        raise InputError(rig.path, "no camera frame shows a jacket marker in the footage (expected frames that place a "
                                   "camera by its jacket markers)")
    return _Views(np.array(frame), np.array(marker), np.array(corners), np.array(K, dtype=float), np.array(time),
                  np.array(topside), np.array(poses), cams)


class _Bundle:
    """Parameters [frames' T_camera_jacket as corrections (δθ, δt) to their first poses [R0, t0]: [R(δθ) R0, t0 + δt]
    (6 F), topside translation knots (3 n), rotation knots (3 m), free markers' corrections (6 M: δθ, δp)] and the
    corners' residuals."""

    def __init__(self, rig: Rig, v: _Views, free: list[int], priors: np.ndarray, p0: np.ndarray, w0: np.ndarray,
                 trans: Spline, rot: Spline) -> None:
        self.v = v
        self.free = free
        self.slot = {m: k for k, m in enumerate(free)}
        self.priors = priors  # (M, 6) σ of δθ (rad) and δp (m)
        self.trans, self.rot = trans, rot
        nf = len(v.T_camera_jacket)
        self.o_t = 6 * nf
        self.o_w = self.o_t + 3 * trans.n
        self.o_m = self.o_w + 3 * rot.n
        self.o_v = self.o_m + 6 * len(free)
        keys = [(v.frame_camera[f], int(m)) for f, m in zip(v.frame, v.marker, strict=True)]
        views = {k: i for i, k in enumerate(dict.fromkeys(keys))}  # (camera, marker) -> its bias slot
        self.view = np.array([views[k] for k in keys], dtype=int)  # (V,)
        self.size = self.o_v + 8 * len(views)
        x = np.zeros(self.size)  # frames: rotation δθ and translation δt about their first pose [R0, t0]
        x[self.o_t:self.o_w] = p0.reshape(-1)
        x[self.o_w:self.o_m] = w0.reshape(-1)
        self.x0 = x
        self.R_nom = np.array([m.R_body_marker for m in rig.markers])
        self.c_nom = np.array([m.center for m in rig.markers], dtype=float)
        self.obj = marker_object_points(rig.marker_size)  # (4, 3)
        self.mslot = np.array([self.slot.get(int(m), -1) for m in v.marker])  # (V,) -1: held
        self.ti, self.tw, _ = trans.basis(v.time)
        self.ri, self.rw, _ = rot.basis(v.time)

    def local(self, x: np.ndarray) -> np.ndarray:
        """(V, 18) each view's camera pose (6), topside pose (rotation, translation: 6) and marker correction (6)."""
        V = len(self.v.frame)
        out = np.zeros((V, 18))
        cam = x[:self.o_t].reshape(-1, 6)
        out[:, :6] = cam[self.v.frame]
        P = x[self.o_t:self.o_w].reshape(-1, 3)
        W = x[self.o_w:self.o_m].reshape(-1, 3)
        top = self.v.topside
        out[top, 6:9] = np.einsum("nk,nkj->nj", self.rw[top], W[self.ri[top]])
        out[top, 9:12] = np.einsum("nk,nkj->nj", self.tw[top], P[self.ti[top]])
        M = x[self.o_m:self.o_v].reshape(-1, 6)
        free = self.mslot >= 0
        out[free, 12:18] = M[self.mslot[free]]
        return out

    def project(self, q: np.ndarray) -> np.ndarray:
        """(V, 8) predicted corners from local parameters q (V, 18)."""
        m = self.v.marker
        X = np.einsum("nij,kj->nki", rotations(q[:, 12:15]) @ self.R_nom[m], self.obj)
        X = X + (self.c_nom[m] + q[:, 15:18])[:, None, :]
        X = np.einsum("nij,nkj->nki", rotations(q[:, 6:9]), X) + q[:, None, 9:12]  # zero pose for jacket markers
        T0 = self.v.T_camera_jacket[self.v.frame]
        X = np.einsum("nij,nkj->nki", rotations(q[:, :3]) @ T0[:, :3, :3], X) + (T0[:, :3, 3] + q[:, 3:6])[:, None]
        K = self.v.K
        u = K[:, None, 0] * X[:, :, 0] / X[:, :, 2] + K[:, None, 2]
        w = K[:, None, 1] * X[:, :, 1] / X[:, :, 2] + K[:, None, 3]
        return np.stack([u, w], axis=2).reshape(-1, 8)

    def corner_errors(self, x: np.ndarray) -> np.ndarray:
        """(V, 8) measured minus predicted corners (each view's bias added), px."""
        return self.v.corners - self.project(self.local(x)) - x[self.o_v:].reshape(-1, 8)[self.view]

    def residuals(self, x: np.ndarray) -> np.ndarray:
        """All residuals whitened, as jacobian differentiates them: predicted minus measured corners over
        FIT_NOISE_PX (8 V), then the priors."""
        return np.concatenate([-self.corner_errors(x).reshape(-1) / FIT_NOISE_PX, self.prior_residuals(x)])

    @property
    def loss(self) -> SoftL1:
        """Soft-L1 per corner (its u and v together) beyond SOFT_L1_PX; the priors as plain squares."""
        return SoftL1(SOFT_L1_PX / FIT_NOISE_PX, rows=8 * len(self.v.frame), group=2)

    def prior_residuals(self, x: np.ndarray) -> np.ndarray:
        """Whitened priors: marker corrections, the topside's accelerations, the views' biases."""
        M = x[self.o_m:self.o_v].reshape(-1, 6) / self.priors
        P = x[self.o_t:self.o_w].reshape(-1, 3)
        W = x[self.o_w:self.o_m].reshape(-1, 3)
        accel, angular = motion_prior(P, self.trans.h, W, self.rot.h)
        return np.concatenate([M.reshape(-1), accel, angular, x[self.o_v:] / VIEW_BIAS_PX])

    def jacobian(self, x: np.ndarray) -> csr_matrix:
        """d residuals / dx (sparse): the corners by forward differences of each view's 18 local parameters."""
        q = self.local(x)
        base = self.project(q)
        D = np.empty((len(q), 8, 18))
        for j in range(18):
            q1 = q.copy()
            q1[:, j] += DIFF_STEP
            D[:, :, j] = (self.project(q1) - base) / DIFF_STEP
        D /= FIT_NOISE_PX
        V = len(q)
        rows8 = (8 * np.arange(V))[:, None] + np.arange(8)  # (V, 8)
        J = Triplets()

        def add(mask: np.ndarray, col: np.ndarray, d: np.ndarray) -> None:
            """d (v, 8, c): derivatives of the views in mask by columns col (v, c)."""
            J.add(rows8[mask][:, :, None], col[:, None, :], d)

        every = np.ones(V, bool)
        add(every, 6 * self.v.frame[:, None] + np.arange(6), D[:, :, :6])
        top = self.v.topside
        for k in range(4):
            add(top, self.o_w + 3 * self.ri[top, k][:, None] + np.arange(3),
                D[top][:, :, 6:9] * self.rw[top, k][:, None, None])
            add(top, self.o_t + 3 * self.ti[top, k][:, None] + np.arange(3),
                D[top][:, :, 9:12] * self.tw[top, k][:, None, None])
        free = self.mslot >= 0
        add(free, self.o_m + 6 * self.mslot[free][:, None] + np.arange(6), D[free][:, :, 12:18])
        bias = np.broadcast_to(np.eye(8) / FIT_NOISE_PX, (V, 8, 8))  # each view's bias adds to its predictions
        add(every, self.o_v + 8 * self.view[:, None] + np.arange(8), bias)
        m = J.diagonal(8 * V, self.o_m, 1.0 / self.priors.reshape(-1))
        m = motion_prior_rows(J, m, ((self.trans, self.o_t), (self.rot, self.o_w)))
        m = J.diagonal(m, self.o_v, np.full(self.size - self.o_v, 1.0 / VIEW_BIAS_PX))
        return J.matrix(m, self.size)

    def solve(self) -> tuple[np.ndarray, int]:
        """The fit from the first poses: the parameters and the iterations taken."""
        fit = minimise(self.residuals, self.jacobian, self.x0, self.loss, MAX_ITERATIONS)
        return fit.x, fit.iterations

    def marker_covariance(self, x: np.ndarray) -> np.ndarray:
        """(6 M, 6 M) joint covariance of the free markers' corrections (δθ, δp of each in slot order; weights as at
        x): markers the footage ties together, or that move together unseen (a body's datum), are correlated."""
        columns = self.o_m + np.arange(6 * len(self.free))
        C = information_columns(self.jacobian(x), self.loss.weights(self.residuals(x)), columns)[columns]
        return 0.5 * (C + C.T)


def independent_sigmas(covariance: np.ndarray, prior: np.ndarray) -> np.ndarray:
    """(n,) σ that, taken as independent (as the fusion filter takes each marker's), still hold the joint covariance
    (n, n): the smallest c (by bisection) for which D = min(prior², c · its diagonal) satisfies D ⪰ covariance, and
    √D. A correction common to a body's markers (no datum) keeps the survey's σ: the footage cannot tell it, and the
    markers' own σ would shrink it by √(markers) when taken as independent (evidence in
    docs/method.md#clocks-and-the-marker-survey-sync-survey)."""
    var = np.maximum(np.diag(covariance), 1e-30)
    top = np.maximum(prior**2, var)

    def holds(c: float) -> bool:
        d = 1.0 / np.sqrt(np.minimum(top, c * var))
        return float(np.linalg.eigvalsh(covariance * np.outer(d, d))[-1]) <= 1.0 + 1e-9

    if not holds(float(np.max(top / var))):  # the prior itself falls short (a linearised fit): widen it
        d = 1.0 / np.sqrt(top)
        return np.sqrt(top * float(np.linalg.eigvalsh(covariance * np.outer(d, d))[-1]))
    lo, hi = 1.0, float(np.max(top / var))
    if holds(lo):
        return np.sqrt(var)
    for _ in range(BISECTIONS):
        mid = np.sqrt(lo * hi)
        lo, hi = (lo, mid) if holds(mid) else (mid, hi)
    return np.sqrt(np.minimum(top, hi * var))


def _initial_motion(rig: Rig, offsets: list[PairOffset], start: float, end: float
                    ) -> tuple[Spline, Spline, np.ndarray, np.ndarray]:
    """The topside's translation and rotation splines with their knots (n, 3), (m, 3) to start from: the motion model's
    linear fit of the pair offsets at zero lag (tracking.motion_model, on sync's splines), or still at the origin
    without pair offsets."""
    s = pair_samples(rig, offsets, [c.name for c in rig.cameras])
    if not len(s.time):
        trans, rot = Spline.spanning(start, end, KNOT_S), Spline.spanning(start, end, ROTATION_KNOT_S)
        return trans, rot, np.zeros((trans.n, 3)), np.zeros((rot.n, 3))
    model = OffsetModel(s, [], SPLINE_MARGIN_S)
    return model.p, model.w, *model.knots(model.linear_fit(np.zeros(model.size)))


def surveyable(rig: Rig) -> dict[int, np.ndarray]:
    """The markers a survey may move (by index in rig.markers): not the reference, with a survey σ of their own or the
    rig's, every axis above 0; each one's prior σ (tilt rad, position m). None is a one-line InputError, found before
    any footage is read."""
    out = {}
    for k, m in enumerate(rig.markers):
        sigma = rig.marker_sigma(m)
        if m.reference or sigma is None:
            continue
        prior = np.concatenate([sigma.tilt_rad(), sigma.position()])
        if np.all(prior > 0):
            out[k] = prior
    if not out:
        raise InputError(rig.path, "no marker to survey (expected survey_sigma, or a sigma on each marker that is not "
                                   "the reference)", "survey_sigma")
    return out


def survey_markers(rig: Rig, measurements: Iterable[PairOffset | BodyObservation]) -> SurveyFit:
    """Every marker's pose refined from the footage's measurements (body observations with their corners, pair
    offsets for the first estimate of the topside's motion); times on the rig's clocks (sync them first)."""
    observations, offsets = [], []
    for m in measurements:
        (observations if isinstance(m, BodyObservation) else offsets).append(m)
    v = _views(rig, observations)
    counts = np.bincount(v.marker, minlength=len(rig.markers))
    free, priors = [], []
    for k, prior in surveyable(rig).items():
        if counts[k] >= MIN_VIEWS:
            free.append(k)
            priors.append(prior)
    if not free:
        raise InputError(rig.path, "no marker to survey (expected survey_sigma, or a sigma on each marker, and "
                                   f"markers seen in at least {MIN_VIEWS} frames)", "survey_sigma")
    untimed = untimed_cameras(rig)
    timed = [o for o in offsets if o.camera not in untimed]
    trans, rot, p0, w0 = _initial_motion(rig, timed, float(v.time.min()), float(v.time.max()))
    bundle = _Bundle(rig, v, free, np.array(priors), p0, w0, trans, rot)
    x, iterations = bundle.solve()
    cov = bundle.marker_covariance(x)
    held = independent_sigmas(cov, np.array(priors).reshape(-1)).reshape(-1, 6)
    res = bundle.corner_errors(x)
    out = []
    tolerance = rig.survey_tolerance
    for k, m in enumerate(rig.markers):
        sigma = rig.marker_sigma(m)
        prior_m = sigma.position() if sigma else np.zeros(3)
        prior_rad = sigma.tilt_rad() if sigma else np.zeros(3)
        if k in bundle.slot:
            i = bundle.slot[k]
            d = x[bundle.o_m + 6 * i:bundle.o_m + 6 * i + 6]
            sd = np.sqrt(np.maximum(np.diag(cov)[6 * i:6 * i + 6], 0.0))
            limit_m = tolerance.position() if tolerance else DEFAULT_TOLERANCE_SIGMAS * prior_m
            limit_rad = tolerance.tilt_rad() if tolerance else DEFAULT_TOLERANCE_SIGMAS * prior_rad
            flagged = bool(np.any(np.abs(d[3:]) > limit_m) or np.any(np.abs(d[:3]) > limit_rad))
            out.append(MarkerSurvey(m.id, m.body, d[3:].copy(), d[:3].copy(), sd[3:], sd[:3], prior_m, prior_rad,
                                    int(counts[k]), held[i, 3:], held[i, :3], False, flagged))
        else:
            out.append(MarkerSurvey(m.id, m.body, np.zeros(3), np.zeros(3), prior_m, prior_rad, prior_m, prior_rad,
                                    int(counts[k]), prior_m, prior_rad, m.reference))
    return SurveyFit(out, len(v.T_camera_jacket), 4 * len(v.frame), float(np.sqrt(np.mean(res**2))), iterations)


def surveyed_rig(rig: Rig, fit: SurveyFit) -> Rig:
    """The rig with every surveyed marker moved to where the footage puts it, its correction and its σ as the filter
    may take it (held_m, held_rad: independent of the other markers'); pairs' mated offsets follow the corrected
    centres."""
    by_id = {s.id: s for s in fit.markers}
    markers: list[Marker] = []
    for m in rig.markers:
        s = by_id.get(m.id)
        if s is None or s.reference or (not np.any(s.position_m) and not np.any(s.rotation_rad)):
            markers.append(m)
            continue
        R = rotations(s.rotation_rad[None])[0] @ m.R_body_marker
        markers.append(Marker(
            id=m.id, body=m.body, cone=m.cone, face=m.face, reference=m.reference,
            center=(np.array(m.center) + s.position_m).round(6).tolist(), R=R.round(9).tolist(),
            sigma=SurveySigma(position_m=(np.ceil(s.held_m * 1e6) / 1e6).tolist(),
                              tilt_deg=(np.ceil(np.degrees(s.held_rad) * 1e6) / 1e6).tolist()),
            correction=SurveyCorrection(position_m=s.position_m.round(6).tolist(),
                                        rotation_deg=np.degrees(s.rotation_rad).round(6).tolist())))
    centres = {m.id: np.array(m.center) for m in markers}
    pairs = [Pair(cone=p.cone, face=p.face, jacket=p.jacket, topside=p.topside,
                  mated=None if p.mated is None else (centres[p.topside] - centres[p.jacket]).round(6).tolist())
             for p in rig.pairs]
    return rig.model_copy(update={"markers": markers, "pairs": pairs})
