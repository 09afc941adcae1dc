"""Fusion of every camera and pair into the topside's rigid pose relative to the jacket, over time.

One Kalman filter for the whole topside. State (12,): translation t and small rotation ω of the
topside frame in the jacket frame, and their rates. A pair offset (topside marker S displaced from
its mated position, jacket frame) is, to first order in ω,

    o = (R - I) r_S + t ≈ t + ω × r_S = t - [r_S]× ω,

linear in the state, with r_S the topside marker's centre in the topside frame. Each measurement
comes with its own covariance (from the markers' PnP Jacobians), so a camera's depth counts for
little and its lateral axes for much, with no per-camera axis rule. Measurements are applied at
their capture times, cameras need no synchronisation, and the offset at every cone follows from
the pose, including cones no camera sees. Outliers such as IPPE flips are gated by their
Mahalanobis distance. Offline, a Rauch-Tung-Striebel pass smooths the whole run.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field

import numpy as np

from tracking.filtering import ConeEstimate, paper_filter, raw_estimates
from tracking.offsets import PairOffset
from tracking.pose import Choice
from tracking.rig import Rig

STATE = 12
GATE_CHI2 = 16.27  # 3 degrees of freedom, 99.9 %
REINIT_AFTER_REJECTS = 15  # consecutive gated measurements before the filter reopens its covariance
CONTRIBUTION_WINDOW_S = 0.5  # a camera counts as contributing when it was accepted this recently
AMBIGUOUS_VARIANCE_GAIN = 25.0  # σ × 5 for poses IPPE could not settle: their error is bimodal, not Gaussian
MEASUREMENT_FLOOR_M = 0.01  # σ added to every measurement: biases the corner noise does not explain
# (tilt of far markers, first-order rotation, timing); 2σ then holds 0.92-0.94 of errors on clear video
REPORT_MAX_SIGMA_M = 0.05  # a cone whose offset σ exceeds this on any axis is reported as unknown (NaN):
# 3σ must fit in the 150 mm concentricity tolerance for a number to be worth showing


@dataclass(frozen=True)
class FilterTuning:
    """Process and prior noise of the topside filter."""

    accel_psd: float = 0.05  # m²/s³: white-noise acceleration of the translation (crane and waves)
    angular_accel_psd: float = 1e-6  # rad²/s³: a topside hanging from cranes yaws and rolls slowly
    prior_position_m: float = 20.0
    prior_rotation_rad: float = 0.05
    prior_speed_mps: float = 1.0
    prior_rate_radps: float = 0.01


def skew(v: np.ndarray) -> np.ndarray:
    """(3, 3) matrix of v× ."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def transition(dt: float) -> np.ndarray:
    """(12, 12) constant-velocity transition over dt seconds."""
    F = np.eye(STATE)
    F[:6, 6:] = dt * np.eye(6)
    return F


def process_noise(dt: float, tuning: FilterTuning) -> np.ndarray:
    """(12, 12) white-noise-acceleration process noise over dt seconds."""
    Q = np.zeros((STATE, STATE))
    for i, q in enumerate([tuning.accel_psd] * 3 + [tuning.angular_accel_psd] * 3):
        Q[i, i] = q * dt**3 / 3
        Q[i, i + 6] = Q[i + 6, i] = q * dt**2 / 2
        Q[i + 6, i + 6] = q * dt
    return Q


def prior_covariance(tuning: FilterTuning) -> np.ndarray:
    """(12, 12) initial covariance: the topside anywhere near, barely rotated."""
    sd = [tuning.prior_position_m] * 3 + [tuning.prior_rotation_rad] * 3 + \
         [tuning.prior_speed_mps] * 3 + [tuning.prior_rate_radps] * 3
    return np.diag(np.square(sd))


def point_offset_matrix(r: np.ndarray) -> np.ndarray:
    """(3, 12) H: offset of a topside point at r (3,) from the state, o = t - [r]× ω."""
    H = np.zeros((3, STATE))
    H[:, :3] = np.eye(3)
    H[:, 3:6] = -skew(r)
    return H


@dataclass
class FilterStep:
    """One time step of the filter, kept for the smoother."""

    time: float
    x_pred: np.ndarray
    P_pred: np.ndarray
    x: np.ndarray
    P: np.ndarray
    F: np.ndarray
    cameras: tuple[str, ...]


