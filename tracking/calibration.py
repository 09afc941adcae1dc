"""Camera calibration from photos or videos of a chessboard or ChArUco board (OpenCV's calibrateCamera).

A video gives a view in every frame that shows the board; of those, at most VIDEO_VIEWS spread over the board's poses
are used (farthest first: a board held still for seconds is one view, not a hundred)."""

from __future__ import annotations

import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from tracking.camera import UNSTATED_RMS_PX, CameraModel
from tracking.errors import InputError
from tracking.images import frames, is_image, read_gray

MIN_VIEWS = 3
MIN_CHARUCO_CORNERS = 6
SUBPIX_WINDOW = 5  # half-size, px, as OpenCV's own calibration test; its calibration.cpp sample uses 11
SUBPIX_CRITERIA = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 0.1)
COVERAGE_GRID = 5  # the image is split into COVERAGE_GRID² cells to judge how much the board covered
COVERAGE_WARN = 0.6  # warn below this share of cells holding a corner; below it the file states the lens model's
# error as at least UNSTATED_RMS_PX: a fit to part of the picture does not vouch for the model's error (caliscope's
# webcams calibrated from their own footage of the board, which covered 12-28 % of the picture, fit to 0.12-0.24 px,
# and the tracker trusting that held 70 % of one session's Δz within 2σ and 15.5 % beyond 3σ; at 0.5 px, all)
# Two views are one pose when the board's shared corners moved on average by less than this share of the board's
# extent in the image (its bounding box's diagonal): the same photo given twice moves nothing, one re-taken from a
# tripod a fraction of a pixel; a board tilted by 20° (what tells calibrateCamera the focal length) moves them by 2 %
# of its extent, moved across the picture by tens of percent.
SAME_POSE_SHARE = 0.005
MIN_SHARED_CORNERS = 4  # fewer shared corners (ChArUco views of different parts of the board): distinct views
VIDEO_VIEWS = 40  # views taken from one video at most: calibrateCamera's cost grows with them, and 40 poses spread
# over a video pin a pinhole and five distortion terms (OpenCV's samples use 10-25 photos)
OUTLIER_VIEW_FACTOR = 3.0  # a video frame's view whose RMS exceeds this many times the median view's, and the median
OUTLIER_VIEW_MARGIN_PX = 0.25  # by this much (a steep view of clean footage, 0.16 px at a 0.05 px median, is no
# outlier), is dropped and the camera fitted again: a blurred or misread frame no one can take out of a video by hand
VIDEO_SCAN_HZ = 10.0  # a video's frames searched for the board at most this often: a board moved by hand changes
# little in 0.1 s, and a 5-minute video at 30 fps is searched in 3000 frames, not 9000 (caliscope's 6 fps: every frame)
INTRINSIC_NAMES = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6")


@dataclass(frozen=True)
class BoardSpec:
    """A calibration board: chessboard (inner corners) or ChArUco (squares), sizes in metres."""

    kind: str  # "chessboard" or "charuco"
    cols: int  # chessboard: inner corners across; charuco: squares across
    rows: int
    square: float
    marker: float = 0.0  # charuco only
    dictionary: str = ""  # charuco only
    legacy: bool = False  # charuco only: OpenCV's pattern before 4.6 (differs on boards with an even number of rows)

    def object_points(self) -> np.ndarray:
        """(N, 3) chessboard inner corners in the board frame, row by row."""
        grid = np.mgrid[0:self.cols, 0:self.rows].T.reshape(-1, 2)
        return np.hstack([grid * self.square, np.zeros((len(grid), 1))]).astype(np.float32)

    def charuco_board(self) -> cv2.aruco.CharucoBoard:
        """The OpenCV ChArUco board object."""
        dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))
        board = cv2.aruco.CharucoBoard((self.cols, self.rows), self.square, self.marker, dictionary)
        board.setLegacyPattern(self.legacy)
        return board


BOARD_FORMS = "chessboard:COLSxROWS:SQUARE or charuco:COLSxROWS:SQUARE:MARKER:DICT"


