"""Marker poses by IPPE_SQUARE on undistorted corners, keeping both solutions of the planar ambiguity."""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum

import cv2
import numpy as np

from tracking.camera import CameraModel
from tracking.detection import MarkerDetection
from tracking.geometry import rt_to_T, rvec_tvec

AMBIGUITY_RATIO = 1.5  # a pose is unambiguous only when the other IPPE solution reprojects this much worse ...
CORNER_SIGMA_PX = 0.08  # corner noise floor: RMS of the edge-fit corners over all conditions (corners.md)
AMBIGUITY_GAP_PX = 0.25  # ... and worse by this much in absolute terms: below it, corner noise could swap them


class Choice(StrEnum):
    """How the pose among the two IPPE solutions was chosen."""

    UNIQUE = "unique"  # the other solution reprojects clearly worse (by AMBIGUITY_RATIO and AMBIGUITY_GAP_PX)
    PAIR = "pair"  # ambiguous alone; chosen by agreement with the other marker of its pair
    AMBIGUOUS = "ambiguous"  # ambiguous and nothing else decided it; the lower reprojection error was kept


def marker_object_points(size: float) -> np.ndarray:
    """(4, 3) marker corners TL TR BR BL in the marker frame (x right, y up, z out of the face)."""
    h = size / 2.0
    return np.array([[-h, h, 0.0], [h, h, 0.0], [h, -h, 0.0], [-h, -h, 0.0]])


@dataclass(frozen=True)
class PoseSolution:
    """One IPPE solution: T_camera_marker, its RMS reprojection error in px, and its covariance."""

    T_camera_marker: np.ndarray  # (4, 4)
    reprojection_error: float
    covariance: np.ndarray  # (6, 6) of (rvec, tvec) of T_camera_marker, from the corner noise


@dataclass(frozen=True)
class MarkerPose:
    """Pose of one marker in one camera, with the rejected alternative kept for the record."""

    id: int
    corners: np.ndarray  # (4, 2) distorted pixels as detected
    solutions: tuple[PoseSolution, PoseSolution]  # sorted by reprojection error
    chosen: int  # index into solutions
    choice: Choice

    @property
    def T_camera_marker(self) -> np.ndarray:
        """(4, 4) chosen pose: marker coordinates to camera coordinates."""
        return self.solutions[self.chosen].T_camera_marker

    @property
    def reprojection_error(self) -> float:
        """RMS reprojection error of the chosen solution, px."""
        return self.solutions[self.chosen].reprojection_error

    @property
    def covariance(self) -> np.ndarray:
        """(6, 6) covariance of the chosen solution's (rvec, tvec)."""
        return self.solutions[self.chosen].covariance

    @property
    def ambiguity(self) -> float:
        """Reprojection error of the worse solution over the better one (large = unambiguous)."""
        e0, e1 = (s.reprojection_error for s in self.solutions)
        return float(e1 / max(e0, 1e-9))

    def with_choice(self, chosen: int, choice: Choice) -> MarkerPose:
        """The same pose with another solution chosen."""
        return MarkerPose(self.id, self.corners, self.solutions, chosen, choice)


def pose_covariance(object_points: np.ndarray, rvec: np.ndarray, tvec: np.ndarray, K: np.ndarray,
                    sigma_px: float) -> np.ndarray:
    """(6, 6) covariance of (rvec, tvec) for isotropic corner noise sigma_px: σ² (JᵀJ)⁻¹ (Gauss-Newton)."""
    _, jac = cv2.projectPoints(object_points, rvec, tvec, K, None)
    J = jac[:, :6]
    try:
        return sigma_px**2 * np.linalg.inv(J.T @ J)
    except np.linalg.LinAlgError:  # a degenerate view: the pseudo-inverse
        return sigma_px**2 * np.linalg.pinv(J.T @ J)


def estimate_pose(detection: MarkerDetection, camera: CameraModel, marker_size: float) -> MarkerPose:
    """Both IPPE_SQUARE solutions for one marker, from its undistorted corners, with their covariances."""
    ideal = camera.undistort_points(detection.corners)
    obj = marker_object_points(marker_size)
    _, rvecs, tvecs, errors = cv2.solvePnPGeneric(obj, ideal.reshape(-1, 1, 2), camera.K, None,
                                                  flags=cv2.SOLVEPNP_IPPE_SQUARE)
    sols = [PoseSolution(rt_to_T(r, t), float(e),
                         pose_covariance(obj, r, t, camera.K, max(CORNER_SIGMA_PX, float(e))))
            for r, t, e in zip(rvecs, tvecs, np.asarray(errors).reshape(-1), strict=True)]
    if len(sols) == 1:
        sols.append(sols[0])
    sols.sort(key=lambda s: s.reprojection_error)
    pose = MarkerPose(detection.id, detection.corners, (sols[0], sols[1]), 0, Choice.UNIQUE)
    gap = sols[1].reprojection_error - sols[0].reprojection_error
    clear = pose.ambiguity >= AMBIGUITY_RATIO and gap >= AMBIGUITY_GAP_PX
    return pose if clear else pose.with_choice(0, Choice.AMBIGUOUS)


