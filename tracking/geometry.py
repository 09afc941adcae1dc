"""Rigid-body geometry: rotations, transforms named by their frames, their Jacobians and covariance propagation.

Conventions: a transform T_a_b (4, 4) maps coordinates in frame b to frame a; a rotation vector (3,) is the axis
times the angle in radians; a pose's parameters (6,) are (rotation vector, translation) as OpenCV's (rvec, tvec);
a pose error (6,) is (δθ, δp): the rotation vector of R_measured R_predictedᵀ and the difference of translations.
Rotations go through OpenCV's Rodrigues, whose results the filter's figures were measured with; scipy's Rotation
serves where quaternions or many rotations at once are wanted (`rotations`, `quaternions_xyzw`).
"""

from __future__ import annotations

from collections.abc import Callable

import cv2
import numpy as np

JACOBIAN_STEP = 1e-6  # rad or m: forward differences of numeric Jacobians


def skew(v: np.ndarray) -> np.ndarray:
    """(3, 3) matrix [v]× of a vector v (3,): [v]× u = v × u."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def skews(v: np.ndarray) -> np.ndarray:
    """(N, 3, 3) matrices [v]× of vectors v (N, 3)."""
    z = np.zeros(len(v))
    return np.stack([np.stack([z, -v[:, 2], v[:, 1]], 1), np.stack([v[:, 2], z, -v[:, 0]], 1),
                     np.stack([-v[:, 1], v[:, 0], z], 1)], 1)


def rotation(v: np.ndarray) -> np.ndarray:
    """(3, 3) rotation matrix of a rotation vector (3,)."""
    return cv2.Rodrigues(np.asarray(v, dtype=np.float64).reshape(3))[0]


def rotations(v: np.ndarray) -> np.ndarray:
    """(N, 3, 3) rotation matrices of rotation vectors (N, 3) (exact for small angles too)."""
    from scipy.spatial.transform import Rotation  # here: scipy costs every command 0.3 s at start

    return Rotation.from_rotvec(np.asarray(v, dtype=float).reshape(-1, 3)).as_matrix()


def rotvec(R: np.ndarray) -> np.ndarray:
    """(3,) rotation vector of a rotation matrix (3, 3), exact for small angles too.

    cv2.Rodrigues returns zero below 1e-5 rad, which would blind numeric Jacobians; below 90° the angle comes from
    atan2(sin, cos) of the skew and symmetric parts instead.
    """
    c = (np.trace(R) - 1.0) / 2.0
    if c < 0.0:  # beyond 90°: OpenCV is exact there
        return cv2.Rodrigues(np.asarray(R, dtype=np.float64))[0].reshape(3)
    v = 0.5 * np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    s = float(np.linalg.norm(v))
    return v if s < 1e-12 else v * (np.arctan2(s, c) / s)


def angle(R: np.ndarray) -> float:
    """Angle (rad) of a rotation (3, 3)."""
    return float(np.arccos(np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0)))


def rotation_angle(R_a: np.ndarray, R_b: np.ndarray) -> float:
    """Angle (rad) between two rotations (3, 3)."""
    return angle(R_a.T @ R_b)


def rotation_jacobian(R: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A rotation (3, 3) through its rotation vector, and the derivatives (3, 3, 3) of its entries with respect to
    that vector's components, dR[k] = ∂R / ∂v_k (OpenCV's analytic Rodrigues Jacobian)."""
    R_v, dR = cv2.Rodrigues(cv2.Rodrigues(np.asarray(R, dtype=np.float64))[0])
    return R_v, dR.reshape(3, 3, 3)