def parse_board(text: str) -> BoardSpec:
    """Parse chessboard:9x6:0.025 or charuco:5x7:0.04:0.02:DICT_6X6_250."""
    m = re.fullmatch(r"chessboard:(\d+)x(\d+):([0-9.]+)", text)
    if m:
        spec = BoardSpec("chessboard", int(m[1]), int(m[2]), float(m[3]))
    else:
        m = re.fullmatch(r"charuco:(\d+)x(\d+):([0-9.]+):([0-9.]+):(DICT_\w+)", text)
        if not m:
            raise InputError("--board", f"{text!r} is not a board (expected {BOARD_FORMS})")
        if not hasattr(cv2.aruco, m[5]):
            raise InputError("--board", f"unknown ArUco dictionary {m[5]!r} (expected e.g. DICT_6X6_250)")
        spec = BoardSpec("charuco", int(m[1]), int(m[2]), float(m[3]), float(m[4]), m[5])
        if spec.marker >= spec.square:
            raise InputError("--board", f"marker {spec.marker} must be smaller than square {spec.square}")
    if spec.cols < 2 or spec.rows < 2 or spec.square <= 0:
        raise InputError("--board", f"{text!r}: need at least 2x2 and a positive square size")
    return spec


@dataclass
class BoardView:
    """Board corners found in one photo or one frame of a video: image points (N, 2) and their board points (N, 3)."""

    path: Path
    image_points: np.ndarray
    object_points: np.ndarray
    frame: int | None = None  # the frame's number in a video (None: a photo)

    @property
    def name(self) -> str:
        """The photo's file name, or the video's with the frame's number: 'cam_0.mp4#17'."""
        return self.path.name if self.frame is None else f"{self.path.name}#{self.frame}"


def find_chessboard(gray: np.ndarray, board: BoardSpec, window: int = SUBPIX_WINDOW, fast: bool = False
                    ) -> tuple[np.ndarray, np.ndarray] | None:
    """Chessboard inner corners refined to sub-pixel, or None when the board is not found (fast: a quick look first,
    for a video's frames, most of which may not show it: 20 against 114 ms a 720p frame without the board)."""
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE | (cv2.CALIB_CB_FAST_CHECK if fast else 0)
    found, corners = cv2.findChessboardCorners(gray, (board.cols, board.rows), flags=flags)
    if not found:
        return None
    corners = cv2.cornerSubPix(gray, corners, (window, window), (-1, -1), SUBPIX_CRITERIA)
    return corners.reshape(-1, 2), board.object_points()


def find_charuco(gray: np.ndarray, board: BoardSpec, window: int = SUBPIX_WINDOW, inverted: bool = False
                 ) -> tuple[np.ndarray, np.ndarray] | None:
    """ChArUco corners (interpolated from the markers, sub-pixel), or None when too few are found; inverted: the
    markers are printed white on black (found either way)."""
    cboard = board.charuco_board()
    params = cv2.aruco.DetectorParameters()
    params.detectInvertedMarker = inverted
    detector = cv2.aruco.CharucoDetector(cboard, cv2.aruco.CharucoParameters(), params)
    corners, ids, _, _ = detector.detectBoard(gray)
    if ids is None or len(ids) < MIN_CHARUCO_CORNERS:
        return None
    obj, img = cboard.matchImagePoints(corners, ids)
    return img.reshape(-1, 2).astype(np.float32), obj.reshape(-1, 3).astype(np.float32)


def find_board(path: Path, board: BoardSpec, window: int = SUBPIX_WINDOW, inverted: bool = False,
               gray: np.ndarray | None = None, frame: int | None = None) -> tuple[BoardView | None, tuple[int, int]]:
    """Board corners in one photo, or in one frame of a video given as gray (None when not found), and the picture's
    size (w, h)."""
    gray = read_gray(path) if gray is None else gray
    if board.kind == "chessboard":
        found = find_chessboard(gray, board, window, fast=frame is not None)
    else:
        found = find_charuco(gray, board, window, inverted)
    size = (gray.shape[1], gray.shape[0])
    if found is None:
        return None, size
    return BoardView(path, found[0], found[1], frame), size


