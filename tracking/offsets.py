"""The paper's relative offsets (eq. 12–16): the topside marker S in the jacket marker W, per camera."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from tracking.camera import CameraModel
from tracking.geometry import angle, rotation_jacobian
from tracking.pose import BodyPose, Choice, MarkerPose, estimate_body_pose
from tracking.rig import Pair, Rig
from tracking.scale import ScaleSample, separation_sample

MAX_PAIR_TILT_RAD = np.deg2rad(10.0)  # topside and jacket markers of a pair are never this far from parallel


@dataclass(frozen=True)
class PairOffset:
    """One camera's measurement of one marker pair at one capture time."""

    time: float  # capture time of the frame, s
    camera: str
    cone: str
    face: str
    jacket_id: int
    topside_id: int
    T_W_S: np.ndarray  # (4, 4) topside marker S in jacket marker W's frame (eq. 12)
    offset: np.ndarray  # (3,) topside minus mated, jacket frame, m
    covariance: np.ndarray  # (3, 3) of the offset, from both markers' pose covariances, m²
    choice: Choice  # how the IPPE ambiguity was settled (the weaker of the two markers)
    alternatives: tuple[tuple[np.ndarray, np.ndarray], ...] = ()  # (offset, covariance) of the other IPPE
    # combinations when a marker was not unique: a filter with a prediction can settle what one frame cannot


def relative_pose(T_camera_W: np.ndarray, T_camera_S: np.ndarray) -> np.ndarray:
    """T_W_S (4, 4) = inv(T_camera_W) @ T_camera_S (eq. 13–16)."""
    R_cw, t_cw = T_camera_W[:3, :3], T_camera_W[:3, 3]
    T = np.eye(4)
    T[:3, :3] = R_cw.T @ T_camera_S[:3, :3]
    T[:3, 3] = R_cw.T @ T_camera_S[:3, 3] - R_cw.T @ t_cw
    return T


def resolve_pair(W: MarkerPose, S: MarkerPose, T_W_S_mated: np.ndarray) -> tuple[MarkerPose, MarkerPose]:
    """Settle IPPE ambiguities of a pair: the two markers are near parallel, so pick the combination that agrees."""
    if W.choice == Choice.UNIQUE and S.choice == Choice.UNIQUE:
        return W, S
    best = None
    for i in range(2):
        for j in range(2):
            rel = relative_pose(W.solutions[i].T_camera_marker, S.solutions[j].T_camera_marker)
            tilt = angle(T_W_S_mated[:3, :3].T @ rel[:3, :3])
            cost = (tilt, W.solutions[i].reprojection_error + S.solutions[j].reprojection_error)
            if best is None or cost < best[0]:
                best = (cost, i, j)
    assert best is not None
    (tilt, _), i, j = best
    if tilt > MAX_PAIR_TILT_RAD:
        return W, S
    W2 = W if W.choice == Choice.UNIQUE else W.with_choice(i, Choice.PAIR)
    S2 = S if S.choice == Choice.UNIQUE else S.with_choice(j, Choice.PAIR)
    return W2, S2


def _weaker(a: Choice, b: Choice) -> Choice:
    order = [Choice.UNIQUE, Choice.PAIR, Choice.AMBIGUOUS]
    return max(a, b, key=order.index)


@dataclass(frozen=True)
class PairGeometry:
    """What the rig fixes about one pair, computed once: its nominal mated pose and the jacket marker's axes."""

    pair: Pair
    T_W_S_mated: np.ndarray  # (4, 4) topside marker in the jacket marker's frame when mated
    R_jacket_W: np.ndarray  # (3, 3) jacket marker axes in the jacket frame


def pair_geometries(rig: Rig) -> list[PairGeometry]:
    """The geometry of every pair of the rig."""
    by_id = rig.marker_by_id
    return [PairGeometry(p, rig.T_W_S_mated(p), by_id[p.jacket].T_body_marker[:3, :3]) for p in rig.all_pairs()]


def offset_jacobian(geometry: PairGeometry, T_camera_W: np.ndarray, T_camera_S: np.ndarray) -> np.ndarray:
    """(3, 12) derivative of the offset R_jacket_W (R_camera_W^T (t_S - t_W) - t_mated) with respect to
    (rvec_W, tvec_W, rvec_S, tvec_S): analytic, through the Jacobian of OpenCV's Rodrigues (the offset does not
    depend on the topside marker's rotation)."""
    R_cw, dR = rotation_jacobian(T_camera_W[:3, :3])
    d = T_camera_S[:3, 3] - T_camera_W[:3, 3]
    J = np.zeros((3, 12))
    J[:, 0:3] = geometry.R_jacket_W @ np.stack([dR[k].T @ d for k in range(3)], axis=1)
    J[:, 9:12] = geometry.R_jacket_W @ R_cw.T
    J[:, 3:6] = -J[:, 9:12]
    return J


def offset_covariance(geometry: PairGeometry, W: MarkerPose, S: MarkerPose) -> np.ndarray:
    """(3, 3) covariance of a pair offset: both markers' (6, 6) pose covariances through offset_jacobian."""
    J = offset_jacobian(geometry, W.T_camera_marker, S.T_camera_marker)
    return J[:, :6] @ W.covariance @ J[:, :6].T + J[:, 6:] @ S.covariance @ J[:, 6:].T


