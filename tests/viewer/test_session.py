"""Recordings read back with rerun's own API: entities, row counts, values equal to the CSV's."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import rerun as rr

from tests.conftest import FRAMES, REPO, Archived
from tests.synthetic import CONE_A
from viewer.playback import rerun_binary, rerun_env
from viewer.readback import chunks_by_entity, component_rows


@pytest.fixture(scope="module")
def recorded(installation: Path, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, pd.DataFrame]:
    out = tmp_path_factory.mktemp("rec")
    proc = subprocess.run([sys.executable, "-m", "tracking.cli", "track", "--rig", str(installation / "rig.yaml"),
                           "--truth", str(installation / "truth.csv"), "--mode", "paper",
                           "-o", str(out / "offsets.csv"), "--rrd", str(out / "run.rrd")],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    return out / "run.rrd", pd.read_csv(out / "offsets.csv")


def test_entities_and_row_counts(recorded: tuple[Path, pd.DataFrame]) -> None:
    rrd, _ = recorded
    chunks = chunks_by_entity(rrd)
    for cam in ("cam-ahead", "cam-port"):
        times, samples = component_rows(chunks[f"/world/cameras/{cam}/image"], "VideoStream:sample")
        assert len(samples) == FRAMES  # the camera's own H.264 packets, one per frame
        assert np.all(np.diff(times) > 0)
        _, keys = component_rows(chunks[f"/world/cameras/{cam}/image"], "VideoStream:is_keyframe")
        assert keys[0][0]
        assert decoded_count(samples) == FRAMES
        _, labels = component_rows(chunks[f"/world/cameras/{cam}/image/markers"], "LineStrips2D:labels")
        assert len(labels) == FRAMES and all(sorted(x for x in row if x) == ["1", "2"] or
                                             sorted(x for x in row if x) == ["3", "4"] for row in labels)
        _, corners = component_rows(chunks[f"/world/cameras/{cam}/image/markers"], "Points2D:positions")
        assert all(len(c) == 8 for c in corners)  # both markers of the pair, four corners each, in every frame
        _, pinhole = component_rows(chunks[f"/world/cameras/{cam}"], "Pinhole:image_from_camera")
        assert len(pinhole) == 1  # static
        _, translations = component_rows(chunks[f"/world/cameras/{cam}"], "Transform3D:translation")
        assert len(translations) == FRAMES  # the markers place the camera in every frame
    labels = {lab for cam in ("cam-ahead", "cam-port")
              for row in component_rows(chunks[f"/world/estimated/{cam}"], "Boxes3D:labels")[1] for lab in row}
    assert labels == {"1", "2", "3", "4"}
    assert "/status" in chunks and "/world/jacket/cones" in chunks
    assert not any(p.startswith("/uncertainty") for p in chunks)  # the paper's average has no σ
    _, ages = component_rows(chunks["/health/cam-port/frame_age_s"], "Scalars:scalars")
    assert len(ages) >= 3  # every 0.2 s of the 0.8 s
    assert max(a[0] for a in ages) <= 1 / 30 + 1e-3  # cameras interleave every 1/30 s


def decoded_count(samples: list) -> int:
    """Frames an H.264 decoder gets out of recorded video-stream samples."""
    import av

    codec = av.CodecContext.create("h264", "r")
    n = sum(len(codec.decode(av.Packet(bytes(np.asarray(s[0], dtype=np.uint8))))) for s in samples)
    return n + len(codec.decode(None))


def test_topside_pose_follows_the_offsets(recorded: tuple[Path, pd.DataFrame]) -> None:
    rrd, df = recorded
    _, translations = component_rows(chunks_by_entity(rrd)["/world/topside"], "Transform3D:translation")
    full = df.dropna(subset=["dx", "dy", "dz"])
    assert len(translations) == full["time"].nunique()  # one pose per capture time with a full offset
    last = full[full["time"] == full["time"].max()]
    np.testing.assert_allclose(translations[-1][0], last[["dx", "dy", "dz"]].mean(), atol=1e-5)


def test_offsets_equal_csv(recorded: tuple[Path, pd.DataFrame]) -> None:
    rrd, df = recorded
    chunks = chunks_by_entity(rrd)
    for axis in ("dx", "dy", "dz"):
        times, values = component_rows(chunks[f"/offsets/{axis}/A/estimate"], "Scalars:scalars")
        expected = df[np.isfinite(df[axis])]
        assert len(values) == len(expected)
        np.testing.assert_allclose(times, expected["time"], atol=1e-6)
        np.testing.assert_allclose([v[0] for v in values], expected[axis], atol=1e-5)


def test_truth_and_errors(recorded: tuple[Path, pd.DataFrame], installation: Path) -> None:
    rrd, df = recorded
    chunks = chunks_by_entity(rrd)
    truth = pd.read_csv(installation / "truth.csv")
    _, true_dx = component_rows(chunks["/offsets/dx/A/truth"], "Scalars:scalars")
    assert len(true_dx) == len(truth)
    _, errors = component_rows(chunks["/errors/dz/A"], "Scalars:scalars")
    assert len(errors) == len(df)
    assert np.abs([e[0] for e in errors]).max() < 0.05


def test_blueprint_stored_and_file_verifies(recorded: tuple[Path, pd.DataFrame]) -> None:
    rrd, _ = recorded
    assert len(rr.chunk.RrdReader(rrd).blueprints()) == 1
    proc = subprocess.run([rerun_binary(), "rrd", "verify", str(rrd)], capture_output=True, text=True, timeout=60,
                          env=rerun_env())
    assert proc.returncode == 0, proc.stderr


def test_logging_is_strict_clean(installation: Path, tmp_path: Path) -> None:
    from tracking.pipeline import track_rig
    from tracking.rig import load_rig
    from viewer.session import Recorder

    rr.set_strict_mode(True)
    try:
        rig = load_rig(installation / "rig.yaml")
        recorder = Recorder(rig, tmp_path / "strict.rrd", pd.read_csv(installation / "truth.csv"), show_rejected=True)
        for i, result in enumerate(track_rig(rig, keep_color=True)):
            recorder.on_frame(result)
            if i == 3:
                break
        recorder.close()
    finally:
        rr.set_strict_mode(False)
    assert (tmp_path / "strict.rrd").stat().st_size > 0


def test_tracking_never_imports_viewer() -> None:
    """Pipeline stages never import viewer/; only the command line (the package tracking/cli/, the composition root
    that pyproject.toml's import contracts declare and lint-imports checks) does. A second check of the contract."""
    composition_root = REPO / "tracking" / "cli"
    for path in (REPO / "tracking").rglob("*.py"):
        if path.is_relative_to(composition_root):
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else (
                [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
            assert not any(n.split(".")[0] == "viewer" for n in names), path


def test_cone_state_never_claims_an_unknown_cone() -> None:
    from viewer.recording import cone_state

    assert cone_state(np.array([np.nan, np.nan, np.nan])) == "NO DATA"
    assert cone_state(np.array([0.01, np.nan, 0.0])) == "NO DATA"  # the paper's mode before camera 2 reports
    assert cone_state(np.array([0.01, -0.02, 0.1])) == "within ±0.15 m"
    assert cone_state(np.array([0.01, -0.2, 0.1])) == "outside"
    assert cone_state(np.array([0.12, -0.12, 0.0])) == "outside"  # 0.17 m from the target, though each axis fits
    assert cone_state(np.array([0.01, -0.02, 2.0])) == "within ±0.15 m"  # 2 m above: concentric, not yet down
    assert cone_state(np.array([0.01, -0.02, np.nan])) == "within ±0.15 m"  # its height withheld alone


def test_a_cone_state_names_the_axes_it_withholds_and_why() -> None:
    from tracking.estimate import WITHHELD_SIGMA, ConeEstimate
    from viewer.recording import said_state

    def said(offset: list[float], withheld: str = WITHHELD_SIGMA) -> str:
        return said_state(ConeEstimate(1.0, "A", np.array(offset), ("cam",), withheld=withheld))

    assert said([0.01, -0.02, np.nan]) == f"within ±0.15 m (Δz withheld: {WITHHELD_SIGMA})"
    assert said([np.nan, -0.02, 0.3]) == f"NO DATA (Δx withheld: {WITHHELD_SIGMA})"
    assert said([np.nan] * 3) == f"NO DATA ({WITHHELD_SIGMA})"
    assert said([0.01, -0.02, 0.3], "") == "within ±0.15 m"


def test_fused_recording_logs_uncertainty(installation: Path, tmp_path: Path) -> None:
    proc = subprocess.run([sys.executable, "-m", "tracking.cli", "track", "--rig", str(installation / "rig.yaml"),
                           "-o", str(tmp_path / "o.csv"), "--rrd", str(tmp_path / "f.rrd")],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    df = pd.read_csv(tmp_path / "o.csv")
    _, sd = component_rows(chunks_by_entity(tmp_path / "f.rrd")["/uncertainty/dy/A"], "Scalars:scalars")
    assert len(sd) == len(df)
    np.testing.assert_allclose([v[0] for v in sd], df["sdy"], atol=1e-5)  # the estimator's 1σ, as in the CSV


def test_a_viewer_that_is_gone_neither_slows_nor_loses_the_recording(installation: Path, tmp_path: Path,
                                                                       capfd: pytest.CaptureFixture[str]) -> None:
    """The viewer's input closed at its end (its process ended): cut loose at once, with one line; the file has
    every frame and never waited."""
    import os
    import time
    from dataclasses import replace

    from tracking.live import LiveUpdate
    from tracking.pipeline import track_rig
    from tracking.rig import load_rig
    from viewer.feed import ViewerFeed
    from viewer.session import Recorder

    rr.set_strict_mode(True)
    rig = load_rig(installation / "rig.yaml")
    results = list(track_rig(rig))
    span = max(r.time for r in results) - min(r.time for r in results) + 0.1
    read, write = os.pipe()
    os.close(read)  # nobody will read: a viewer that is gone
    recorder = Recorder(rig, tmp_path / "run.rrd", viewer=ViewerFeed(os.fdopen(write, "wb")), segment_s=1.0)
    laps = int(np.ceil(10.0 / span))  # 10 s of capture
    start = time.monotonic()
    for k in range(laps):
        lap = [replace(r, frame=replace(r.frame, time=r.time + k * span, index=r.frame.index + k * 1000))
               for r in results]
        recorder.on_update(LiveUpdate(now=lap[-1].time, results=lap))
    recorder.close()
    assert time.monotonic() - start < 30.0  # nothing waited for the viewer (a 10 s wait would show)
    assert recorder.backlog_timeouts == 0
    assert capfd.readouterr().err.count("cut loose") == 1  # said once
    found = 0
    for name in pd.read_csv(tmp_path / "run.segments.csv")["file"]:
        times, _ = component_rows(chunks_by_entity(tmp_path / name)["/world/cameras/cam-port/image"],
                                  "EncodedImage:blob")
        found += len(times)
    assert found >= laps * sum(r.camera == "cam-port" for r in results)  # every frame in the file


def test_a_live_update_lands_in_the_segments_that_span_its_times(installation: Path, tmp_path: Path) -> None:
    """One update holding frames across a segment boundary, and their estimates: each in the file of its time."""
    from tracking.estimate import ConeEstimate
    from tracking.live import LiveUpdate
    from tracking.pipeline import track_rig
    from tracking.rig import load_rig
    from viewer.session import Recorder

    rig = load_rig(installation / "rig.yaml")
    results = [r for _, r in zip(range(12), track_rig(rig, packets=True), strict=False)]
    estimates = [ConeEstimate(r.time, "A", np.zeros(3), (r.camera,), np.eye(3) * 1e-4) for r in results]
    recorder = Recorder(rig, tmp_path / "live.rrd", segment_s=0.1)
    recorder.on_update(LiveUpdate(now=results[-1].time, results=results, estimates=estimates))
    recorder.close()
    index = pd.read_csv(tmp_path / "live.segments.csv")
    assert len(index) >= 2
    found = 0
    for name, start, end in index[["file", "start", "end"]].itertuples(index=False):
        chunks = chunks_by_entity(tmp_path / name)
        if "/offsets/dx/A/estimate" in chunks:
            times, _ = component_rows(chunks["/offsets/dx/A/estimate"], "Scalars:scalars")
            assert not times.size or (start - 1e-6 <= times.min() and times.max() <= end + 1e-6), name
            found += times.size
    assert found == len(estimates)


def test_the_filters_cameras_are_drawn_beside_the_true_ones(archived: Archived,
                                                           recorded: tuple[Path, pd.DataFrame]) -> None:
    """The fused run draws where its filter has each camera, over time, and where the truth log has it; the paper's
    mode, which keeps no camera poses, draws none."""
    chunks = chunks_by_entity(archived.rrd)
    for cam in ("cam-ahead", "cam-port"):
        _, estimated = component_rows(chunks[f"/world/filter/cameras/{cam}"], "Transform3D:translation")
        _, true = component_rows(chunks[f"/world/truth/cameras/{cam}"], "Transform3D:translation")
        _, pinholes = component_rows(chunks[f"/world/filter/cameras/{cam}"], "Pinhole:image_from_camera")
        assert len(estimated) > 10 and len(true) > 10 and len(pinholes) == 1
        estimated, true = np.array([r[0] for r in estimated]), np.array([r[0] for r in true])
        distance = np.linalg.norm(true[0] - CONE_A)
        error = np.linalg.norm(estimated[-1] - true[-1])
        assert error < 0.005 * distance  # 22 mm at 20.6 m
    assert not any(p.startswith("/world/filter") for p in chunks_by_entity(recorded[0]))


def layout_view_names(rrd: Path) -> set[str]:
    """Display names of the views in the layout logged last into the file's blueprint (each send logs a whole layout
    at the next step of the "blueprint" timeline)."""
    reader = rr.chunk.RrdReader(rrd)
    names: dict[int, set[str]] = {}  # the live layouts' store (the file's default layout is another, at step 0)
    for store in reader.blueprints():
        for chunk in reader.stream(store=store):
            data = chunk.to_record_batch().to_pydict()
            if chunk.entity_path.startswith("/view/") and "ViewBlueprint:display_name" in data:
                for step, name in zip(data["blueprint"], data["ViewBlueprint:display_name"], strict=True):
                    if name:
                        names.setdefault(step, set()).add(name[0])
    return names[max(names)]


@pytest.mark.filterwarnings("ignore:RRD file has no footer")  # read while recording, as a viewer would: the footer
# is written when the recording closes
def test_a_cone_gets_its_image_as_soon_as_a_camera_measures_it(installation: Path, tmp_path: Path) -> None:
    """The layout first sent names one cone's camera; another cone measured a moment later gets its image at once,
    not after BLUEPRINT_MIN_PERIOD_S; a cone's camera changing still waits for it."""
    from dataclasses import replace

    from tracking.live import LiveUpdate
    from tracking.pipeline import track_rig
    from tracking.rig import load_rig
    from viewer.session import BLUEPRINT_MIN_PERIOD_S, Recorder

    rr.set_strict_mode(True)
    rig = load_rig(installation / "rig.yaml")
    rig = rig.model_copy(update={"cones": {"A": CONE_A, "D": [CONE_A[0], CONE_A[1] + 20.0, CONE_A[2]]}})
    results = [r for r in track_rig(rig) if r.offsets]
    port = [replace(r, offsets=[replace(m, cone="D") for m in r.offsets]) for r in results if r.camera == "cam-port"]
    ahead = [r for r in results if r.camera == "cam-ahead"]
    recorder = Recorder(rig, tmp_path / "live.rrd", layout="superintendent")
    t0 = min(r.time for r in results)
    recorder.on_update(LiveUpdate(now=t0, results=port[:1]))  # cone D measured by cam-port (its offsets relabelled)
    recorder.on_update(LiveUpdate(now=t0 + 1.0, results=ahead[:1]))  # then cone A by cam-ahead, 1 s later
    assert recorder.cone_cameras() == {"A": "cam-ahead", "D": "cam-port"}
    recorder.flush_estimates()
    recorder.rec.flush()
    assert {"A: cam-ahead", "D: cam-port"} <= layout_view_names(tmp_path / "live.rrd")
    # cam-port now measures cone A most: the layout keeps cam-ahead until BLUEPRINT_MIN_PERIOD_S has passed
    relabelled = [replace(r, offsets=[replace(m, cone="A") for m in r.offsets]) for r in port[1:4]]
    recorder.on_update(LiveUpdate(now=t0 + 2.0, results=relabelled))
    assert recorder.cone_cameras()["A"] == "cam-port"
    recorder.rec.flush()
    assert "A: cam-ahead" in layout_view_names(tmp_path / "live.rrd")
    recorder.on_update(LiveUpdate(now=t0 + 2.0 + BLUEPRINT_MIN_PERIOD_S))
    recorder.close()
    assert {"A: cam-port", "D: cam-port"} <= layout_view_names(tmp_path / "live.rrd")


def test_the_viewers_own_stream_shows_a_camera_from_a_keyframe(installation: Path, tmp_path: Path) -> None:
    """Unsegmented, the frames before the first layout went to the file only: the viewer's own stream began the
    camera's video at a P-frame it could not decode until the next keyframe (250 frames later in the simulator's)."""
    from tracking.live import LiveUpdate
    from tracking.pipeline import track_rig
    from tracking.rig import load_rig
    from viewer.feed import ViewerFeed
    from viewer.session import Recorder

    rr.set_strict_mode(True)
    rig = load_rig(installation / "rig.yaml")
    results = list(track_rig(rig, packets=True))
    view = ViewerFeed((tmp_path / "view.rrd").open("wb"))  # what the viewer gets, into a file (closed with it)
    recorder = Recorder(rig, None, viewer=view, layout="superintendent")
    recorder.on_update(LiveUpdate(now=results[5].time, results=results[:6]))  # the first layout comes after these
    recorder.on_update(LiveUpdate(now=results[-1].time, results=results[6:]))
    recorder.close()
    # the feed's bytes are a run of whole .rrd streams (one per read of Rerun's binary sink), as `rerun -` reads them
    subprocess.run([rerun_binary(), "rrd", "merge", str(tmp_path / "view.rrd"), "-o", str(tmp_path / "merged.rrd")],
                   check=True, capture_output=True, env=rerun_env())
    chunks = chunks_by_entity(tmp_path / "merged.rrd")
    for cam in recorder.cone_cameras().values():
        times, keys = component_rows(chunks[f"/world/cameras/{cam}/image"], "VideoStream:is_keyframe")
        first = np.argmin(times)
        assert keys[first][0], cam  # its video decodes from the first sample the viewer gets
        assert len(times) == sum(r.camera == cam for r in results)  # every frame of it, the early ones too


def test_the_viewers_own_stream_sends_small_pictures_at_its_rate(installation: Path, tmp_path: Path) -> None:
    """A tablet's budget: with view_image_rate, each shown camera's pictures reach the viewer's own stream as JPEGs
    at most that often and at most view_image_width wide, their pinhole and marker outlines scaled with them; the
    file keeps every frame of the video."""
    import cv2

    from tracking.live import LiveUpdate
    from tracking.pipeline import track_rig
    from tracking.rig import load_rig
    from viewer.feed import ViewerFeed
    from viewer.session import Recorder

    rr.set_strict_mode(True)
    rig = load_rig(installation / "rig.yaml")
    results = list(track_rig(rig, packets=True))
    view = ViewerFeed((tmp_path / "view.rrd").open("wb"))
    recorder = Recorder(rig, tmp_path / "live.rrd", viewer=view, layout="superintendent", view_image_rate=2.0,
                        view_image_width=320)
    recorder.on_update(LiveUpdate(now=results[5].time, results=results[:6]))
    recorder.on_update(LiveUpdate(now=results[-1].time, results=results[6:]))
    recorder.close()
    subprocess.run([rerun_binary(), "rrd", "merge", str(tmp_path / "view.rrd"), "-o", str(tmp_path / "merged.rrd")],
                   check=True, capture_output=True, env=rerun_env())
    chunks = chunks_by_entity(tmp_path / "merged.rrd")
    recorded = chunks_by_entity(tmp_path / "live.rrd")
    shown = set(recorder.cone_cameras().values())
    assert shown
    for cam in shown:
        image = f"/world/cameras/{cam}/image"
        times, blobs = component_rows(chunks[image], "EncodedImage:blob")
        assert len(times) >= 2 and np.diff(times).min() >= 0.5 - 1e-6  # two a second at most
        span = max(r.time for r in results if r.camera == cam) - min(r.time for r in results if r.camera == cam)
        assert len(times) <= span * 2.0 + 2
        picture = cv2.imdecode(np.frombuffer(bytes(blobs[-1][0]), np.uint8), cv2.IMREAD_UNCHANGED)
        assert picture is not None and picture.shape[1] == 320
        _, resolution = component_rows(chunks[f"/world/cameras/{cam}"], "Pinhole:resolution", timeline="")
        assert resolution and resolution[0][0] == pytest.approx([320, 320 * picture.shape[0] / picture.shape[1]],
                                                                 abs=1)
        _, points = component_rows(chunks[f"{image}/markers"], "Points2D:positions")
        assert max(p[0] for row in points for p in row) <= 320  # the corners on the small picture
        assert "VideoStream:sample" not in {n for c in chunks[image] for n in c.to_record_batch().schema.names}
        key_times, _ = component_rows(recorded[image], "VideoStream:is_keyframe")
        assert len(key_times) == sum(r.camera == cam for r in results)  # the file: every frame of the video


def test_the_live_commands_picture_budget_is_the_recorders() -> None:
    """`topside live`'s defaults are the recorder's (the CLI starts without importing rerun), and the budget they
    give a 920x600 camera streaming 2.6 Mbit/s is under a fifth of its video."""
    from tracking.cli.options import VIEW_IMAGE_RATE_DEFAULT, VIEW_IMAGE_WIDTH_DEFAULT
    from viewer.session import VIEW_IMAGE_RATE_HZ, VIEW_IMAGE_WIDTH_PX, view_bytes_per_s

    assert (VIEW_IMAGE_RATE_DEFAULT, VIEW_IMAGE_WIDTH_DEFAULT) == (VIEW_IMAGE_RATE_HZ, VIEW_IMAGE_WIDTH_PX)
    video = 2.6e6 / 8
    assert view_bytes_per_s(video, VIEW_IMAGE_RATE_HZ, VIEW_IMAGE_WIDTH_PX) < 0.2 * video
    assert view_bytes_per_s(video, 0.0, VIEW_IMAGE_WIDTH_PX) == video
