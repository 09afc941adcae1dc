"""sync and survey write the rig file they read, edited: comments, order and style kept, only what changed set."""

from __future__ import annotations

import shutil
from pathlib import Path

from tracking.fieldwork import write_rig
from tracking.rig import Marker, load_rig

RIG = """\
# Rig of cone A, from survey report S-114 (2026-05-01, J. Smith, total station TS-16)
name: edited   # as on the drawings
dictionary: DICT_6X6_250
marker_size: 1.0  # the black square, measured on the print
cones: {A: [-12.0, -12.0, 0.0]}
markers:
# jacket, leg A1
- {id: 1, body: jacket, cone: A, face: ahead, center: [-12.0, -12.8, -1.5]}
- id: 2
  body: topside
  cone: A
  face: ahead
  rotation_deg: 90   # mounted turned: its top to port
  center:            # bolted to the padeye
  - -12.0
  - -12.8
  - 0.3
cameras:
- name: cam-ahead    # the drone over A
  calibration: calibration/cam-ahead.yaml
  source: cam-ahead.mp4
  time_offset: 100.0   # from the drone's log
  mount: drone
"""


def test_an_edited_rig_keeps_its_comments_and_layout(installation: Path, tmp_path: Path) -> None:
    """A clock and a marker's pose changed, written to another folder: the file reads back as the new rig, every
    comment and untouched line is as written, the replaced orientation (rotation_deg) gone, paths made relative."""
    folder = tmp_path / "site"
    (folder / "calibration").mkdir(parents=True)
    shutil.copy(installation / "calibration" / "cam-ahead.yaml", folder / "calibration")
    shutil.copy(installation / "cam-ahead.mp4", folder)
    (folder / "rig.yaml").write_text(RIG)
    source = load_rig(folder / "rig.yaml")
    R = [[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]]
    marker = Marker(id=2, body="topside", cone="A", face="ahead", center=[-12.0, -12.8, 0.31], R=R)
    camera = source.cameras[0].model_copy(update={"time_offset": 100.0125, "time_offset_sigma": 0.0004})
    new = source.model_copy(update={"markers": [source.markers[0], marker], "cameras": [camera]})
    out = tmp_path / "results" / "synced.yaml"
    out.parent.mkdir()
    write_rig(new, out, source)
    text = out.read_text()
    written = load_rig(out)
    assert written.markers[1].R == R and written.markers[1].rotation_deg is None
    assert written.cameras[0].time_offset == 100.0125 and written.cameras[0].time_offset_sigma == 0.0004
    assert written.resolve(written.cameras[0].source).resolve() == (folder / "cam-ahead.mp4").resolve()
    for line in RIG.splitlines():
        if "#" in line and "rotation_deg" not in line and "time_offset" not in line:
            assert line.split("#", 1)[1] in text, line  # every comment kept
    assert text.startswith(RIG.split("markers:")[0])  # the header, untouched, as written
    assert "- {id: 1, body: jacket, cone: A, face: ahead, center: [-12.0, -12.8, -1.5]}" in text  # its flow style
    assert "  - 0.31\n" in text and "  - -12.8\n" in text  # a block list edited in place
    assert "  time_offset: 100.0125 # from the drone's log" in text
    assert "  R:\n  - [0.0, -1.0, 0.0]\n" in text  # a new key as save_rig lays it out
    assert list(out.parent.iterdir()) == [out]  # written atomically: nothing else left


def test_without_a_source_file_the_rig_is_written_whole(installation: Path, tmp_path: Path) -> None:
    rig = load_rig(installation / "rig.yaml")
    write_rig(rig, tmp_path / "copy.yaml")
    assert load_rig(tmp_path / "copy.yaml").model_dump(exclude={"path", "cameras"}) == rig.model_dump(
        exclude={"path", "cameras"})
