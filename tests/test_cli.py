"""The `topside` command end to end: real files, real video encode/decode, one-line errors with exit 2."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

from tests.cli_runs import Run, topside_runner
from tests.conftest import FPS, FRAMES, T0, motion

TOPSIDE = [sys.executable, "-m", "tracking.cli"]


@pytest.fixture
def run(capfd: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> Run:
    """`run(*args)`: the command in this test's process (the sigterm test runs a real one)."""
    return topside_runner(capfd, monkeypatch)


def assert_one_line_error(proc: subprocess.CompletedProcess, *fragments: str) -> None:
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert "Traceback" not in proc.stderr
    for fragment in fragments:
        assert fragment in lines[0]


def test_track_raw(run: Run, installation: Path, tmp_path: Path) -> None:
    out = tmp_path / "offsets.csv"
    proc = run("track", "--rig", installation / "rig.yaml", "--mode", "raw", "-o", out)
    assert proc.returncode == 0, proc.stderr
    df = pd.read_csv(out)
    assert list(df.columns) == ["time", "cone", "dx", "dy", "dz", "cameras", "sdx", "sdy", "sdz", "withheld"]
    assert len(df) == 2 * FRAMES  # each camera sees one pair in every frame
    assert df["time"].is_monotonic_increasing
    assert set(df["cameras"]) == {"cam-ahead", "cam-port"}
    ahead = df[df.cameras == "cam-ahead"]
    np.testing.assert_allclose(ahead["time"], T0 + np.arange(FRAMES) / FPS, atol=1e-3)  # capture time
    port = df[df.cameras == "cam-port"]
    np.testing.assert_allclose(port["time"], T0 + 1 / 30 + np.arange(FRAMES) / FPS, atol=1e-3)
    err = ahead[["dx", "dy", "dz"]].to_numpy() - np.array([motion(t) for t in ahead["time"]])
    assert np.abs(err[:, [0, 2]]).max() < 0.03  # lateral and vertical for the camera facing the 'ahead' face
    assert np.abs(err[:, 1]).max() < 0.15  # depth
    assert "cam-ahead" in proc.stdout and "wrote 24 rows" in proc.stdout


def test_track_paper_mode(run: Run, installation: Path, tmp_path: Path) -> None:
    out = tmp_path / "paper.csv"
    proc = run("track", "--rig", installation / "rig.yaml", "--mode", "paper", "-o", out)
    assert proc.returncode == 0, proc.stderr
    df = pd.read_csv(out)
    assert len(df) == 2 * FRAMES
    # dx from the camera on the 'ahead' face, dy from the one on 'port', dz the mean of both (eq. 21)
    last = df.iloc[-1]
    assert last["cameras"] == "cam-ahead cam-port"
    window = np.mean([motion(t) for t in df["time"].to_numpy()[-20:]], axis=0)  # 10 per camera: lags the ramp
    assert last["dx"] == pytest.approx(window[0], abs=0.03)
    assert last["dy"] == pytest.approx(window[1], abs=0.03)
    assert last["dz"] == pytest.approx(window[2], abs=0.03)
    assert np.isnan(df.iloc[0]["dy"])  # the first row has only the first camera's axes


def test_track_fused_is_the_default(run: Run, installation: Path, tmp_path: Path) -> None:
    out = tmp_path / "fused.csv"
    proc = run("track", "--rig", installation / "rig.yaml", "-o", out)
    assert proc.returncode == 0, proc.stderr
    df = pd.read_csv(out)
    assert len(df) == 2 * FRAMES  # one row per frame for the one cone
    assert set(df["cameras"].iloc[1:]) == {"cam-ahead cam-port"}  # both cameras fused from the second frame
    truth = np.array([motion(t) for t in df["time"]])
    err = df[["dx", "dy", "dz"]].to_numpy() - truth
    shown = np.isfinite(err).all(axis=1)
    assert set(df["withheld"][~shown]) == {"σ too large", "warming up", "cameras not yet compared"}  # until both
    # are compared, and under the warm-up's limit
    assert shown[-6:].all() and np.abs(err[shown]).max() < 0.01  # each camera's depth is covered by the other's
    assert (df[["sdx", "sdy", "sdz"]].to_numpy()[shown] < 0.05).all()  # lateral axis
    row = next(line for line in proc.stdout.splitlines() if line.strip("│ ").startswith("A "))  # the cones table
    assert f"{shown.mean():.0%}" in row and "cam-ahead" in row  # its share shown, as the CSV has it
    assert "never shown" not in proc.stderr