def pair_offset(geometry: PairGeometry, W: MarkerPose, S: MarkerPose, camera: str, time: float) -> PairOffset:
    """The offset of one pair seen by one camera, in the jacket frame (topside minus mated), with covariance."""
    pair = geometry.pair
    W, S = resolve_pair(W, S, geometry.T_W_S_mated)
    T_W_S = relative_pose(W.T_camera_marker, S.T_camera_marker)
    offset = geometry.R_jacket_W @ (T_W_S[:3, 3] - geometry.T_W_S_mated[:3, 3])
    alternatives = []
    for i in range(2) if W.choice != Choice.UNIQUE else (W.chosen,):
        for j in range(2) if S.choice != Choice.UNIQUE else (S.chosen,):
            if (i, j) == (W.chosen, S.chosen):
                continue
            Wi, Sj = W.with_choice(i, W.choice), S.with_choice(j, S.choice)
            rel = relative_pose(Wi.T_camera_marker, Sj.T_camera_marker)
            alternatives.append((geometry.R_jacket_W @ (rel[:3, 3] - geometry.T_W_S_mated[:3, 3]),
                                 offset_covariance(geometry, Wi, Sj)))
    return PairOffset(time=time, camera=camera, cone=pair.cone, face=pair.face, jacket_id=pair.jacket,
                      topside_id=pair.topside, T_W_S=T_W_S, offset=offset,
                      covariance=offset_covariance(geometry, W, S), choice=_weaker(W.choice, S.choice),
                      alternatives=tuple(alternatives))


def frame_offsets(geometries: list[PairGeometry], poses: dict[int, MarkerPose], camera: str, time: float
                  ) -> list[PairOffset]:
    """Offsets of every pair whose two markers are both among the poses of one frame."""
    return [pair_offset(g, poses[g.pair.jacket], poses[g.pair.topside], camera, time)
            for g in geometries if g.pair.jacket in poses and g.pair.topside in poses]


@dataclass(frozen=True)
class BodyGeometry:
    """The markers of each body as the rig fixes them: (4, 4) T_body_marker by id."""

    jacket: dict[int, np.ndarray]
    topside: dict[int, np.ndarray]


def body_geometry(rig: Rig) -> BodyGeometry:
    """Marker poses in their body frames (the topside frame is the jacket frame when mated)."""
    by_body: dict[str, dict[int, np.ndarray]] = {"jacket": {}, "topside": {}}
    for m in rig.markers:
        by_body[m.body][m.id] = m.T_body_marker
    return BodyGeometry(by_body["jacket"], by_body["topside"])


@dataclass(frozen=True)
class BodyObservation:
    """One camera frame's view of the two bodies: each fitted to all of its markers the frame shows."""

    time: float  # capture time of the frame, s
    camera: str
    jacket: BodyPose | None  # T_camera_jacket, None when no jacket marker is seen
    topside: BodyPose | None  # T_camera_topside (topside frame = jacket frame when mated)
    corners: dict[int, np.ndarray] = field(default_factory=dict)  # id -> (4, 2) undistorted (ideal) pixels
    K: np.ndarray = field(default_factory=lambda: np.eye(3))  # (3, 3) camera matrix of the ideal pixels
    scale: tuple[ScaleSample, ...] = ()  # the markers' size against the rig's, from two markers of one body
    model_px: float = 0.0  # RMS reprojection error of the camera's calibration, px (CameraModel.model_px: assumed where
    # it states none): how well its model maps a point, which no corner of it can beat

    @property
    def choice(self) -> Choice:
        """The weaker of the two bodies' choices."""
        choices = [b.choice for b in (self.jacket, self.topside) if b is not None]
        return _weaker(*choices) if len(choices) == 2 else choices[0]


def observe_bodies(geometry: BodyGeometry, poses: dict[int, MarkerPose], camera: CameraModel, name: str,
                   time: float, marker_size: float) -> BodyObservation | None:
    """Both bodies' poses in one camera frame from its marker poses; None when it shows no rig marker."""
    bodies: list[BodyPose | None] = []
    for body, markers in (("jacket", geometry.jacket), ("topside", geometry.topside)):
        ids = sorted(i for i in poses if i in markers)
        bodies.append(estimate_body_pose(body, [poses[i] for i in ids], [markers[i] for i in ids], camera,
                                         marker_size) if ids else None)
    if bodies[0] is None and bodies[1] is None:
        return None
    corners = {i: camera.undistort_points(p.corners) for i, p in poses.items()
               if i in geometry.jacket or i in geometry.topside}
    return BodyObservation(time, name, bodies[0], bodies[1], corners, camera.K,
                           separations(geometry, poses, name, marker_size), camera.model_px)


def separations(geometry: BodyGeometry, poses: dict[int, MarkerPose], name: str, marker_size: float
                ) -> tuple[ScaleSample, ...]:
    """Scale samples (tracking.scale) from every two markers of one body one frame shows: their separation in the
    rig against the one measured (their IPPE translations, the same for both solutions)."""
    out = []
    for markers in (geometry.jacket, geometry.topside):
        ids = sorted(i for i in poses if i in markers)
        for k, i in enumerate(ids):
            for j in ids[k + 1:]:
                sample = separation_sample(
                    name, (i, j), poses[i].T_camera_marker, poses[j].T_camera_marker,
                    poses[i].covariance[3:, 3:], poses[j].covariance[3:, 3:],
                    float(np.linalg.norm(markers[i][:3, 3] - markers[j][:3, 3])), marker_size)
                if sample is not None:
                    out.append(sample)
    return tuple(out)
