"""Camera model: intrinsics K, distortion and image size, stored as OpenCV FileStorage YAML.

The file layout is the one OpenCV's calibration sample writes (`camera_matrix`,
`distortion_coefficients`, `image_width`, `image_height`, `avg_reprojection_error`), so files
from OpenCV, from `topside calibrate` and from the simulator are interchangeable.

ROS's camera_info YAML (camera_calibration's `ost.yaml`: the same keys, each matrix as rows, cols and data without
OpenCV's tag, and a `distortion_model`) is read too; a distortion model other than the pinhole's (plumb_bob,
rational_polynomial) is refused, since the tracker does not model it.

A file without `image_width` and `image_height` (OpenCV's tutorial files ship so) is read too: its model has no size
until the first frame of its camera gives one (CameraModel.sized_from), with one warning line naming the file and the
size taken; a later frame of another size is still an error. Undistortion and poses use only K and the distortion.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field, replace
from pathlib import Path

import cv2
import numpy as np

from tracking.errors import InputError, a_or_an, one_line, read_text
from tracking.outputs import atomic_path

DISTORTION_SIZES = (4, 5, 8, 12, 14)
MAX_IMAGE_SIDE_PX = 100_000  # beyond any sensor: a bigger image_width is a typo
MAX_FOCAL_PX = 1e7  # beyond any lens on any sensor; keeps every projection finite
RMS_KEY = "avg_reprojection_error"
UNSTATED_RMS_PX = 0.5  # the lens model error taken for a calibration that states none: the top of what a sound
# calibration leaves (0.1-0.5 px); the real webcams' calibrations state 0.33-0.54 px, and without it their σ held
# 51-79 % of the errors within 2σ on some axis (docs/accuracy.md#real-footage)
PINHOLE_MODELS = ("plumb_bob", "rational_polynomial")  # ROS camera_info's names for the models OpenCV's coefficients
# hold (5 and 8 of them); "equidistant" (fisheye) and others are not modelled
# what OpenCV's reader raises: its cv2.error, the SystemError its binding wraps that in, and UnicodeDecodeError for a
# string it unescaped into invalid UTF-8 ("\\é" drops the é's first byte)
OPENCV_READ_ERRORS = (cv2.error, SystemError, UnicodeDecodeError)
# "error: (-212:Parsing error) parse in function 'file(3): Missing , ...'": the parser's line and complaint, or
# "error: (-215:Assertion failed) nelems == m.total() in function 'read'": the kind of failure and its condition
OPENCV_ERROR = re.compile(r"error: \(-?\d+:(?P<kind>[^)]*)\) (?P<what>.*?) in function "
                          r"'(?:[^']*?\((?P<line>\d+)\): (?P<message>.*))?[^']*'\s*$")
UNDISTORT_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-10)


@dataclass(frozen=True)
class CameraModel:
    """Pinhole intrinsics with OpenCV distortion for one camera."""

    K: np.ndarray  # (3, 3) camera matrix
    dist: np.ndarray  # (N,) distortion k1 k2 p1 p2 [k3 [k4 k5 k6 ...]]
    width: int | None  # px; None: the file gives no size, the first frame will (sized_from)
    height: int | None
    rms: float | None = None  # average reprojection error of the calibration, px
    extra: dict[str, float] = field(default_factory=dict)  # other scalars kept from the file

    @property
    def model_px(self) -> float:
        """The lens model's RMS error the tracker takes, px: the stated rms, else UNSTATED_RMS_PX."""
        return self.rms if self.rms is not None else UNSTATED_RMS_PX

    @property
    def sized(self) -> bool:
        """True when the image size is known (from the file, or from a first frame)."""
        return self.width is not None and self.height is not None

    @property
    def image_size(self) -> tuple[int, int] | None:
        """(width, height) in pixels; None until a frame gives a size the file did not."""
        return (self.width, self.height) if self.width is not None and self.height is not None else None

    def sized_from(self, width: int, height: int, path: str | Path, source: str | Path) -> tuple[CameraModel, str]:
        """This model with the size of its camera's first frame, and the warning line that says so (path: the
        calibration file, source: the camera's source)."""
        warning = (f"{path}: image_width/image_height: not given; took {width}x{height} from the first frame of "
                   f"{source}")
        return replace(self, width=int(width), height=int(height)), warning

    def size_problem(self, width: int, height: int) -> str | None:
        """Why a frame of width x height does not fit this model, or None when it does (or the size is unknown)."""
        if not self.sized or (width, height) == self.image_size:
            return None
        return f"frame is {width}x{height} but the calibration is for {self.width}x{self.height}"

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


