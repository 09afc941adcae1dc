"""Camera clocks from the footage itself: every camera's time offset against a reference camera's.

What the cameras see in common is the topside's motion relative to the jacket: every camera's pair offsets (topside
marker minus its mated position, jacket frame; tracking.offsets) sample one rigid motion, each at its own capture
times. A camera whose clock is off by τ samples that motion τ late: its offsets lag the others' by τ wherever the
topside moves. So the offsets of all cameras are fitted together with one motion (translation p(t) and small
rotation ω(t) of the topside, cubic B-splines) and a clock offset per camera (the reference's held at zero):

    o(t) = (I + [ε]×) (p(t + τ_c) - [r]× ω(t + τ_c)) + b

r the topside marker's centre, b a constant per camera and pair (the pair's survey errors and each camera's
persistent corner errors do not move in time, so they say nothing of clocks), ε a small rotation per camera and pair
with the jacket marker's survey tilt σ as its prior: a jacket marker turned 1° off its survey turns the pair's offsets
with it, 350 mm at 20 m, which grows as the topside comes in and, taken as surveyed, read as a lag (clocks 74-158 ms
off in config2-setdown-realities without it, 19-45 ms with it). What is observable: τ_c is the shift
that lines a camera's offsets up with the others' along the topside's velocity, so its information is the squared
velocity over the offsets' variance along it. A still topside gives nothing; a topside moving 0.05 m/s, seen by a
camera whose offsets scatter by 5 mm, gives 0.1 s per frame, a few milliseconds over a minute. The cameras' own
motion (a vessel's waves, a drone's hovering) is not used: each camera's pose is measured from its own images, and a
drone's motion is its own. The shared wave motion of vessel-mounted cameras would tie those to each other even with
a still topside; it is left out (see the README).

A first estimate comes from matching each camera's topside track with the reference's (within ±SEARCH_S, their
constant difference removed); the joint fit (Gauss-Newton on sparse normal equations, soft-L1 weights) refines it.
Each camera's σ is the larger of the fit's covariance, scaled by its residuals' spread and by their correlation in
time (a view's corner errors last for seconds, so its frames are not independent), and a cluster-robust (sandwich)
variance over CLUSTER_S blocks of every camera's residuals. Where σ exceeds UNKNOWN_SIGMA_S the offset is not
changed and the reason is given.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np
from scipy.sparse import coo_matrix, csr_matrix, diags
from scipy.sparse.linalg import splu, spsolve

from tracking.errors import InputError
from tracking.offsets import PairOffset
from tracking.pose import Choice
from tracking.rig import Rig

KNOT_S = 0.5  # spacing of the topside translation's cubic spline: follows a pendulum swing (14 s) and 8 s waves to
# well under a millimetre (a cubic's error ~ h⁴ ω⁴ A / 77), while the offsets' noise between knots averages out instead
# of showing as velocity (at 0.2 s the spline followed the noise: clocks 10 ms off with a stated σ of 1 ms)
ROTATION_KNOT_S = 1.0  # spacing of its rotation's spline: twist (24 s) and tilt (6.5 s) of a hanging topside
ROTATION_PRIOR_RAD = 0.01  # σ of the topside's rotation at every knot: only its changes between cones are seen
ANGULAR_ACCEL_RADPS2 = 1e-3  # σ of the topside's angular acceleration (second differences of its rotation's knots):
# a 10,000 t topside in slings twists ~0.1° over 24 s and tilts ~0.03° over 6.5 s (1e-4 and 5e-4 rad/s²). Without it
# the rotation follows whatever the cameras at one cone see later than those at another: its lever (20 m between
# cones) turns a 20 ms lag at 0.05 m/s into 5e-5 rad, within any looser bound
ACCEL_MPS2 = 1.0  # σ of the topside's acceleration (second differences of its translation's knots): a crane hook in
# waves, a swinging load; only bridges frames no camera saw
TILT_FLOOR_RAD = np.radians(0.2)  # σ of a pair's frame rotation beside the survey's: a far camera's view of the jacket
# marker's face
BIAS_PRIOR_M = 1.0  # σ of each camera's constant bias per pair: only fixes the gauge between p and the biases
OFFSET_FLOOR_M = 0.002  # σ added to every offset axis: corner noise the pose covariance does not hold (rain, coding)
SEARCH_S = 2.0  # the first estimate looks this far either side of the rig's offset, s
SEARCH_STEP_S = 0.01  # ... in these steps, then a parabola through the best three
TRACK_STEP_S = 0.05  # grid of the matched tracks, s
UNKNOWN_SIGMA_S = 0.01  # beyond this σ, a camera's offset is not changed: the motion is too small to tell. The
# issue's target; the stated σ of a far stern camera misses its systematic errors (config1-procedure1-realities:
# stern4 148 ms off at a stated σ of 17 ms, stern1 84 ms at 16 ms on the run's second half), so no looser bound
MAX_CORRELATION_LAG = 60  # residual autocorrelation summed over at most this many frames (4 s at 15 FPS)
CLUSTER_S = 20.0  # residuals within blocks this long count as correlated (σ's sandwich): a far camera's depth wanders
# for tens of seconds as the topside's view changes (at 5 s blocks config1-procedure1's stern1 was 87 ms off at σ 32 ms)
SOFT_L1_SCALE = 3.0  # whitened residuals beyond this count linearly (rain-struck corners, a wrong IPPE pose)
MAX_ITERATIONS = 20  # Gauss-Newton steps of the joint fit
STEP_TOLERANCE_S = 1e-5  # ... until no clock moves by more than this
RIDGE = 1e-9  # relative damping of the normal equations: keeps a parameter no sample reaches finite


@dataclass(frozen=True)
class CameraClock:
    """One camera's clock as the footage shows it: its time offset before and after, with σ, or why it is unknown."""

    camera: str
    rig_offset: float  # s, time_offset in the rig that was given
    offset: float  # s, the estimate (the rig's where unknown)
    sigma: float | None  # s, 1σ of the estimate against the reference's clock; None where unknown
    frames: int  # frames with a pair offset used
    reference: bool = False
    note: str = ""  # why the offset is unknown, or what limits it

    @property
    def known(self) -> bool:
        """Whether the footage tells this camera's offset to within UNKNOWN_SIGMA_S (the reference always)."""
        return self.reference or (self.sigma is not None and self.sigma <= UNKNOWN_SIGMA_S)

    @property
    def change(self) -> float:
        """Estimated minus the rig's offset, s."""
        return self.offset - self.rig_offset


