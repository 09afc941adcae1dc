"""The measurement models: what a camera frame's marker corners and a pair offset say about the state.

A marker's four undistorted corners (8 ideal pixels) are predicted through T_camera_jacket (jacket markers) or
T_camera_jacket · T_jacket_topside (topside markers), the marker turned and moved by its survey error (consider
states), plus its view's bias (per corner coordinate of each (camera, marker), the sum of two states). Their Jacobian
is analytic, over the state entries they depend on. Corners far off are down-weighted (Huber-like, CORNER_HUBER_CHI2),
a marker's corners gated by their Mahalanobis distance (CORNER_GATE_CHI2). A view's bias renews in two parts: one as
its marker's image travels (the pixels it falls on), one as the image's shape changes (what the marker's edges look
like: how near, how turned, what lies beyond the plate).

A pair offset (topside marker S displaced from its mated position, jacket frame) is, to first order in ω,
o = (R - I) r_S + t ≈ t - [r_S]× ω: linear in the state (point_offset_matrix).

The measurement stream: time-ordered PairOffset and BodyObservation, grouped by camera frame (frames); a frame's body
observation, when it has one, holds its pair offsets and replaces them (preferred).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator
from dataclasses import dataclass

import numpy as np
from scipy.linalg.lapack import dgesv

from tracking.estimator.noise import (
    CORNER_GATE_CHI2,
    CORNER_HUBER_CHI2,
    CORNER_ITERATIONS,
    CORNER_NOISE_PX,
    GATE_CHI2,
    JOLT_CHI2_2,
    LINEARISATION_TOL_PX,
    STATE,
    VIEW,
    VIEW_BIAS_RENEW_PX,
    VIEW_BIAS_TAU_S,
    VIEW_MISREAD_CHI2,
    VIEW_MISREAD_GAIN,
    VIEW_MISREAD_MIN_WEIGHT,
    VIEW_MISREAD_STEP_S,
    VIEW_MISREAD_TAU_S,
    VIEW_SHAPE_RENEW,
    VIEW_STATES,
)
from tracking.estimator.process import renew_states
from tracking.estimator.state import (
    CameraState,
    FilterState,
    ViewBias,
    camera_pose,
    centred,
    point_offset_matrix,
    topside_pose,
)
from tracking.geometry import inverse, rotation, rotation_jacobian_of, skew
from tracking.offsets import BodyObservation, PairOffset

Measurement = PairOffset | BodyObservation


def frames(measurements: Iterable[Measurement]) -> Iterator[list[Measurement]]:
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


def predict_corners(s: FilterState, nominal: np.ndarray, index: int, marker: int, x: np.ndarray, K: np.ndarray,
                    T_camera_jacket: np.ndarray | None = None) -> np.ndarray:
    """(8,) ideal pixels of a marker's corners predicted from a state x (n,), through a camera at nominal
    T_jacket_camera (4, 4) whose error states start at index (T_camera_jacket: that camera's pose in x, when the
    caller has it), and intrinsics K (3, 3)."""
    T = inverse(camera_pose(nominal, index, x)) if T_camera_jacket is None else T_camera_jacket
    if marker in s.topside_corners:
        T = T @ topside_pose(x)
        X = s.topside_corners[marker]
    else:
        X = s.jacket_corners[marker]
    i = s.consider.markers.get(marker)
    if i is not None and x[i:i + 6].any():  # the marker turned by δθ about its centre and moved by δp
        c = s.centres[marker]
        X = c + (X - c) @ rotation(x[i:i + 3]).T + x[i + 3:i + 6]
    pc = X @ T[:3, :3].T + T[:3, 3]
    uv = pc @ K.T
    return (uv[:, :2] / uv[:, 2:3]).reshape(-1)


_EYE8 = np.eye(VIEW)  # (read only)
_BIAS = np.hstack([_EYE8, _EYE8])  # (8, VIEW_STATES) a view's two biases enter its corners one to one (read only)


def bias(x: np.ndarray, index: int) -> np.ndarray:
    """(8,) the bias of a view's corners in a state x (n,), its states from index: the sum of its two parts."""
    return x[index:index + VIEW] + x[index + VIEW:index + VIEW_STATES]
