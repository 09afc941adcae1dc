"""A caliscope session (github.com/mprib/caliscope: webcams filming a hand-held ChArUco board) as a rig with a truth.

caliscope keeps a session's board in `charuco.toml` (or the `[charuco]` table of `config.toml`), its cameras'
intrinsics in `camera_array.toml` (`[cameras.N]`) or `config.toml` (`[cam_N]`), its videos as `cam_N.mp4` or
`port_N.mp4` in `calibration/extrinsic/` and every frame's capture time beside them in `timestamps.csv` (sync_index,
cam_id, [frame_index,] frame_time) or `frame_time_history.csv` / `frame_timestamps.csv` (the same with `port`).

The board is rigid, so it makes a mated pair whose truth needs no tracker: its first half of markers (by id) is the
"topside", the rest the "jacket", both at one cone A at the board's centre, and the true offset is zero whatever the
board does. Board frame (OpenCV's: x right, y down the printed face, z into it) to jacket frame: x to port = -board
x, z up = -board y, the printed face looks astern (+y). Square and marker sizes follow caliscope: the override in cm
where given, else the largest square that fits the stated board (inches or cm); markers `aruco_scale` of a square.

Frames: a camera's rows in sync_index (else frame_time) order are its video's frames, one row a frame as caliscope's
recorder writes them; frame_index is caliscope's own counter (it skips where the synchroniser dropped a frame, and
its test sessions, cut from longer recordings, keep the original numbers), so it is not read.
Capture times are seconds after the session's first frame. A session without a times file (caliscope's
post_monocal layout) takes its videos' own presentation times, said so: caliscope records them nominal (k / fps), so
its cameras' frames are then taken as simultaneous where they were only near it. Cameras caliscope marks `ignore` or
calibrates as fisheye (which the tracker does not model) are left out and said so. A camera without intrinsics (or a
session without camera_array.toml or config.toml, its cameras then the videos there are) is calibrated from its own
video of the board, the intrinsic one (`calibration/intrinsic/`) where there is one, as `topside calibrate` does, and
said so. A camera's `rotation_count` is
how caliscope shows its frames: its trackers turn a frame, detect, and turn the points back, so its intrinsics are the
video's as recorded.
"""

from __future__ import annotations

import math
import os
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import av
import cv2
import numpy as np
import pandas as pd
from pydantic import ValidationError

from tracking.calibration import BoardSpec, CalibrationResult, calibrate
from tracking.camera import CameraModel, save_camera
from tracking.errors import InputError
from tracking.images import open_video
from tracking.outputs import write_text
from tracking.rig import CameraEntry, Marker, Mount, Rig, dictionary_size, rig_error, save_rig

CONE = "A"
INCHES_PER_CM = 0.393701  # caliscope's own conversion of a board stated in inches
BOARD_FILES = ("charuco.toml", "calibration/targets/extrinsic_charuco.toml")  # older sessions; caliscope's newer
TIMES_FILES = ("timestamps.csv", "frame_time_history.csv", "frame_timestamps.csv")  # newest name first
CAMERA_COLUMNS = ("cam_id", "port")
MAX_SQUARES = 100  # squares a side: a printed board has a few dozen; more is a typo (and OpenCV would allocate it)
POOLS = (50, 100, 250, 1000)  # the sizes of OpenCV's nested dictionary pools of one family
VIDEO_NAMES = ("cam_{}.mp4", "port_{}.mp4")
MOUNT: Mount = "moving"  # the board turns before the cameras: each camera sees its "jacket" turn, as a camera that
# moves would (a fixed mount's prior would hold the camera still against what its images show)