OUTLIER_PX = 1.0  # a corner this far from the body's fit is an outlier (rain, occlusion) when others outvote it
MIN_BODY_POINTS = 8  # corners a multi-marker fit keeps at least: two markers' worth


@dataclass(frozen=True)
class BodyPose:
    """Pose of a rigid body (jacket or topside) in one camera, from the corners of all its markers it sees."""

    body: str
    marker_ids: tuple[int, ...]
    T_camera_body: np.ndarray  # (4, 4)
    covariance: np.ndarray  # (6, 6) of (rvec, tvec) of T_camera_body
    reprojection_error: float  # RMS over the corners kept, px
    choice: Choice  # UNIQUE for several markers or a clear single marker; AMBIGUOUS otherwise
    alternatives: tuple[tuple[np.ndarray, np.ndarray], ...] = ()  # (T_camera_body, covariance) of the other
    # IPPE solution when a single marker could not settle it
    outliers: int = 0  # corners dropped as outliers


def body_object_points(T_body_markers: list[np.ndarray], size: float) -> np.ndarray:
    """(4 N, 3) corners of N markers in their body's frame, from their (4, 4) T_body_marker."""
    obj = marker_object_points(size)
    return np.concatenate([(T[:3, :3] @ obj.T).T + T[:3, 3] for T in T_body_markers])


def _residuals(obj: np.ndarray, ideal: np.ndarray, T: np.ndarray, K: np.ndarray) -> np.ndarray:
    """(N,) reprojection distances of object points under T_camera_body, px."""
    r, t = rvec_tvec(T)
    proj, _ = cv2.projectPoints(obj, r, t, K, None)
    return np.linalg.norm(proj.reshape(-1, 2) - ideal, axis=1)


def _fit(obj: np.ndarray, ideal: np.ndarray, T0: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Levenberg-Marquardt refinement of T_camera_body (4, 4) from an initial guess."""
    r, t = rvec_tvec(T0)
    r, t = cv2.solvePnPRefineLM(obj, ideal.reshape(-1, 1, 2), K, None, r.reshape(3, 1), t.reshape(3, 1))
    return rt_to_T(r, t)


def estimate_body_pose(body: str, poses: list[MarkerPose], T_body_markers: list[np.ndarray], camera: CameraModel,
                       marker_size: float) -> BodyPose:
    """One body's pose from the markers of it one frame shows: their marker poses (4, 4) T_body_marker each.

    One marker: its IPPE solutions moved to the body frame. Several: every marker's IPPE solutions seed a
    joint Levenberg-Marquardt fit over all corners; the seed that fits all of them best wins, so the planar
    ambiguity of a lone 1 m marker is settled by the others, and depth rests on the spread of the markers
    instead of one marker's size. A corner beyond OUTLIER_PX and 3 RMS of the others is dropped, worst
    first, while enough remain.
    """
    K = camera.K
    ids = tuple(p.id for p in poses)
    if len(poses) == 1:
        p, T_bm_inv = poses[0], np.linalg.inv(T_body_markers[0])
        obj = body_object_points(T_body_markers, marker_size)
        sols = []
        for s in (p.solutions[p.chosen], p.solutions[1 - p.chosen]):
            T = s.T_camera_marker @ T_bm_inv
            r, t = rvec_tvec(T)
            sols.append((T, pose_covariance(obj, r, t, K, max(CORNER_SIGMA_PX, s.reprojection_error))))
        alternatives = () if p.choice == Choice.UNIQUE else (sols[1],)
        return BodyPose(body, ids, sols[0][0], sols[0][1], p.reprojection_error, p.choice, alternatives)
    obj = body_object_points(T_body_markers, marker_size)
    ideal = np.concatenate([camera.undistort_points(p.corners) for p in poses])
    seeds = [s.T_camera_marker @ np.linalg.inv(Tb) for p, Tb in zip(poses, T_body_markers, strict=True)
             for s in p.solutions]
    best = min(seeds, key=lambda T: float(np.sum(_residuals(obj, ideal, T, K) ** 2)))
    T = _fit(obj, ideal, best, K)
    keep = np.ones(len(obj), bool)
    while True:
        res = _residuals(obj, ideal, T, K)
        worst = int(np.argmax(np.where(keep, res, -1.0)))
        others = keep.copy()
        others[worst] = False
        rms_others = float(np.sqrt(np.mean(res[others] ** 2)))
        if res[worst] <= max(OUTLIER_PX, 3.0 * rms_others) or keep.sum() <= MIN_BODY_POINTS:
            break
        keep[worst] = False
        T = _fit(obj[keep], ideal[keep], T, K)
    res = _residuals(obj[keep], ideal[keep], T, K)
    rms = float(np.sqrt(np.mean(res**2)))
    r, t = rvec_tvec(T)
    cov = pose_covariance(obj[keep], r, t, K, max(CORNER_SIGMA_PX, rms))
    return BodyPose(body, ids, T, cov, rms, Choice.UNIQUE, (), int((~keep).sum()))
