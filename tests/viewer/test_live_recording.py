"""The live recording: segments that each open on their own, the superintendent's figures, NO DATA when stale."""

from __future__ import annotations

import dataclasses
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from rerun.chunk import RrdReader

from tracking.estimate import WITHHELD_CLOCKS, WITHHELD_SCALE, WITHHELD_WARMING, ConeEstimate
from viewer.readback import chunks_by_entity, component_rows
from viewer.superintendent import ConeState, clock_text, cone_markdown, cone_reading, cones_line, no_data_reason


@pytest.fixture(scope="module")
def live_run(installation: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("live")
    proc = subprocess.run([sys.executable, "-m", "tracking.cli", "live", "--rig", str(installation / "rig.yaml"),
                           "--rrd", str(out / "live.rrd"), "-o", str(out / "offsets.csv"), "--speed", "inf",
                           "--segment-minutes", str(0.25 / 60)], capture_output=True, text=True, timeout=180)
    assert proc.returncode == 0, proc.stderr
    assert "write_footer" not in proc.stderr  # rerun's warning per footer-less segment is silenced
    return out


def test_segments_each_open_on_their_own(live_run: Path) -> None:
    index = pd.read_csv(live_run / "live.segments.csv")
    assert len(index) >= 3  # 0.8 s of video in 0.25 s segments
    assert (index["start"].iloc[1:].to_numpy() >= index["end"].iloc[:-1].to_numpy() - 0.25).all()
    for name, start, end in index[["file", "start", "end"]].itertuples(index=False):
        chunks = chunks_by_entity(live_run / name)
        if "/offsets/dx/A/estimate" in chunks:  # estimates land in the segment that spans their capture time
            times, _ = component_rows(chunks["/offsets/dx/A/estimate"], "Scalars:scalars")
            assert not times.size or (start - 1e-6 <= times.min() and times.max() <= end + 1e-6)
        for cam in ("cam-ahead", "cam-port"):
            assert component_rows(chunks[f"/world/cameras/{cam}"], "Pinhole:image_from_camera")[1]  # static again
            _, keys = component_rows(chunks[f"/world/cameras/{cam}/image"], "VideoStream:is_keyframe")
            assert keys and keys[0][0]  # every segment starts its video with a keyframe
        assert "/superintendent/cones/A" in chunks
        assert RrdReader(live_run / name).blueprints()  # the first as logged, the others merged from live.rbl
    assert (live_run / "live.rbl").is_file()


def test_superintendent_figures_follow_the_csv(live_run: Path) -> None:
    df = pd.read_csv(live_run / "offsets.csv").dropna(subset=["dx", "dy", "dz"])
    last = pd.read_csv(live_run / "live.segments.csv")["file"].iloc[-1]
    _, docs = component_rows(chunks_by_entity(live_run / last)["/superintendent/cones/A"], "TextDocument:text")
    final = docs[-1][0]
    a = df[df.cone == "A"].iloc[-1]
    assert f"{np.hypot(a.dx, a.dy) * 1000:.0f} mm" in final
    _, table = component_rows(chunks_by_entity(live_run / last)["/superintendent/cameras"], "TextDocument:text")
    assert "cam-ahead" in table[-1][0] and "ended" in table[-1][0]


def estimate(offset: list[float], sd: float = 0.005) -> ConeEstimate:
    return ConeEstimate(10.0, "A", np.array(offset), ("cam",), np.eye(3) * sd**2)


def viewer_safe(text: str) -> bool:
    """Only characters the viewer's font has (Latin, Greek, common punctuation): a missing glyph panics it."""
    return all(ord(c) < 0x250 or 0x370 <= ord(c) < 0x400 or c in "–—·±×…" for c in text)


def test_texts_have_only_glyphs_the_viewer_can_draw(live_run: Path) -> None:
    from tracking.live import CameraHealth
    from tracking.sources import CameraState
    from viewer.superintendent import cameras_markdown

    for state in (estimate([0.03, 0.04, 1.0]), estimate([0.12, 0.1, 0.0]), None):
        assert viewer_safe(cone_markdown(cone_reading(state, "A", 10.1, 10.05)))
    assert viewer_safe(cameras_markdown({s: CameraHealth(s, s, "detail") for s in CameraState}, 10.0))
    texts = ("TextDocument:text", "Boxes3D:labels", "LineStrips2D:labels", "Points2D:labels", "SeriesLines:names")
    for name in pd.read_csv(live_run / "live.segments.csv")["file"]:
        for path, chunks in chunks_by_entity(live_run / name).items():
            for component in texts:
                assert all(viewer_safe(str(v)) for v in component_rows(chunks, component)[1]), path


def test_cone_states() -> None:
    assert cone_reading(estimate([0.03, 0.04, 1.0]), "A", 10.1, 10.05).state == ConeState.GREEN
    assert cone_reading(estimate([0.09, 0.10, 0.0]), "A", 10.1, 10.05).concentricity == pytest.approx(0.1345, abs=1e-4)
    assert cone_reading(estimate([0.09, 0.10, 0.0], sd=0.02), "A", 10.1, 10.05).state == ConeState.AMBER
    assert cone_reading(estimate([0.12, 0.10, 0.0]), "A", 10.1, 10.05).state == ConeState.RED
    stale = cone_reading(estimate([0.0, 0.0, 0.0]), "A", 10.8, 10.2)
    assert stale.state == ConeState.NO_DATA and "NO DATA" in cone_markdown(stale)
    unknown = cone_reading(estimate([np.nan] * 3), "A", 10.1, 10.05)  # the filter's σ beyond its reporting limit
    assert unknown.state == ConeState.NO_DATA and "σ" in cone_markdown(unknown)
    assert no_data_reason(unknown, short=True) == "σ too large"  # the ring's label: no limit that may not be in force
    lone = cone_reading(dataclasses.replace(estimate([np.nan] * 3), covariance=np.diag([0.012, 0.071, 0.009]) ** 2),
                        "A", 10.1, 10.05)  # one camera's line of sight along y
    assert "(σ Δx 12 · Δy 71 · Δz 9 mm)" in cone_markdown(lone) and "well enough along Δy (" in cone_markdown(lone)
    assert viewer_safe(cone_markdown(lone))
    untimed = cone_reading(dataclasses.replace(estimate([np.nan] * 3), withheld=WITHHELD_CLOCKS), "A", 10.1, 10.05)
    assert no_data_reason(untimed, short=True) == "clocks not measured" and "topside sync" in cone_markdown(untimed)
    assert viewer_safe(cone_markdown(untimed))
    warming = cone_reading(dataclasses.replace(estimate([np.nan] * 3), withheld=WITHHELD_WARMING,
                                               covariance=np.diag([0.03, 0.02, 0.01]) ** 2), "A", 10.1, 10.05)
    assert no_data_reason(warming, short=True) == "warming up"  # not "σ too large": it would be shown in a second
    assert "first 4 s" in cone_markdown(warming) and "(σ Δx 30 · Δy 20 · Δz 10 mm)" in cone_markdown(warming)
    assert viewer_safe(cone_markdown(warming))
    older = cone_reading(dataclasses.replace(estimate([np.nan] * 3), covariance=np.diag([0.03, 0.02, 0.01]) ** 2,
                                             withheld="σ too large"), "A", 10.1, 10.05)  # a recording from before
    # 'warming up': its warm-up rows say σ too large at a σ within 50 mm
    assert "first 4 s" in cone_markdown(older) and "1σ above" not in cone_markdown(older)
    wrong = cone_reading(dataclasses.replace(estimate([np.nan] * 3), withheld=WITHHELD_SCALE), "A", 10.1, 10.05)
    assert no_data_reason(wrong, short=True) == "rig error: marker size" and "topside check" in cone_markdown(wrong)
    assert viewer_safe(cone_markdown(wrong))
    old_news = cone_reading(dataclasses.replace(estimate([np.nan] * 3), withheld=WITHHELD_CLOCKS), "A", 10.8, 10.2)
    assert no_data_reason(old_news, short=True) == "newest 0.6 s old"  # a stale reading: its age, not its clocks
    assert cone_reading(None, "A", 10.1, None).state == ConeState.NO_DATA
    fresh = cone_reading(estimate([0.03, 0.04, 1.0]), "A", 10.1, 10.05)
    assert "0.05 s old at 10.1 s" in cone_markdown(fresh)  # its age against the live clock, and that clock
    assert cone_reading(estimate([0.03, 0.04, 1.0]), "A", 10.1, 10.05, behind=2.0).state == ConeState.GREEN
    late = cone_reading(estimate([0.03, 0.04, 1.0]), "A", 10.1, 10.05, behind=7.4)  # the view lags the live clock
    assert late.state == ConeState.NO_DATA and no_data_reason(late, short=True) == "view behind by 7 s"
    assert "7 s behind the live clock" in cone_markdown(late) and viewer_safe(cone_markdown(late))
    assert re.fullmatch(r"\d\d:\d\d:\d\d", clock_text(1.7e9))  # a live camera's Unix time: the time of day


def test_the_axes_a_camera_sees_are_shown_when_another_is_withheld() -> None:
    """One camera alone, square on: its depth (Δx) withheld at σ 54 mm, its height and sideways offset shown within
    their σ; a height withheld alone leaves the concentricity standing."""
    cov = np.diag([0.054, 0.007, 0.026]) ** 2
    depth = cone_reading(dataclasses.replace(estimate([np.nan, 0.012, 1.234]), covariance=cov), "A", 10.1, 10.05)
    assert depth.state == ConeState.NO_DATA  # no concentricity without Δx
    assert "Measured: Δy +12 ±14 · Δz +1234 ±52 mm (2σ)" in cone_markdown(depth)
    assert viewer_safe(cone_markdown(depth))
    assert cones_line([depth]) == "A NO DATA (σ too large; Δy +12 ±14 · Δz +1234 ±52 mm (2σ))"  # `live`'s log
    height = cone_reading(dataclasses.replace(estimate([0.03, 0.04, np.nan]), covariance=np.diag([0.005, 0.005, 0.06])
                                              ** 2), "A", 10.1, 10.05)
    assert height.state == ConeState.GREEN and height.concentricity == pytest.approx(0.05)
    assert "Δz — mm" in cone_markdown(height) and viewer_safe(cone_markdown(height))


def test_a_window_of_the_segments(live_run: Path, tmp_path: Path) -> None:
    from viewer.playback import window_recording

    index = pd.read_csv(live_run / "live.segments.csv")
    everything = pd.read_csv(live_run / "offsets.csv").query("cone == 'A'").dropna(subset=["dx", "dy", "dz"])
    first = float(everything["time"].min())  # the first offset shown (the cone waited for its cameras' comparison)
    k = int(np.searchsorted(index["start"].to_numpy(), first, side="right")) - 1  # the segment it is in
    start, end = first + 0.05, index["end"].iloc[k] - 0.02
    window = window_recording(live_run / "live.rrd", start, end, tmp_path)
    chunks = chunks_by_entity(window)
    times, _ = component_rows(chunks["/offsets/dx/A/estimate"], "Scalars:scalars")
    assert times.size and times.max() <= end + 1e-6
    assert times.min() <= start  # opened at the keyframe before --from, so the video decodes from the first frame
    assert times.size < len(everything)
    assert "/world/cameras/cam-port" in chunks  # static data comes along
