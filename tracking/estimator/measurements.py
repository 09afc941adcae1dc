"""The measurement models: what a camera frame's marker corners and a pair offset say about the state.

A marker's four undistorted corners (8 ideal pixels) are predicted through T_camera_jacket (jacket markers) or
T_camera_jacket · T_jacket_topside (topside markers), the marker turned and moved by its survey error (consider
states), plus its view's bias (8 states per (camera, marker)). Their Jacobian is a forward difference over the
state entries they depend on. Corners far off are down-weighted (Huber-like, CORNER_HUBER_CHI2), a marker's corners
gated by their Mahalanobis distance (CORNER_GATE_CHI2). A view's bias renews as its marker's image moves.

A pair offset (topside marker S displaced from its mated position, jacket frame) is, to first order in ω,
o = (R - I) r_S + t ≈ t - [r_S]× ω: linear in the state (point_offset_matrix).

The measurement stream: time-ordered PairOffset and BodyObservation, grouped by camera frame (frames); a frame's body
observation, when it has one, holds its pair offsets and replaces them (preferred).
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator

import numpy as np

from tracking.estimator.noise import (
    CORNER_GATE_CHI2,
    CORNER_HUBER_CHI2,
    CORNER_NOISE_PX,
    GATE_CHI2,
    STATE,
    VIEW,
    VIEW_BIAS_PX,
    VIEW_BIAS_RENEW_PX,
    VIEW_BIAS_TAU_S,
)
from tracking.estimator.state import (
    CameraState,
    FilterState,
    ViewBias,
    camera_pose,
    point_offset_matrix,
    topside_pose,
)
from tracking.geometry import JACOBIAN_STEP, inverse, rotation, skew
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


def predict_corners(s: FilterState, nominal: np.ndarray, index: int, marker: int, x: np.ndarray, K: np.ndarray
                    ) -> np.ndarray:
    """(8,) ideal pixels of a marker's corners predicted from a state x (n,), through a camera at nominal
    T_jacket_camera (4, 4) whose error states start at index, and intrinsics K (3, 3)."""
    T = inverse(camera_pose(nominal, index, x))
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


def corner_jacobian(s: FilterState, nominal: np.ndarray, index: int, marker: int, x: np.ndarray, K: np.ndarray,
                    columns: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """A marker's corners predicted from a state x (n,) as predict_corners, (8,) ideal pixels, and their (8, C)
    forward-difference Jacobian with respect to the state's entries at columns (C,)."""
    h = predict_corners(s, nominal, index, marker, x, K)
    J = np.empty((8, len(columns)))
    for j, k in enumerate(columns):
        x1 = x.copy()
        x1[k] += JACOBIAN_STEP
        J[:, j] = (predict_corners(s, nominal, index, marker, x1, K) - h) / JACOBIAN_STEP
    return h, J


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
        for v, share in _renewed(s, o):
            keep[v.index - nb:v.index - nb + VIEW] = share
    if (keep < 1.0).any():  # as Transition.covariance does for the views, in place: predict and apply leave
        s.x[nb:] *= keep  # arrays that nothing else holds
        s.P[nb:, :] *= keep[:, None]
        s.P[:, nb:] *= keep
        s.P[nb:, nb:] += np.diag((1.0 - keep**2) * VIEW_BIAS_PX**2)
    return keep


def _renewed(s: FilterState, o: BodyObservation) -> list[tuple[ViewBias, float]]:
    """The views of a camera frame not yet renewed for it, each with the share of its bias that stays: exp(-travel /
    VIEW_BIAS_RENEW_PX), travel the mean shift of its marker's predicted corners since its last frame, but at least
    exp(-dt / VIEW_BIAS_TAU_S), dt the time since then."""
    cam = s.cameras.get(o.camera)
    if cam is None or cam.T_jacket_camera is None:
        return []
    out = []
    for marker in o.corners:
        v = s.views.get((o.camera, marker))
        if v is None or v.time == o.time or (marker in s.topside_corners and not s.topside_placed):
            continue
        h = predict_corners(s, cam.T_jacket_camera, cam.index, marker, s.x, o.K)
        travel = float(np.linalg.norm((h - v.corners).reshape(4, 2), axis=1).mean())
        by_travel, by_time = np.exp(-travel / VIEW_BIAS_RENEW_PX), np.exp(-(o.time - v.time) / VIEW_BIAS_TAU_S)
        v.corners, v.time = h, o.time
        out.append((v, float(max(by_travel, by_time))))
    return out


def corner_update(s: FilterState, cam: CameraState, corners: dict[int, np.ndarray], K: np.ndarray, topside: bool,
                  time: float) -> bool:
    """One Kalman update with the corners (4, 2) of some markers of one body, each with its view's bias; False when
    none was used."""
    columns = [*(range(6) if topside else ()), *range(cam.index, cam.index + 6)]
    views = {marker: view(s, cam, marker, K, time).index for marker in sorted(corners)}
    Hs, ys, Rs = [], [], []
    for marker, z in sorted(corners.items()):
        i = s.consider.markers.get(marker)
        cols = columns if i is None else [*columns, *range(i, i + 6)]
        h, J = corner_jacobian(s, placed(cam), cam.index, marker, s.x, K, cols)
        v = slice(views[marker], views[marker] + VIEW)
        H = np.zeros((8, s.size))
        H[:, cols] = J
        H[:, v] = np.eye(VIEW)
        y = z.reshape(-1) - h - s.x[v]
        HPH = H @ s.P @ H.T
        R = _corner_covariance(s, cam, J, HPH, y, topside)
        if float(y @ np.linalg.solve(HPH + R, y)) > CORNER_GATE_CHI2:
            s.rejected += 1
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
    s.apply(H, np.concatenate(ys), R)
    return True


def _corner_covariance(s: FilterState, cam: CameraState, J: np.ndarray, HPH: np.ndarray, y: np.ndarray,
                       topside: bool) -> np.ndarray:
    """(8, 8) noise of a marker's corners: CORNER_NOISE_PX or the camera model's own RMS error, a topside seen up to its
    camera clock's σ early or late, and a corner far off (rain, glare) counted as if at the Huber threshold."""
    R = max(CORNER_NOISE_PX, cam.model_px) ** 2 * np.eye(8)
    if topside and s.clock_sigma.get(cam.name):  # a clock known to σ_t: the topside seen up to σ_t early
        moved = J[:, :6] @ s.x[6:12] * s.clock_sigma[cam.name]  # or late, (8,) px along its motion
        R += np.outer(moved, moved)  # (cone_estimates adds what the cameras' clocks share)
    for j in range(4):
        b = slice(2 * j, 2 * j + 2)
        d2_j = float(y[b] @ np.linalg.solve(HPH[b, b] + R[b, b], y[b]))
        if d2_j > CORNER_HUBER_CHI2:
            R[b, b] *= d2_j / CORNER_HUBER_CHI2
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