def video_views(path: Path, board: BoardSpec, window: int = SUBPIX_WINDOW, inverted: bool = False
                ) -> tuple[list[BoardView], tuple[int, int] | None]:
    """A video's views of the board, at most VIDEO_VIEWS spread over its poses (spread_views), from frames at most
    VIDEO_SCAN_HZ apart; its pictures' size (w, h), None when it has no frame. A picture of another size than the
    first is an error."""
    views: list[BoardView] = []
    size: tuple[int, int] | None = None
    last = -np.inf
    for f in frames(path):
        if f.gray is None or f.time - last < 1.0 / VIDEO_SCAN_HZ - 1e-6:
            continue
        last = f.time
        view, frame_size = find_board(path, board, window, inverted, gray=f.gray, frame=f.index)
        if size is not None and frame_size != size:
            raise InputError(path, f"frame {f.index} is {frame_size[0]}x{frame_size[1]}, its first "
                                   f"{size[0]}x{size[1]} (expected one camera's pictures)")
        size = frame_size
        if view is not None:
            views.append(view)
    return spread_views(views, VIDEO_VIEWS), size


def pose_distances(views: Sequence[BoardView]) -> Callable[[int], np.ndarray]:
    """How far each view's board lies from view k's in the image, (V,) for a k: the mean distance of their shared
    corners (matched by board point) over the board's extent in the image (its bounding box's diagonal), the smaller
    of the two views' shares; inf where they share fewer than MIN_SHARED_CORNERS (different parts of a ChArUco
    board). Vectorised over the views (9000 frames' views against one in milliseconds)."""
    index: dict[tuple[float, ...], int] = {}
    keys = [[index.setdefault(tuple(np.round(p, 6)), len(index)) for p in v.object_points] for v in views]
    points = np.full((len(views), len(index), 2), np.nan)  # (V, C, 2) NaN where a view lacks a board point
    for k, (v, columns) in enumerate(zip(views, keys, strict=True)):
        points[k, columns] = v.image_points
    extent = np.maximum([np.linalg.norm(np.ptp(v.image_points, axis=0)) for v in views], 1e-9)  # (V,)
    seen = np.isfinite(points[:, :, 0])

    def distances(k: int) -> np.ndarray:
        shared = seen & seen[k]
        count = shared.sum(axis=1)
        mean = np.where(shared, np.linalg.norm(points - points[k], axis=2), 0.0).sum(axis=1) / np.maximum(count, 1)
        return np.where(count >= MIN_SHARED_CORNERS, np.minimum(mean / extent[k], mean / extent), np.inf)

    return distances


def spread_views(views: Sequence[BoardView], most: int) -> list[BoardView]:
    """At most `most` of the views, far apart: the one with the most corners first, then each time the one farthest
    from those taken (pose_distances, to the nearest taken), until none lies SAME_POSE_SHARE or more from them; in
    their order."""
    if not views:
        return []
    distances = pose_distances(views)
    taken = [max(range(len(views)), key=lambda k: len(views[k].image_points))]
    nearest = distances(taken[0])
    while len(taken) < most:
        k = int(np.argmax(nearest))
        if nearest[k] < SAME_POSE_SHARE:
            break
        taken.append(k)
        nearest = np.minimum(nearest, distances(k))
    return [views[k] for k in sorted(taken)]


