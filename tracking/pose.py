"""Marker poses by IPPE_SQUARE on undistorted corners, keeping both solutions of the planar ambiguity."""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum

import cv2
import numpy as np

from tracking.camera import CameraModel
from tracking.detection import MarkerDetection

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


def rt_to_T(rvec: np.ndarray, tvec: np.ndarray) -> np.ndarray:
    """Rotation vector (3,) and translation (3,) to a (4, 4) transform."""
    T = np.eye(4)
    T[:3, :3] = cv2.Rodrigues(np.asarray(rvec, dtype=np.float64).reshape(3))[0]
    T[:3, 3] = np.asarray(tvec, dtype=np.float64).reshape(3)
    return T


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