@dataclass
class _Samples:
    """Pair offsets of all cameras as arrays: N samples."""

    camera: np.ndarray  # (N,) camera index
    time: np.ndarray  # (N,) capture time on the rig's clocks, s
    offset: np.ndarray  # (N, 3) m
    whiten: np.ndarray  # (N, 3, 3) Lᵀ with L Lᵀ = inverse covariance
    r: np.ndarray  # (N, 3) topside marker centre, topside frame, m
    bias: np.ndarray  # (N,) index of the (camera, pair) bias
    tilt: np.ndarray = field(default_factory=lambda: np.zeros(0))  # (B,) σ of each (camera, pair)'s frame rotation, rad
    axis_sigma: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))  # (N, 3) σ per axis, m


def reference_camera(rig: Rig, name: str | None = None, information: dict[str, float] | None = None) -> str:
    """The camera whose clock the others are set to: the one named, else the one whose offsets time the topside's
    motion best (information: Σ vᵀ C⁻¹ v per camera, s⁻²; a far camera's noisy offsets would make every other clock
    as uncertain as its own), else the first fixed camera, else the first on the vessel, else the first."""
    names = [c.name for c in rig.cameras]
    if name is not None:
        if name not in names:
            raise InputError("--reference", f"{name!r} is not a camera of the rig (expected one of {', '.join(names)})")
        return name
    if information and max(information.values()) > 0:
        return max(names, key=lambda n: information.get(n, 0.0))
    for mount in ("fixed", "vessel"):
        for cam in rig.cameras:
            if cam.mount == mount:
                return cam.name
    return names[0]


def timing_information(s: _Samples, cameras: list[str]) -> dict[str, float]:
    """Per camera, how well its offsets time the topside's motion: Σ over its samples of vᵀ C⁻¹ v (v the velocity of
    a spline through its own offsets), s⁻²: 1/σ² of its clock offset were its errors independent."""
    out = {}
    for k, name in enumerate(cameras):
        mine = np.flatnonzero(s.camera == k)
        if len(mine) < 20:
            continue
        v, _ = _camera_velocity(s, k, s.time[mine])
        g = np.einsum("nij,nj->ni", s.whiten[mine], v)
        out[name] = float(np.sum(g**2))
    return out


