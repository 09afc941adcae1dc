import re
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


def test_a_file_without_a_size_is_read_without_one(shared_data: Path) -> None:
    """OpenCV's tutorial camera file has no image size: read as it is, sized by its camera's first frame."""
    path = shared_data / "aruco/opencv-tutorial/tutorial_camera_params.yml"
    cam = load_camera(path)
    assert not cam.sized and cam.image_size is None and cam.width is None
    assert cam.K[0, 0] == pytest.approx(628.158) and cam.size_problem(640, 480) is None
    sized, warning = cam.sized_from(640, 480, path, "tutorial.mp4")
    assert sized.image_size == (640, 480) and sized.sized and not cam.sized  # a new model; the old one unchanged
    assert warning == (f"{path}: image_width/image_height: not given; took 640x480 from the first frame of "
                       "tutorial.mp4")
    assert sized.size_problem(640, 480) is None
    assert sized.size_problem(1280, 720) == "frame is 1280x720 but the calibration is for 640x480"


@pytest.mark.parametrize("missing", ["image_width", "image_height"])
def test_a_size_half_given_names_the_other_half(tmp_path: Path, missing: str) -> None:
    text = "\n".join(line for line in GOOD.splitlines() if not line.startswith(missing))
    with pytest.raises(InputError, match=f"{missing}: missing \\(expected image_width and image_height both"):
        load_camera(_calibration(tmp_path, text))


def test_a_model_without_a_size_saves_without_one(tmp_path: Path) -> None:
    cam = CameraModel(np.array([[1000.0, 0, 460], [0, 1000, 300], [0, 0, 1]]), np.zeros(5), None, None)
    save_camera(tmp_path / "c.yaml", cam)
    assert "image_width" not in (tmp_path / "c.yaml").read_text()
    assert load_camera(tmp_path / "c.yaml").image_size is None


def test_undistort_inverts_project() -> None:
    K = np.array([[1000.0, 0, 460], [0, 1000, 300], [0, 0, 1]])
    cam = CameraModel(K, np.array([-0.2, 0.08, 0.001, -0.001, 0.0]), 920, 600)
    pts = np.array([[0.3, -0.2, 1.0], [-0.4, 0.25, 1.0]])
    px = cam.project(pts)
    ideal = cam.undistort_points(px)
    np.testing.assert_allclose(ideal, (pts[:, :2] * 1000 + [460, 300]), atol=1e-6)


# --- anything OpenCV's reader refuses, and values it would take, are one line naming the file ---------------------

GOOD = """%YAML:1.0
---
image_width: 920
image_height: 600
camera_matrix: !!opencv-matrix
   rows: 3
   cols: 3
   dt: d
   data: [ 1258.27, 0., 468.746, 0., 1259.0, 296.561, 0., 0., 1. ]
distortion_coefficients: !!opencv-matrix
   rows: 5
   cols: 1
   dt: d
   data: [ -0.1, 0.05, 0., 0., 0. ]
avg_reprojection_error: 0.2
"""


def _calibration(tmp_path: Path, text: str | bytes) -> Path:
    path = tmp_path / "cam.yaml"
    path.write_bytes(text.encode() if isinstance(text, str) else text)
    return path


def test_good_calibration_loads(tmp_path: Path) -> None:
    cam = load_camera(_calibration(tmp_path, GOOD))
    assert cam.image_size == (920, 600) and cam.dist.shape == (5,) and cam.rms == 0.2


@pytest.mark.parametrize(("content", "message"), [
    (b"", "is empty (expected a calibration file)"),
    (b"   \n", "is empty"),
    (b"\x00\x01\x02\x03", "is binary, not text"),
    (b"\xff\xfe\xfd camera_matrix", "is binary, not text"),
    (b"hello world", "not OpenCV FileStorage YAML (line 1: Only collections as YAML streams are supported"),
    (b"%YAML:1.0\nfoo: [1, 2", "not OpenCV FileStorage YAML (line 2"),
    (b"%YAML:1.0\n- 1\n- 2\n", "not a YAML mapping"),
])
def test_not_a_calibration_file(tmp_path: Path, content: bytes, message: str) -> None:
    path = _calibration(tmp_path, content)
    with pytest.raises(InputError) as info:
        load_camera(path)
    text = str(info.value)
    assert text.startswith(f"{path}: ") and message in text and len(text.splitlines()) == 1


def test_folder_and_missing_file(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="is a folder"):
        load_camera(tmp_path)
    with pytest.raises(InputError, match="calibration file not found"):
        load_camera(tmp_path / "nope.yaml")


