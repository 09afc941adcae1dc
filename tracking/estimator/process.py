"""The process model: how the state moves from one capture time to the next, and how much a camera moves.

Per body (the topside, each camera) the state holds a pose error and its rates. Over dt the pose gains b × rate and
the rate keeps a share a of itself: the topside keeps its speed (a = 1, b = dt), a camera's rates revert to zero
within CAMERA_RATE_TAU_S. The states after the bodies (consider states, view biases) keep a share of themselves, the
rest renewed with their prior (estimator.noise.VIEW_PRIOR). A camera's process noise follows the motion its jacket
markers' images show (CameraMotionLevel), or its fitted jacket poses' turns where they are measured well enough
(PoseMotionLevel).
"""

from __future__ import annotations

import bisect
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from tracking.estimator.noise import (
    GAUSSIAN_MEDIAN_CHI2_1,
    MOTION_LAG_S,
    MOTION_MIN_SAMPLES,
    MOTION_SAMPLES,
    MOTION_UPDATE_EVERY,
    POSE_MOTION_LAG_S,
    POSE_MOTION_SNR,
    STATE,
)
from tracking.geometry import rotvec


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
    """M Fᵀ in place for M (k, n), F as in _body_rows: F on the first 12 B columns taken as rows (contiguous, which
    costs less than the strided columns in place)."""
    block = M[:, :a.size * 2].T.copy()  # (12 B, k)
    rows = block.reshape(len(a), 2, 6, -1)
    rows[:, 0] += b[:, :, None] * rows[:, 1]
    rows[:, 1] *= a[:, :, None]
    M[:, :a.size * 2] = block.T


@dataclass(frozen=True)
class Transition:
    """One prediction of the state (n,): bodies first (12 each), then consider states and view biases.

    Per body, its rates' decay a (B, 6), their weight b (B, 6) on the pose and its process noise (B, 12, 12); per
    state after the bodies, the share of it that stays (V,), the rest renewed with the variance renewal (V,)
    (consider states: all of it stays).
    """

    a: np.ndarray
    b: np.ndarray
    noise: np.ndarray
    keep: np.ndarray
    renewal: np.ndarray

    def apply(self, M: np.ndarray) -> np.ndarray:
        """F M for M (n, k)."""
        out = _body_rows(M, self.a, self.b)
        if (self.keep < 1.0).any():  # (all kept between a frame's prediction and its views' renewal)
            out[self.a.size * 2:] *= self.keep[:, None]
        return out

    def covariance(self, P: np.ndarray) -> np.ndarray:
        """F P Fᵀ + Q for a covariance P (n, n)."""
        out = _body_rows(P, self.a, self.b)
        _body_columns(out, self.a, self.b)
        for k, Q in enumerate(self.noise):
            out[STATE * k:STATE * (k + 1), STATE * k:STATE * (k + 1)] += Q
        d = np.flatnonzero(self.keep < 1.0)
        if d.size:
            renew_states(out, d + self.a.size * 2, self.keep[d], self.renewal[d])
        return out


def renew_states(P: np.ndarray, d: np.ndarray, keep: np.ndarray, renewal: np.ndarray) -> None:
    """In place on a covariance P (n, n): the states d (V,) keep the share keep (V,) of themselves, the rest renewed
    with the variance renewal (V,): P <- K P K + (I - K²) renewal, K = keep on d and 1 elsewhere. The transition's
    view part (Transition.covariance), and the filter's renewal of a frame's views (measurements.renew)."""
    P[d, :] *= keep[:, None]
    P[:, d] *= keep
    P[d, d] += (1.0 - keep**2) * renewal