def _samples(rig: Rig, offsets: Iterable[PairOffset], cameras: list[str]) -> _Samples:
    """The usable pair offsets (settled IPPE choices, cameras of the rig) as arrays."""
    centres = {m.id: np.array(m.center, dtype=float) for m in rig.markers}
    index = {name: k for k, name in enumerate(cameras)}
    biases: dict[tuple[str, str, str], int] = {}
    tilts: list[float] = []
    rows = []
    for m in offsets:
        if m.camera not in index or m.choice == Choice.AMBIGUOUS:
            continue
        C = m.covariance + OFFSET_FLOOR_M**2 * np.eye(3)
        try:
            L = np.linalg.cholesky(np.linalg.inv(C))
        except np.linalg.LinAlgError:
            continue
        b = biases.setdefault((m.camera, m.cone, m.face), len(biases))
        if b == len(tilts):
            tilts.append(_tilt_sigma(rig, m.jacket_id))
        rows.append((index[m.camera], m.time, m.offset, L.T, centres[m.topside_id], b, np.sqrt(np.diag(C))))
    if not rows:
        return _Samples(np.zeros(0, int), np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3, 3)), np.zeros((0, 3)),
                        np.zeros(0, int), np.zeros(0), np.zeros((0, 3)))
    rows.sort(key=lambda r: r[1])
    cols = list(zip(*rows, strict=True))
    return _Samples(np.array(cols[0]), np.array(cols[1], dtype=float), np.array(cols[2]), np.array(cols[3]),
                    np.array(cols[4]), np.array(cols[5]), np.array(tilts), np.array(cols[6]))


def _tilt_sigma(rig: Rig, jacket_id: int) -> float:
    """σ of the rotation of a pair's offsets (its jacket marker's tilt as the survey leaves it, with a floor for a
    far camera's view of it), rad."""
    marker = rig.marker_by_id.get(jacket_id)
    sigma = rig.marker_sigma(marker) if marker is not None else None
    tilt = float(np.max(sigma.tilt_rad())) if sigma is not None else 0.0
    return float(np.hypot(tilt, TILT_FLOOR_RAD))


