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
with it, 350 mm at 20 m, which grows as the topside comes in and, taken as surveyed, reads as a lag. What is
observable: τ_c is the shift that lines a camera's offsets up with the others' along the topside's velocity, so its
information is the squared velocity over the offsets' variance along it. A still topside gives nothing; a topside
moving 0.05 m/s, seen by a camera whose offsets scatter by 5 mm, gives 0.1 s per frame, a few milliseconds over a
minute. The cameras' own motion (a vessel's waves, a drone's hovering) is not used: each camera's pose is measured
from its own images, and a drone's motion is its own. The shared wave motion of vessel-mounted cameras would tie
those to each other even with a still topside; it is left out (see the README).

The model, its splines and priors are tracking/motion_model.py's. A first estimate comes from matching each camera's
topside track with the reference's (within ±SEARCH_S, their constant difference removed); the joint fit refines it
(tracking/least_squares.py: Levenberg-Marquardt on the sparse normal equations, soft-L1 beyond SOFT_L1_SCALE σ).
Each camera's σ is the larger of the fit's covariance, scaled by its residuals' spread and by their correlation in
time (a view's corner errors last for seconds, so its frames are not independent), and a cluster-robust (sandwich)
variance over CLUSTER_S blocks of every camera's residuals. Where σ exceeds UNKNOWN_SIGMA_S the offset is not
changed and the reason is given.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from tracking.errors import InputError
from tracking.least_squares import SoftL1, information_columns, minimise
from tracking.motion_model import OffsetModel, Samples, pair_samples
from tracking.offsets import PairOffset
from tracking.rig import Rig

SEARCH_S = 2.0  # the first estimate looks this far either side of the rig's offset, s
SEARCH_STEP_S = 0.01  # ... in these steps, then a parabola through the best three
TRACK_STEP_S = 0.05  # grid of the matched tracks, s
SPLINE_MARGIN_S = SEARCH_S + 1.0  # the motion's splines reach this far beyond the samples, s: a clock moved by up to
# SEARCH_S still samples them, with a knot's support to spare
UNKNOWN_SIGMA_S = 0.01  # beyond this σ, a camera's offset is not changed: the motion is too small to tell. The
# issue's target, and no looser: a far camera's stated σ misses its systematic errors (evidence in
# docs/method.md#clocks-and-the-marker-survey-sync-survey)
MAX_CORRELATION_LAG = 60  # residual autocorrelation summed over at most this many frames (4 s at 15 FPS)
CLUSTER_S = 20.0  # residuals within blocks this long count as correlated (σ's sandwich): a far camera's depth wanders
# for tens of seconds as the topside's view changes
SOFT_L1_SCALE = 3.0  # whitened residuals beyond this count linearly (rain-struck corners, a wrong IPPE pose)
MAX_ITERATIONS = 20  # Levenberg-Marquardt steps of the joint fit
STEP_TOLERANCE_S = 1e-5  # ... until no clock moves by more than this, s (or the cost no longer falls)


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


def timing_information(s: Samples, cameras: list[str]) -> dict[str, float]:
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


def _camera_velocity(s: Samples, camera: int, grid: np.ndarray, position: bool = False
                     ) -> tuple[np.ndarray, np.ndarray]:
    """One camera's topside velocity (G, 3) (or position, with its own constant bias) on a time grid (G,), from a
    spline through its own offsets alone, and whether each grid time lies within its samples (G,)."""
    model = OffsetModel(s.of_camera(camera), [], SPLINE_MARGIN_S)
    P, _ = model.knots(model.linear_fit(np.zeros(model.size)))
    i, w, dw = model.p.basis(grid)
    t = model.s.time
    inside = (grid >= t.min()) & (grid <= t.max())
    gaps = np.diff(t) > 1.0  # a camera that lost its markers for a second says nothing in between
    for a, b in zip(t[:-1][gaps], t[1:][gaps], strict=True):
        inside &= ~((grid > a) & (grid < b))
    return np.einsum("nk,nkj->nj", w if position else dw, P[i]), inside


def first_estimates(s: Samples, cameras: list[str], reference: int) -> dict[int, float]:
    """Each camera's clock offset against the reference by matching their topside tracks (positions from each camera's
    own spline, their constant difference removed: a camera's biases), s; cameras without overlapping motion are left
    out. Positions, not velocities: velocities differentiate each camera's noise and can match the wrong swing of a
    slow motion."""
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
    s = pair_samples(rig, offsets, cameras)
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
    model = OffsetModel(s, free, SPLINE_MARGIN_S)
    x = np.zeros(model.size)
    for c, k in model.i_tau.items():
        x[k] = first[c]
    x = minimise(model.residuals, model.jacobian, model.linear_fit(x), SoftL1(SOFT_L1_SCALE), MAX_ITERATIONS,
                 settled=lambda step: bool(np.all(np.abs(step[:model.o_p]) < STEP_TOLERANCE_S))).x
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


def _sigmas(model: OffsetModel, x: np.ndarray) -> dict[int, float]:
    """σ of each free camera's τ (s): the larger of the fit's covariance (scaled by the camera's residual spread and by
    their correlation in time) and a cluster-robust (sandwich) variance over CLUSTER_S blocks of every camera's
    residuals, which also holds what the reference's errors and slower drifts do to τ."""
    J = model.jacobian(x)
    r = model.residuals(x)
    weight = SoftL1(SOFT_L1_SCALE).weights(r)  # as the fit weighed them
    taus = sorted(model.i_tau.items())
    columns = information_columns(J, weight, np.array([k for _, k in taus], dtype=int))  # (J^T W J)⁻¹'s τ columns
    n = 3 * len(model.s.time)
    block = np.floor((model.s.time - model.s.time.min()) / CLUSTER_S).astype(int)
    cluster = np.repeat(block * (int(model.s.camera.max()) + 1) + model.s.camera, 3)
    velocity = model.predict(x)[3]
    res = r[:n].reshape(-1, 3)
    out = {}
    for (c, k), u in zip(taus, columns.T, strict=True):
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
