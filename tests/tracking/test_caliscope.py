"""A caliscope session as a rig (tracking/caliscope.py): the two shared sessions, and the layouts of caliscope's
other versions (config.toml's tables, port_N videos, frame_time_history.csv) made from them."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import av
import numpy as np
import pandas as pd
import pytest

from tracking.caliscope import read_board, read_session, write_session
from tracking.errors import InputError
from tracking.frame_times import read_frame_times
from tracking.rig import load_rig


@pytest.fixture()
def caliscope(shared_data: Path) -> Path:
    folder = shared_data / "caliscope"
    if not folder.is_dir():
        pytest.skip("the caliscope footage is not in ../shared/data")
    return folder


def import_caliscope(session: Path, out: Path) -> subprocess.CompletedProcess:
    """`topside import-caliscope SESSION -o OUT`, which must succeed."""
    result = subprocess.run([sys.executable, "-m", "tracking.cli", "import-caliscope", str(session), "-o", str(out)],
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    return result


def video_frames(path: Path) -> int:
    with av.open(str(path)) as container:
        return sum(1 for _ in container.decode(video=0))


def test_a_sessions_frames_count_from_its_videos_first(caliscope: Path, tmp_path: Path) -> None:
    """charuco_calibration's timestamps.csv numbers its frames 26-136 (cut from a longer recording); its videos hold
    111 frames from 0: the times go to frames 0-110, each camera's in sync_index order."""
    session = read_session(caliscope / "charuco_calibration")
    rig = load_rig(write_session(session, tmp_path))
    assert [c.name for c in rig.cameras] == ["cam_0", "cam_1", "cam_2", "cam_3"] and not session.left_out
    source = pd.read_csv(caliscope / "charuco_calibration" / "calibration" / "extrinsic" / "timestamps.csv")
    assert source["frame_index"].min() == 26
    for cam in rig.cameras:
        times = read_frame_times(rig.resolve(cam.times))
        assert len(times) == video_frames(rig.resolve(cam.source)) == 111 and np.isfinite(times).all()
        rows = source[source["cam_id"] == int(cam.name[-1])].sort_values("sync_index")
        assert np.allclose(times, rows["frame_time"] - source["frame_time"].min(), atol=1e-6)
    assert rig.marker_size == pytest.approx(0.0405) and rig.inverted and rig.dictionary == "DICT_4X4_1000"
    assert sorted(m.id for m in rig.markers if m.body == "topside") == [0, 1, 2, 3, 4]
    truth = pd.read_csv(tmp_path / "truth.csv")
    assert list(truth.columns) == ["time", "cone", "dx", "dy", "dz"] and (truth[["dx", "dy", "dz"]] == 0).all().all()


def older_layout(caliscope: Path, tmp_path: Path) -> Path:
    """post_optimization laid out as caliscope's older sessions are: one config.toml with [cam_N] tables (port) and
    [charuco] (the misspelt square_size_overide_cm), port_N.mp4 videos, frame_time_history.csv (port,
    frame_index); cam_1 shown turned by caliscope, cam_2 marked ignore."""
    src = caliscope / "post_optimization"
    out = tmp_path / "old"
    (out / "calibration" / "extrinsic").mkdir(parents=True)
    import tomllib

    cameras = tomllib.loads((src / "camera_array.toml").read_text())["cameras"]
    lines = ["fps_recording = 6", ""]
    for key, cam in cameras.items():
        lines += [f"[cam_{key}]", f"port = {key}", f"size = {cam['size']}", f"matrix = {cam['matrix']}",
                  f"distortions = {cam['distortions']}", f"error = {cam['error']}",
                  f"rotation_count = {1 if key == '1' else 0}", f"ignore = {'true' if key == '2' else 'false'}", ""]
    lines += ["[charuco]", "columns = 4", "rows = 5", "board_height = 11.0", "board_width = 8.5",
              'dictionary = "DICT_4X4_1000"', 'units = "inch"', "aruco_scale = 0.75", "square_size_overide_cm = 5.4",
              "inverted = true"]
    (out / "config.toml").write_text("\n".join(lines) + "\n")
    times = pd.read_csv(src / "calibration" / "extrinsic" / "timestamps.csv").rename(columns={"cam_id": "port"})
    times.insert(2, "frame_index", times["sync_index"] + 100)
    times.to_csv(out / "calibration" / "extrinsic" / "frame_time_history.csv", index=False)
    for k in range(4):
        shutil.copy(src / "calibration" / "extrinsic" / f"cam_{k}.mp4",
                    out / "calibration" / "extrinsic" / f"port_{k}.mp4")
    return out


