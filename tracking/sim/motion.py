"""Motion: the crane's path, JONSWAP vessel motion through simple RAOs, the hanging topside, drone jitter.

Every motion is sampled once on a fine grid (DT) from the seed, then interpolated, so any capture
time of any camera and the truth log see the same poses.

Vessel response (per metre of wave amplitude, at the vessel's midship waterline; beta is the wave
direction relative to the bow, 180 deg = head seas; H2(w; T, zeta) = 1 / (1 - r^2 + 2 i zeta r),
r = w T / 2 pi, a second-order system of natural period T):

- surge cos(beta) / (1 + (w / 0.55)^2), sway sin(beta) / (1 + (w / 0.55)^2), lagging 90 deg
  (long waves carry the hull with the water particles; ~0.33 m/m at Tp = 8 s)
- heave H2(w; 20 s, 0.15)                       (~0.19 m/m at 8 s: a semi-submersible)
- roll  k sin(beta) H2(w; 50 s, 0.05), pitch k cos(beta) H2(w; 50 s, 0.05), k = w^2 / g,
  lagging 90 deg                                (~0.1 deg/m at 8 s)
- yaw   0.3 k sin(2 beta) H2(w; 60 s, 0.05)

The topside hangs from the crane hook (a point fixed to the vessel, pendulum_length above the
topside's centre of gravity): it follows the hook vertically (stiff rigging) and swings as a
damped pendulum horizontally, with a slow torsional twist about z. Stern cameras move with the
vessel; fixed cameras (on a platform) do not move. Drones hold position with two-stage-filtered
Ornstein-Uhlenbeck jitter and wind gusts.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import pairwise

import numpy as np

from tracking.sim.scenario import CameraSpec, MotionSpec, Scenario, SeaSpec
from tracking.sim.scene import VESSEL_ORIGIN
from tracking.sim.transforms import inv_T, look_at, make_T, pose_to_T, rotvec_to_R

DT = 0.01  # s, motion grid step
GRAVITY = 9.81
KNOT = 0.5144  # m/s
HOOK_ABOVE_COG = 15.0  # m, centre of gravity above the topside frame origin
N_FREQ = 96
N_DIR = 15
TWIST_PERIOD = 24.0  # s
TILT_AMPLITUDE_DEG = 0.03
TILT_PERIOD = 6.5  # s
DRONE_POS_TAU = 2.5  # s
DRONE_ANG_TAU = 0.4  # s
DRONE_SMOOTH_TAU = 0.15  # s
GUST_RATE = 1 / 15.0  # gusts per second
MARGIN = 1.0  # s of grid beyond the duration


def smooth_distance(tau: np.ndarray, d: float, v: float, ramp: float) -> tuple[np.ndarray, float]:
    """Distance travelled at times tau (s) on a move of length d: smoothstep speed ramps; and its duration."""
    if d <= 0:
        return np.zeros_like(tau), 0.0
    if ramp <= 0:
        T = d / v
        return np.clip(tau, 0, T) * v, T
    if d < v * ramp:
        v = d / ramp
    T = ramp + d / v
    tau = np.clip(tau, 0, T)

    def up(t: np.ndarray) -> np.ndarray:
        u = np.clip(t / ramp, 0, 1)
        return v * ramp * (u**3 - u**4 / 2) + v * np.maximum(t - ramp, 0)

    s = np.where(tau <= T / 2, up(tau), d - up(T - tau))
    return s, T


@dataclass(frozen=True)
class CranePath:
    """Commanded topside offset from mated (jacket frame) along the scenario's waypoints."""

    points: np.ndarray  # (n, 3)
    starts: np.ndarray  # (n - 1,) start time of each move
    durations: np.ndarray  # (n - 1,)
    spec: MotionSpec
    length: float  # s, the whole procedure

    @classmethod
    def from_spec(cls, spec: MotionSpec) -> CranePath:
        """Build the timed path: dwell, move, dwell, ..., hold."""
        pts = np.array([[*w[:2], w[2] if len(w) == 3 else spec.hover] for w in spec.waypoints], float)
        t = spec.dwell
        starts, durs = [], []
        for p0, p1 in pairwise(pts):
            d = float(np.linalg.norm(p1 - p0))
            v = spec.speed if abs(p1[2] - p0[2]) < 1e-9 else min(spec.speed, spec.lower_speed * d / abs(p1[2] - p0[2]))
            _, T = smooth_distance(np.zeros(1), d, v, spec.ramp_time)
            starts.append(t)
            durs.append(T)
            t += T + spec.dwell
        return cls(pts, np.array(starts), np.array(durs), spec, t + spec.hold)

    def at(self, t: np.ndarray) -> np.ndarray:
        """(N, 3) commanded offset at times t (N,)."""
        t = np.asarray(t, float)
        out = np.repeat(self.points[:1], t.size, axis=0)
        for i, t0 in enumerate(self.starts):
            p0, p1 = self.points[i], self.points[i + 1]
            d = float(np.linalg.norm(p1 - p0))
            if d == 0:
                continue
            v = self.spec.speed if abs(p1[2] - p0[2]) < 1e-9 else min(
                self.spec.speed, self.spec.lower_speed * d / abs(p1[2] - p0[2]))
            s, _ = smooth_distance(t - t0, d, v, self.spec.ramp_time)
            mask = t >= t0
            out[mask] = p0 + np.outer(s[mask] / d, p1 - p0)
        return out


