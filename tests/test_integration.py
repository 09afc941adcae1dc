"""The simulator and the tracker meet only through files: videos, rig, calibration, truth."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from tracking.camera import load_camera
from tracking.evaluate import errors, read_offsets, read_truth

TOPSIDE = [sys.executable, "-m", "tracking.cli"]


def run(*args: str | Path) -> subprocess.CompletedProcess:
    return subprocess.run([*TOPSIDE, *map(str, args)], capture_output=True, text=True, timeout=300)


def test_calibrate_recovers_the_simulated_camera(tmp_path: Path) -> None:
    assert run("simulate", "calibration-shots", "-o", tmp_path).returncode == 0
    shots = sorted((tmp_path / "calibration_shots" / "camera").glob("*.png"))
    assert len(shots) == 30
    proc = run("calibrate", *shots, "--board", "chessboard:9x6:0.25", "-o", tmp_path / "est.yaml")
    assert proc.returncode == 0, proc.stderr
    true, est = load_camera(tmp_path / "calibration" / "camera.yaml"), load_camera(tmp_path / "est.yaml")
    i, j = [0, 1, 0, 1], [0, 1, 2, 2]
    assert np.abs(est.K[i, j] / true.K[i, j] - 1).max() < 0.005  # fx, fy, cx, cy within 0.5 %
    assert est.rms < 0.1


@pytest.fixture(scope="module")
def clear_scene(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("sim")
    proc = run("simulate", "config2-procedure5-clear", "-o", out, "--duration", "2")
    assert proc.returncode == 0, proc.stderr
    return out


def test_track_simulated_videos_by_capture_time(clear_scene: Path, tmp_path: Path) -> None:
    proc = run("track", "--rig", clear_scene / "rig.yaml", "--mode", "raw", "-o", tmp_path / "raw.csv")
    assert proc.returncode == 0, proc.stderr
    df = read_offsets(tmp_path / "raw.csv")
    frames = pd.read_csv(clear_scene / "truth_frames.csv").drop_duplicates(["camera", "frame_index"])
    assert set(df["cameras"]) == set(frames["camera"])  # every camera sees its full pair
    for cam, rows in df.groupby("cameras"):
        expected = np.sort(frames[frames.camera == cam]["capture_time"].to_numpy())
        np.testing.assert_allclose(np.sort(rows["time"].to_numpy()), expected, atol=1e-4)
    err = errors(df, read_truth(clear_scene / "truth.csv"))
    drones = err[err["cameras"].str.startswith("drone")]
    assert len(drones) > 100
    assert np.median(np.abs(drones[["ex", "ey", "ez"]].to_numpy())) < 0.05  # drones 10-25 m: a few cm


def test_fused_on_simulated_videos(clear_scene: Path, tmp_path: Path) -> None:
    proc = run("track", "--rig", clear_scene / "rig.yaml", "-o", tmp_path / "fused.csv")
    assert proc.returncode == 0, proc.stderr
    df = read_offsets(tmp_path / "fused.csv")
    assert set(df["cone"]) == {"A", "B", "C", "D"}  # every cone of the rig, seen or not
    err = errors(df[df["cone"].isin(["A", "D"])].dropna(subset=["dx"]), read_truth(clear_scene / "truth.csv"))
    late = err[err["time"] > err["time"].min() + 0.5]
    assert len(late) > 50
    assert np.median(np.abs(late[["ex", "ey", "ez"]].to_numpy())) < 0.02
