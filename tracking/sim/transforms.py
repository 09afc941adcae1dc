"""Rigid transforms as 4x4 matrices; `T_a_b` maps coordinates in frame b to frame a."""

from __future__ import annotations

import cv2
import numpy as np

WORLD_UP = np.array([0.0, 0.0, 1.0])


def make_T(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(4, 4) transform from a rotation (3, 3) and a translation (3,)."""
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = t
    return T


def inv_T(T: np.ndarray) -> np.ndarray:
    """Inverse of a rigid transform."""
    R = T[:3, :3]
    return make_T(R.T, -R.T @ T[:3, 3])


def rotvec_to_R(rotvec: np.ndarray) -> np.ndarray:
    """Rotation matrix (3, 3) from a rotation vector (3,), Rodrigues."""
    return cv2.Rodrigues(np.asarray(rotvec, dtype=np.float64).reshape(3, 1))[0]


def R_to_rotvec(R: np.ndarray) -> np.ndarray:
    """Rotation vector (3,) of a rotation matrix (3, 3)."""
    return cv2.Rodrigues(np.asarray(R, dtype=np.float64))[0].reshape(3)


def pose_to_T(pose: np.ndarray) -> np.ndarray:
    """(4, 4) transform from a pose vector x, y, z, rx, ry, rz."""
    return make_T(rotvec_to_R(pose[3:6]), pose[:3])


def T_to_pose(T: np.ndarray) -> np.ndarray:
    """Pose vector x, y, z, rx, ry, rz (6,) of a transform."""
    return np.concatenate([T[:3, 3], R_to_rotvec(T[:3, :3])])


def apply(T: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Transform points (N, 3) by T (4, 4)."""
    return points @ T[:3, :3].T + T[:3, 3]


def look_at(eye: np.ndarray, target: np.ndarray, roll: float = 0.0) -> np.ndarray:
    """T_world_camera (4, 4) of an OpenCV camera (x right, y down, z forward) at eye looking at target."""
    eye = np.asarray(eye, dtype=float)
    z = np.asarray(target, dtype=float) - eye
    z /= np.linalg.norm(z)
    ref = WORLD_UP if abs(z @ WORLD_UP) < 0.99 else np.array([0.0, 1.0, 0.0])
    x = np.cross(z, ref)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.column_stack([x, y, z])
    if roll:
        R = R @ rot_z(roll)
    return make_T(R, eye)


def rot_x(a: float) -> np.ndarray:
    """Rotation about x by a radians."""
    c, s = np.cos(a), np.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def rot_y(a: float) -> np.ndarray:
    """Rotation about y by a radians."""
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def rot_z(a: float) -> np.ndarray:
    """Rotation about z by a radians."""
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def small_rotation(rx: float, ry: float, rz: float) -> np.ndarray:
    """Rotation matrix of a rotation vector given by components."""
    return rotvec_to_R(np.array([rx, ry, rz]))
