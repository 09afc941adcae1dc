"""Layouts: successive layouts through one blueprint stream, read back from the file, without memory growth."""

import os
import uuid
from pathlib import Path

import pytest
import rerun as rr
import rerun.blueprint as rrb
from rerun.chunk import RrdReader

from tracking.rig import load_rig
from viewer.blueprint import LayoutSender, analysis_blueprint
from viewer.recording import TIMELINE
from viewer.superintendent import superintendent_blueprint

SENDS = 100
LEAK_LIMIT_MB = 20.0  # rerun's own send_blueprint grew ~0.6 MB a call with this layout: 60 MB over SENDS


def rss_mb() -> float:
    """Resident memory of this process, MB (Linux)."""
    for line in Path(f"/proc/{os.getpid()}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    raise AssertionError("no VmRSS")


def layout(name: str) -> rrb.Blueprint:
    """A layout of 20 plots, the first named."""
    return rrb.Blueprint(rrb.Horizontal(*[rrb.TimeSeriesView(origin=f"a/{i}", name=name if i == 0 else f"plot {i}")
                                          for i in range(20)]))


def latest_layout_names(path: Path) -> list[str]:
    """Display names of the views in the layout that is active last in the file's blueprint."""
    reader = RrdReader(path)
    [store] = reader.blueprints()
    rows: dict[str, list[tuple[int, dict]]] = {}
    for chunk in reader.stream(store=store):
        data = chunk.to_record_batch().to_pydict()
        for k in range(chunk.num_rows):
            rows.setdefault(chunk.entity_path, []).append((data["blueprint"][k], {c: data[c][k] for c in data}))
    root = max(rows["/viewport"], key=lambda r: r[0])[1]["ViewportBlueprint:root_container"][0]
    contents = rows[f"/container/{uuid.UUID(bytes=bytes(root))}"][-1][1]["ContainerBlueprint:contents"]
    return [rows[f"/{v.lstrip('/')}"][-1][1]["ViewBlueprint:display_name"][0] for v in contents]


def test_the_last_layout_sent_is_the_one_in_the_file(tmp_path: Path) -> None:
    rr.set_strict_mode(True)
    rec = rr.RecordingStream("topside")
    rec.set_sinks(rr.FileSink(tmp_path / "run.rrd"))
    rr.log("a/0", rr.Scalars(1.0), recording=rec)
    sender = LayoutSender("topside")
    sender.send(rec, layout("first"))
    sender.send(rec, layout("second"))
    rec.flush()
    rec.disconnect()
    names = latest_layout_names(tmp_path / "run.rrd")
    assert names[0] == "second" and len(names) == 20


def test_sending_layouts_does_not_grow_memory(tmp_path: Path) -> None:
    rec = rr.RecordingStream("topside")
    rec.set_sinks(rr.FileSink(tmp_path / "run.rrd", write_footer=False))
    sender = LayoutSender("topside")
    sender.send(rec, layout("warm-up"))
    before = rss_mb()
    for k in range(SENDS):
        sender.send(rec, layout(f"layout {k}"))
    rec.flush()
    assert rss_mb() - before < LEAK_LIMIT_MB
    rec.disconnect()


def time_panel_timeline(path: Path) -> str:
    """The timeline a saved layout's time panel shows."""
    reader = RrdReader(path)
    [store] = reader.blueprints()
    rows = [chunk.to_record_batch().to_pydict() for chunk in reader.stream(store=store)
            if chunk.entity_path == "/time_panel"]
    return rows[-1]["TimePanelBlueprint:timeline"][-1][0]


@pytest.mark.parametrize("layout", ["superintendent", "analysis"])
def test_both_layouts_open_on_the_capture_time(installation: Path, tmp_path: Path, layout: str) -> None:
    # Without a timeline named, the web viewer opened a live replay on a camera's frame numbers (frame_stern_A):
    # the trend plots' axes in frames, the last minute's window not a minute
    rig = load_rig(installation / "rig.yaml")
    blueprint = (superintendent_blueprint(rig, {"A": "cam-ahead"}) if layout == "superintendent"
                 else analysis_blueprint(rig, with_truth=True))
    blueprint.save("topside", tmp_path / "layout.rbl")
    assert time_panel_timeline(tmp_path / "layout.rbl") == TIMELINE == "capture_time"