@dataclass(frozen=True)
class Spline:
    """A uniform cubic B-spline over time: knots h apart from t0, n control points."""

    t0: float
    h: float
    n: int

    @classmethod
    def spanning(cls, start: float, end: float, h: float) -> Spline:
        """A spline covering [start, end] (its first and last spans padded by one knot)."""
        t0 = start - h
        return cls(t0, h, int(np.ceil((end - t0) / h)) + 3)

    def basis(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Control point indices (N, 4), weights (N, 4) and their time derivatives (N, 4) at times t (N,)."""
        u = (np.asarray(t, dtype=float) - self.t0) / self.h
        i = np.clip(np.floor(u).astype(int), 0, self.n - 4)
        f = np.clip(u - i, 0.0, 1.0)
        w = np.stack([(1 - f) ** 3, 3 * f**3 - 6 * f**2 + 4, -3 * f**3 + 3 * f**2 + 3 * f + 1, f**3], axis=1) / 6
        dw = np.stack([-(1 - f) ** 2, 3 * f**2 - 4 * f, -3 * f**2 + 2 * f + 1, f**2], axis=1) / (2 * self.h)
        return i[:, None] + np.arange(4), w, dw


def cross_matrices(r: np.ndarray) -> np.ndarray:
    """(N, 3, 3) matrices [r]× of vectors r (N, 3)."""
    z = np.zeros(len(r))
    return np.stack([np.stack([z, -r[:, 2], r[:, 1]], 1), np.stack([r[:, 2], z, -r[:, 0]], 1),
                     np.stack([-r[:, 1], r[:, 0], z], 1)], 1)


class _Model:
    """The joint fit: parameters [τ (free cameras), p knots (3 n), ω knots (3 m), biases (3 B), frame rotations
    ε (3 B)]."""

    def __init__(self, s: _Samples, free: list[int], reference: int) -> None:
        self.s = s
        self.free = free  # camera indices whose τ is a parameter
        self.reference = reference
        span = (s.time.min() - SEARCH_S - 1.0, s.time.max() + SEARCH_S + 1.0)
        self.p = Spline.spanning(*span, KNOT_S)
        self.w = Spline.spanning(*span, ROTATION_KNOT_S)
        self.nb = int(s.bias.max()) + 1
        self.i_tau = {c: k for k, c in enumerate(free)}
        self.o_p = len(free)
        self.o_w = self.o_p + 3 * self.p.n
        self.o_b = self.o_w + 3 * self.w.n
        self.o_e = self.o_b + 3 * self.nb
        self.size = self.o_e + 3 * self.nb
        self.rx = cross_matrices(s.r)

    def tau(self, x: np.ndarray) -> np.ndarray:
        """(N,) clock offset of each sample's camera."""
        taus = np.zeros(int(self.s.camera.max()) + 1)
        for c, k in self.i_tau.items():
            taus[c] = x[k]
        return taus[self.s.camera]

    def predict(self, x: np.ndarray) -> tuple[np.ndarray, tuple, tuple, np.ndarray, np.ndarray]:
        """(N, 3) offsets predicted by x, with the bases used, the predicted velocity (N, 3) and the topside's motion
        before the pair's frame is turned (N, 3)."""
        t = self.s.time + self.tau(x)
        P = x[self.o_p:self.o_w].reshape(-1, 3)
        W = x[self.o_w:self.o_b].reshape(-1, 3)
        B = x[self.o_b:self.o_e].reshape(-1, 3)
        E = x[self.o_e:].reshape(-1, 3)[self.s.bias]
        ip, wp, dp = self.p.basis(t)
        iw, ww, dw = self.w.basis(t)
        omega = np.einsum("nk,nkj->nj", ww, W[iw])
        d_omega = np.einsum("nk,nkj->nj", dw, W[iw])
        motion = np.einsum("nk,nkj->nj", wp, P[ip]) - np.einsum("nij,nj->ni", self.rx, omega)
        pred = motion + np.cross(E, motion) + B[self.s.bias]  # the pair's frame turned by ε: its jacket marker's tilt
        velocity = np.einsum("nk,nkj->nj", dp, P[ip]) - np.einsum("nij,nj->ni", self.rx, d_omega)
        velocity = velocity + np.cross(E, velocity)
        return pred, (ip, wp), (iw, ww), velocity, motion

    def residuals(self, x: np.ndarray) -> np.ndarray:
        """Whitened residuals of the offsets (3 N), then the priors on ω and the biases."""
        pred, *_ = self.predict(x)
        r = np.einsum("nij,nj->ni", self.s.whiten, self.s.offset - pred).reshape(-1)
        P = x[self.o_p:self.o_w].reshape(-1, 3)
        W = x[self.o_w:self.o_b].reshape(-1, 3)
        accel, angular = motion_prior(P, self.p.h, W, self.w.h)
        tilt = (x[self.o_e:].reshape(-1, 3) / self.s.tilt[:, None]).reshape(-1)
        return np.concatenate([r, x[self.o_w:self.o_b] / ROTATION_PRIOR_RAD, x[self.o_b:self.o_e] / BIAS_PRIOR_M,
                               tilt, accel, angular])

    def jacobian(self, x: np.ndarray) -> csr_matrix:
        """Sparse Jacobian of residuals."""
        _, (ip, wp), (iw, ww), velocity, motion = self.predict(x)
        n = len(self.s.time)
        Lt = self.s.whiten  # (N, 3, 3)
        rows, cols, vals = [], [], []
        row3 = (3 * np.arange(n))[:, None] + np.arange(3)  # (N, 3)

        def block(col0: np.ndarray, M: np.ndarray) -> None:
            """M (N, 3, 3): d residual rows of each sample / d columns col0 (N,) .. col0 + 2."""
            rows.append(np.broadcast_to(row3[:, :, None], M.shape).reshape(-1))
            cols.append((col0[:, None, None] + np.arange(3)[None, None, :]).repeat(3, axis=1).reshape(-1))
            vals.append(M.reshape(-1))

        for k in range(4):
            block(self.o_p + 3 * ip[:, k], -Lt * wp[:, k, None, None])
            block(self.o_w + 3 * iw[:, k], np.einsum("nij,njk->nik", Lt, self.rx) * ww[:, k, None, None])
        block(self.o_b + 3 * self.s.bias, -Lt)
        block(self.o_e + 3 * self.s.bias, np.einsum("nij,njk->nik", Lt, cross_matrices(motion)))  # d(ε × o)/dε = -[o]×
        d_tau = -np.einsum("nij,nj->ni", Lt, velocity)  # (N, 3)
        for c, k in self.i_tau.items():
            mine = np.flatnonzero(self.s.camera == c)
            rows.append(row3[mine].reshape(-1))
            cols.append(np.full(3 * len(mine), k))
            vals.append(d_tau[mine].reshape(-1))
        m0 = 3 * n
        nw, nb3 = self.o_b - self.o_w, 3 * self.nb
        rows += [m0 + np.arange(nw), m0 + nw + np.arange(nb3), m0 + nw + nb3 + np.arange(nb3)]
        cols += [self.o_w + np.arange(nw), self.o_b + np.arange(nb3), self.o_e + np.arange(nb3)]
        vals += [np.full(nw, 1 / ROTATION_PRIOR_RAD), np.full(nb3, 1 / BIAS_PRIOR_M),
                 np.repeat(1 / self.s.tilt, 3)]
        m1 = m0 + nw + 2 * nb3
        m1 = motion_prior_rows(rows, cols, vals, m1, ((self.p, self.o_p), (self.w, self.o_w)))
        J = coo_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(m1, self.size))
        return J.tocsr()

    def linear_fit(self, x: np.ndarray) -> np.ndarray:
        """x with its spline and bias parameters fitted by linear least squares at x's clock offsets."""
        J = self.jacobian(x)[:, self.o_p:]
        step = _solve(J, self.residuals(x))
        out = x.copy()
        out[self.o_p:] += step
        return out

    def fit(self, x: np.ndarray) -> np.ndarray:
        """Gauss-Newton with soft-L1 weights (iteratively reweighted) from x: every parameter."""
        for _ in range(MAX_ITERATIONS):
            r = self.residuals(x)
            weight = soft_l1_weights(r)
            J = self.jacobian(x)
            step = _solve(diags(np.sqrt(weight)) @ J, np.sqrt(weight) * r)
            x = x + step
            if np.all(np.abs(step[:self.o_p]) < STEP_TOLERANCE_S):
                break
        return x


