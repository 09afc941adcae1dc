"""Camera model: intrinsics K, distortion and image size, stored as OpenCV FileStorage YAML.

The file layout is the one OpenCV's calibration sample writes (`camera_matrix`,
`distortion_coefficients`, `image_width`, `image_height`, `avg_reprojection_error`), so files
from OpenCV, from `topside calibrate` and from the simulator are interchangeable.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from tracking.errors import InputError

DISTORTION_SIZES = (4, 5, 8, 12, 14)
UNDISTORT_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-10)


@dataclass(frozen=True)
class CameraModel:
    """Pinhole intrinsics with OpenCV distortion for one camera."""

    K: np.ndarray  # (3, 3) camera matrix
    dist: np.ndarray  # (N,) distortion k1 k2 p1 p2 [k3 [k4 k5 k6 ...]]
    width: int
    height: int
    rms: float | None = None  # average reprojection error of the calibration, px
    extra: dict[str, float] = field(default_factory=dict)  # other scalars kept from the file

    @property
    def image_size(self) -> tuple[int, int]:
        """(width, height) in pixels."""
        return (self.width, self.height)

    def undistort_points(self, pixels: np.ndarray) -> np.ndarray:
        """Distorted pixels (N, 2) to ideal pixels (N, 2) of the same K with no distortion."""
        pts = np.asarray(pixels, dtype=np.float64).reshape(-1, 1, 2)
        out = cv2.undistortPoints(pts, self.K, self.dist, P=self.K, criteria=UNDISTORT_CRITERIA)
        return out.reshape(-1, 2)

    def project(self, points_cam: np.ndarray) -> np.ndarray:
        """Points in camera coordinates (N, 3) to distorted pixels (N, 2)."""
        pts = np.asarray(points_cam, dtype=np.float64).reshape(-1, 3)
        px, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), self.K, self.dist)
        return px.reshape(-1, 2)


def _read_matrix(fs: cv2.FileStorage, path: Path, key: str, required: bool = True) -> np.ndarray | None:
    node = fs.getNode(key)
    if node.empty() or node.isNone():
        if required:
            raise InputError(path, "missing (expected an OpenCV matrix)", key)
        return None
    mat = node.mat()
    if mat is None:
        raise InputError(path, "not an OpenCV matrix (expected !!opencv-matrix)", key)
    return np.asarray(mat, dtype=np.float64)


def _read_int(fs: cv2.FileStorage, path: Path, key: str) -> int:
    node = fs.getNode(key)
    if node.empty() or node.isNone():
        raise InputError(path, "missing (expected an integer number of pixels)", key)
    value = node.real()
    if value <= 0 or value != int(value):
        raise InputError(path, f"{value!r} is not a positive integer", key)
    return int(value)


def load_camera(path: str | Path) -> CameraModel:
    """Read a camera model from an OpenCV FileStorage YAML file."""
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "calibration file not found")
    try:
        fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ | cv2.FILE_STORAGE_FORMAT_YAML)
    except cv2.error as exc:
        raise InputError(path, f"not an OpenCV FileStorage YAML file ({exc.err.strip()})") from None
    if not fs.isOpened():
        raise InputError(path, "not an OpenCV FileStorage YAML file")
    try:
        K = _read_matrix(fs, path, "camera_matrix")
        dist = _read_matrix(fs, path, "distortion_coefficients")
        width = _read_int(fs, path, "image_width")
        height = _read_int(fs, path, "image_height")
        rms_node = fs.getNode("avg_reprojection_error")
        rms = None if rms_node.empty() or rms_node.isNone() else float(rms_node.real())
    finally:
        fs.release()
    assert K is not None and dist is not None
    if K.shape != (3, 3) or K[0, 0] <= 0 or K[1, 1] <= 0 or K[2, 2] != 1.0:
        raise InputError(path, f"expected a 3x3 matrix with fx, fy > 0 and K[2,2] = 1, got {K.tolist()}",
                         "camera_matrix")
    dist = dist.reshape(-1)
    if dist.size not in DISTORTION_SIZES:
        raise InputError(path, f"expected 4, 5, 8, 12 or 14 coefficients, got {dist.size}",
                         "distortion_coefficients")
    return CameraModel(K=K, dist=dist, width=width, height=height, rms=rms)


def save_camera(path: str | Path, camera: CameraModel, extra: dict[str, float | int | str] | None = None) -> None:
    """Write a camera model as OpenCV's calibration sample does (FileStorage YAML)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE | cv2.FILE_STORAGE_FORMAT_YAML)
    fs.write("image_width", int(camera.width))
    fs.write("image_height", int(camera.height))
    fs.write("camera_matrix", np.asarray(camera.K, dtype=np.float64))
    fs.write("distortion_coefficients", np.asarray(camera.dist, dtype=np.float64).reshape(-1, 1))
    if camera.rms is not None:
        fs.write("avg_reprojection_error", float(camera.rms))
    for key, value in (extra or {}).items():
        if isinstance(value, np.ndarray):
            fs.write(key, value)
        else:
            fs.write(key, value)
    fs.release()