def test_an_older_sessions_layout_makes_the_same_rig(caliscope: Path, tmp_path: Path) -> None:
    new = load_rig(write_session(read_session(caliscope / "post_optimization"), tmp_path / "new"))
    session = read_session(older_layout(caliscope, tmp_path))
    old = load_rig(write_session(session, tmp_path / "from-old"))
    assert [c.name for c in old.cameras] == ["cam_0", "cam_1", "cam_3"]  # cam_1 turned for display only
    assert len(session.left_out) == 1 and "cam_2" in session.left_out[0] and "ignore" in session.left_out[0]
    assert old.marker_size == new.marker_size and old.markers == new.markers and old.inverted == new.inverted
    for name in ("cam_0", "cam_1", "cam_3"):
        a = read_frame_times(tmp_path / "new" / "times" / f"{name}.csv")
        b = read_frame_times(tmp_path / "from-old" / "times" / f"{name}.csv")
        assert np.array_equal(a, b)
        assert (tmp_path / "new" / "calibration" / f"{name}.yaml").read_text() == \
            (tmp_path / "from-old" / "calibration" / f"{name}.yaml").read_text()


def test_a_board_stated_by_its_size_gets_the_largest_square_that_fits() -> None:
    board = read_board(Path("charuco.toml"), {"columns": 4, "rows": 5, "board_height": 11.0, "board_width": 8.5,
                                              "units": "inch", "aruco_scale": 0.75, "dictionary": "DICT_4X4_50"})
    assert board.square_m == pytest.approx(min(11.0 / 5, 8.5 / 4) / 0.393701 / 100)  # 5.4 cm: width-bound
    assert board.marker_m == pytest.approx(0.75 * board.square_m) and not board.inverted
    markers = board.markers()
    assert len(markers) == 10 and abs(np.mean([m.center for m in markers], axis=0)).max() < 0.03  # about the centre


def test_a_board_with_more_markers_than_its_pool_takes_the_next_pool_of_its_family() -> None:
    """As caliscope does: DICT_4X4_50 cannot hold a 20 × 20 board's 200 markers, DICT_4X4_250 can."""
    board = read_board(Path("charuco.toml"), {"columns": 20, "rows": 20, "square_size_override_cm": 2,
                                              "dictionary": "DICT_4X4_50"})
    assert board.dictionary == "DICT_4X4_250" and len(board.markers()) == 200


@pytest.mark.parametrize(("table", "field"), [({"rows": 5}, "columns"), ({"columns": 4, "rows": 0}, "rows"),
                                              ({"columns": 4.7, "rows": 5}, "columns"),
                                              ({"columns": 10**7, "rows": 5}, "columns"),
                                              ({"columns": 1, "rows": 1}, "columns"),
                                              ({"columns": 60, "rows": 60, "square_size_override_cm": 1,
                                                "dictionary": "DICT_4X4_50"}, "dictionary"),
                                              ({"columns": 4, "rows": 5, "dictionary": "DICT_9X9"}, "dictionary"),
                                              ({"columns": 4, "rows": 5, "square_size_override_cm": 5,
                                                "aruco_scale": 1.5}, "aruco_scale")])
def test_a_bad_board_is_named(table: dict, field: str) -> None:
    with pytest.raises(InputError) as info:
        read_board(Path("charuco.toml"), table)
    assert f"charuco.toml: {field}: " in str(info.value)