def orbit_psd(T_jacket_camera: np.ndarray, centre: np.ndarray, q: float) -> np.ndarray:
    """(6, 6) acceleration psd (rotation, then position; jacket frame, as a camera's error states) of a camera orbiting
    a point centre (3,) at angular psd q, rad²/s³: a turn by φ about an axis u through the point, across the camera's
    line of sight to it, turns the camera by φ u and moves it by φ u × (c - centre), and leaves the point's image
    where it was (what no image motion shows, and one marker's corners barely tell)."""
    arm = T_jacket_camera[:3, 3] - centre
    d = float(np.linalg.norm(arm))
    if not d > 0.0:
        return np.zeros((6, 6))
    u1 = np.cross(arm, np.eye(3)[int(np.argmin(np.abs(arm)))])
    u1 /= np.linalg.norm(u1)
    u2 = np.cross(arm / d, u1)
    V = np.array([np.concatenate([u, np.cross(u, arm)]) for u in (u1, u2)])  # (2, 6)
    return q * V.T @ V


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


@dataclass
class PoseMotionLevel:
    """How fast a camera turns about its jacket markers, from its own jacket poses (T_camera_jacket of each frame's
    body fit): what CameraMotionLevel cannot see when the camera orbits the markers (a board turned by hand before a
    webcam, a drone circling), for the markers' image then stays put while their shape turns.

    Per frame, the second divided difference a of the camera's turn over POSE_MOTION_LAG_S (its rotation increments
    over the two lags, rad/s); as for CameraMotionLevel each of its three components squared × 3 / (2 Δ) estimates
    the angular psd q, and the fits' own rotation variances σ² give what noise alone reads, 3 (σ₀² + 4 σ₁² + σ₂²) /
    (2 Δ³).
    The level, the largest axis's median of q over GAUSSIAN_MEDIAN_CHI2_1 less the noise's median (a board swung about
    one axis is still when seen about the other two), counts only where it is
    POSE_MOTION_SNR times the noise: a far camera's fits (a 1 m marker at 40 m: 10 mrad) read noise and nothing else.
    """

    lag_s: float = POSE_MOTION_LAG_S
    poses: tuple[list[float], list[np.ndarray], list[float]] = field(default_factory=lambda: ([], [], []))  # times,
    # R_camera_jacket (3, 3) and rotation variances (rad², per axis) of the last 2.5 lags
    samples: deque = field(default_factory=lambda: deque(maxlen=MOTION_SAMPLES // 3))  # (q per camera axis,
    # noise) estimates, rad²/s³
    level: float | None = None  # angular acceleration psd, rad²/s³ (None until enough samples, or below the noise)
    pending: int = 0

    def add(self, time: float, R_camera_jacket: np.ndarray, rotation_var: float) -> None:
        """One frame's jacket fit: its rotation (3, 3) and the mean variance of its rotation vector's axes, rad²."""
        times, rotations, variances = self.poses
        times.append(time)
        rotations.append(R_camera_jacket)
        variances.append(rotation_var)
        old = bisect.bisect_left(times, time - 2.5 * self.lag_s)
        if old:
            del times[:old], rotations[:old], variances[:old]
        if times[0] > time - 1.75 * self.lag_s:
            return
        i1, i0 = (CameraMotionLevel._nearest(times, time - k * self.lag_s) for k in (1, 2))
        t0, t1 = times[i0], times[i1]
        if not (t0 < t1 < time) or abs(t1 - (time - self.lag_s)) > 0.25 * self.lag_s:
            return
        R0, R1, R2 = rotations[i0], rotations[i1], R_camera_jacket
        a = rotvec(R2 @ R1.T) / (time - t1) - rotvec(R1 @ R0.T) / (t1 - t0)
        half = (time - t0) / 2
        noise = 1.5 / half * (variances[i0] + 4 * variances[i1] + rotation_var) / half**2
        self.samples.append((*(1.5 / half * a**2).tolist(), noise))
        self.pending += 1
        if self.pending >= MOTION_UPDATE_EVERY and 3 * len(self.samples) >= MOTION_MIN_SAMPLES:
            medians = np.median(np.array(self.samples), axis=0)
            noise = float(medians[3])
            level = float(medians[:3].max()) / GAUSSIAN_MEDIAN_CHI2_1 - noise  # the axis it turns about most
            self.level = level if level > POSE_MOTION_SNR * noise else None
            self.pending = 0
