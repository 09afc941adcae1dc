"""The field guide's worked example, run with the guide's commands in the guide's order on a copy of docs/example."""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "docs" / "example"
GUIDE = REPO / "docs" / "field-guide.md"
TOPSIDE = [sys.executable, "-m", "tracking.cli"]


def guide_commands() -> list[list[str]]:
    """The `topside ...` lines of the guide's worked example, in order, with each shell glob expanded later."""
    text = GUIDE.read_text().split("## The worked example", 1)[1]
    block = re.search(r"```bash\n(.*?)```", text, re.S)
    assert block is not None
    return [line.split("#")[0].split() for line in block.group(1).splitlines() if line.startswith("topside ")]


@pytest.fixture(scope="module")
def example(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("example") / "example"
    shutil.copytree(EXAMPLE, folder, ignore=shutil.ignore_patterns("build.py"))
    return folder


def run(args: list[str], folder: Path) -> subprocess.CompletedProcess:
    """One guide command, its globs expanded in the example's folder."""
    expanded = []
    for a in args[1:]:
        expanded += sorted(str(p.relative_to(folder)) for p in folder.glob(a)) if "*" in a else [a]
    return subprocess.run([*TOPSIDE, *expanded], cwd=folder, capture_output=True, text=True, timeout=300)


def test_the_guide_runs_from_photos_to_a_verified_archive(example: Path) -> None:
    commands = guide_commands()
    assert [c[1] for c in commands][:1] == ["calibrate"] and [c[1] for c in commands][-2:] == ["export", "verify"]
    for args in commands:
        proc = run(args, example)
        expected = 1 if args[1] == "check" else 0  # the guide's example is not ready: it says why (below)
        assert proc.returncode == expected, f"{' '.join(args)}\n{proc.stdout}\n{proc.stderr}"
        assert "Traceback" not in proc.stderr
        if args[1] == "check":
            assert "cone A: ready" in proc.stdout and "cone D: weak: seen by drone_D1;" in proc.stdout
            assert "cone B: blind: no marker at B" in proc.stdout and "no camera sees: 6, 7" in proc.stdout
        if args[1] == "verify":
            assert "run.mcap: OK" in proc.stdout
    assert {p.name for p in (example / "calibration").iterdir()} == {"stern_A.yaml", "drone_A.yaml", "drone_D1.yaml"}
    offsets = pd.read_csv(example / "offsets.csv")
    assert set(offsets["cone"]) == {"A", "B", "C", "D"}
    shown = offsets.groupby("cone")["dx"].apply(lambda dx: dx.notna().mean())
    assert shown["A"] > 0.9 and shown["D"] > 0.3  # A by two cameras, D by one drone; B and C are blind, as check said
    assert offsets.loc[offsets["dx"].isna(), "withheld"].notna().all()  # every row not shown says why
    assert (example / "run.mcap").is_file()