@dataclass
class CalibrationResult:
    """What calibrateCamera found, with its uncertainty and the views it used."""

    camera: CameraModel  # its rms: what the file states, the fit's RMS or at least UNSTATED_RMS_PX (COVERAGE_WARN)
    rms: float  # px, over all points
    per_view_rms: dict[str, float]  # view (a photo's name, a video frame's name#frame) -> px
    std_intrinsics: dict[str, float]  # fx, fy, cx, cy, k1, ... -> one standard deviation
    missed: list[str] = field(default_factory=list)  # photos, and videos, with no board
    coverage: float = 1.0  # share of image cells that held a corner in some view
    flags: int = 0  # cv2.CALIB_* flags used
    rvecs: list[np.ndarray] = field(default_factory=list)
    tvecs: list[np.ndarray] = field(default_factory=list)
    repeated: dict[str, str] = field(default_factory=dict)  # view -> the earlier view whose board pose it repeats
    far_off: dict[str, float] = field(default_factory=dict)  # video frame's view -> its RMS in the first fit, px, where
    # that was far beyond the median view's (OUTLIER_VIEW_FACTOR, OUTLIER_VIEW_MARGIN_PX)
    refitted: bool = False  # the camera fitted again without them (else too few poses would have remained)
    video_frames: int = 0  # of the views used, those from videos (the rest photos)


def board_coverage(views: Sequence[BoardView], size: tuple[int, int]) -> float:
    """Share of a COVERAGE_GRID² split of the image in which at least one board corner fell."""
    hit = np.zeros((COVERAGE_GRID, COVERAGE_GRID), dtype=bool)
    for view in views:
        cells = (view.image_points / np.array(size) * COVERAGE_GRID).astype(int)
        cells = np.clip(cells, 0, COVERAGE_GRID - 1)
        hit[cells[:, 1], cells[:, 0]] = True
    return float(hit.mean())


def board_views(paths: Sequence[Path], board: BoardSpec, subpix_window: int = SUBPIX_WINDOW,
                inverted: bool = False, progress: Callable[[], None] | None = None
                ) -> tuple[list[BoardView], list[str], tuple[int, int] | None]:
    """The board's views in the photos and videos (video_views), what showed none, and the pictures' size; a file
    whose pictures are of another size than the first's is an error."""
    views: list[BoardView] = []
    missed: list[str] = []
    size: tuple[int, int] | None = None
    for path in map(Path, paths):
        if is_image(path):
            view, view_size = find_board(path, board, subpix_window, inverted)
            found = [view] if view is not None else []
        else:
            found, video_size = video_views(path, board, subpix_window, inverted)
            if video_size is None:
                raise InputError(path, "video has no frame (expected a video of the board)")
            view_size = video_size
        if size is None:
            size = view_size
        elif view_size != size:
            raise InputError(path, f"picture size {view_size[0]}x{view_size[1]} differs from the first file's "
                                   f"{size[0]}x{size[1]} (expected one camera)")
        if not found:
            missed.append(path.name if is_image(path) else f"{path.name} (none of its frames)")
        views += found
        if progress is not None:
            progress()
    return views, missed, size


def _too_few(paths: Sequence[Path], views: list[BoardView], poses: list[list[int]], board: BoardSpec,
             inverted: bool) -> InputError:
    """The error for fewer than MIN_VIEWS distinct views: none found (and a hint where markers may be inverted), or
    found at too few poses."""
    first = views[0].path if views else (paths[0] if paths else "IMAGES")
    what = f"board {board.kind} {board.cols}x{board.rows}"
    hint = "; markers printed white on black need --inverted" if board.kind == "charuco" and not inverted and \
        not views else ""
    if all(is_image(p) for p in paths) and len(views) < MIN_VIEWS:
        return InputError(first, f"board found in {len(views)} of {len(paths)} photos; need at least {MIN_VIEWS} "
                                 f"usable views ({what}{hint})")
    if not views:
        return InputError(first, f"board found in none of the frames of the {len(paths)} file{'s' * (len(paths) > 1)}; "
                                 f"need at least {MIN_VIEWS} usable views ({what}{hint})")
    repeats = _repeats_text(views, poses)
    photos = all(is_image(p) for p in paths)
    return InputError(first, f"the board is in {len(views)} {'photo' if photos else 'view'}{'s' * (len(views) > 1)} "
                             f"but at only {len(poses)} distinct pose{'s' * (len(poses) > 1)}"
                             f"{f' ({repeats})' if repeats else ''}; need at least {MIN_VIEWS} distinct views (move "
                             f"and tilt the board {'between photos' if photos else 'while filming'})")