def test_evaluate(run: Run, installation: Path, tmp_path: Path) -> None:
    out = tmp_path / "offsets.csv"
    assert run("track", "--rig", installation / "rig.yaml", "--mode", "raw", "-o", out).returncode == 0
    proc = run("evaluate", out, installation / "truth.csv", "--markdown", tmp_path / "acc.md")
    assert proc.returncode == 0, proc.stderr
    table = (tmp_path / "acc.md").read_text()
    rows = {line.split("|")[1].strip(): line for line in table.splitlines() if line.startswith("| ")}
    mae_z = float(rows["z"].split("|")[2])
    assert 0.0 < mae_z < 0.02  # height is lateral for both cameras
    assert "| 24 |" in rows["x"]


def test_detect_json_with_poses(run: Run, installation: Path, tmp_path: Path) -> None:
    proc = run("detect", installation / "cam-ahead.mp4", "--rig", installation / "rig.yaml",
               "--camera", installation / "calibration/cam-ahead.yaml", "--json")
    assert proc.returncode == 0, proc.stderr
    rows = [json.loads(line) for line in proc.stdout.splitlines()]
    assert len(rows) == FRAMES
    assert [m["id"] for m in rows[0]["markers"]] == [1, 2]
    assert rows[0]["markers"][0]["pose"]["choice"] in ("unique", "ambiguous")
    assert 19 < np.linalg.norm(rows[0]["markers"][0]["pose"]["tvec"]) < 22  # camera 20.2 m from marker 1


def test_unknown_ids_in_video_counted(run: Run, installation: Path, tmp_path: Path) -> None:
    rig = yaml.safe_load((installation / "rig.yaml").read_text())
    rig["markers"] = [m for m in rig["markers"] if m["id"] != 2]
    rig["pairs"] = [p for p in rig["pairs"] if p["topside"] != 2]
    for cam in rig["cameras"]:
        cam["calibration"] = str(installation / cam["calibration"])
        cam["source"] = str(installation / cam["source"])
    (tmp_path / "rig.yaml").write_text(yaml.safe_dump(rig))
    proc = run("track", "--rig", tmp_path / "rig.yaml", "-o", tmp_path / "o.csv")
    assert proc.returncode == 0, proc.stderr
    assert f"id 2: {FRAMES}" in proc.stdout


def test_calibrate_cli(run: Run, shared_data: Path, tmp_path: Path) -> None:
    photos = sorted((shared_data / "calibration/opencv-left").glob("left*.jpg"))
    proc = run("calibrate", *photos, "--board", "chessboard:9x6:0.025", "-o", tmp_path / "cam.yaml")
    assert proc.returncode == 0, proc.stderr
    assert "total RMS reprojection error: 0.196" in proc.stdout
    assert "fx =" in proc.stdout and "±" in proc.stdout
    from tracking.camera import load_camera

    assert load_camera(tmp_path / "cam.yaml").K[0, 0] == pytest.approx(532.8, abs=1)


def test_calibrate_from_a_video(run: Run, shared_data: Path, tmp_path: Path) -> None:
    video = shared_data / "caliscope/post_optimization/calibration/extrinsic/cam_1.mp4"
    proc = run("calibrate", video, "--board", "charuco:4x5:0.054:0.0405:DICT_4X4_1000", "--inverted",
               "-o", tmp_path / "cam.yaml")
    assert proc.returncode == 0, proc.stderr
    assert "from 1 file" in proc.stdout and "cam_1.mp4#" in proc.stdout
    assert "states the lens model's error as 0.50 px" in proc.stdout  # the board over a fifth of the picture
    from tracking.camera import load_camera

    camera = load_camera(tmp_path / "cam.yaml")
    assert camera.K[0, 0] == pytest.approx(760.33, rel=0.03) and camera.rms == 0.5