def jonswap(w: np.ndarray, hs: float, tp: float, gamma: float) -> np.ndarray:
    """JONSWAP spectral density S(w) (m^2 s / rad), scaled so that 4 sqrt(m0) = hs."""
    wp = 2 * np.pi / tp
    sigma = np.where(w <= wp, 0.07, 0.09)
    r = np.exp(-((w - wp) ** 2) / (2 * sigma**2 * wp**2))
    s = w**-5.0 * np.exp(-1.25 * (wp / w) ** 4) * gamma**r
    m0 = np.trapezoid(s, w)
    return s * (hs / 4) ** 2 / m0


def _h2(w: np.ndarray, period: float, zeta: float) -> np.ndarray:
    r = w * period / (2 * np.pi)
    return 1.0 / (1 - r**2 + 2j * zeta * r)


def raos(w: np.ndarray, beta: np.ndarray) -> np.ndarray:
    """(6, F, D) complex responses surge, sway, heave, roll, pitch, yaw per metre wave amplitude."""
    W, B = np.meshgrid(w, beta, indexing="ij")
    k = W**2 / GRAVITY
    horiz = -1j / (1 + (W / 0.55) ** 2)
    return np.stack([
        horiz * np.cos(B),
        horiz * np.sin(B),
        _h2(W, 20.0, 0.15) + 0 * B,
        -1j * k * np.sin(B) * _h2(W, 50.0, 0.05),
        -1j * k * np.cos(B) * _h2(W, 50.0, 0.05),
        0.3 * k * np.sin(2 * B) * _h2(W, 60.0, 0.05),
    ])