def rotation_jacobian_of(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The rotation (3, 3) of a rotation vector v (3,) and its derivatives (3, 3, 3), dR[k] = ∂R / ∂v_k (OpenCV's
    analytic Rodrigues Jacobian)."""
    R, dR = cv2.Rodrigues(np.asarray(v, dtype=np.float64).reshape(3))
    return R, dR.reshape(3, 3, 3)


def quaternion_rotation(q: np.ndarray) -> np.ndarray:
    """(3, 3) rotation matrix of a quaternion (4,) [w, x, y, z] (Hamilton, scalar first; normalised here). The closed
    form, as the rigs' markers were measured with."""
    w, x, y, z = np.asarray(q, dtype=float) / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def quaternions_xyzw(R: np.ndarray) -> np.ndarray:
    """(N, 4) unit quaternions x, y, z, w of rotation matrices (N, 3, 3)."""
    from scipy.spatial.transform import Rotation

    return Rotation.from_matrix(np.asarray(R, dtype=float).reshape(-1, 3, 3)).as_quat()


def nearest_rotation(R: np.ndarray) -> np.ndarray:
    """The rotation (3, 3) nearest a near-orthonormal matrix (3, 3) (polar decomposition by SVD)."""
    U, _, Vt = np.linalg.svd(np.asarray(R, dtype=float))
    return U @ Vt


def transform(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(4, 4) T from a rotation (3, 3) and a translation (3,)."""
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = t
    return T


def inverse(T: np.ndarray) -> np.ndarray:
    """(4, 4) inverse of a rigid transform: T_b_a of T_a_b."""
    out = np.eye(4)
    out[:3, :3] = T[:3, :3].T
    out[:3, 3] = -T[:3, :3].T @ T[:3, 3]
    return out


def pose_params(T: np.ndarray) -> np.ndarray:
    """(6,) rotation vector and translation of a transform (4, 4)."""
    return np.concatenate([rotvec(T[:3, :3]), T[:3, 3]])


def from_params(p: np.ndarray) -> np.ndarray:
    """(4, 4) transform of a rotation vector and translation (6,)."""
    return transform(rotation(p[:3]), p[3:])


def rt_to_T(rvec: np.ndarray, tvec: np.ndarray) -> np.ndarray:
    """(4, 4) transform of OpenCV's rvec (3,) and tvec (3,)."""
    return transform(rotation(rvec), np.asarray(tvec, dtype=np.float64).reshape(3))


def rvec_tvec(T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """OpenCV's rvec (3,) and tvec (3,) of a transform (4, 4)."""
    return cv2.Rodrigues(np.asarray(T[:3, :3], dtype=np.float64))[0].reshape(3), T[:3, 3].copy()


def pose_residual(T_measured: np.ndarray, T_predicted: np.ndarray) -> np.ndarray:
    """(6,) pose error of a measured against a predicted transform (4, 4): the rotation vector of R_m R_pᵀ, then the
    translation difference."""
    return np.concatenate([rotvec(T_measured[:3, :3] @ T_predicted[:3, :3].T),
                           T_measured[:3, 3] - T_predicted[:3, 3]])


def between(poses: list[np.ndarray]) -> np.ndarray:
    """(4, 4) the pose midway between poses (4, 4) close to each other: their mean rotation vector about the first,
    their mean translation."""
    from scipy.spatial.transform import Rotation

    R_0 = poses[0][:3, :3]
    R = Rotation.from_rotvec(np.mean([Rotation.from_matrix(P[:3, :3] @ R_0.T).as_rotvec() for P in poses], axis=0))
    return transform(R.as_matrix() @ R_0, np.mean([P[:3, 3] for P in poses], axis=0))


def numeric_jacobian(f: Callable[[np.ndarray], np.ndarray], x0: np.ndarray, step: float = JACOBIAN_STEP
                     ) -> np.ndarray:
    """(M, N) forward-difference Jacobian of f (N,) -> (M,) at x0 (N,)."""
    base = f(x0)
    J = np.empty((base.size, x0.size))
    for k in range(x0.size):
        dx = np.zeros(x0.size)
        dx[k] = step
        J[:, k] = (f(x0 + dx) - base) / step
    return J


def propagate(J: np.ndarray, covariance: np.ndarray) -> np.ndarray:
    """(M, M) covariance J C Jᵀ of a linear map J (M, N) applied to a quantity of covariance C (N, N)."""
    return J @ covariance @ J.T


def error_covariance(T: np.ndarray, covariance: np.ndarray, T_about: np.ndarray, invert: bool = False) -> np.ndarray:
    """(6, 6) covariance of the pose error (pose_residual) of T (4, 4), or of its inverse (invert), about T_about
    (4, 4), from the covariance (6, 6) of T's (rvec, tvec)."""
    def error(p: np.ndarray) -> np.ndarray:
        T_p = from_params(p)
        return pose_residual(inverse(T_p) if invert else T_p, T_about)

    return propagate(numeric_jacobian(error, pose_params(T)), covariance)


def point_covariance(T: np.ndarray, covariance: np.ndarray, point: np.ndarray) -> np.ndarray:
    """(3, 3) covariance of T's image of a point (3,), from the covariance (6, 6) of T's (rvec, tvec) (OpenCV's
    analytic Rodrigues Jacobian)."""
    _, dR = rotation_jacobian(T[:3, :3])
    J = np.hstack([np.stack([dR[k] @ point for k in range(3)], axis=1), np.eye(3)])
    return propagate(J, covariance)