def test_calibrate_warns_partial_coverage(run: Run, shared_data: Path, tmp_path: Path) -> None:
    photos = sorted((shared_data / "aruco/opencv-tutorial").glob("img_0*.jpg"))
    proc = run("calibrate", *photos, "--board", "charuco:5x7:0.04:0.02:DICT_6X6_250", "-o", tmp_path / "c.yaml")
    assert proc.returncode == 0, proc.stderr
    assert "covered only" in proc.stdout


# --- bad input: one line naming the file and field, exit status 2 ---------------------------------------

def test_unreadable_image(run: Run, tmp_path: Path) -> None:
    bad = tmp_path / "broken.png"
    bad.write_bytes(b"not an image")
    assert_one_line_error(run("detect", bad), str(bad), "cannot be read as an image")


def test_unreadable_video(run: Run, tmp_path: Path) -> None:
    bad = tmp_path / "broken.mp4"
    bad.write_bytes(b"\x00" * 1000)
    assert_one_line_error(run("detect", bad), str(bad), "cannot be opened as a video")


def test_unknown_dictionary(run: Run, installation: Path) -> None:
    assert_one_line_error(run("detect", installation / "cam-ahead.mp4", "--dictionary", "DICT_7X7_9"),
                          "--dictionary", "unknown ArUco dictionary 'DICT_7X7_9'")


def test_rig_with_duplicate_id(run: Run, installation: Path, tmp_path: Path) -> None:
    rig = yaml.safe_load((installation / "rig.yaml").read_text())
    rig["markers"][1]["id"] = rig["markers"][0]["id"]
    (tmp_path / "rig.yaml").write_text(yaml.safe_dump(rig))
    assert_one_line_error(run("track", "--rig", tmp_path / "rig.yaml"), str(tmp_path / "rig.yaml"),
                          "duplicate marker id 1")


def test_calibration_missing_field(run: Run, installation: Path, tmp_path: Path) -> None:
    text = (installation / "calibration/cam-ahead.yaml").read_text()
    cam = tmp_path / "cam.yaml"
    cam.write_text("\n".join(line for line in text.splitlines() if not line.startswith("image_height")))
    assert_one_line_error(run("detect", installation / "cam-ahead.mp4", "--camera", cam),
                          str(cam), "image_height: missing")


def test_marker_not_in_rig_in_an_image(run: Run, installation: Path, tmp_path: Path, shared_data: Path) -> None:
    photo = shared_data / "aruco/opencv-tutorial/singlemarkersoriginal.jpg"
    assert_one_line_error(run("detect", photo, "--rig", installation / "rig.yaml"),
                          str(photo), "marker id 23 is not in the rig")


def test_missing_rig_file(run: Run, tmp_path: Path) -> None:
    assert_one_line_error(run("track", "--rig", tmp_path / "nope.yaml"), "nope.yaml", "rig file not found")


# --- outputs: complete under their names, never half-written, nothing recorded lost ------------------------------