def vessel_motion(sea: SeaSpec, t: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """(N, 6) vessel surge, sway, heave (m) and roll, pitch, yaw (rad) at times t."""
    dw = (2.5 - 0.25) / N_FREQ
    w = 0.25 + dw * (np.arange(N_FREQ) + rng.uniform(0, 1, N_FREQ))  # jittered: no repeat period
    spread = np.linspace(-np.pi / 2, np.pi / 2, N_DIR)
    d = np.cos(spread) ** (2 * sea.spreading) if sea.spreading > 0 else np.ones(N_DIR)
    d /= d.sum()
    amp = np.sqrt(2 * jonswap(w, sea.hs, sea.tp, sea.gamma)[:, None] * dw * d[None, :])
    phase = rng.uniform(0, 2 * np.pi, amp.shape)
    beta = np.radians(sea.heading) + spread
    coef = (raos(w, beta) * (amp * np.exp(1j * phase))[None]).sum(axis=2)  # (6, F)
    out = np.empty((t.size, 6))
    for start in range(0, t.size, 4096):
        chunk = t[start:start + 4096]
        out[start:start + 4096] = np.real(coef @ np.exp(1j * np.outer(w, chunk))).T
    return out


def vessel_T(motion6: np.ndarray) -> np.ndarray:
    """T_jacket_vessel (4, 4) from surge, sway, heave, roll, pitch, yaw (vessel axes = jacket axes at rest)."""
    surge, sway, heave, roll, pitch, yaw = motion6
    R = rotvec_to_R(np.array([pitch, roll, yaw]))  # pitch about x (athwartships), roll about y (fore-aft)
    return make_T(R, VESSEL_ORIGIN + np.array([sway, -surge, heave]))


def _ou(rng: np.random.Generator, n: int, dims: int, sigma: np.ndarray, tau: float) -> np.ndarray:
    """Stationary Ornstein-Uhlenbeck series (n, dims), then low-passed so it is smooth."""
    a = np.exp(-DT / tau)
    b = np.sqrt(1 - a * a)
    noise = rng.standard_normal((n, dims)) * sigma * b
    x = np.empty((n, dims))
    y = np.empty((n, dims))
    x[0] = rng.standard_normal(dims) * sigma
    y[0] = x[0]
    c = DT / DRONE_SMOOTH_TAU
    for i in range(1, n):
        x[i] = a * x[i - 1] + noise[i]
        y[i] = y[i - 1] + c * (x[i - 1] - y[i - 1])
    return y


def drone_jitter(rng: np.random.Generator, t: np.ndarray, wind_knots: float, wind_dir: float) -> np.ndarray:
    """(N, 6) drone position (m) and attitude (rad) errors around its hold pose."""
    wind = wind_knots * KNOT
    pos_sigma = 0.05 + 0.02 * wind
    ang_sigma = np.radians(0.05 + 0.01 * wind)
    pos = _ou(rng, t.size, 3, np.array([pos_sigma, pos_sigma, 0.5 * pos_sigma]), DRONE_POS_TAU)
    ang = _ou(rng, t.size, 3, np.full(3, ang_sigma), DRONE_ANG_TAU)
    gust_dir = np.array([np.cos(wind_dir), np.sin(wind_dir), 0.0])
    n_gusts = rng.poisson(GUST_RATE * t[-1]) if wind > 0 else 0
    for _ in range(n_gusts):
        t0, length = rng.uniform(0, t[-1]), rng.uniform(2.0, 5.0)
        size = rng.uniform(0.3, 1.0) * 0.03 * wind
        u = np.clip((t - t0) / length, 0, 1)
        shape = 0.5 * (1 - np.cos(2 * np.pi * u)) * size
        pos += np.outer(shape, gust_dir)
        ang[:, 1] += shape * 0.02  # the gimbal lags a little in a gust
    return np.hstack([pos, ang])


def interp_rows(grid: np.ndarray, t: float) -> np.ndarray:
    """Row of grid (N, k) at time t, linear between DT-spaced samples."""
    x = min(max(t / DT, 0.0), grid.shape[0] - 1.000001)
    i = int(x)
    f = x - i
    return grid[i] * (1 - f) + grid[i + 1] * f


class Motion:
    """All poses of a scenario as functions of time on the common clock."""

    def __init__(self, scenario: Scenario, duration: float, seed: int) -> None:
        self.scenario = scenario
        spec = scenario.motion
        self.path = CranePath.from_spec(spec)
        self.t = np.arange(0.0, duration + MARGIN + DT, DT)
        rng_sea = np.random.default_rng([seed, 1])
        if spec.sea is not None and spec.sea.hs > 0:
            self.vessel6 = vessel_motion(spec.sea, self.t, rng_sea)
        else:
            self.vessel6 = np.zeros((self.t.size, 6))
        self.T_jacket_vessel0 = vessel_T(np.zeros(6))
        self.topside6, self.hook = self._hang(spec, np.random.default_rng([seed, 2]))
        wind_dir = np.radians(spec.sea.heading if spec.sea else 135.0) + np.pi / 2
        self.drone6: dict[str, np.ndarray] = {}
        self.T_vessel_camera: dict[str, np.ndarray] = {}
        self.T_hold: dict[str, np.ndarray] = {}
        for i, cam in enumerate(scenario.cameras):
            T0 = camera_rest_pose(cam)
            self.T_hold[cam.name] = T0
            if cam.kind == "fixed":
                continue
            if cam.kind == "drone":
                self.drone6[cam.name] = drone_jitter(np.random.default_rng([seed, 3, i]), self.t,
                                                     spec.wind_knots, wind_dir)
            else:
                self.T_vessel_camera[cam.name] = inv_T(self.T_jacket_vessel0) @ T0

    def _hang(self, spec: MotionSpec, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """Topside pose grid (N, 6) and hook position grid (N, 3)."""
        cmd = self.path.at(self.t)
        hook_rest = cmd + np.array([0.0, 0.0, HOOK_ABOVE_COG + spec.pendulum_length])
        surge, sway, heave, roll, pitch, yaw = self.vessel6.T
        rot = np.column_stack([pitch, roll, yaw])  # small angles: R r ~ r + rot x r
        arm = hook_rest - VESSEL_ORIGIN
        hook = hook_rest + np.cross(rot, arm) + np.column_stack([sway, -surge, heave])
        w0 = np.sqrt(GRAVITY / spec.pendulum_length)
        zeta = spec.pendulum_damping
        hv = np.gradient(hook[:, :2], DT, axis=0)
        angle = rng.uniform(0, 2 * np.pi)
        p = hook[0, :2] + spec.initial_swing * np.array([np.cos(angle), np.sin(angle)])
        v = np.zeros(2)
        xy = np.empty((self.t.size, 2))
        for i in range(self.t.size):
            xy[i] = p
            a = w0 * w0 * (hook[i, :2] - p) + 2 * zeta * w0 * (hv[i] - v)
            v = v + a * DT
            p = p + v * DT
        z = cmd[:, 2] + (hook[:, 2] - hook_rest[:, 2])
        tw = np.radians(spec.twist_amplitude) * np.sin(2 * np.pi * self.t / TWIST_PERIOD + rng.uniform(0, 2 * np.pi))
        tilt = np.radians(TILT_AMPLITUDE_DEG) * np.sin(
            2 * np.pi * self.t[:, None] / (TILT_PERIOD * np.array([1.0, 1.23])) + rng.uniform(0, 2 * np.pi, 2))
        yaw = tw + self.vessel6[:, 5]
        pose = np.column_stack([xy, z, tilt, yaw])
        return pose, hook

    def topside(self, t: float) -> np.ndarray:
        """T_jacket_topside at time t."""
        return pose_to_T(interp_rows(self.topside6, t))

    def vessel(self, t: float) -> np.ndarray:
        """T_jacket_vessel at time t."""
        return vessel_T(interp_rows(self.vessel6, t))

    def hook_at(self, t: float) -> np.ndarray:
        """Crane hook position (3,), jacket frame."""
        return interp_rows(self.hook, t)

    def camera(self, name: str, t: float) -> np.ndarray:
        """T_jacket_camera at time t."""
        if name in self.drone6:
            j = interp_rows(self.drone6[name], t)
            T0 = self.T_hold[name]
            return make_T(T0[:3, :3] @ rotvec_to_R(j[3:]), T0[:3, 3] + j[:3])
        if name in self.T_vessel_camera:
            return self.vessel(t) @ self.T_vessel_camera[name]
        return self.T_hold[name]  # fixed: on a platform, still


def camera_rest_pose(cam: CameraSpec) -> np.ndarray:
    """T_jacket_camera of a camera at its hold position (vessel at rest)."""
    return look_at(np.array(cam.position), np.array(cam.look_at), np.radians(cam.roll))