def soft_l1_weights(r: np.ndarray) -> np.ndarray:
    """Soft-L1's IRLS weights of whitened residuals r (N,): 1 near zero, SOFT_L1_SCALE / |r| far out."""
    return 1.0 / np.sqrt(1.0 + (r / SOFT_L1_SCALE) ** 2)


def motion_prior(P: np.ndarray, h_p: float, W: np.ndarray, h_w: float) -> tuple[np.ndarray, np.ndarray]:
    """Residuals of the topside motion's prior: second differences of the translation's knots P (n, 3) and the
    rotation's W (m, 3), knots h_p and h_w s apart, over h² times ACCEL_MPS2 and ANGULAR_ACCEL_RADPS2."""
    return ((P[2:] - 2 * P[1:-1] + P[:-2]).reshape(-1) / (h_p**2 * ACCEL_MPS2),
            (W[2:] - 2 * W[1:-1] + W[:-2]).reshape(-1) / (h_w**2 * ANGULAR_ACCEL_RADPS2))


def motion_prior_rows(rows: list, cols: list, vals: list, first: int,
                      splines: tuple[tuple[Spline, int], tuple[Spline, int]]) -> int:
    """motion_prior's Jacobian appended to a sparse Jacobian's (rows, cols, vals) from row first (splines: the
    translation's and the rotation's, each with its first column); returns the next free row."""
    for (spline, offset), accel in zip(splines, (ACCEL_MPS2, ANGULAR_ACCEL_RADPS2), strict=True):
        k = np.arange(3 * (spline.n - 2))  # rows: (knot j, axis a) for j = 1 .. n-2
        j, a = k // 3, k % 3
        for shift, value in ((0, 1.0), (1, -2.0), (2, 1.0)):
            rows.append(first + k)
            cols.append(offset + 3 * (j + shift) + a)
            vals.append(np.full(k.size, value / (spline.h**2 * accel)))
        first += k.size
    return first


def _solve(J: csr_matrix, r: np.ndarray) -> np.ndarray:
    """The Gauss-Newton step minimising |J step + r|² (sparse normal equations, a tiny ridge for the gauge)."""
    A = (J.T @ J).tocsc()
    A = A + RIDGE * diags(np.maximum(A.diagonal(), 1.0))
    return spsolve(A, -(J.T @ r))


