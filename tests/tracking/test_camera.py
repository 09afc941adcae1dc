from pathlib import Path

import numpy as np
import pytest

from tracking.camera import CameraModel, load_camera, save_camera
from tracking.errors import InputError


def test_reads_opencv_sample_output(shared_data: Path) -> None:
    cam = load_camera(shared_data / "calibration/opencv-left/left_intrinsics.yml")
    assert cam.image_size == (640, 480)
    assert cam.K[0, 0] == pytest.approx(535.91573396, abs=1e-6)
    assert cam.dist.shape == (5,)
    assert cam.rms == pytest.approx(0.39259, abs=1e-5)


def test_round_trip(tmp_path: Path) -> None:
    K = np.array([[1258.27, 0, 468.746], [0, 1259.0, 296.561], [0, 0, 1]])
    cam = CameraModel(K, np.array([-0.1, 0.05, 0, 0, 0, 0.01, 0, 0]), 920, 600, rms=0.02)
    save_camera(tmp_path / "c.yaml", cam)
    back = load_camera(tmp_path / "c.yaml")
    np.testing.assert_allclose(back.K, K)
    np.testing.assert_allclose(back.dist, cam.dist)
    assert (back.width, back.height, back.rms) == (920, 600, 0.02)


def test_missing_field_names_it(shared_data: Path) -> None:
    # OpenCV's tutorial camera file has no image size
    with pytest.raises(InputError, match="image_width: missing"):
        load_camera(shared_data / "aruco/opencv-tutorial/tutorial_camera_params.yml")


def test_undistort_inverts_project() -> None:
    K = np.array([[1000.0, 0, 460], [0, 1000, 300], [0, 0, 1]])
    cam = CameraModel(K, np.array([-0.2, 0.08, 0.001, -0.001, 0.0]), 920, 600)
    pts = np.array([[0.3, -0.2, 1.0], [-0.4, 0.25, 1.0]])
    px = cam.project(pts)
    ideal = cam.undistort_points(px)
    np.testing.assert_allclose(ideal, (pts[:, :2] * 1000 + [460, 300]), atol=1e-6)