def test_import_caliscope_refuses_a_folder_that_is_no_session_in_one_line(tmp_path: Path) -> None:
    bad = subprocess.run([sys.executable, "-m", "tracking.cli", "import-caliscope", str(tmp_path), "-o",
                          str(tmp_path / "x")], capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and "no charuco.toml" in bad.stderr and len(bad.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "x").exists()


def test_a_session_of_intrinsic_videos_alone_says_so_and_how_to_track_one(caliscope: Path, tmp_path: Path) -> None:
    """caliscope's prerecorded_calibration: charuco.toml, a config.toml without camera tables and each camera's own
    intrinsic video, filmed one at a time. Refused in one line that names what it holds and how to track one alone."""
    session = tmp_path / "session"
    (session / "calibration" / "intrinsic").mkdir(parents=True)
    shutil.copy(caliscope / "charuco_calibration" / "charuco.toml", session / "charuco.toml")
    (session / "config.toml").write_text("CreationDate = 2023-05-06T11:12:27.631355\n")
    for n in (0, 1):
        (session / "calibration" / "intrinsic" / f"cam_{n}.mp4").write_bytes(b"")
    bad = subprocess.run([sys.executable, "-m", "tracking.cli", "import-caliscope", str(session), "-o",
                          str(tmp_path / "x")], capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1
    assert "no camera tables in config.toml" in bad.stderr
    assert "calibration/intrinsic holds cam_0.mp4, cam_1.mp4, each camera filmed on its own" in bad.stderr
    assert not (tmp_path / "x").exists()


@pytest.mark.parametrize(("edit", "field"), [
    (lambda t: t.replace("[cameras.0]\ncam_id =0", '[cameras.0]\ncam_id ="front"'), "0"),
    (lambda t: t.replace("rotation_count = 0", 'rotation_count = "none"', 1), "cam_0.rotation_count"),
    (lambda t: t.replace("size = [1280, 720]", "size = [1280.5, 720]", 1), "cam_0"),
    (lambda t: t.replace("matrix = [[", "matrix = [[1.0], [", 1), "cam_0")])
def test_a_bad_camera_table_is_named_in_one_line(caliscope: Path, tmp_path: Path, edit, field: str) -> None:
    session = tmp_path / "session"
    shutil.copytree(caliscope / "post_optimization", session)
    array = session / "camera_array.toml"
    array.write_text(edit(array.read_text()))
    with pytest.raises(InputError) as info:
        read_session(session)
    assert f"camera_array.toml: {field}: " in str(info.value) and "\n" not in str(info.value)


def test_a_times_file_with_a_camera_that_is_no_number_is_named(caliscope: Path, tmp_path: Path) -> None:
    session = tmp_path / "session"
    shutil.copytree(caliscope / "post_optimization", session)
    times = session / "calibration" / "extrinsic" / "timestamps.csv"
    times.write_text(times.read_text().replace("\n35,2,", "\n35,2.5,", 1))
    with pytest.raises(InputError) as info:
        read_session(session)
    assert "timestamps.csv: cam_id: line 2: expected a whole number" in str(info.value)


def test_a_board_no_rig_can_hold_writes_nothing(caliscope: Path, tmp_path: Path) -> None:
    """A square of 200 m (a typo for cm): the rig refuses its markers' size before any file is written."""
    session = tmp_path / "session"
    shutil.copytree(caliscope / "post_optimization", session)
    board = session / "charuco.toml"
    board.write_text(board.read_text().replace("square_size_override_cm = 5.4", "square_size_override_cm = 20000"))
    with pytest.raises(InputError) as info:
        write_session(read_session(session), tmp_path / "out")
    assert "marker_size" in str(info.value) and not (tmp_path / "out").exists()


def session_copy(caliscope: Path, tmp_path: Path) -> Path:
    session = tmp_path / "session"
    shutil.copytree(caliscope / "post_optimization", session)
    return session


def test_a_dropped_frames_row_shifts_only_the_frames_after_it(caliscope: Path, tmp_path: Path) -> None:
    """One row a video frame: a camera whose sync 40 has no row (the synchroniser dropped it) numbers its frames by
    their order, whatever caliscope's own frame counter says."""
    session = session_copy(caliscope, tmp_path)
    path = session / "calibration" / "extrinsic" / "timestamps.csv"
    df = pd.read_csv(path)
    df = df[~((df["cam_id"] == 0) & (df["sync_index"] == 40))].assign(frame_index=lambda d: d["sync_index"])
    df.to_csv(path, index=False)
    times = read_session(session).times[0]
    assert list(times["frame"]) == list(range(56))
    rows = df[df["cam_id"] == 0].sort_values("sync_index")
    assert np.allclose(times["time"], rows["frame_time"] - df["frame_time"].min(), atol=1e-6)


def test_the_newest_caliscope_layout_is_read(caliscope: Path, tmp_path: Path) -> None:
    """caliscope's newest files: timestamps.csv of cam_id and frame_time alone, the board in
    calibration/targets/extrinsic_charuco.toml without units (inches, its default), an uncalibrated camera's
    matrix written as the string "null" (calibrated from its own video of the board, and said so)."""
    session = session_copy(caliscope, tmp_path)
    path = session / "calibration" / "extrinsic" / "timestamps.csv"
    pd.read_csv(path)[["cam_id", "frame_time"]].to_csv(path, index=False)
    board = (session / "charuco.toml").read_text().replace('units = "inch"\n', "")
    (session / "charuco.toml").unlink()
    (session / "calibration" / "targets").mkdir()
    (session / "calibration" / "targets" / "extrinsic_charuco.toml").write_text(board)
    array = session / "camera_array.toml"
    text = array.read_text()
    start = text.index("[cameras.3]")
    array.write_text(text[:start] + text[start:].replace("matrix = [[", 'matrix = "null"\nold = [[', 1))
    loaded = read_session(session)
    assert [c.number for c in loaded.cameras] == [0, 1, 2, 3] and not loaded.left_out
    assert any(x.startswith("cam_3: no intrinsics in camera_array.toml: calibrated from calibration/extrinsic/cam_3")
               for x in loaded.notes)
    assert loaded.board.marker_m == pytest.approx(0.0405)
    reference = read_session(caliscope / "post_optimization")
    assert all(np.array_equal(loaded.times[k], reference.times[k]) for k in (0, 1, 2))


@pytest.mark.parametrize(("edit", "message"), [
    (lambda t: t.replace("[cameras.1]\ncam_id =1", "[cameras.1]\ncam_id =0"), "camera 0 is given twice"),
    (lambda t: t.replace("ignore = false", 'ignore = "no"', 1), "cam_0.ignore: expected true or false")])
def test_camera_tables_that_contradict_themselves_are_named(caliscope: Path, tmp_path: Path, edit, message: str
                                                            ) -> None:
    session = session_copy(caliscope, tmp_path)
    array = session / "camera_array.toml"
    array.write_text(edit(array.read_text()))
    with pytest.raises(InputError, match=message):
        read_session(session)


def test_a_frame_listed_twice_is_named_in_the_sessions_file(caliscope: Path, tmp_path: Path) -> None:
    session = session_copy(caliscope, tmp_path)
    path = session / "calibration" / "extrinsic" / "timestamps.csv"
    df = pd.read_csv(path)
    pd.concat([df, df.iloc[[0]]]).to_csv(path, index=False)
    with pytest.raises(InputError) as info:
        read_session(session)
    assert "timestamps.csv: frame_time: line" in str(info.value) and "is not after the one before it" in str(info.value)


def test_a_session_without_a_times_file_takes_its_videos_own_times_and_says_so(caliscope: Path,
                                                                               tmp_path: Path) -> None:
    """caliscope's post_monocal layout has no timestamps.csv: each frame's time is its video's presentation time
    (nominal k / 6 s here), a line says so, and the truth covers those times."""
    src = caliscope / "post_optimization"
    session_dir = tmp_path / "post_monocal"
    shutil.copytree(src, session_dir, ignore=shutil.ignore_patterns("timestamps.csv"))
    out = tmp_path / "out"
    result = import_caliscope(session_dir, out)
    assert "no timestamps.csv" in result.stderr and "video's own" in result.stderr
    rig = load_rig(out / "rig.yaml")
    for cam in rig.cameras:
        times = read_frame_times(rig.resolve(cam.times))
        assert len(times) == video_frames(rig.resolve(cam.source)) == 57
        assert np.allclose(times, np.arange(57) / 6.0, atol=1e-5)
    truth = pd.read_csv(out / "truth.csv")
    assert np.allclose(truth["time"], np.arange(57) / 6.0, atol=1e-5)


def test_a_session_without_intrinsics_calibrates_each_camera_from_its_own_video(caliscope: Path,
                                                                                tmp_path: Path) -> None:
    """No camera_array.toml (only the board, the videos and their times): every camera is calibrated from its own
    video of the board, said camera by camera, and stated at 0.5 px (the board over 12-28 % of the picture); its focal
    length within 4 % of caliscope's own calibration, which the test reads from the file it left out."""
    import tomllib

    from tracking.camera import load_camera

    src = caliscope / "charuco_calibration"
    session_dir = tmp_path / "no_intrinsics"
    shutil.copytree(src, session_dir, ignore=shutil.ignore_patterns("camera_array.toml"))
    out = tmp_path / "out"
    result = import_caliscope(session_dir, out)
    assert result.stderr.count("calibrated from calibration/extrinsic/cam_") == 4
    theirs = tomllib.loads((src / "camera_array.toml").read_text())["cameras"]
    rig = load_rig(out / "rig.yaml")
    assert [c.name for c in rig.cameras] == ["cam_0", "cam_1", "cam_2", "cam_3"]
    for k, c in enumerate(rig.cameras):
        camera = load_camera(rig.resolve(c.calibration))
        assert camera.K[0, 0] == pytest.approx(theirs[str(k)]["matrix"][0][0], rel=0.04) and camera.rms == 0.5


def test_a_camera_calibrated_from_its_video_is_named_relative_to_its_session(caliscope: Path, tmp_path: Path) -> None:
    """A video reached another way than its session (a rig elsewhere names it through '..' and a link): it is named
    as the session holds it, not by the path it was reached through."""
    from tracking.caliscope import calibrate_camera, session_board

    session = caliscope / "post_optimization"
    (tmp_path / "x").mkdir()
    (tmp_path / "link").symlink_to(session, target_is_directory=True)
    video = tmp_path / "x" / ".." / "link" / "calibration" / "extrinsic" / "cam_1.mp4"
    result, said = calibrate_camera(session, video, 1, session_board(session))
    assert result is not None and said.startswith("calibrated from calibration/extrinsic/cam_1.mp4 (")