@pytest.mark.parametrize(("old", "new", "message"), [
    ("1258.27", ".nan", "camera_matrix: holds NaN or infinity"),
    ("-0.1", ".inf", "distortion_coefficients: holds NaN or infinity"),
    ("1258.27", "-5.", "camera_matrix: expected a 3x3 matrix"),
    ("rows: 3\n   cols: 3", "rows: 1\n   cols: 9", "camera_matrix: expected a 3x3 matrix"),
    ("0., 0., 1. ]", "0., 0., 2. ]", "camera_matrix: expected a 3x3 matrix"),
    ("rows: 3\n   cols: 3", "rows: 30000\n   cols: 30000", "camera_matrix: is 30000x30000"),
    ("rows: 5\n   cols: 1", "rows: 20\n   cols: 1", "distortion_coefficients: is 20x1"),
    ("rows: 5\n   cols: 1\n   dt: d\n   data: [ -0.1, 0.05, 0., 0., 0. ]",
     "rows: 1\n   cols: 3\n   dt: d\n   data: [ -0.1, 0.05, 0. ]", "distortion_coefficients: expected a vector of 4"),
    ("rows: 5\n   cols: 1\n   dt: d\n   data: [ -0.1, 0.05, 0., 0., 0. ]",
     "rows: 2\n   cols: 2\n   dt: d\n   data: [ -0.1, 0.05, 0., 0. ]", "distortion_coefficients: expected a vector"),
    ("dt: d\n   data: [ 1258.27", "dt: q\n   data: [ 1258.27", "camera_matrix: not a readable matrix"),
    ("data: [ 1258.27, 0.,", "data: [ 0.,", "camera_matrix: not a readable matrix"),
    ("camera_matrix: !!opencv-matrix", "camera_matrix: 3\nunused: !!opencv-matrix", "camera_matrix: not a matrix"),
    ("image_width: 920", "image_width: wide", "image_width: not a number"),
    ("image_width: 920", "image_width: 0", "image_width: 0.0 is not an integer from 1"),
    ("image_height: 600", "image_height: 600.5", "image_height: 600.5 is not an integer"),
    ("image_height: 600", "image_height: 1e300", "image_height: 1e+300 is not an integer from 1 to 100000"),
    ("avg_reprojection_error: 0.2", "avg_reprojection_error: -1", "avg_reprojection_error: expected a finite"),
    ("avg_reprojection_error: 0.2", "avg_reprojection_error: .nan", "avg_reprojection_error: expected a finite"),
    ("avg_reprojection_error: 0.2", "avg_reprojection_error: low", "avg_reprojection_error: expected a finite"),
])
def test_bad_values_name_the_field(tmp_path: Path, old: str, new: str, message: str) -> None:
    assert old in GOOD
    path = _calibration(tmp_path, GOOD.replace(old, new))
    with pytest.raises(InputError) as info:
        load_camera(path)
    text = str(info.value)
    assert text.startswith(f"{path}: ") and message in text and len(text.splitlines()) == 1


def test_save_camera_is_atomic(tmp_path: Path) -> None:
    cam = CameraModel(np.array([[1000.0, 0, 460], [0, 1000, 300], [0, 0, 1]]), np.zeros(5), 920, 600)
    save_camera(tmp_path / "c.yaml", cam)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.yaml"]  # written beside, renamed when complete
    with pytest.raises(Exception):  # noqa: B017 - OpenCV's own error for a value FileStorage cannot write
        save_camera(tmp_path / "d.yaml", cam, extra={"bad": object()})  # type: ignore[dict-item]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.yaml"]  # a failure leaves nothing, not half a file


# --- a calibration without a size, on a real rig: the first frame of its camera gives it -------------------------

def _sizeless_rig(installation: Path, tmp_path: Path) -> Path:
    """The installation's rig with cam-ahead's calibration stripped of its size (as OpenCV's tutorial files are)."""
    import yaml

    text = (installation / "calibration/cam-ahead.yaml").read_text()
    (tmp_path / "sizeless.yaml").write_text("\n".join(line for line in text.splitlines()
                                                      if not line.startswith(("image_width", "image_height"))))
    rig = yaml.safe_load((installation / "rig.yaml").read_text())
    for cam in rig["cameras"]:
        cam["source"] = str(installation / cam["source"])
        cam["calibration"] = str(installation / cam["calibration"])
    rig["cameras"][0]["calibration"] = "sizeless.yaml"
    (tmp_path / "rig.yaml").write_text(yaml.safe_dump(rig))
    return tmp_path / "rig.yaml"


def test_the_first_frame_sizes_a_calibration_without_one(installation: Path, tmp_path: Path) -> None:
    import dataclasses

    from tracking.detection import DEFAULT_REFINEMENT
    from tracking.pipeline import CameraTracker, track_rig
    from tracking.rig import load_rig

    rig = load_rig(_sizeless_rig(installation, tmp_path))
    results = list(track_rig(rig))
    warned = [(r.camera, r.frame.index, w) for r in results for w in r.warnings]
    assert warned == [("cam-ahead", 0, f"{tmp_path / 'sizeless.yaml'}: image_width/image_height: not given; took "
                                       f"920x600 from the first frame of {installation / 'cam-ahead.mp4'}")]
    assert all(r.poses for r in results)  # poses as with the sized file
    tracker = CameraTracker.from_rig(rig, rig.cameras[0], DEFAULT_REFINEMENT)
    first = next(iter(results))
    assert tracker.process(first.frame).warnings and tracker.camera.image_size == (920, 600)
    small = dataclasses.replace(first.frame, gray=first.frame.gray[:480, :640])
    with pytest.raises(InputError, match="image size: frame is 640x480 but the calibration is for 920x600"):
        tracker.process(small)  # a later frame of another size is still an error