def calibrate(paths: Sequence[Path], board: BoardSpec, fix_aspect: bool = False,
              rational: bool = False, subpix_window: int = SUBPIX_WINDOW,
              progress: Callable[[], None] | None = None, inverted: bool = False) -> CalibrationResult:
    """Find the board in every photo and in the frames of every video (inverted: ChArUco markers printed white on
    black) and calibrate; refuses when fewer than MIN_VIEWS distinct views are usable."""
    views, missed, size = board_views(paths, board, subpix_window, inverted, progress)
    poses = distinct_poses(views)
    if len(poses) < MIN_VIEWS:
        raise _too_few(paths, views, poses, board, inverted)
    assert size is not None
    flags = 0
    K0 = None
    if fix_aspect:
        flags |= cv2.CALIB_FIX_ASPECT_RATIO
        K0 = np.eye(3)
    if rational:
        flags |= cv2.CALIB_RATIONAL_MODEL
    def fit(views: list[BoardView]) -> tuple:
        return cv2.calibrateCameraExtended([v.object_points for v in views], [v.image_points for v in views], size,
                                           None if K0 is None else K0.copy(), None, flags=flags)

    rms, K, dist, rvecs, tvecs, std_intr, _std_extr, per_view = fit(views)
    errors = per_view.reshape(-1)
    median = float(np.median(errors))
    bound = max(OUTLIER_VIEW_FACTOR * median, median + OUTLIER_VIEW_MARGIN_PX)
    far = {k: float(errors[k]) for k, v in enumerate(views) if v.frame is not None and errors[k] > bound}
    far_off = {views[k].name: e for k, e in far.items()}
    refitted = False
    if far:
        kept = [v for k, v in enumerate(views) if k not in far]
        kept_poses = distinct_poses(kept)
        if len(kept_poses) >= MIN_VIEWS:  # else kept, and said: without them too few poses remain
            views, poses, refitted = kept, kept_poses, True
            rms, K, dist, rvecs, tvecs, std_intr, _std_extr, per_view = fit(views)
    std = std_intr.reshape(-1)
    std_named = {name: float(std[i]) for i, name in enumerate(INTRINSIC_NAMES[: 4 + dist.size])}
    coverage = board_coverage(views, size)
    stated = float(rms) if coverage >= COVERAGE_WARN else max(float(rms), UNSTATED_RMS_PX)
    camera = CameraModel(K=K, dist=dist.reshape(-1), width=size[0], height=size[1], rms=stated)
    return CalibrationResult(
        camera=camera, rms=float(rms),
        per_view_rms={v.name: float(e) for v, e in zip(views, per_view.reshape(-1), strict=True)},
        std_intrinsics=std_named, missed=missed, coverage=coverage, flags=flags,
        rvecs=list(rvecs), tvecs=list(tvecs),
        repeated={views[k].name: views[group[0]].name for group in poses for k in group[1:]},
        far_off=far_off, refitted=refitted, video_frames=sum(v.frame is not None for v in views))


def distinct_poses(views: Sequence[BoardView]) -> list[list[int]]:
    """The views grouped by board pose, in order: each group a first view and the views within SAME_POSE_SHARE of it
    (pose_distances: photos re-taken, or the same photo given twice)."""
    if not views:
        return []
    distances = pose_distances(views)
    groups: list[list[int]] = []
    firsts: list[np.ndarray] = []  # each group's first view's distances to every view
    for k in range(len(views)):
        same = next((g for g, d in zip(groups, firsts, strict=True) if d[k] < SAME_POSE_SHARE), None)
        if same is None:
            groups.append([k])
            firsts.append(distances(k))
        else:
            same.append(k)
    return groups


def _repeats_text(views: Sequence[BoardView], poses: list[list[int]]) -> str:
    """'b.png, c.png repeat a.png's view; ...' for the groups of more than one view."""
    parts = [f"{', '.join(views[k].name for k in g[1:])} repeat{'s' if len(g) == 2 else ''} "
             f"{views[g[0]].name}'s view" for g in poses if len(g) > 1]
    return "; ".join(parts)