def opencv_reason(exc: BaseException) -> str:
    """The useful part of an OpenCV error, one line: "line 3: Missing , between the elements" or the assertion."""
    cause = exc if isinstance(exc, cv2.error) else (exc.__cause__ or exc.__context__ or exc)
    text = one_line(str(cause))
    found = OPENCV_ERROR.search(text)
    if not found:
        return text
    if found.group("line"):
        return f"line {found.group('line')}: {found.group('message')}"
    return f"{found.group('kind').lower()}: {found.group('what')}"


def open_storage(path: Path, what: str, fmt: int = cv2.FILE_STORAGE_FORMAT_YAML) -> cv2.FileStorage:
    """An open OpenCV FileStorage of a small text file; a one-line InputError naming the file for anything its
    reader refuses (missing, folder, unreadable, empty, binary, too large, not YAML). what: e.g. "calibration file"."""
    text = read_text(path, what)
    try:  # from memory: the file is read once, and its name (.gz, .json) cannot change how it is parsed
        fs = cv2.FileStorage(text, cv2.FILE_STORAGE_READ | cv2.FILE_STORAGE_MEMORY | fmt)
    except OPENCV_READ_ERRORS as exc:
        reason = opencv_reason(exc)
        raise InputError(path, f"not OpenCV FileStorage YAML ({reason}); expected {a_or_an(what)}") from None
    if not fs.isOpened():
        raise InputError(path, f"not OpenCV FileStorage YAML (expected {a_or_an(what)})")
    if not fs.root().isMap():
        fs.release()
        raise InputError(path, f"not a YAML mapping (expected {a_or_an(what)})")
    return fs


def present(node: cv2.FileNode) -> bool:
    """True when a FileStorage node exists and holds something."""
    return not (node.empty() or node.isNone())


def read_integer(fs: cv2.FileStorage, path: Path, key: str, low: int, high: int, what: str) -> int:
    """An integer field in [low, high]; a one-line InputError naming the field otherwise. what: its unit, for the
    message ("an integer number of pixels")."""
    node = fs.getNode(key)
    if not present(node):
        raise InputError(path, f"missing (expected {what})", key)
    if not (node.isInt() or node.isReal()):  # real() of a string or a mapping is DBL_MAX, not an error
        raise InputError(path, f"not a number (expected {what})", key)
    value = node.real()
    if not np.isfinite(value) or value != int(value) or not low <= value <= high:
        raise InputError(path, f"{value!r} is not an integer from {low} to {high} (expected {what})", key)
    return int(value)


def _read_matrix(fs: cv2.FileStorage, path: Path, key: str, max_elements: int) -> np.ndarray | None:
    """A !!opencv-matrix field as float64, None when absent; its size is checked before OpenCV allocates it."""
    node = fs.getNode(key)
    if not present(node):
        return None
    expected = f"expected an !!opencv-matrix of at most {max_elements} numbers"
    if not node.isMap():
        raise InputError(path, f"not a matrix ({expected})", key)
    sizes = [node.getNode(part) for part in ("rows", "cols")]
    if not all(present(n) and n.isInt() for n in sizes) or not node.getNode("data").isSeq():
        raise InputError(path, f"not a matrix: needs rows, cols and data ({expected})", key)
    rows, cols = (int(n.real()) for n in sizes)
    if rows <= 0 or cols <= 0 or rows * cols > max_elements:
        raise InputError(path, f"is {rows}x{cols} ({expected})", key)
    if not present(node.getNode("dt")):  # ROS camera_info: rows, cols and data, no element type
        values = _untyped_matrix(node.getNode("data"), rows, cols, path, key)
    else:
        try:
            mat = node.mat()
        except OPENCV_READ_ERRORS as exc:
            raise InputError(path, f"not a readable matrix ({opencv_reason(exc)}); {expected}", key) from None
        if mat is None:
            raise InputError(path, f"not a matrix ({expected})", key)
        values = np.asarray(mat, dtype=np.float64)
    if not np.isfinite(values).all():
        raise InputError(path, "holds NaN or infinity (expected finite numbers)", key)
    return values


def _untyped_matrix(data: cv2.FileNode, rows: int, cols: int, path: Path, key: str) -> np.ndarray:
    """(rows, cols) float64 from a sequence of rows x cols numbers (a matrix without OpenCV's dt, as ROS writes it)."""
    items = [data.at(i) for i in range(data.size())]
    if len(items) != rows * cols:
        raise InputError(path, f"data: expected {rows * cols} numbers ({rows}x{cols}), got {len(items)} items", key)
    bad = next((i for i, n in enumerate(items) if not (n.isInt() or n.isReal())), None)
    if bad is not None:
        raise InputError(path, f"data: item {bad + 1} is not a number (expected {rows * cols} numbers)", key)
    return np.array([n.real() for n in items], dtype=np.float64).reshape(rows, cols)