@dataclass
class TopsideFilter:
    """The rigid-body Kalman filter of one installation."""

    rig: Rig
    tuning: FilterTuning = field(default_factory=FilterTuning)
    x: np.ndarray = field(default_factory=lambda: np.zeros(STATE))
    P: np.ndarray | None = None
    time: float | None = None
    rejected: int = 0  # total gated measurements
    consecutive_rejects: int = 0
    last_accepted: dict[str, float] = field(default_factory=dict)  # camera -> capture time

    def __post_init__(self) -> None:
        self.P = prior_covariance(self.tuning) if self.P is None else self.P
        markers = self.rig.marker_by_id
        self.topside_points = {m.id: np.array(m.center) for m in markers.values() if m.body == "topside"}
        self.cones = {c: np.array(p) for c, p in self.rig.cones.items()}
        for pair in self.rig.all_pairs():  # a cone without a tip in the rig: use its topside markers
            if pair.cone not in self.cones:
                self.cones[pair.cone] = self.topside_points[pair.topside]

    def predict(self, time: float) -> np.ndarray:
        """Move the state to a capture time; returns the transition used."""
        dt = 0.0 if self.time is None else max(0.0, time - self.time)
        F = transition(dt)
        self.x = F @ self.x
        self.P = F @ self.P @ F.T + process_noise(dt, self.tuning)
        self.time = time if self.time is None else max(self.time, time)
        return F

    def update(self, m: PairOffset) -> bool:
        """Apply one pair offset; False when it was gated out as an outlier."""
        if not self.last_accepted and m.choice == Choice.AMBIGUOUS:
            return False  # never start from a pose IPPE could not settle: nothing could gate it
        H = point_offset_matrix(self.topside_points[m.topside_id])
        gain = AMBIGUOUS_VARIANCE_GAIN if m.choice == Choice.AMBIGUOUS else 1.0
        d2, y, S, R = np.inf, None, None, None
        for offset, cov in ((m.offset, m.covariance), *m.alternatives):  # the IPPE combination nearest the prediction
            R_k = gain * cov + MEASUREMENT_FLOOR_M**2 * np.eye(3)
            y_k = offset - H @ self.x
            S_k = H @ self.P @ H.T + R_k
            d2_k = float(y_k @ np.linalg.solve(S_k, y_k))
            if d2_k < d2:
                d2, y, S, R = d2_k, y_k, S_k, R_k
        if not np.isfinite(d2) or d2 > GATE_CHI2:
            self.rejected += 1
            self.consecutive_rejects += 1
            if self.consecutive_rejects >= REINIT_AFTER_REJECTS:  # lost: reopen, keep the state
                self.P = self.P + prior_covariance(self.tuning)
                self.consecutive_rejects = 0
            return False
        assert y is not None and S is not None and R is not None
        K = np.linalg.solve(S, H @ self.P).T
        self.x = self.x + K @ y
        I_KH = np.eye(STATE) - K @ H
        self.P = I_KH @ self.P @ I_KH.T + K @ R @ K.T  # Joseph form: stays symmetric positive
        self.consecutive_rejects = 0
        self.last_accepted[m.camera] = m.time
        return True

    def contributing(self) -> tuple[str, ...]:
        """Cameras accepted within CONTRIBUTION_WINDOW_S of the current time."""
        assert self.time is not None
        return tuple(sorted(c for c, t in self.last_accepted.items() if self.time - t <= CONTRIBUTION_WINDOW_S))

    def cone_estimates(self, x: np.ndarray | None = None, P: np.ndarray | None = None,
                       time: float | None = None, cameras: tuple[str, ...] | None = None) -> list[ConeEstimate]:
        """Offset and covariance at every cone from a state (default: the current one)."""
        x = self.x if x is None else x
        P = self.P if P is None else P
        time = self.time if time is None else time
        cameras = self.contributing() if cameras is None else cameras
        out = []
        for cone, r in sorted(self.cones.items()):
            H = point_offset_matrix(r)
            cov = H @ P @ H.T
            offset = H @ x if np.sqrt(np.diag(cov)).max() <= REPORT_MAX_SIGMA_M else np.full(3, np.nan)
            out.append(ConeEstimate(time, cone, offset, cameras, cov))
        return out


def _frames(measurements: Iterable[PairOffset]) -> Iterator[list[PairOffset]]:
    """Group time-ordered measurements by capture time (one group per camera frame)."""
    group: list[PairOffset] = []
    for m in measurements:
        if group and (m.time != group[0].time or m.camera != group[0].camera):
            yield group
            group = []
        group.append(m)
    if group:
        yield group


def fused_estimates(rig: Rig, measurements: Iterable[PairOffset], tuning: FilterTuning | None = None
                    ) -> Iterator[ConeEstimate]:
    """Live: after each frame with measurements, the filtered offset at every cone."""
    kf = TopsideFilter(rig, tuning or FilterTuning())
    for group in _frames(measurements):
        kf.predict(group[0].time)
        for m in group:
            kf.update(m)
        if kf.last_accepted:  # once anything was accepted, every frame gives an estimate
            yield from kf.cone_estimates()


def smoothed_estimates(rig: Rig, measurements: Iterable[PairOffset], tuning: FilterTuning | None = None
                       ) -> list[ConeEstimate]:
    """Recorded: the filter forward, then a Rauch-Tung-Striebel pass backward; the offset at every cone."""
    kf = TopsideFilter(rig, tuning or FilterTuning())
    steps: list[FilterStep] = []
    for group in _frames(measurements):
        F = kf.predict(group[0].time)
        x_pred, P_pred = kf.x.copy(), kf.P.copy()
        for m in group:
            kf.update(m)
        if kf.last_accepted:
            steps.append(FilterStep(kf.time, x_pred, P_pred, kf.x.copy(), kf.P.copy(), F, kf.contributing()))
    if not steps:
        return []
    xs, Ps = [steps[-1].x], [steps[-1].P]
    for k in range(len(steps) - 2, -1, -1):
        nxt = steps[k + 1]
        C = steps[k].P @ nxt.F.T @ np.linalg.pinv(nxt.P_pred)
        xs.append(steps[k].x + C @ (xs[-1] - nxt.x_pred))
        Ps.append(steps[k].P + C @ (Ps[-1] - nxt.P_pred) @ C.T)
    xs.reverse()
    Ps.reverse()
    out: list[ConeEstimate] = []
    for step, x, P in zip(steps, xs, Ps, strict=True):
        out.extend(kf.cone_estimates(x, P, step.time, step.cameras))
    return out


ESTIMATORS: dict[str, Callable[[Rig, Iterable[PairOffset]], Iterable[ConeEstimate]]] = {
    "fused": fused_estimates,  # live, the default
    "smoothed": smoothed_estimates,  # recorded runs
    "paper": paper_filter,  # the paper's method, for comparison
    "raw": lambda rig, measurements: raw_estimates(measurements),  # every camera's pair offset
}