def test_track_and_detect_warn_once_for_a_calibration_without_a_size(installation: Path, tmp_path: Path) -> None:
    import subprocess
    import sys

    rig = _sizeless_rig(installation, tmp_path)
    warning = f"topside: warning: {tmp_path / 'sizeless.yaml'}: image_width/image_height: not given; took 920x600"
    track = subprocess.run([sys.executable, "-m", "tracking.cli", "track", "--rig", str(rig), "--mode", "raw", "-o",
                            str(tmp_path / "out.csv")], capture_output=True, text=True, timeout=120)
    assert track.returncode == 0, track.stderr
    assert track.stderr.count(warning) == 1
    detect = subprocess.run([sys.executable, "-m", "tracking.cli", "detect", str(installation / "cam-ahead.mp4"),
                             "--camera", str(tmp_path / "sizeless.yaml"), "--json"], capture_output=True, text=True,
                            timeout=120)
    assert detect.returncode == 0, detect.stderr
    assert detect.stderr.count("image_width/image_height: not given; took 920x600 from the first frame of") == 1
    assert '"pose"' in detect.stdout


ROS_CAMERA_INFO = """image_width: 920
image_height: 600
camera_name: stern1
camera_matrix:
  rows: 3
  cols: 3
  data: [1000.5, 0, 460.2, 0, 1001.1, 300.7, 0, 0, 1]
distortion_model: {model}
distortion_coefficients:
  rows: 1
  cols: {n}
  data: [{coefficients}]
rectification_matrix:
  rows: 3
  cols: 3
  data: [1, 0, 0, 0, 1, 0, 0, 0, 1]
projection_matrix:
  rows: 3
  cols: 4
  data: [1000.5, 0, 460.2, 0, 0, 1001.1, 300.7, 0, 0, 0, 1, 0]
"""


@pytest.mark.parametrize("model, coefficients", [("plumb_bob", [-0.1, 0.05, 0.001, -0.002, 0.0]),
                                                 ("rational_polynomial", [-0.1, 0.05, 0.001, -0.002, 0, 0.01, 0, 0])])
def test_reads_ros_camera_info(tmp_path: Path, model: str, coefficients: list[float]) -> None:
    """ROS's camera_calibration writes its matrices without OpenCV's tag (rows, cols, data) and names the model."""
    path = tmp_path / "ost.yaml"
    path.write_text(ROS_CAMERA_INFO.format(model=model, n=len(coefficients),
                                           coefficients=", ".join(map(str, coefficients))))
    cam = load_camera(path)
    np.testing.assert_array_equal(cam.K, [[1000.5, 0, 460.2], [0, 1001.1, 300.7], [0, 0, 1]])
    np.testing.assert_array_equal(cam.dist, coefficients)
    assert cam.image_size == (920, 600) and cam.rms is None  # ROS states no error: `check` says so


@pytest.mark.parametrize("model, data, message", [
    ("equidistant", "-0.1, 0.05, 0.001, -0.002", "distortion_model: equidistant: the tracker models a pinhole lens"),
    ("plumb_bob", "-0.1, 0.05, 0.001, -0.002", "distortion_coefficients: data: expected 5 numbers (1x5), got 4"),
    ("plumb_bob", "-0.1, 0.05, 0.001, -0.002, k3", "distortion_coefficients: data: item 5 is not a number")])
def test_a_ros_camera_info_the_tracker_cannot_use_is_named(tmp_path: Path, model: str, data: str,
                                                          message: str) -> None:
    path = tmp_path / "ost.yaml"
    path.write_text(ROS_CAMERA_INFO.format(model=model, n=5, coefficients=data))
    with pytest.raises(InputError, match=re.escape(message)):
        load_camera(path)


def test_a_calibration_that_states_no_error_is_taken_at_the_top_of_a_sound_ones() -> None:
    from tracking.camera import UNSTATED_RMS_PX

    K = np.array([[1000.0, 0, 460], [0, 1000, 300], [0, 0, 1]])
    assert CameraModel(K, np.zeros(5), 920, 600).model_px == UNSTATED_RMS_PX == 0.5
    assert CameraModel(K, np.zeros(5), 920, 600, rms=0.0).model_px == 0.0  # stated: exact (the simulator's)
    assert CameraModel(K, np.zeros(5), 920, 600, rms=0.31).model_px == 0.31