def _check_distortion_model(fs: cv2.FileStorage, path: Path) -> None:
    """ROS camera_info's distortion_model, where given: one whose coefficients OpenCV's pinhole model holds."""
    node = fs.getNode("distortion_model")
    if not present(node):
        return
    model = node.string() if node.isString() else ""
    if model not in PINHOLE_MODELS:
        raise InputError(path, f"{model or 'not a name'}: the tracker models a pinhole lens with OpenCV's "
                               f"coefficients (expected {' or '.join(PINHOLE_MODELS)}; calibrate a fisheye lens "
                               "with them, or undistort its video first)", "distortion_model")


def load_camera(path: str | Path) -> CameraModel:
    """Read a camera model from an OpenCV FileStorage YAML file (or ROS camera_info YAML); a one-line InputError
    for anything else."""
    path = Path(path)
    fs = open_storage(path, "calibration file")
    try:
        _check_distortion_model(fs, path)
        K = _read_matrix(fs, path, "camera_matrix", 9)
        if K is None:
            raise InputError(path, "missing (expected an OpenCV matrix)", "camera_matrix")
        dist = _read_matrix(fs, path, "distortion_coefficients", max(DISTORTION_SIZES))
        if dist is None:
            raise InputError(path, "missing (expected an OpenCV matrix)", "distortion_coefficients")
        sizes = [present(fs.getNode(key)) for key in ("image_width", "image_height")]
        if sizes[0] != sizes[1]:  # one without the other is a damaged file, not OpenCV's tutorial's
            missing = "image_height" if sizes[0] else "image_width"
            raise InputError(path, "missing (expected image_width and image_height both, or neither: then the first "
                                   "frame gives the size)", missing)
        width = height = None
        if all(sizes):
            width = read_integer(fs, path, "image_width", 1, MAX_IMAGE_SIDE_PX, "an integer number of pixels")
            height = read_integer(fs, path, "image_height", 1, MAX_IMAGE_SIDE_PX, "an integer number of pixels")
        rms = _read_rms(fs, path)
    finally:
        fs.release()
    if K.shape != (3, 3) or not (0 < K[0, 0] <= MAX_FOCAL_PX and 0 < K[1, 1] <= MAX_FOCAL_PX) \
            or K[2].tolist() != [0, 0, 1] or K[1, 0] != 0:
        raise InputError(path, f"expected a 3x3 matrix [[fx, s, cx], [0, fy, cy], [0, 0, 1]] with 0 < fx, fy <= "
                               f"{MAX_FOCAL_PX:g}, got {K.tolist()}", "camera_matrix")
    if min(dist.shape) != 1 or dist.size not in DISTORTION_SIZES:
        shape = "x".join(map(str, dist.shape))
        raise InputError(path, f"expected a vector of 4, 5, 8, 12 or 14 coefficients, got a {shape} matrix",
                         "distortion_coefficients")
    return CameraModel(K=K, dist=dist.reshape(-1), width=width, height=height, rms=rms)


def _read_rms(fs: cv2.FileStorage, path: Path) -> float | None:
    """The optional avg_reprojection_error, px: a finite number >= 0."""
    node = fs.getNode(RMS_KEY)
    if not present(node):
        return None
    value = node.real() if node.isInt() or node.isReal() else float("nan")
    if not (np.isfinite(value) and value >= 0):
        raise InputError(path, "expected a finite number of pixels >= 0", RMS_KEY)
    return float(value)


def save_camera(path: str | Path, camera: CameraModel, extra: dict[str, float | int | str] | None = None) -> None:
    """Write a camera model as OpenCV's calibration sample does (FileStorage YAML), atomically: the file appears
    complete under its name or not at all (without a size when the model has none)."""
    with atomic_path(Path(path)) as partial:  # <stem>.partial.yaml: keeps the suffix OpenCV may look at
        fs = cv2.FileStorage(str(partial), cv2.FILE_STORAGE_WRITE | cv2.FILE_STORAGE_FORMAT_YAML)
        try:
            if camera.width is not None and camera.height is not None:
                fs.write("image_width", int(camera.width))
                fs.write("image_height", int(camera.height))
            fs.write("camera_matrix", np.asarray(camera.K, dtype=np.float64))
            fs.write("distortion_coefficients", np.asarray(camera.dist, dtype=np.float64).reshape(-1, 1))
            if camera.rms is not None:
                fs.write(RMS_KEY, float(camera.rms))
            for key, value in (extra or {}).items():
                fs.write(key, value)
        finally:
            fs.release()
