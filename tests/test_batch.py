"""`topside batch`: three installations, one broken on purpose (a worker meets it), tracked on two workers; the
manifest's errors as one line naming the file and the field."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from tests.tracking.test_parallel import clip  # noqa: F401 (the simulated clip, a session fixture)
from tracking.batch import load_manifest
from tracking.errors import InputError

TOPSIDE = [sys.executable, "-m", "tracking.cli"]


def broken_rig(scene: Path, folder: Path) -> Path:
    """A scene's rig with one camera's calibration made for another image size: it fails inside a worker."""
    folder.mkdir()
    data = yaml.safe_load((scene / "rig.yaml").read_text())
    for c in data["cameras"]:
        c["source"], c["calibration"] = str(scene / c["source"]), str(scene / c["calibration"])
    calibration = Path(data["cameras"][-1]["calibration"]).read_text()
    (folder / "small.yaml").write_text(calibration.replace("image_width: 920", "image_width: 640"))
    data["cameras"][-1]["calibration"] = "small.yaml"
    (folder / "rig.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
    return folder / "rig.yaml"


def test_batch_goes_on_past_a_broken_installation(clip: Path, installation: Path, tmp_path: Path) -> None:  # noqa: F811
    broken = broken_rig(clip, tmp_path / "broken")
    manifest = tmp_path / "manifest.yaml"
    manifest.write_text(
        "installations:\n"
        f"  - {{rig: {installation / 'rig.yaml'}, out: results/reported, truth: {installation / 'truth.csv'}, "
        "report: true, name: reported}\n"
        f"  - {{rig: {broken}, out: results/broken, name: broken-on-purpose}}\n"
        f"  - {{rig: {installation / 'rig.yaml'}, out: results/cone-a, truth: {installation / 'truth.csv'}, "
        "name: cone-a}\n")
    proc = subprocess.run([*TOPSIDE, "batch", str(manifest), "--workers", "2", "--chunk-frames", "20"],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 1, proc.stderr
    assert "2 of 3 installations" in proc.stdout
    rows = {line.split()[0]: line.split() for line in proc.stdout.splitlines() if line.strip()}
    assert rows["broken-on-purpose"][-1] == "FAILED"
    assert rows["cone-a"][-1] == rows["reported"][-1] == "ok"
    assert int(rows["reported"][1]) == int(rows["cone-a"][1]) == 24  # frames
    (failure,) = [line for line in proc.stderr.splitlines() if "failed" in line]
    assert failure.startswith("topside: broken-on-purpose failed: ") and failure.endswith(
        ": image size: frame is 920x600 but the calibration is for 640x600")
    assert "Traceback" not in proc.stderr
    for name in ("reported", "cone-a"):
        assert (tmp_path / "results" / name / "offsets.csv").read_text().count("\n") > 10
        assert "e_MAE" in (tmp_path / "results" / name / "accuracy.md").read_text()
    assert (tmp_path / "results" / "reported" / "run.rrd").stat().st_size > 10_000  # report: true records the run
    page = (tmp_path / "results" / "reported" / "report.html").read_text()
    (verdict,) = [line for line in proc.stdout.splitlines() if line.startswith("reported: ")]
    assert verdict.removeprefix("reported: ") in page  # the lift's verdict, printed and on its page
    assert not (tmp_path / "results" / "cone-a" / "report.html").exists()
    assert not (tmp_path / "results" / "broken").exists()


@pytest.mark.parametrize(("text", "field", "message"), [
    ("installations:\n  - {rig: a.yaml}\n", "installations[0].out", "missing"),
    ("- {rig: a.yaml, out: a}\n- {rig: b.yaml, out: b, mode: best}\n", "installations[1].mode", "'best' is not a mode"),
    ("- {rig: a.yaml, out: a, colour: red}\n", "installations[0].colour", "not a field"),
    ("- {rig: a.yaml, out: same}\n- {rig: b.yaml, out: same}\n", "installations[1].out", "also installations[0]"),
    ("installations: []\n", "installations", "at least 1"),
    ("- {rig: a.yaml, out: a, name: B}\n- {rig: b.yaml, out: b, name: B}\n", "installations[1].name",
     "'B' is also installations[0]'s name"),
])
def test_manifest_errors_name_the_file_and_field(tmp_path: Path, text: str, field: str, message: str) -> None:
    path = tmp_path / "manifest.yaml"
    path.write_text(text)
    with pytest.raises(InputError) as err:
        load_manifest(path)
    assert err.value.source == str(path) and err.value.field == field and message in err.value.message
    assert "\n" not in str(err.value)


def test_installations_without_names_are_told_apart(tmp_path: Path) -> None:
    """Two rigs in one folder: labelled by their out folders as the manifest writes them; one alone by its rig's."""
    (tmp_path / "manifest.yaml").write_text("- {rig: a.yaml, out: results/a}\n- {rig: b.yaml, out: results/b}\n"
                                            "- {rig: site/rig.yaml, out: results/site}\n")
    assert [i.label for i in load_manifest(tmp_path / "manifest.yaml")] == ["results/a", "results/b", "site"]


def test_manifest_paths_are_relative_to_it(tmp_path: Path) -> None:
    (tmp_path / "m").mkdir()
    (tmp_path / "m" / "manifest.yaml").write_text("- {rig: site/rig.yaml, out: out/site, truth: site/truth.csv}\n")
    (inst,) = load_manifest(tmp_path / "m" / "manifest.yaml")
    assert inst.rig == tmp_path / "m" / "site" / "rig.yaml" and inst.out == tmp_path / "m" / "out" / "site"
    assert inst.truth == tmp_path / "m" / "site" / "truth.csv" and inst.label == "site" and inst.mode == "fused"
