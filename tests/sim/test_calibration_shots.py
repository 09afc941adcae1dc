"""Calibration shots: OpenCV's chessboard calibration recovers the true camera (paper experiment 1)."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import yaml

from tracking.camera import load_camera
from tracking.sim.builtins import builtin_scenario
from tracking.sim.calibration_shots import write_calibration_shots

K_TOLERANCE = 0.005
RMS_LIMIT = 0.1
SUBPIX_CRITERIA = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 100, 1e-4)


def test_chessboard_calibration_recovers_k(tmp_path: Path) -> None:
    sc = builtin_scenario("calibration-shots")
    shots = write_calibration_shots(sc, tmp_path, quiet=True)
    assert len(shots) == 30
    board = yaml.safe_load((tmp_path / "calibration_shots" / "board.yaml").read_text())
    assert board["board"] == "chessboard:9x6:0.25"
    cols, rows = board["inner_corners"]
    obj = np.zeros((cols * rows, 3), np.float32)
    obj[:, :2] = np.mgrid[0:cols, 0:rows].T.reshape(-1, 2) * board["square"]
    objs, imgs = [], []
    for path in shots:
        gray = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
        found, corners = cv2.findChessboardCorners(gray, (cols, rows))
        assert found, path
        imgs.append(cv2.cornerSubPix(gray, corners, (5, 5), (-1, -1), SUBPIX_CRITERIA))
        objs.append(obj)
    truth = load_camera(tmp_path / "calibration" / "camera.yaml")
    rms, K, _, _, _ = cv2.calibrateCamera(objs, imgs, truth.image_size, None, None)
    assert rms < RMS_LIMIT
    for i, j in ((0, 0), (1, 1), (0, 2), (1, 2)):
        assert abs(K[i, j] / truth.K[i, j] - 1) < K_TOLERANCE, (i, j, K[i, j], truth.K[i, j])
