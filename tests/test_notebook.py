"""The accuracy notebook runs top to bottom (nbclient, a real kernel) on a small tracked run."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import nbformat
from nbclient import NotebookClient

from tests.conftest import REPO


def test_accuracy_notebook_executes(installation: Path, tmp_path: Path, monkeypatch) -> None:
    offsets = tmp_path / "offsets.csv"
    proc = subprocess.run([sys.executable, "-m", "tracking.cli", "track", "--rig", str(installation / "rig.yaml"),
                           "-o", str(offsets)], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    monkeypatch.setenv("TOPSIDE_SCENE", str(installation))
    monkeypatch.setenv("TOPSIDE_OFFSETS", str(offsets))
    monkeypatch.delenv("MPLBACKEND", raising=False)  # the kernel's inline backend makes the PNGs
    nb = nbformat.read(REPO / "notebooks" / "accuracy.ipynb", as_version=4)
    NotebookClient(nb, timeout=120, kernel_name="python3", resources={"metadata": {"path": str(REPO)}}).execute()
    outputs = [o for cell in nb.cells if cell.cell_type == "code" for o in cell.get("outputs", [])]
    text = "".join(o.get("text", "") for o in outputs if o.get("output_type") == "stream")
    assert "24 estimates of cones ['A']" in text
    assert "availability" in text
    tables = [o for o in outputs if o.get("output_type") == "execute_result" and "text/html" in o.get("data", {})]
    assert tables and "e_MAE [m]" in tables[0]["data"]["text/html"]
    assert any("image/png" in o.get("data", {}) for o in outputs)  # the Fig. 12 plot
