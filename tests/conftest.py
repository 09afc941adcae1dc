"""Shared fixtures: the real reference data in ../shared/data, and a small rendered installation, tracked."""

from __future__ import annotations

import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from tests.synthetic import PAPER_DIST, made_once, render_installation

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = REPO.parent / "shared" / "data"


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """The real photos with published results; skips when the folder is absent."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"reference data not found at {SHARED_DATA}")
    return SHARED_DATA


FRAMES = 12
T0 = 100.0
FPS = 15.0


def motion(t: float) -> np.ndarray:
    """The topside's true offset at capture time t: a ramp in x and y at constant height."""
    s = (t - T0) / (FRAMES / FPS)
    return np.array([0.6 * s, -0.3 + 0.3 * s, 0.4])


@pytest.fixture(scope="session")
def installation(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Cone A with two faces filmed by two unsynchronised cameras: rig, calibration, H.264 videos, truth.csv (made
    once per run for every worker: read it, write beside it in a test's own folder)."""

    def make(folder: Path) -> None:
        folder.mkdir()
        t = T0 + np.arange(FRAMES) / FPS
        render_installation(folder, motion, {"cam-ahead": t, "cam-port": t + 1 / 30}, PAPER_DIST)

    return made_once(tmp_path_factory, "installation", make)


@dataclass(frozen=True)
class Archived:
    """The files of one `topside track --rrd --mcap` run."""

    rrd: Path
    mcap: Path
    offsets: Path


@pytest.fixture(scope="session")
def archived(installation: Path, tmp_path_factory: pytest.TempPathFactory) -> Archived:
    """The installation tracked once per run into a recording, an archive and the offsets CSV."""

    def make(out: Path) -> None:
        out.mkdir()
        proc = subprocess.run([sys.executable, "-m", "tracking.cli", "track", "--rig", str(installation / "rig.yaml"),
                               "--truth", str(installation / "truth.csv"), "-o", str(out / "offsets.csv"),
                               "--rrd", str(out / "run.rrd"), "--mcap", str(out / "run.mcap"),
                               "--vessel", "Sleipnir", "--operator", "J. Doe"],
                              capture_output=True, text=True, timeout=120)
        assert proc.returncode == 0, proc.stderr

    out = made_once(tmp_path_factory, "archived", make)
    return Archived(out / "run.rrd", out / "run.mcap", out / "offsets.csv")
