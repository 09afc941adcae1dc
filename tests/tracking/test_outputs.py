"""The output rule: outputs never overwrite inputs and appear under their names only when complete."""

from __future__ import annotations

from pathlib import Path

import pytest

from tracking.errors import InputError
from tracking.outputs import Outputs, atomic_path, check_outputs, partial_dir, partial_path, replace_dir, write_text


def test_an_output_that_is_an_input_is_refused(tmp_path: Path) -> None:
    rig = tmp_path / "rig.yaml"
    rig.write_text("x")
    (tmp_path / "link.yaml").symlink_to(rig)
    (tmp_path / "hard.yaml").hardlink_to(rig)
    for name in ("rig.yaml", "link.yaml", "hard.yaml", "./sub/../rig.yaml"):
        with pytest.raises(InputError, match="is an input of this command"):
            check_outputs({"--out": tmp_path / name}, [rig])
    check_outputs({"--out": tmp_path / "offsets.csv"}, [rig])  # a new name is fine
    assert rig.read_text() == "x"


def test_outputs_must_differ_and_not_be_folders(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="also given as --out"):
        check_outputs({"--out": tmp_path / "a.csv", "--rrd": tmp_path / "a.csv"})
    with pytest.raises(InputError, match="is a directory"):
        check_outputs({"--out": tmp_path})
    (tmp_path / "file").write_text("")
    with pytest.raises(InputError, match="not a folder"):
        check_outputs({"--out": tmp_path / "file" / "deeper" / "a.csv"})


def test_atomic_path_renames_when_complete_and_removes_on_failure(tmp_path: Path) -> None:
    target = tmp_path / "offsets.csv"
    target.write_text("earlier")
    with pytest.raises(RuntimeError), atomic_path(target) as partial:
        assert partial.name == "offsets.partial.csv" and partial.exists()
        partial.write_text("half")
        assert target.read_text() == "earlier"  # nothing under the final name while writing
        raise RuntimeError("failed")
    assert target.read_text() == "earlier" and sorted(p.name for p in tmp_path.iterdir()) == ["offsets.csv"]
    with atomic_path(target) as partial:
        partial.write_text("complete")
    assert target.read_text() == "complete" and sorted(p.name for p in tmp_path.iterdir()) == ["offsets.csv"]


def test_a_leftover_temporary_file_is_never_overwritten(tmp_path: Path) -> None:
    target = tmp_path / "run.rrd"
    (tmp_path / "run.partial.rrd").write_text("a killed run's recording")
    partial = partial_path(target)
    assert partial.name == "run.partial-2.rrd"
    assert (tmp_path / "run.partial.rrd").read_text() == "a killed run's recording"


def test_outputs_kept_on_interrupt_only_when_asked(tmp_path: Path) -> None:
    outputs = Outputs(keep_on_interrupt=True)
    with pytest.raises(KeyboardInterrupt), outputs:
        outputs.claim(tmp_path / "a.mcap").write_text("recorded")
        outputs.claim(tmp_path / "b.rrd")  # nothing written yet: removed
        raise KeyboardInterrupt
    assert [p.name for p in outputs.kept] == ["a.partial.mcap"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.partial.mcap"]
    plain = Outputs()
    with pytest.raises(KeyboardInterrupt), plain:
        plain.claim(tmp_path / "c.csv").write_text("x")
        raise KeyboardInterrupt
    assert not (tmp_path / "c.partial.csv").exists() and not (tmp_path / "c.csv").exists()


def test_replace_dir_swaps_a_finished_folder_in(tmp_path: Path) -> None:
    out = tmp_path / "sim"
    out.mkdir()
    (out / "old.txt").write_text("old")
    new = partial_dir(out)
    write_text(new / "rig.yaml", "new")
    replace_dir(new, out)
    assert [p.name for p in out.iterdir()] == ["rig.yaml"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["sim"]
