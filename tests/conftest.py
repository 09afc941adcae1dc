"""Shared fixtures: the real reference data in ../shared/data, and a small rendered installation."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tests.synthetic import PAPER_DIST, render_installation

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
    """Cone A with two faces filmed by two unsynchronised cameras: rig, calibration, H.264 videos, truth.csv."""
    folder = tmp_path_factory.mktemp("installation")
    t = T0 + np.arange(FRAMES) / FPS
    render_installation(folder, motion, {"cam-ahead": t, "cam-port": t + 1 / 30}, PAPER_DIST)
    return folder
