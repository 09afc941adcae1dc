"""Published results on real photos (see ../shared/data/README.md)."""

from pathlib import Path

import numpy as np
import pytest

from tracking.calibration import BoardView, calibrate, parse_board
from tracking.errors import InputError

PUBLISHED_K = np.array([[532.80992189, 0, 342.4952186], [0, 532.93346422, 233.8879292], [0, 0, 1]])
PUBLISHED_DIST = np.array([-0.281325576, 0.0291130406, 0.0012123433, -0.000140825372, 0.154865844])


@pytest.fixture(scope="module")
def left_photos(shared_data: Path) -> list[Path]:
    return sorted((shared_data / "calibration/opencv-left").glob("left*.jpg"))


def test_opencv_test_calibration_flags_0(left_photos: list[Path]) -> None:
    r = calibrate(left_photos, parse_board("chessboard:9x6:0.025"))
    assert r.rms == pytest.approx(0.196334638, abs=0.01)
    assert np.abs(r.camera.K - PUBLISHED_K).sum() < 10
    assert np.abs(r.camera.dist - PUBLISHED_DIST).sum() < 0.05
    assert len(r.per_view_rms) == 13 and not r.missed
    assert set(r.std_intrinsics) >= {"fx", "fy", "cx", "cy", "k1"}


def test_calibration_sample_fix_aspect(left_photos: list[Path]) -> None:
    # OpenCV's samples/cpp/calibration.cpp refines with half-size 11 (23x23), which gives left_intrinsics.yml
    r = calibrate(left_photos, parse_board("chessboard:9x6:0.025"), fix_aspect=True, subpix_window=11)
    assert r.camera.K[0, 0] == r.camera.K[1, 1]
    assert r.camera.K[0, 0] == pytest.approx(535.9, abs=2)
    assert r.rms == pytest.approx(0.39, abs=0.03)


def test_charuco_tutorial(shared_data: Path) -> None:
    photos = sorted((shared_data / "aruco/opencv-tutorial").glob("img_0*.jpg"))
    r = calibrate(photos, parse_board("charuco:5x7:0.04:0.02:DICT_6X6_250"))
    assert r.rms == pytest.approx(0.19, abs=0.03)
    assert 430 < r.camera.K[0, 0] < 500  # four views pin f poorly (README): compare loosely
    assert r.coverage < 0.6  # the board covered part of the image only: the CLI warns


def test_too_few_views_refused(shared_data: Path) -> None:
    photos = sorted((shared_data / "aruco/opencv-tutorial").glob("img_0*.jpg"))
    with pytest.raises(InputError, match="board found in 0 of 4 photos; need at least 3"):
        calibrate(photos, parse_board("chessboard:9x6:0.025"))


@pytest.mark.parametrize("text", ["chessboard:9:0.025", "charuco:5x7:0.04:0.02:DICT_NOPE", "square:3x3:1"])
def test_bad_board(text: str) -> None:
    with pytest.raises(InputError, match="--board"):
        parse_board(text)


def _view(name: str, shift_px: tuple[float, float], tilt: float = 0.0) -> BoardView:
    """A 9x6 chessboard's corners as a camera at 800 px focal length sees it 1 m away, turned by tilt (rad) about the
    board's x axis and moved by shift_px in the image."""
    from tracking.calibration import BoardView

    board = parse_board("chessboard:9x6:0.025")
    obj = board.object_points().astype(float)
    c, s = np.cos(tilt), np.sin(tilt)
    p = obj @ np.array([[1, 0, 0], [0, c, s], [0, -s, c]]) + [-0.1, -0.06, 1.0]
    img = 800 * p[:, :2] / p[:, 2:] + np.array([320.0, 240.0]) + shift_px
    return BoardView(Path(name), img.astype(np.float32), board.object_points())


def test_views_of_one_pose_are_told_apart_from_distinct_ones() -> None:
    """A photo re-taken from a tripod (0.3 px off), the same photo twice: one pose; the board moved 40 px or tilted
    20°: another each."""
    from tracking.calibration import distinct_poses

    views = [_view("a", (0, 0)), _view("b", (0.3, 0.2)), _view("c", (40, 0)), _view("a-again", (0, 0)),
             _view("d", (0, 0), tilt=np.radians(20))]
    assert distinct_poses(views) == [[0, 1, 3], [2], [4]]