def _camera_velocity(s: _Samples, camera: int, grid: np.ndarray, position: bool = False
                     ) -> tuple[np.ndarray, np.ndarray]:
    """One camera's topside velocity (G, 3) (or position, with its own constant bias) on a time grid (G,), from a
    spline through its own offsets alone, and whether each grid time lies within its samples (G,)."""
    mine = np.flatnonzero(s.camera == camera)
    used, bias = np.unique(s.bias[mine], return_inverse=True)
    sub = _Samples(np.zeros(len(mine), int), s.time[mine], s.offset[mine], s.whiten[mine], s.r[mine], bias,
                   s.tilt[used], s.axis_sigma[mine])
    model = _Model(sub, [], 0)
    x = model.linear_fit(np.zeros(model.size))
    P = x[model.o_p:model.o_w].reshape(-1, 3)
    i, w, dw = model.p.basis(grid)
    t = s.time[mine]
    inside = (grid >= t.min()) & (grid <= t.max())
    gaps = np.diff(t) > 1.0  # a camera that lost its markers for a second says nothing in between
    for a, b in zip(t[:-1][gaps], t[1:][gaps], strict=True):
        inside &= ~((grid > a) & (grid < b))
    return np.einsum("nk,nkj->nj", w if position else dw, P[i]), inside


def first_estimates(s: _Samples, cameras: list[str], reference: int) -> dict[int, float]:
    """Each camera's clock offset against the reference by matching their topside tracks (positions from each camera's
    own spline, their constant difference removed: a camera's biases), s; cameras without overlapping motion are left
    out. Velocities, which differentiate each camera's noise, matched the wrong swing of a slow set-down (first
    estimates 0.5-1.1 s off, config2-setdown-realities)."""
    grid = np.arange(s.time.min(), s.time.max(), TRACK_STEP_S)
    p_ref, in_ref = _camera_velocity(s, reference, grid, position=True)
    out = {}
    shifts = np.arange(-SEARCH_S, SEARCH_S + SEARCH_STEP_S / 2, SEARCH_STEP_S)
    for c in range(len(cameras)):
        if c == reference or not np.any(s.camera == c):
            continue
        sig = np.median(s.axis_sigma[s.camera == c], axis=0)
        sig_ref = np.median(s.axis_sigma[s.camera == reference], axis=0)
        weight = 1.0 / (sig**2 + sig_ref**2)
        p_c, in_c = _camera_velocity(s, c, grid, position=True)
        cost = np.full(len(shifts), np.inf)
        for k, tau in enumerate(shifts):
            # camera c's sample at rig time t is the motion at t + τ: its track at t - τ lines up with the
            # reference's at t
            u = grid - tau
            j = np.round((u - grid[0]) / TRACK_STEP_S).astype(int)
            ok = in_ref & (j >= 0) & (j < len(grid))
            ok[ok] &= in_c[j[ok]]
            if ok.sum() < 20:
                continue
            d = p_c[j[ok]] - p_ref[ok]
            d -= d.mean(axis=0)
            cost[k] = float(np.mean(d**2 @ weight))
        if not np.isfinite(cost).any():
            continue
        k = int(np.argmin(cost))
        tau = float(shifts[k])
        if 0 < k < len(shifts) - 1 and np.isfinite(cost[k - 1]) and np.isfinite(cost[k + 1]):
            den = cost[k - 1] - 2 * cost[k] + cost[k + 1]
            if den > 0:
                tau += 0.5 * SEARCH_STEP_S * (cost[k - 1] - cost[k + 1]) / den
        out[c] = tau
    return out