@dataclass(frozen=True)
class Board:
    """A caliscope ChArUco board: squares across (columns) and down (rows), their side and the markers', m."""

    columns: int
    rows: int
    square_m: float
    marker_m: float
    dictionary: str
    inverted: bool = False
    legacy: bool = False  # OpenCV's pattern before 4.6 (differs on boards with an even number of rows)

    def spec(self) -> BoardSpec:
        """The board as `topside calibrate` takes it."""
        return BoardSpec("charuco", self.columns, self.rows, self.square_m, self.marker_m, self.dictionary,
                         legacy=self.legacy)

    def opencv(self) -> cv2.aruco.CharucoBoard:
        return self.spec().charuco_board()

    def markers(self, topside_ids: set[int] | None = None) -> list[Marker]:
        """The board's markers in the jacket frame, its centre at the origin; topside_ids (default: the first half by
        id) on the topside, the rest on the jacket."""
        b = self.opencv()
        ids = [int(i) for i in np.asarray(b.getIds()).ravel()]
        topside = set(sorted(ids)[:len(ids) // 2]) if topside_ids is None else topside_ids
        width, height = self.square_m * self.columns, self.square_m * self.rows
        out = []
        for i, corners in zip(ids, b.getObjPoints(), strict=True):
            bx, by = np.asarray(corners)[:, :2].mean(axis=0)
            center = [round(float(-(bx - width / 2)), 6), 0.0, round(float(-(by - height / 2)), 6)]
            out.append(Marker(id=i, body="topside" if i in topside else "jacket", cone=CONE, face="astern",
                              center=center))
        return out


@dataclass(frozen=True)
class SessionCamera:
    """One camera of a session: its number (cam_id or port), intrinsics (3, 3), distortion (k1 k2 p1 p2 k3), picture
    size, calibration RMS (px) and its video."""

    number: int
    K: np.ndarray
    dist: np.ndarray
    size: tuple[int, int]
    rms: float | None
    video: Path


@dataclass
class Session:
    """What a caliscope session holds that the tracker needs."""

    source: Path
    board: Board
    cameras: list[SessionCamera]
    times: dict[int, pd.DataFrame]  # camera number -> frame, time (s after the session's first frame)
    left_out: list[str] = field(default_factory=list)  # one line per camera left out, and why
    notes: list[str] = field(default_factory=list)  # what a user should know of the import (one line each)


def _nulls(value: Any) -> Any:
    """A TOML value with caliscope's "null" strings (rtoml writes a missing value so) as None."""
    if value == "null":
        return None
    if isinstance(value, dict):
        return {k: _nulls(v) for k, v in value.items()}
    return [_nulls(v) for v in value] if isinstance(value, list) else value


def _toml(path: Path) -> dict[str, Any]:
    try:
        return _nulls(tomllib.loads(path.read_text()))
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(path, f"cannot be read ({exc})") from None
    except tomllib.TOMLDecodeError as exc:
        raise InputError(path, f"not a TOML file ({exc})") from None


def _number(path: Path, table: dict[str, Any], key: str, what: str, positive: bool = True) -> float:
    value = table.get(key)
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value) or \
            (positive and value <= 0):
        raise InputError(path, f"expected {what}, got {value!r}", key)
    return float(value)


def _squares(path: Path, table: dict[str, Any], key: str, what: str) -> int:
    value = table.get(key)
    if isinstance(value, bool) or not isinstance(value, int) or not 2 <= value <= MAX_SQUARES:
        raise InputError(path, f"expected the number of squares {what}, 2 to {MAX_SQUARES}, got {value!r}", key)
    return value


def _fitting_pool(path: Path, dictionary: str, markers: int) -> str:
    """The dictionary of the family (DICT_4X4_*) that holds a board's markers: the one named, or the smallest larger
    one (caliscope grows an undersized pool so: the pools nest, a smaller one's codes are a larger one's first)."""
    if markers <= dictionary_size(dictionary):
        return dictionary
    family = dictionary.rsplit("_", 1)[0]
    pools = sorted((dictionary_size(f"{family}_{n}"), f"{family}_{n}") for n in POOLS if hasattr(cv2.aruco,
                                                                                              f"{family}_{n}"))
    bigger = [name for size, name in pools if size >= markers]
    if not bigger:
        raise InputError(path, f"a board of {markers} markers needs more codes than {family} has", "dictionary")
    return bigger[0]


def read_board(path: Path, table: dict[str, Any]) -> Board:
    """The board of a charuco.toml (or config.toml's [charuco]) table read from path."""
    columns, rows = (_squares(path, table, key, what) for key, what in (("columns", "across"), ("rows", "down")))
    dictionary = str(table.get("dictionary", "DICT_4X4_50"))
    if not dictionary.startswith("DICT_") or not hasattr(cv2.aruco, dictionary):
        raise InputError(path, f"expected an OpenCV dictionary name such as DICT_4X4_50, got {dictionary!r}",
                         "dictionary")
    dictionary = _fitting_pool(path, dictionary, columns * rows // 2)
    override = table.get("square_size_override_cm", table.get("square_size_overide_cm"))
    if override:
        square = _number(path, {"square_size_override_cm": override}, "square_size_override_cm",
                         "the square's side in cm") / 100
    else:
        height, width = (_number(path, table, k, f"the board's {k.removeprefix('board_')}")
                         for k in ("board_height", "board_width"))
        units = table.get("units", "inch")  # caliscope's default
        if units not in ("inch", "cm"):
            raise InputError(path, f"expected inch or cm, got {units!r}", "units")
        scale = 1 / INCHES_PER_CM if units == "inch" else 1.0
        square = min(height * scale / 100 / rows, width * scale / 100 / columns)
    aruco_scale = _number(path, {"aruco_scale": table.get("aruco_scale", 0.75)}, "aruco_scale",
                          "the marker's share of a square (0-1)")
    if aruco_scale >= 1:
        raise InputError(path, f"expected the marker's share of a square (0-1), got {aruco_scale}", "aruco_scale")
    return Board(columns, rows, square, square * aruco_scale, dictionary, _flag(path, table, "inverted"),
                 _flag(path, table, "legacy_pattern"))


def _flag(path: Path, table: dict[str, Any], key: str, within: str | None = None) -> bool:
    value = table.get(key)
    if value is not None and not isinstance(value, bool):
        raise InputError(path, f"expected true or false, got {value!r}", f"{within}.{key}" if within else key)
    return bool(value)


def _camera_tables(folder: Path, videos: Path) -> tuple[Path, dict[int, dict[str, Any]]]:
    """The cameras' tables by number, from camera_array.toml or config.toml; without either (or with no camera table
    in config.toml), an empty table for every camera whose video is in videos (to be calibrated from it)."""
    array, config = folder / "camera_array.toml", folder / "config.toml"
    settings = _toml(config) if config.is_file() and not array.is_file() else {}
    if array.is_file():
        cameras = _toml(array).get("cameras", {})
        path, tables = array, [(str(t.get("cam_id", k)), k, t) for k, t in
                               (cameras.items() if isinstance(cameras, dict) else []) if isinstance(t, dict)]
    elif any(k.startswith("cam_") for k in settings):
        path, tables = config, [(str(t.get("port", k.removeprefix("cam_"))), k, t) for k, t in settings.items()
                                if k.startswith("cam_") and isinstance(t, dict)]
    else:
        found = _numbered_videos(videos)
        if not found:
            raise _no_cameras(folder, videos, config)
        return videos, {n: {} for n in found}
    out = {}
    for number, key, table in tables:
        if not (number.isascii() and number.isdecimal()):
            raise InputError(path, f"expected a camera number (cam_id or port), got {number!r}", key)
        if int(number) in out:
            raise InputError(path, f"camera {number} is given twice (expected one table a camera)", key)
        out[int(number)] = table
    return path, out


def session_board(folder: Path) -> Board:
    """A session folder's board: its charuco.toml (or extrinsic target file), else config.toml's [charuco] table."""
    for charuco in BOARD_FILES:
        if (folder / charuco).is_file():
            return read_board(folder / charuco, _toml(folder / charuco))
    config = folder / "config.toml"
    table = _toml(config).get("charuco") if config.is_file() else None
    if isinstance(table, dict):
        return read_board(config, table)
    raise InputError(folder, "no charuco.toml (or calibration/targets/extrinsic_charuco.toml), nor a [charuco] "
                             "table in config.toml (expected the session's board)")


def times_file(videos: Path) -> Path | None:
    """The session's times file in the videos' folder, if it has one."""
    return next((videos / name for name in TIMES_FILES if (videos / name).is_file()), None)


def video_times(videos: dict[int, Path]) -> dict[int, pd.DataFrame]:
    """Each camera's frame, time table from its video's own presentation times (seconds after the first frame of
    any of them), for a session without a times file."""
    own = {}
    for number, video in videos.items():
        try:
            with open_video(video) as container:
                stream = container.streams.video[0]
                pts = sorted(p.pts for p in container.demux(stream) if p.size and p.pts is not None)
        except av.error.FFmpegError as exc:
            raise InputError(video, f"video is damaged ({exc.strerror or exc})") from None
        own[number] = np.asarray(pts, dtype=float) * float(stream.time_base)
    t0 = min((t[0] for t in own.values() if t.size), default=0.0)
    return {n: pd.DataFrame({"frame": np.arange(t.size), "time": (t - t0).round(6)}) for n, t in own.items()}


def read_times(videos: Path) -> tuple[Path, dict[int, pd.DataFrame]]:
    """Each camera's frame, time table from the session's times file in the videos' folder."""
    path = times_file(videos)
    if path is None:
        raise InputError(videos, f"no {' or '.join(TIMES_FILES)} (expected each frame's capture time)")
    try:
        df = pd.read_csv(path)
    except (OSError, UnicodeDecodeError, pd.errors.ParserError, pd.errors.EmptyDataError) as exc:
        raise InputError(path, f"not a CSV file ({' '.join(str(exc).split())})") from None
    camera = next((c for c in CAMERA_COLUMNS if c in df.columns), None)
    for column in (camera or CAMERA_COLUMNS[0], "frame_time"):
        if column not in df.columns:
            raise InputError(path, "missing (expected cam_id or port, frame_time, and optionally sync_index)", column)
    for column in (camera, "frame_time", *(["sync_index"] if "sync_index" in df.columns else [])):
        values = pd.to_numeric(df[column], errors="coerce").to_numpy(dtype=float)
        whole = column != "frame_time"  # numbers of cameras and syncs
        bad = ~np.isfinite(values) | (whole & (values != np.round(values)))
        if bad.any():
            raise InputError(path, f"line {int(np.argmax(bad)) + 2}: expected "
                                   f"{'a whole number' if whole else 'a number'}", column)
        df[column] = values
    t0 = float(df["frame_time"].min())
    out = {}
    for number, rows in df.groupby(camera):
        rows = rows.sort_values(["sync_index", "frame_time"] if "sync_index" in rows else "frame_time",
                                kind="stable")  # a row per video frame, as caliscope's recorder writes them
        times = rows["frame_time"].to_numpy()
        if np.any(np.diff(times) <= 0):
            k = int(np.argmax(np.diff(times) <= 0)) + 1
            raise InputError(path, f"line {int(rows.index[k]) + 2}: cam {int(number)}'s frame at {times[k]} s is not "
                                   "after the one before it (expected one row per frame, in time order)", "frame_time")
        out[int(number)] = pd.DataFrame({"frame": np.arange(len(rows)), "time": (times - t0).round(6)})
    return path, out


def _numbered_videos(folder: Path) -> dict[int, Path]:
    """A folder's cameras' videos (cam_N.mp4, port_N.mp4) by camera number, in number order."""
    found = {int(m): v for n in VIDEO_NAMES for v in folder.glob(n.format("*"))
             if (m := v.stem.rpartition("_")[2]).isascii() and m.isdecimal()} if folder.is_dir() else {}
    return dict(sorted(found.items()))


def _no_cameras(folder: Path, videos: Path, config: Path) -> InputError:
    """The error of a session with neither camera tables nor videos in videos; one of intrinsic videos alone (each
    camera filmed on its own) says so and how to track one."""
    tables = "no camera tables in config.toml" if config.is_file() else "no camera_array.toml or config.toml"
    intrinsic = [v.name for v in _numbered_videos(folder / "calibration" / "intrinsic").values()]
    alone = f"; calibration/intrinsic holds {', '.join(intrinsic)}, each camera filmed on its own, not one scene at " \
            "one time (to track one alone: a folder of its own with charuco.toml and the video as " \
            "calibration/extrinsic/cam_N.mp4)" if intrinsic else ""
    return InputError(folder, f"{tables}, nor cam_N.mp4 videos in {videos} (expected a caliscope session folder)"
                              f"{alone}")


def _video(videos: Path, number: int) -> Path | None:
    return next((videos / n.format(number) for n in VIDEO_NAMES if (videos / n.format(number)).is_file()), None)


def read_session(folder: Path, videos: Path | None = None) -> Session:
    """A caliscope session folder (its videos and times file in videos, default calibration/extrinsic/)."""
    folder = Path(folder)
    if not folder.is_dir():
        raise InputError(folder, "not a folder (expected a caliscope session folder)")
    videos = folder / "calibration" / "extrinsic" if videos is None else Path(videos)
    board = session_board(folder)
    source, tables = _camera_tables(folder, videos)
    times_path = times_file(videos)
    times = read_times(videos)[1] if times_path is not None else \
        video_times({n: v for n in tables if (v := _video(videos, n)) is not None})
    cameras, left_out, notes = [], [], []
    for number, table in sorted(tables.items()):
        name = f"cam_{number}"
        video = _video(videos, number)
        turns = table.get("rotation_count", 0)  # how caliscope shows the frames (and turns them for its detectors):
        # its points and intrinsics are in the video's own pixels, so nothing here depends on it
        if isinstance(turns, bool) or not isinstance(turns, int):
            raise InputError(source, f"expected quarter turns (an integer), got {turns!r}", f"{name}.rotation_count")
        if _flag(source, table, "ignore", name):
            left_out.append(f"{name}: caliscope marks it ignore")
        elif _flag(source, table, "fisheye", name):
            left_out.append(f"{name}: calibrated with caliscope's fisheye model, which the tracker does not model")
        elif video is None:
            left_out.append(f"{name}: no {' or '.join(n.format(number) for n in VIDEO_NAMES)} in {videos}")
        elif number not in times:
            left_out.append(f"{name}: no rows in {times_path.name if times_path else 'its video'}")
        elif table.get("matrix") is None or table.get("distortions") is None:
            result, said = calibrate_camera(folder, video, number, board)
            lacking = f"no intrinsics in {source.name}" if source.is_file() else \
                "no intrinsics (no camera_array.toml, nor camera tables in a config.toml)"
            if result is None:
                left_out.append(f"{name}: {lacking}, and {said}")
            else:
                notes.append(f"{name}: {lacking}: {said}")
                c = result.camera
                cameras.append(SessionCamera(number, c.K, c.dist, (c.width, c.height), c.rms, video))
        else:
            size = table.get("size")
            try:
                K = np.asarray(table["matrix"], dtype=float)
                dist = np.asarray(table["distortions"], dtype=float).ravel()
            except (TypeError, ValueError):
                K, dist = np.zeros(0), np.zeros(0)
            if K.shape != (3, 3) or not np.isfinite(K).all() or not np.isfinite(dist).all() or \
                    dist.size not in (4, 5, 8, 12, 14) or not (isinstance(size, list) and len(size) == 2) or \
                    not all(isinstance(v, int) and not isinstance(v, bool) and v > 0 for v in size):
                raise InputError(source, "expected matrix (3 × 3 numbers), distortions (OpenCV's 4, 5, 8, 12 or 14) "
                                         "and size [width, height] in pixels", name)
            rms = table.get("error")
            cameras.append(SessionCamera(number, K, dist, (size[0], size[1]),
                                         float(rms) if isinstance(rms, int | float) else None, video))
    if not cameras:
        raise InputError(folder, "no camera can be used: " + "; ".join(left_out or ["none listed"]))
    if times_path is None:
        notes.append(f"{videos}: no {' or '.join(TIMES_FILES)}: each frame's time is its video's own (caliscope writes "
                     "them nominal, k / fps), so the cameras are taken as synchronised frame by frame")
    return Session(folder, board, cameras, times, left_out, notes)


def calibrate_camera(folder: Path, video: Path, number: int, board: Board
                     ) -> tuple[CalibrationResult | None, str]:
    """A session's camera calibrated from its own video of the board (its intrinsic video where the session has one,
    else the one it tracks), as `topside calibrate` does, and what was done in a few words; None and why where no
    video of it shows the board enough."""
    intrinsic = _video(folder / "calibration" / "intrinsic", number)
    why = []
    root = folder.resolve()
    for path in ([intrinsic] if intrinsic is not None else []) + [video]:
        path = path.resolve()
        where = path.relative_to(root) if path.is_relative_to(root) else path
        try:
            result = calibrate([path], board.spec(), inverted=board.inverted)
        except InputError as exc:
            why.append(f"{where}: {exc.message}")
            continue
        return result, (f"calibrated from {where} ({len(result.per_view_rms)} views, fit {result.rms:.2f} px, the "
                        f"board over {result.coverage:.0%} of the picture: its error taken as "
                        f"{result.camera.rms:.2f} px)")
    return None, "no video of it calibrates it (" + "; ".join(why) + ")"


def write_session(session: Session, out: Path, topside_ids: set[int] | None = None,
                  mount: Mount = MOUNT) -> Path:
    """Write out/rig.yaml, out/calibration/cam_N.yaml, out/times/cam_N.csv and out/truth.csv (the offset at cone A,
    zero at every frame time of the cameras kept); the rig's path. The rig is checked before any file is written;
    each file is written whole or not at all."""
    out = Path(out)
    names = {cam.number: f"cam_{cam.number}" for cam in session.cameras}
    entries = [CameraEntry(name=names[cam.number], calibration=f"calibration/{names[cam.number]}.yaml",
                           source=os.path.relpath(cam.video.resolve(), out.resolve()),
                           times=f"times/{names[cam.number]}.csv", mount=mount) for cam in session.cameras]
    board = session.board
    try:
        rig = Rig(name=f"caliscope-{session.source.resolve().name}", dictionary=board.dictionary,
                  inverted=board.inverted, marker_size=round(board.marker_m, 9), cones={CONE: [0.0, 0.0, 0.0]},
                  markers=board.markers(topside_ids), cameras=entries)
    except ValidationError as exc:  # what the board or the cameras give that no rig can hold (sizes beyond limits)
        raise rig_error(session.source, exc) from None
    for cam in session.cameras:
        name = names[cam.number]
        save_camera(out / "calibration" / f"{name}.yaml", CameraModel(cam.K, cam.dist, *cam.size, rms=cam.rms))
        write_text(out / "times" / f"{name}.csv", session.times[cam.number].to_csv(index=False))
    times = np.unique(np.concatenate([session.times[cam.number]["time"].to_numpy() for cam in session.cameras]))
    truth = pd.DataFrame({"time": times, "cone": CONE, "dx": 0.0, "dy": 0.0, "dz": 0.0})
    write_text(out / "truth.csv", truth.to_csv(index=False))
    save_rig(out / "rig.yaml", rig)
    return out / "rig.yaml"