_UNIT = np.repeat(np.eye(3)[:, None, :], 4, axis=1)  # (3, 4, 3) ∂(corner + δ)/∂δ_k of four corners: [k, n] = e_k


def corner_jacobian(s: FilterState, nominal: np.ndarray, index: int, marker: int, x: np.ndarray, K: np.ndarray,
                    columns: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """A marker's corners predicted from a state x (n,) as predict_corners, (8,) ideal pixels, and their (8, C)
    Jacobian with respect to the state's entries at columns (C,), in runs of six from a block's first: the topside's
    (0-5), the camera's (from index) and the marker's consider states, analytic (each rotation through OpenCV's
    Rodrigues Jacobian); zero elsewhere."""
    R_err, dR_err = rotation_jacobian_of(x[index:index + 3])
    R_n = nominal[:3, :3]
    R_c = R_err @ R_n  # T_jacket_camera's rotation: a corner P (jacket frame) is at pc = R_cᵀ (P - t_c)
    t_c = nominal[:3, 3] + x[index + 3:index + 6]
    topside = marker in s.topside_corners
    X = s.topside_corners[marker] if topside else s.jacket_corners[marker]  # (4, 3) in its body's frame
    firsts: list[int] = []  # each block's first state index; its (6, 4, 3) derivatives of the jacket-frame corners
    blocks: list[np.ndarray] = []
    i = s.consider.markers.get(marker)
    if i is not None:  # the marker turned by δθ about its centre and moved by δp
        c = s.centres[marker]
        R_m, dR_m = rotation_jacobian_of(x[i:i + 3])
        firsts.append(i)
        blocks.append(np.concatenate([(X - c) @ dR_m.transpose(0, 2, 1), _UNIT]))
        if x[i:i + 6].any():
            X = c + (X - c) @ R_m.T + x[i + 3:i + 6]
    if topside:
        R_t, dR_t = rotation_jacobian_of(x[3:6])
        blocks = [d @ R_t.T for d in blocks]
        firsts.append(0)
        blocks.append(np.concatenate([_UNIT, X @ dR_t.transpose(0, 2, 1)]))  # (t, ω)
        X = X @ R_t.T + x[:3]
    d = X - t_c
    D = np.concatenate([*blocks, np.zeros((6, 4, 3))]) @ R_c  # (6 B + 6, 4, 3): ∂pc, the camera's last
    D[-6:-3] = d @ dR_err @ R_n
    D[-3:] = -R_c[:, None, :]
    firsts.append(index)
    uv = (d @ R_c) @ K.T
    h = uv[:, :2] / uv[:, 2:3]
    A = (K[None, :2, :] - h[:, :, None] * K[None, 2:3, :]) / uv[:, 2, None, None]  # (4, 2, 3) ∂pixel / ∂pc
    full = (A @ D.transpose(1, 2, 0)).reshape(8, -1)  # (8, 6 B + 6)
    J = np.zeros((8, len(columns)))
    for b, first in enumerate(firsts):  # columns come in runs of six, a block's states
        if first in columns:
            j = columns.index(first)
            J[:, j:j + 6] = full[:, 6 * b:6 * b + 6]
    return h.reshape(-1), J


def placed(cam: CameraState) -> np.ndarray:
    """The nominal T_jacket_camera (4, 4) of a placed camera."""
    assert cam.T_jacket_camera is not None, f"camera {cam.name} is not placed"
    return cam.T_jacket_camera


def view(s: FilterState, cam: CameraState, marker: int, K: np.ndarray, time: float) -> ViewBias:
    """The bias states of a camera's view of a marker; a new view's appended to the state with its prior."""
    key = (cam.name, marker)
    if key not in s.views:
        return s.append_view(key, predict_corners(s, placed(cam), cam.index, marker, s.x, K), time)
    return s.views[key]


def renew(s: FilterState, frame: list[BodyObservation]) -> np.ndarray:
    """Renew the biases of a frame's views not yet renewed for it; the share of each bias state that stayed (V,)."""
    nb = s.body_size
    keep = np.ones(s.size - nb)
    for o in frame:
        for v, by_travel, by_shape in _renewed(s, o):
            keep[v.index - nb:v.index - nb + VIEW] = by_travel
            keep[v.index - nb + VIEW:v.index - nb + VIEW_STATES] = by_shape
    d = np.flatnonzero(keep < 1.0)
    if d.size:  # in place (predict and apply leave arrays that nothing else holds), on the renewed views alone
        s.x[d + nb] *= keep[d]
        renew_states(s.P, d + nb, keep[d], s.renewal[d])
    return keep


def _renewed(s: FilterState, o: BodyObservation) -> list[tuple[ViewBias, float, float]]:
    """The views of a camera frame not yet renewed for it, each with the shares of its two biases that stay.
    The travel's: exp(-travel / VIEW_BIAS_RENEW_PX), travel the mean shift of its marker's predicted corners since its
    last frame, but at least exp(-dt / VIEW_BIAS_TAU_S), dt the time since then. The shape's (shape_kept): by how much
    further the image's shape departs from the one it had when last renewed, so a shape that only trembles about one
    renews it once."""
    cam = s.cameras.get(o.camera)
    if cam is None or cam.T_jacket_camera is None:
        return []
    out = []
    T_camera_jacket = None  # the camera's pose, once a view needs it
    for marker in o.corners:
        v = s.views.get((o.camera, marker))
        if v is None or v.time == o.time or (marker in s.topside_corners and not s.topside_placed):
            continue
        if T_camera_jacket is None:
            T_camera_jacket = inverse(camera_pose(cam.T_jacket_camera, cam.index, s.x))
        h = predict_corners(s, cam.T_jacket_camera, cam.index, marker, s.x, o.K, T_camera_jacket)
        shift = (h - v.corners).reshape(4, 2)
        travel = float(np.sqrt((shift * shift).sum(axis=1)).sum()) / 4  # mean of the corners' shifts, px
        by_travel, by_time = np.exp(-travel / VIEW_BIAS_RENEW_PX), np.exp(-(o.time - v.time) / VIEW_BIAS_TAU_S)
        by_shape = shape_kept(v, h)
        v.corners, v.time = h, o.time
        out.append((v, float(max(by_travel, by_time)), by_shape))
    return out


def shape_kept(v: ViewBias, corners: np.ndarray) -> float:
    """The share of a view's shape bias that stays as its marker's corners come to corners (8,) (ideal pixels):
    exp(-growth / VIEW_SHAPE_RENEW), growth how much further the corners about their centre depart from the view's
    shape than they did since it was kept (RMS over the corners, over the shape's RMS size). Where the departure
    reaches VIEW_SHAPE_RENEW the view keeps these corners' shape instead. Corners that are not finite change nothing.
    (A shape swinging by more than VIEW_SHAPE_RENEW about one, as a marker's image in a camera rolling 3-5° in waves,
    renews the bias at every swing once a reset falls at one end: the travel's bias, in effect.)"""
    c = centred(corners)
    if not np.isfinite(c).all():
        return 1.0
    departure = float(np.sqrt(np.sum((c - v.shape) ** 2) / max(float(np.sum(v.shape**2)), 1e-12)))
    growth = max(0.0, departure - v.departure)
    v.departure = max(v.departure, departure)
    if v.departure >= VIEW_SHAPE_RENEW:
        v.shape, v.departure = c, 0.0
    return float(np.exp(-growth / VIEW_SHAPE_RENEW))


def misread(s: FilterState, v: ViewBias, r: _Rows, z: np.ndarray, time: float) -> None:
    """Weigh over VIEW_MISREAD_TAU_S how a view's detected corners z (4, 2) depart from those its prior predicts (r.h,
    a frame's first linearisation) in the one way no affine map of its marker's image gives: along w (4,), the unit
    weights of its four predicted corners that sum their positions to zero, on each image axis (2,). A pose that lags
    or errs moves a far marker's image affinely; one corner misread by δ puts δ/2 there. A near marker's perspective
    moves there too as its pose errs: the pose's own σ along w (from the prior's covariance, r.P) is allowed.
    The weights start from zero (a view's first frame only starts its clock) and a frame stands for at most
    VIEW_MISREAD_STEP_S, so a view is judged only once its frames weigh VIEW_MISREAD_MIN_S: one frame a raindrop
    struck is a share of the average (after a gap, at most VIEW_MISREAD_STEP_S's).
    Beyond VIEW_MISREAD_CHI2 of what the view's bias prior, its white noise (this frame's R, as weighted) and its pose
    allow, the view is misread beyond its prior: its shape bias's variance widens to the average's square
    (over its weight), and after as far as the average goes, for good (a shadow's or a plate's edge against a dark leg
    stays with the marker)."""
    p = r.h.tolist()
    w = np.array([_area(p, 1, 2, 3), -_area(p, 0, 2, 3), _area(p, 0, 1, 3), -_area(p, 0, 1, 2)])  # Σ w_i (x_i, y_i,
    # 1) = 0 (Cramer's rule)
    norm2 = float(w @ w)
    if not norm2 > 0.0:
        return
    unit = w / math.sqrt(norm2)
    departure = unit @ (z.reshape(4, 2) - r.h.reshape(4, 2))  # (2,) px
    if not (math.isfinite(departure[0]) and math.isfinite(departure[1])):
        return
    if v.misread_time is None:
        v.misread_time = time
        return  # (a view's first frame starts the clock and weighs nothing)
    if time <= v.misread_time:
        return  # (nor does a frame back in time)
    n_pose = len(r.idx) - VIEW_STATES
    J = np.stack((unit @ r.H[0::2, :n_pose], unit @ r.H[1::2, :n_pose]))  # (2, n_pose) the pose's reach along w
    pose_px = np.sqrt(np.maximum(((J @ r.P[:n_pose, :n_pose]) * J).sum(axis=1), 0.0))  # (2,)
    alpha = 1.0 - math.exp(-min(time - v.misread_time, VIEW_MISREAD_STEP_S) / VIEW_MISREAD_TAU_S)
    v.misread = (1.0 - alpha) * v.misread + alpha * departure
    v.misread_pose_px = (1.0 - alpha) * v.misread_pose_px + alpha * pose_px  # σ of a sum ≤ the sum of σ
    v.misread_weight = (1.0 - alpha) * v.misread_weight + alpha
    v.misread_weight2 = (1.0 - alpha) ** 2 * v.misread_weight2 + alpha**2
    v.misread_time = time
    if v.misread_weight < VIEW_MISREAD_MIN_WEIGHT:
        return
    nb = s.body_size
    k = v.index - nb
    prior = s.renewal[k:k + VIEW] + s.renewal[k + VIEW:k + VIEW_STATES]  # (8,) per corner coordinate, x then y
    allowed = v.misread_weight**2 * float((unit * unit) @ (prior[0::2] + prior[1::2])) / 2.0 + \
        v.misread_weight2 * float(np.trace(r.R)) / VIEW + float(v.misread_pose_px @ v.misread_pose_px) / 2.0  # (R
    # now, not each frame's own: a misread corner's Huber-widened R then hid random-9009 D's misread)
    m2 = float(v.misread @ v.misread)
    limit = (v.misread_px * v.misread_weight) ** 2 if v.misread_px else VIEW_MISREAD_CHI2 * allowed
    if m2 <= limit:
        return  # (once found misread, it widens as far as the average goes)
    m2 /= v.misread_weight**2  # the departure's estimate
    shape = s.renewal[k + VIEW:k + VIEW_STATES]
    grow = np.maximum(VIEW_MISREAD_GAIN**2 * m2 - shape, 0.0)
    s.renewal = s.renewal.copy()  # transitions already taken hold the old
    s.renewal[k + VIEW:k + VIEW_STATES] += grow
    i = np.arange(v.index + VIEW, v.index + VIEW_STATES)
    s.P[i, i] += grow
    v.misread_px = max(v.misread_px, math.sqrt(m2))


def _area(p: list[float], a: int, b: int, c: int) -> float:
    """det [[x, y, 1]] of corners a, b, c of p (8,) as a list: twice their triangle's signed area."""
    ax, ay = p[2 * a], p[2 * a + 1]
    return (p[2 * b] - ax) * (p[2 * c + 1] - ay) - (p[2 * b + 1] - ay) * (p[2 * c] - ax)


def corner_update(s: FilterState, cam: CameraState, corners: dict[int, np.ndarray], K: np.ndarray, topside: bool,
                  time: float) -> bool:
    """One Kalman update with the corners (4, 2) of some markers of one body, each with its view's bias; False when
    none was used. Each marker's H touches only its columns (the bodies', its consider and bias states): the
    products are taken over those.

    Iterated (an IEKF: Gauss-Newton on the update): where the update moves the state so far that the corners predicted
    there depart from their linearisation by more than LINEARISATION_TOL_PX, the Jacobians are taken again at the
    updated state and the update redone from the prior, up to CORNER_ITERATIONS times. A camera just placed from a far
    marker moves metres at its first updates; Jacobians taken metres from where it settles grant information along
    its swing about that marker which the corners never held (a confident wrong depth, docs/method.md)."""
    columns = [*(range(6) if topside else ()), *range(cam.index, cam.index + 6)]
    views = {marker: view(s, cam, marker, K, time).index for marker in sorted(corners)}
    x0, P0 = s.x, s.P  # the prior: apply replaces both arrays, never writes into them
    rows: list[_Rows] = []
    for marker, z in sorted(corners.items()):
        r = _rows(s, cam, marker, z, K, columns, views[marker], x0, x0, P0, topside)
        _, _, solved, info = dgesv(r.HPH + r.R, r.y)  # LAPACK's solve, without numpy's checks
        if info != 0 or float(r.y @ solved) > CORNER_GATE_CHI2:  # (singular: refused, as numpy's error would)
            s.rejected += 1
            continue
        rows.append(r)
    if not rows:
        return False
    for r in rows:
        misread(s, s.views[(cam.name, r.marker)], r, corners[r.marker], time)
        if topside:
            s.topside_seen[r.marker] = time
    xi = x0
    for iteration in range(CORNER_ITERATIONS):
        s.x, s.P = x0, P0
        H, union = _apply_rows(s, rows)
        step = float(np.abs(H @ (s.x[union] - xi[union])).max())  # the update's largest corner travel, px
        if iteration + 1 == CORNER_ITERATIONS or step**2 < 0.1 * LINEARISATION_TOL_PX * K[0, 0] or \
                _linearisation_error(s, cam, rows, K) <= LINEARISATION_TOL_PX:
            break  # a projection's second-order term is about (its first-order step)² / f: below the tolerance
        xi = s.x
        rows = [_rows(s, cam, r.marker, corners[r.marker], K, columns, views[r.marker], xi, x0, P0, topside)
                for r in rows]
    return True


@dataclass(frozen=True)
class _Rows:
    """One marker's part of a corner update, linearised at a state x: its state entries idx (C,), H (8, C), the
    innovation y (8,) against the prior x0 (z - h(x) - bias + H (x - x0)), R (8, 8), H P0 Hᵀ (8, 8), P0 over idx
    (C, C), and h (8,) and x where taken."""

    marker: int
    idx: list[int]
    H: np.ndarray
    y: np.ndarray
    R: np.ndarray
    HPH: np.ndarray
    P: np.ndarray
    h: np.ndarray
    x: np.ndarray


def _rows(s: FilterState, cam: CameraState, marker: int, z: np.ndarray, K: np.ndarray, columns: list[int], v: int,
          x: np.ndarray, x0: np.ndarray, P0: np.ndarray, topside: bool) -> _Rows:
    """A marker's corners z (4, 2) linearised at the state x (n,), their innovation against the prior x0 (n,) and
    their noise (Huber-weighted against the prior's covariance P0 (n, n))."""
    i = s.consider.markers.get(marker)
    cols = columns if i is None else [*columns, *range(i, i + 6)]
    h, J = corner_jacobian(s, placed(cam), cam.index, marker, x, K, cols)
    idx = [*cols, *range(v, v + VIEW_STATES)]
    H = np.concatenate((J, _BIAS), axis=1)  # (8, |idx|)
    y = z.reshape(-1) - h - bias(x, v)
    if x is not x0:
        y = y + H @ (x[idx] - x0[idx])
    P = P0.take(idx, 0).take(idx, 1)  # P0[np.ix_(idx, idx)], 2.5 times faster
    HPH = H @ P @ H.T
    return _Rows(marker, idx, H, y, _corner_covariance(s, cam, J, HPH, y, topside), HPH, P, h, x)


def _apply_rows(s: FilterState, rows: list[_Rows]) -> tuple[np.ndarray, list[int]]:
    """One Kalman update with every marker's rows, over the union of their state entries; their stacked H (8 M, C)
    and that union (C,)."""
    union = sorted({k for r in rows for k in r.idx})
    where = {k: j for j, k in enumerate(union)}
    H = np.zeros((VIEW * len(rows), len(union)))
    R = np.zeros((H.shape[0], H.shape[0]))
    for k, r in enumerate(rows):
        H[VIEW * k:VIEW * k + VIEW, [where[c] for c in r.idx]] = r.H
        R[VIEW * k:VIEW * k + VIEW, VIEW * k:VIEW * k + VIEW] = r.R
    s.apply(H, np.concatenate([r.y for r in rows]), R, union)
    return H, union


def _linearisation_error(s: FilterState, cam: CameraState, rows: list[_Rows], K: np.ndarray) -> float:
    """Largest departure, px, of the corners predicted at the updated state from their linearisation at the state
    each marker's rows were taken at (the bias states enter linearly: left out)."""
    worst = 0.0
    for r in rows:
        n_pose = len(r.idx) - VIEW_STATES
        dx = s.x[r.idx[:n_pose]] - r.x[r.idx[:n_pose]]
        linear = r.h + r.H[:, :n_pose] @ dx
        worst = max(worst, float(np.abs(predict_corners(s, placed(cam), cam.index, r.marker, s.x, K) - linear).max()))
    return worst


def jolted(s: FilterState, cam: CameraState, corners: dict[int, np.ndarray], K: np.ndarray, time: float) -> bool:
    """Whether a placed camera's jacket corners (id -> (4, 2)) in its frame at a capture time say it moved beyond its
    prior since its last frame: the median of their corners' squared innovations (corner_d2) beyond JOLT_CHI2_2.
    The median, so a rain-struck corner or marker does not count, while a camera that moved moves all."""
    columns = list(range(cam.index, cam.index + 6))
    sigma2 = max(CORNER_NOISE_PX, cam.model_px) ** 2
    views = {m: s.views[(cam.name, m)] for m in corners if (cam.name, m) in s.views}
    predicted = {m: v.corners if v.time == time else predict_corners(s, placed(cam), cam.index, m, s.x, K)
                 for m, v in views.items()}  # renew predicted the frame's views' corners already
    bound = [np.sum((z.reshape(4, 2) - (predicted[m] + bias(s.x, views[m].index)).reshape(4, 2)) ** 2,
                    axis=1) for m, z in corners.items() if m in views]  # |y|² per corner: d² ≤ |y|² / σ², S ≥ σ² I
    if not bound or _median(np.concatenate(bound)) <= JOLT_CHI2_2 * sigma2:
        return False
    d2: list[np.ndarray] = []
    for marker, v in views.items():
        z = corners[marker]
        h, J = corner_jacobian(s, placed(cam), cam.index, marker, s.x, K, columns)
        idx = [*columns, *range(v.index, v.index + VIEW_STATES)]
        H = np.concatenate((J, _BIAS), axis=1)
        y = z.reshape(-1) - h - bias(s.x, v.index)
        d2.append(corner_d2(H @ s.P.take(idx, 0).take(idx, 1) @ H.T + sigma2 * _EYE8, y))
    return bool(d2) and _median(np.concatenate(d2)) > JOLT_CHI2_2


def _median(values: np.ndarray) -> float:
    """The median of a few values (N,), sorted in place: np.median costs ten times as much on a frame's corners."""
    values.sort()
    n = len(values)
    return float(values[(n - 1) // 2] + values[n // 2]) / 2


def corner_d2(S: np.ndarray, y: np.ndarray) -> np.ndarray:
    """(4,) each corner's yᵀ S⁻¹ y over its own 2 × 2 block of a marker's innovation covariance S (8, 8), innovation
    y (8,)."""
    a, b = S[0::2, 0::2].diagonal(), S[0::2, 1::2].diagonal()  # (4,) each: the corners' blocks [[a, b], [c, d]]
    c, d = S[1::2, 0::2].diagonal(), S[1::2, 1::2].diagonal()
    u, w = y[0::2], y[1::2]
    return (d * u * u - (b + c) * u * w + a * w * w) / (a * d - b * c)


def _corner_covariance(s: FilterState, cam: CameraState, J: np.ndarray, HPH: np.ndarray, y: np.ndarray,
                       topside: bool) -> np.ndarray:
    """(8, 8) noise of a marker's corners: CORNER_NOISE_PX or the camera model's own RMS error, a topside seen up to its
    camera clock's σ early or late, and a corner far off (rain, glare) counted as if at the Huber threshold."""
    R = max(CORNER_NOISE_PX, cam.model_px) ** 2 * _EYE8
    if topside and s.clock_sigma.get(cam.name):  # a clock known to σ_t: the topside seen up to σ_t early
        moved = J[:, :6] @ s.x[6:12] * s.clock_sigma[cam.name]  # or late, (8,) px along its motion
        R += np.outer(moved, moved)  # (cone_estimates adds what the cameras' clocks share)
    d2 = corner_d2(HPH + R, y)
    if d2.max() <= CORNER_HUBER_CHI2:
        return R
    for j in np.flatnonzero(d2 > CORNER_HUBER_CHI2):
        b = slice(2 * j, 2 * j + 2)
        R[b, b] *= d2[j] / CORNER_HUBER_CHI2
    return R


def pair_rows(s: FilterState, m: PairOffset) -> np.ndarray:
    """(3, n) H of a pair offset: its topside marker's point offset, and its markers' consider states (off by (δθ_W,
    δp_W) and (δθ_S, δp_S), they put it off by δp_S - δp_W - δθ_W × (p_S - c_W), p_S where the state has the topside
    marker now: a jacket marker's tilt turns the whole distance, 20 m while the topside comes in)."""
    H = np.zeros((3, s.size))
    H[:, :STATE] = point_offset_matrix(s.centres[m.topside_id])
    w, t = s.consider.markers.get(m.jacket_id), s.consider.markers.get(m.topside_id)
    if w is not None:
        p_s = s.centres[m.topside_id] + H[:, :STATE] @ s.x[:STATE]
        H[:, w:w + 3] = skew(p_s - s.centres[m.jacket_id])
        H[:, w + 3:w + 6] = -np.eye(3)
    if t is not None:
        H[:, t + 3:t + 6] = np.eye(3)
    return H


def nearest(P: np.ndarray, candidates: list[tuple[np.ndarray, np.ndarray]], H: np.ndarray, gain: float,
            floor: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """Of a measurement's candidates (innovation, covariance), the one nearest the prediction of covariance P (n, n):
    (d², y, R); inflated by gain when the prediction does not settle which it is."""
    HPH = H @ P @ H.T
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
