"""Published results on real photos (see ../shared/data/README.md)."""

from pathlib import Path

import numpy as np
import pytest

from tracking.calibration import COVERAGE_WARN, BoardView, calibrate, parse_board
from tracking.camera import UNSTATED_RMS_PX
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
    assert r.coverage >= COVERAGE_WARN and r.camera.rms == r.rms  # the board over the picture: its fit is stated


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
    assert r.coverage < COVERAGE_WARN  # the board covered part of the image only: the CLI warns, and the file states
    assert r.camera.rms == UNSTATED_RMS_PX  # the lens model's error as one that states none, not the fit's 0.19 px


CALISCOPE_BOARD = "charuco:4x5:0.054:0.0405:DICT_4X4_1000"  # caliscope's charuco.toml: printed white on black
CALISCOPE_FX = 903.550124089999  # its camera_array.toml's cam_0, from its own intrinsic footage


def test_a_video_of_the_board_calibrates_its_camera(shared_data: Path) -> None:
    """caliscope's cam_0 filming its hand-held board (111 frames, the markers white on black): the frames that show
    the board give at most VIDEO_VIEWS views spread over its poses, named by frame; f within 3 % of caliscope's own
    calibration of that webcam (the board fills a third of the picture, so the distortion is loose: compare f)."""
    from tracking.calibration import VIDEO_VIEWS

    video = shared_data / "caliscope/charuco_calibration/calibration/extrinsic/cam_0.mp4"
    r = calibrate([video], parse_board(CALISCOPE_BOARD), inverted=True)
    assert 10 <= len(r.per_view_rms) <= VIDEO_VIEWS
    assert all(name.startswith("cam_0.mp4#") for name in r.per_view_rms) and not r.repeated
    assert r.rms < 0.3 and r.camera.rms == UNSTATED_RMS_PX  # the board over 28 % of the picture
    assert r.camera.K[0, 0] == pytest.approx(CALISCOPE_FX, rel=0.03)
    assert (r.camera.width, r.camera.height) == (1280, 720)
    with pytest.raises(InputError, match="need --inverted"):  # read as black on white, it finds no board
        calibrate([video], parse_board(CALISCOPE_BOARD))


def test_a_board_held_still_is_one_view_of_a_video() -> None:
    """Of fifty frames of one pose and three others, the spread views are one of the fifty and the three, in order."""
    from tracking.calibration import spread_views

    still = [_view(f"v#{k}", (0.01 * k, 0.0)) for k in range(50)]
    moved = [_view("v#60", (60, 0)), _view("v#70", (0, 45)), _view("v#80", (0, 0), tilt=np.radians(20))]
    names = [v.path.name for v in spread_views(still + moved, 40)]
    assert len(names) == 4 and names[1:] == ["v#60", "v#70", "v#80"] and names[0].startswith("v#")
    assert len(spread_views(still + moved, 2)) == 2


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


def test_a_video_of_a_board_held_still_is_refused_as_one_pose(tmp_path: Path) -> None:
    """Two seconds of a chessboard that does not move (real H.264 encode and decode): one view, and the error says to
    move the board while filming, not that no board was found."""
    import av

    square = 40
    board = np.kron((np.indices((7, 10)).sum(axis=0) % 2) * 255, np.ones((square, square))).astype(np.uint8)
    picture = np.full((480, 640), 255, np.uint8)
    picture[100:100 + board.shape[0], 120:120 + board.shape[1]] = board
    video = tmp_path / "still.mp4"
    with av.open(str(video), "w") as out:
        stream = out.add_stream("libx264", rate=15)
        stream.width, stream.height, stream.pix_fmt = 640, 480, "yuv420p"
        for _ in range(30):
            out.mux(stream.encode(av.VideoFrame.from_ndarray(np.dstack([picture] * 3), format="rgb24")))
        out.mux(stream.encode())
    with pytest.raises(InputError, match=r"the board is in 1 view but at only 1 distinct pose.*while filming"):
        calibrate([video], parse_board("chessboard:9x6:0.025"))


def test_a_video_frame_far_off_the_others_is_left_out_and_the_camera_fitted_again(tmp_path: Path) -> None:
    """A chessboard filmed at eight poses (a real H.264 encode, nearly lossless), one frame of them warped by a ripple
    no lens makes (a misread frame): that frame is dropped, named with its RMS, and the fit is left at the others'."""
    import av
    import cv2

    square, K = 30, np.array([[700.0, 0, 320], [0, 700.0, 240], [0, 0, 1]])
    flat = np.kron((np.indices((7, 10)).sum(axis=0) % 2) * 255, np.ones((square, square))).astype(np.uint8)
    flat = cv2.copyMakeBorder(flat, square, square, square, square, cv2.BORDER_CONSTANT, value=255)
    h, w = flat.shape
    video = tmp_path / "board.mp4"
    with av.open(str(video), "w") as out:
        stream = out.add_stream("libx264", rate=5, options={"crf": "2"})
        stream.width, stream.height, stream.pix_fmt = 640, 480, "yuv420p"
        for k in range(8):
            tilt = np.radians([(-1) ** k * 25, (k - 4) * 6, k * 4])
            R, _ = cv2.Rodrigues(tilt)
            corners = np.array([[0, 0, 0], [w, 0, 0], [w, h, 0], [0, h, 0]], float) - [w / 2, h / 2, 0]
            image = (K @ (R @ (corners * 0.0012).T + [[0], [0], [0.75]])).T
            H = cv2.getPerspectiveTransform(np.float32([[0, 0], [w, 0], [w, h], [0, h]]),
                                            np.float32(image[:, :2] / image[:, 2:]))
            picture = cv2.warpPerspective(flat, H, (640, 480), borderValue=255)
            if k == 5:  # the misread frame: a ripple of 4 px across the picture
                ys, xs = np.mgrid[0:480, 0:640].astype(np.float32)
                picture = cv2.remap(picture, xs + 4 * np.sin(ys / 25), ys, cv2.INTER_LINEAR, borderValue=255)
            frame = av.VideoFrame.from_ndarray(np.dstack([picture] * 3), format="rgb24")
            out.mux(stream.encode(frame))
        out.mux(stream.encode())
    r = calibrate([video], parse_board("chessboard:9x6:0.03"))
    assert list(r.far_off) == ["board.mp4#5"] and r.far_off["board.mp4#5"] > 3 * r.rms and r.refitted
    assert "board.mp4#5" not in r.per_view_rms and len(r.per_view_rms) == 7 and r.rms < 0.3