def _correlation_gain(series: np.ndarray) -> float:
    """Integrated autocorrelation 1 + 2 Σ ρ_k of a series (N,) up to its first non-positive ρ (at least 1)."""
    x = series - series.mean()
    var = float(x @ x)
    if var <= 0 or len(x) < 10:
        return 1.0
    gain = 1.0
    for k in range(1, min(MAX_CORRELATION_LAG, len(x) // 4)):
        rho = float(x[:-k] @ x[k:]) / var
        if rho <= 0:
            break
        gain += 2 * rho
    return gain


def synchronise(rig: Rig, offsets: Iterable[PairOffset], reference: str | None = None) -> list[CameraClock]:
    """Every camera's clock offset against the reference camera's, from the pair offsets of all cameras (their times
    on the rig's clocks); see the module docstring."""
    cameras = [c.name for c in rig.cameras]
    rig_offsets = {c.name: c.time_offset for c in rig.cameras}
    s = _samples(rig, offsets, cameras)
    ref_name = reference_camera(rig, reference, timing_information(s, cameras) if reference is None else None)
    ref = cameras.index(ref_name)
    frames = {c: int(np.unique(s.time[s.camera == k]).size) for k, c in enumerate(cameras)}

    def unknown(name: str, note: str) -> CameraClock:
        return CameraClock(name, rig_offsets[name], rig_offsets[name], None, frames[name], name == ref_name, note)

    if frames[ref_name] == 0:
        return [unknown(c, "" if c != ref_name else "the reference saw no marker pair") if c == ref_name else
                unknown(c, f"the reference {ref_name} saw no marker pair") for c in cameras]
    first = first_estimates(s, cameras, ref)
    free = sorted(first)
    model = _Model(s, free, ref)
    x = np.zeros(model.size)
    for c, k in model.i_tau.items():
        x[k] = first[c]
    x = model.fit(model.linear_fit(x))
    sigmas = _sigmas(model, x)
    out = []
    for k, name in enumerate(cameras):
        if k == ref:
            out.append(CameraClock(name, rig_offsets[name], rig_offsets[name], 0.0, frames[name], True,
                                   "reference: the others are set to its clock"))
            continue
        if frames[name] == 0:
            out.append(unknown(name, "no marker pair seen"))
            continue
        if k not in model.i_tau:
            out.append(unknown(name, f"never saw the topside move while {ref_name} did"))
            continue
        tau, sigma = float(x[model.i_tau[k]]), sigmas[k]
        if not np.isfinite(sigma) or sigma > UNKNOWN_SIGMA_S:
            shown = f"{sigma * 1e3:.0f} ms" if np.isfinite(sigma) else "unbounded"
            out.append(CameraClock(name, rig_offsets[name], rig_offsets[name], None, frames[name], False,
                                   f"motion too small to tell (σ {shown} > {UNKNOWN_SIGMA_S * 1e3:.0f} ms)"))
            continue
        out.append(CameraClock(name, rig_offsets[name], rig_offsets[name] + tau, sigma, frames[name]))
    return out


def _sigmas(model: _Model, x: np.ndarray) -> dict[int, float]:
    """σ of each free camera's τ (s): the larger of the fit's covariance (scaled by the camera's residual spread and by
    their correlation in time) and a cluster-robust (sandwich) variance over CLUSTER_S blocks of every camera's
    residuals, which also holds what the reference's errors and slower drifts do to τ."""
    J = model.jacobian(x)
    r = model.residuals(x)
    weight = soft_l1_weights(r)  # as the fit weighed them
    info = (J.T @ diags(weight) @ J).tocsc()
    lu = splu(info + RIDGE * diags(np.maximum(info.diagonal(), 1.0)))
    n = 3 * len(model.s.time)
    block = np.floor((model.s.time - model.s.time.min()) / CLUSTER_S).astype(int)
    cluster = np.repeat(block * (int(model.s.camera.max()) + 1) + model.s.camera, 3)
    velocity = model.predict(x)[3]
    res = r[:n].reshape(-1, 3)
    out = {}
    for c, k in model.i_tau.items():
        e = np.zeros(model.size)
        e[k] = 1.0
        u = lu.solve(e)
        sums = np.bincount(cluster, weights=((J @ u) * weight * r)[:n])  # each block's pull on τ
        mine = model.s.camera == c
        spread = float(np.median(np.abs(res[mine])) / 0.6745) if mine.any() else 1.0  # robust σ, whitened
        # the residual along the direction τ moves this camera's offsets: what τ is fitted from
        g = np.einsum("nij,nj->ni", model.s.whiten[mine], velocity[mine])
        along = np.einsum("ni,ni->n", res[mine], g) / np.maximum(np.linalg.norm(g, axis=1), 1e-12)
        formal = max(float(u[k]), 0.0) * max(spread, 1.0) ** 2 * _correlation_gain(along)
        out[c] = float(np.sqrt(max(formal, float(sums @ sums))))
    return out


def synced_rig(rig: Rig, clocks: list[CameraClock]) -> Rig:
    """The rig with every known camera's estimated time_offset and its σ (unknown ones unchanged)."""
    by_name = {c.camera: c for c in clocks}
    cameras = []
    for cam in rig.cameras:
        clock = by_name.get(cam.name)
        if clock is None or not clock.known:
            cameras.append(cam)
            continue
        cameras.append(cam.model_copy(update={"time_offset": round(clock.offset, 6),
                                              "time_offset_sigma": round(float(clock.sigma or 0.0), 6)}))
    return rig.model_copy(update={"cameras": cameras})
