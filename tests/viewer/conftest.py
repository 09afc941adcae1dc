"""A tracked installation written both as a recording (.rrd) and as an MCAP archive, once per test session."""

from __future__ import annotations

import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest


@dataclass(frozen=True)
class Archived:
    """The files of one `topside track --rrd --mcap` run."""

    rrd: Path
    mcap: Path
    offsets: Path


@pytest.fixture(scope="session")
def archived(installation: Path, tmp_path_factory: pytest.TempPathFactory) -> Archived:
    out = tmp_path_factory.mktemp("archived")
    proc = subprocess.run([sys.executable, "-m", "tracking.cli", "track", "--rig", str(installation / "rig.yaml"),
                           "--truth", str(installation / "truth.csv"), "-o", str(out / "offsets.csv"),
                           "--rrd", str(out / "run.rrd"), "--mcap", str(out / "run.mcap"),
                           "--vessel", "Sleipnir", "--operator", "J. Doe"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    return Archived(out / "run.rrd", out / "run.mcap", out / "offsets.csv")
