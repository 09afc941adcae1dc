"""The topside's motion relative to the jacket as every camera's pair offsets sample it: the model `topside sync` fits
with a clock offset per camera (tracking/clocks.py) and `topside survey` starts its bundle adjustment from
(tracking/survey.py).

A camera c's pair offset (topside marker minus its mated position, jacket frame; tracking.offsets) at capture time t
on the rig's clocks is

    o(t) = (I + [ε]×) (p(t + τ_c) - [r]× ω(t + τ_c)) + b

- p(t), ω(t): the topside's translation and small rotation, uniform cubic B-splines (Spline) with knots KNOT_S and
  ROTATION_KNOT_S apart, their second differences held to a hanging topside's accelerations (motion_prior) and ω to
  ROTATION_PRIOR_RAD at every knot;
- r: the topside marker's centre, topside frame;
- τ_c: the camera's clock offset against a reference camera's (zero where not fitted);
- b: a constant per camera and pair (its survey and view errors, which do not move in time), prior BIAS_PRIOR_M;
- ε: a small rotation of the pair's frame per camera and pair (its jacket marker's tilt), prior the survey's tilt σ
  with a floor.

Every offset is whitened by its covariance plus OFFSET_FLOOR_M² per axis.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np
from scipy.sparse import csr_matrix

from tracking.geometry import skews
from tracking.least_squares import Triplets, linear_step
from tracking.offsets import PairOffset
from tracking.pose import Choice
from tracking.rig import Rig

KNOT_S = 0.5  # spacing of the topside translation's cubic spline: follows a pendulum swing (14 s) and 8 s waves to
# well under a millimetre (a cubic's error ~ h⁴ ω⁴ A / 77), while the offsets' noise between knots averages out instead
# of showing as velocity (denser knots follow the noise: docs/method.md#clocks-and-the-marker-survey-sync-survey)
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


@dataclass
class Samples:
    """Pair offsets of all cameras as arrays: N samples."""

    camera: np.ndarray  # (N,) camera index
    time: np.ndarray  # (N,) capture time on the rig's clocks, s
    offset: np.ndarray  # (N, 3) m
    whiten: np.ndarray  # (N, 3, 3) Lᵀ with L Lᵀ = inverse covariance
    r: np.ndarray  # (N, 3) topside marker centre, topside frame, m
    bias: np.ndarray  # (N,) index of the (camera, pair) bias
    tilt: np.ndarray = field(default_factory=lambda: np.zeros(0))  # (B,) σ of each (camera, pair)'s frame rotation, rad
    axis_sigma: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))  # (N, 3) σ per axis, m

    def of_camera(self, camera: int) -> Samples:
        """One camera's samples alone (as camera 0, its biases numbered from 0)."""
        mine = np.flatnonzero(self.camera == camera)
        used, bias = np.unique(self.bias[mine], return_inverse=True)
        return Samples(np.zeros(len(mine), int), self.time[mine], self.offset[mine], self.whiten[mine], self.r[mine],
                       bias, self.tilt[used], self.axis_sigma[mine])