def test_live_stopped_by_sigterm_keeps_every_row_under_its_name(installation: Path, tmp_path: Path) -> None:
    import signal
    import time

    out, rrd = tmp_path / "live.csv", tmp_path / "live.rrd"
    proc = subprocess.Popen([*TOPSIDE, "live", "--rig", str(installation / "rig.yaml"), "--rrd", str(rrd), "-o",
                             str(out), "--speed", "0.1"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        while "live:" not in (line := proc.stdout.readline()):
            assert line, proc.stderr.read()
        time.sleep(5.0)  # 0.8 s of video replayed at a tenth of real time: stopped past the middle (a loaded
        # machine starts the replay late: 3 s had left no row)
        proc.send_signal(signal.SIGTERM)
        stdout, stderr = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 0, stderr
    rows = len(pd.read_csv(out))
    assert 0 < rows < 2 * FRAMES  # some, not all
    assert f"wrote {rows} rows to {out}" in stdout
    assert any(line.strip("│ ").startswith("A ") for line in stdout.splitlines())  # the cones table, as track's
    assert not list(tmp_path.glob("*.partial*"))  # everything renamed to its final name
    index = pd.read_csv(tmp_path / "live.segments.csv")
    assert all((tmp_path / f).is_file() for f in index["file"])


def test_live_never_overwrites_an_earlier_session(run: Run, installation: Path, tmp_path: Path) -> None:
    (tmp_path / "live-000.rrd").write_bytes(b"an earlier session")
    proc = run("live", "--rig", installation / "rig.yaml", "--rrd", tmp_path / "live.rrd", "-o", tmp_path / "n.csv",
               "--speed", "inf")
    assert_one_line_error(proc, "live-000.rrd", "never overwrites")
    assert (tmp_path / "live-000.rrd").read_bytes() == b"an earlier session"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["live-000.rrd"]


def test_simulate_replaces_its_own_earlier_folder(run: Run, tmp_path: Path) -> None:
    out = tmp_path / "sim"
    for seed in ("1", "2"):
        proc = run("simulate", "config1-procedure1-clear", "-o", out, "--duration", "0.2", "--seed", seed)
        assert proc.returncode == 0, proc.stderr
    assert yaml.safe_load((out / "scenario.yaml").read_text())["seed"] == 2
    assert sorted(p.name for p in tmp_path.iterdir()) == ["sim"]  # no temporary folder left


def test_recover_an_intact_archive_writes_nothing(run: Run, installation: Path, tmp_path: Path) -> None:
    archive = tmp_path / "run.mcap"
    proc = run("track", "--rig", installation / "rig.yaml", "-o", tmp_path / "o.csv", "--mcap", archive)
    assert proc.returncode == 0, proc.stderr
    before = archive.read_bytes()
    proc = run("verify", archive, "--recover")
    assert proc.returncode == 0, proc.stderr
    assert "nothing to recover" in proc.stdout and ": OK;" in proc.stdout
    assert sorted(p.name for p in tmp_path.iterdir()) == ["o.csv", "run.mcap"]
    assert archive.read_bytes() == before


def changed_rig(installation: Path, folder: Path, **changes) -> Path:
    """The installation's rig with some top-level fields changed (and its camera paths absolute), in folder."""
    data = yaml.safe_load((installation / "rig.yaml").read_text())
    for cam in data["cameras"]:
        cam["source"], cam["calibration"] = str(installation / cam["source"]), str(installation / cam["calibration"])
    cameras = changes.pop("cameras", {})
    for cam in data["cameras"]:
        cam.update(cameras.get(cam["name"], {}))
    data.update(changes)
    (folder / "rig.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
    return folder / "rig.yaml"


def test_track_names_a_wrong_marker_size(run: Run, installation: Path, tmp_path: Path) -> None:
    """The plate's side (1.5 m) entered for the 1 m black square, with one camera's position surveyed: track names the
    marker size in one line, exits 2, and keeps the offsets it wrote with none shown. Without the survey nothing fixes
    the scale, and it says so."""
    truth = pd.read_csv(installation / "truth.csv").iloc[0]
    eye = [float(truth[f"camera_cam-ahead_{a}"]) for a in "xyz"]
    rig = changed_rig(installation, tmp_path, marker_size=1.5,
                      cameras={"cam-ahead": {"position": eye, "position_sigma": 0.05}})
    out = tmp_path / "offsets.csv"
    proc = run("track", "--rig", rig, "-o", out)
    assert_one_line_error(proc, "marker_size", "0.67× their stated size", "black square's side")
    df = pd.read_csv(out)
    assert len(df) and df["dx"].isna().all() and set(df["withheld"].dropna()) <= {"rig error: marker size"}
    plain = run("track", "--rig", installation / "rig.yaml", "-o", tmp_path / "plain.csv")
    assert plain.returncode == 0 and "nothing fixes the scale" in plain.stderr


def test_track_refuses_the_topside_through_its_cones(run: Run, installation: Path, tmp_path: Path) -> None:
    """A marker size half the real one puts the topside about 0.9 m below its cone: those offsets are withheld as a rig
    error, named in one line, exit 2."""
    rig = changed_rig(installation, tmp_path, marker_size=0.5)
    out = tmp_path / "offsets.csv"
    proc = run("track", "--rig", rig, "-o", out)
    assert_one_line_error(proc, "marker_size", "below its cone tips")
    df = pd.read_csv(out)
    assert (df["withheld"] == "rig error: through the cones").any() and not (df["dz"] < -0.1).any()