def pair_samples(rig: Rig, offsets: Iterable[PairOffset], cameras: list[str]) -> Samples:
    """The usable pair offsets (settled IPPE choices, cameras of the rig) as arrays, in time order."""
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
        return Samples(np.zeros(0, int), np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3, 3)), np.zeros((0, 3)),
                       np.zeros(0, int), np.zeros(0), np.zeros((0, 3)))
    rows.sort(key=lambda r: r[1])
    cols = list(zip(*rows, strict=True))
    return Samples(np.array(cols[0]), np.array(cols[1], dtype=float), np.array(cols[2]), np.array(cols[3]),
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


def motion_prior(P: np.ndarray, h_p: float, W: np.ndarray, h_w: float) -> tuple[np.ndarray, np.ndarray]:
    """Residuals of the topside motion's prior: second differences of the translation's knots P (n, 3) and the
    rotation's W (m, 3), knots h_p and h_w s apart, over h² times ACCEL_MPS2 and ANGULAR_ACCEL_RADPS2."""
    return ((P[2:] - 2 * P[1:-1] + P[:-2]).reshape(-1) / (h_p**2 * ACCEL_MPS2),
            (W[2:] - 2 * W[1:-1] + W[:-2]).reshape(-1) / (h_w**2 * ANGULAR_ACCEL_RADPS2))


def motion_prior_rows(J: Triplets, first: int, splines: tuple[tuple[Spline, int], tuple[Spline, int]]) -> int:
    """motion_prior's Jacobian added to J from row first (splines: the translation's and the rotation's, each with
    its first column); returns the next free row."""
    for (spline, offset), accel in zip(splines, (ACCEL_MPS2, ANGULAR_ACCEL_RADPS2), strict=True):
        k = np.arange(3 * (spline.n - 2))  # rows: (knot j, axis a) for j = 1 .. n-2
        j, a = k // 3, k % 3
        for shift, value in ((0, 1.0), (1, -2.0), (2, 1.0)):
            J.add(first + k, offset + 3 * (j + shift) + a, np.full(k.size, value / (spline.h**2 * accel)))
        first += k.size
    return first


class OffsetModel:
    """The model of the module docstring over samples s: parameters [τ (free cameras), p knots (3 n), ω knots (3 m),
    biases (3 B), frame rotations ε (3 B)]; the splines reach margin s beyond the samples' times."""

    def __init__(self, s: Samples, free: list[int], margin: float) -> None:
        self.s = s
        self.free = free  # camera indices whose τ is a parameter
        span = (s.time.min() - margin, s.time.max() + margin)
        self.p = Spline.spanning(*span, KNOT_S)
        self.w = Spline.spanning(*span, ROTATION_KNOT_S)
        self.nb = int(s.bias.max()) + 1
        self.i_tau = {c: k for k, c in enumerate(free)}
        self.o_p = len(free)
        self.o_w = self.o_p + 3 * self.p.n
        self.o_b = self.o_w + 3 * self.w.n
        self.o_e = self.o_b + 3 * self.nb
        self.size = self.o_e + 3 * self.nb
        self.rx = skews(s.r)

    def tau(self, x: np.ndarray) -> np.ndarray:
        """(N,) clock offset of each sample's camera."""
        taus = np.zeros(int(self.s.camera.max()) + 1)
        for c, k in self.i_tau.items():
            taus[c] = x[k]
        return taus[self.s.camera]

    def knots(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The translation's (n, 3) and rotation's (m, 3) knots in x."""
        return x[self.o_p:self.o_w].reshape(-1, 3), x[self.o_w:self.o_b].reshape(-1, 3)

    def predict(self, x: np.ndarray) -> tuple[np.ndarray, tuple, tuple, np.ndarray, np.ndarray]:
        """(N, 3) offsets predicted by x, with the bases used, the predicted velocity (N, 3) and the topside's motion
        before the pair's frame is turned (N, 3)."""
        t = self.s.time + self.tau(x)
        P, W = self.knots(x)
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
        """Whitened residuals of the offsets (3 N), then the priors on ω, the biases, ε and the accelerations."""
        pred, *_ = self.predict(x)
        r = np.einsum("nij,nj->ni", self.s.whiten, self.s.offset - pred).reshape(-1)
        P, W = self.knots(x)
        accel, angular = motion_prior(P, self.p.h, W, self.w.h)
        tilt = (x[self.o_e:].reshape(-1, 3) / self.s.tilt[:, None]).reshape(-1)
        return np.concatenate([r, x[self.o_w:self.o_b] / ROTATION_PRIOR_RAD, x[self.o_b:self.o_e] / BIAS_PRIOR_M,
                               tilt, accel, angular])

    def jacobian(self, x: np.ndarray) -> csr_matrix:
        """Sparse Jacobian of residuals."""
        _, (ip, wp), (iw, ww), velocity, motion = self.predict(x)
        n = len(self.s.time)
        Lt = self.s.whiten  # (N, 3, 3)
        J = Triplets()
        row3 = (3 * np.arange(n))[:, None, None] + np.arange(3)[None, :, None]  # (N, 3, 1): each sample's rows

        def block(col0: np.ndarray, M: np.ndarray) -> None:
            """M (N, 3, 3): d residual rows of each sample / d columns col0 (N,) .. col0 + 2."""
            J.add(row3, col0[:, None, None] + np.arange(3), M)

        for k in range(4):
            block(self.o_p + 3 * ip[:, k], -Lt * wp[:, k, None, None])
            block(self.o_w + 3 * iw[:, k], np.einsum("nij,njk->nik", Lt, self.rx) * ww[:, k, None, None])
        block(self.o_b + 3 * self.s.bias, -Lt)
        block(self.o_e + 3 * self.s.bias, np.einsum("nij,njk->nik", Lt, skews(motion)))  # d(ε × o)/dε = -[o]×
        d_tau = -np.einsum("nij,nj->ni", Lt, velocity)  # (N, 3)
        for c, k in self.i_tau.items():
            mine = np.flatnonzero(self.s.camera == c)
            J.add(row3[mine, :, 0], k, d_tau[mine])
        nw, nb3 = self.o_b - self.o_w, 3 * self.nb
        m = J.diagonal(3 * n, self.o_w, np.full(nw, 1 / ROTATION_PRIOR_RAD))
        m = J.diagonal(m, self.o_b, np.full(nb3, 1 / BIAS_PRIOR_M))
        m = J.diagonal(m, self.o_e, np.repeat(1 / self.s.tilt, 3))
        m = motion_prior_rows(J, m, ((self.p, self.o_p), (self.w, self.o_w)))
        return J.matrix(m, self.size)

    def linear_fit(self, x: np.ndarray) -> np.ndarray:
        """x with its spline and bias parameters fitted by linear least squares at x's clock offsets."""
        J = self.jacobian(x)[:, self.o_p:]
        out = x.copy()
        out[self.o_p:] += linear_step(J, self.residuals(x))
        return out
