"""The live path: worker processes per camera, capture-time order, the same fusion as `topside track`."""

from __future__ import annotations

import math
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import FRAMES
from tests.streams import mpegts_copy, serving
from tracking.estimator import fused_estimates
from tracking.images import Frame
from tracking.live import LiveTracker
from tracking.pipeline import track_rig
from tracking.rig import load_rig
from tracking.sources import (
    FROZEN_AFTER_S,
    CameraState,
    FreezeDetector,
    H264Encoder,
    SourceKind,
    source_kind,
    uses_wall_clock,
)


def run_live(rig_path: Path, speed: float) -> list:
    """Every update of a live run over the rig's files."""
    with LiveTracker(load_rig(rig_path), speed=speed) as tracker:
        return list(tracker.updates())


def test_flat_out_replay_equals_offline_fusion(installation: Path) -> None:
    updates = run_live(installation / "rig.yaml", speed=math.inf)
    results = [r for u in updates for r in u.results]
    assert len(results) == 2 * FRAMES and all(r.tracked for r in results)
    assert [r.time for r in results] == sorted(r.time for r in results)  # fused in capture-time order
    assert all(r.frame.packet is not None and r.frame.gray is None for r in results)  # pixels stay in the worker
    live = [e for u in updates for e in u.estimates]
    rig = load_rig(installation / "rig.yaml")
    offline = list(fused_estimates(rig, (m for r in track_rig(rig, roi_tracking=True)
                                         for m in [*r.offsets, r.observation] if m is not None)))
    assert len(live) == len(offline) > 0
    for a, b in zip(live, offline, strict=True):
        assert (a.time, a.cone) == (b.time, b.cone)
        np.testing.assert_allclose(a.offset, b.offset, atol=1e-9, equal_nan=True)
    final = updates[-1].cameras
    assert {h.state for h in final.values()} == {CameraState.ENDED}
    assert all(h.frames == FRAMES for h in final.values())


def test_a_camera_far_ahead_waits_for_the_slower_one(installation: Path, tmp_path: Path) -> None:
    """Flat out, fusion waits for the camera furthest behind; one whose clock is 10 s ahead must not pile up its
    whole file in memory meanwhile: it holds at most its credits."""
    import yaml

    rig_dict = yaml.safe_load((installation / "rig.yaml").read_text())
    for cam in rig_dict["cameras"]:
        cam["source"], cam["calibration"] = str(installation / cam["source"]), str(installation / cam["calibration"])
        if cam["name"] == "cam-port":
            cam["time_offset"] += 10.0
    (tmp_path / "rig.yaml").write_text(yaml.safe_dump(rig_dict, sort_keys=False))
    ahead = 3
    waiting = []
    results = []
    with LiveTracker(load_rig(tmp_path / "rig.yaml"), speed=math.inf, ahead_frames=ahead) as tracker:
        for update in tracker.updates():
            waiting.append(sum(r.camera == "cam-port" for _, _, r, _ in tracker._pending))  # held for fusion
            results += update.results
    assert len(results) == 2 * FRAMES  # nothing lost, nothing stuck
    assert [r.time for r in results] == sorted(r.time for r in results)
    assert 0 < max(waiting) <= ahead  # before credits: all 12 of its frames waited


def test_real_time_replay_keeps_the_frame_rate(installation: Path) -> None:
    updates = run_live(installation / "rig.yaml", speed=1.0)
    results = [r for u in updates for r in u.results]
    assert len(results) == 2 * FRAMES  # every frame recorded, searched or not
    health = updates[-1].cameras["cam-port"]
    assert health.fps == pytest.approx(15.0, rel=0.05)  # from capture times, not processing times


def test_a_missing_camera_does_not_stop_the_others(installation: Path, tmp_path: Path) -> None:
    text = (installation / "rig.yaml").read_text().replace("cam-port.mp4", "unplugged.mp4")
    rig = tmp_path / "rig.yaml"
    rig.write_text(text.replace("calibration/", f"{installation}/calibration/"))
    (tmp_path / "cam-ahead.mp4").symlink_to(installation / "cam-ahead.mp4")
    updates = run_live(rig, speed=math.inf)
    events = [e for u in updates for e in u.events if e.camera == "cam-port"]
    assert events[-1].state == CameraState.ENDED and "not found" in events[-1].detail
    assert sum(len(u.results) for u in updates) == FRAMES  # cam-ahead tracked to its end
    assert {e.cameras for u in updates for e in u.estimates} <= {("cam-ahead",), ()}


def test_source_kinds_and_clocks(installation: Path) -> None:
    assert source_kind("0") == SourceKind.DEVICE
    assert source_kind("rtsp://10.0.0.5/stream1") == SourceKind.STREAM
    assert source_kind("videos/cam.mp4") == SourceKind.FILE
    assert not uses_wall_clock(load_rig(installation / "rig.yaml"))


def test_what_a_late_web_page_is_sent_follows_the_cameras_byte_rates(installation: Path) -> None:
    import av

    from tracking.sources import ENCODE_BITRATE, STREAM_ASSUMED_BITRATE, byte_rate
    from viewer.playback import (
        LATE_JOIN_S,
        MIN_PICTURES_SERVER_BYTES,
        MIN_SERVER_MEMORY_BYTES,
        VIEW_FIGURE_BYTES_PER_S,
        late_join_bytes,
        live_viewer_command,
    )

    rig = load_rig(installation / "rig.yaml")
    entry = rig.cameras[0]
    video = rig.resolve(entry.source)
    with av.open(str(video)) as container:  # the file's own duration, read apart from byte_rate
        seconds = float(container.streams.video[0].frames / container.streams.video[0].average_rate)
    assert byte_rate(rig, entry) == pytest.approx(video.stat().st_size / seconds, rel=0.15)
    assert byte_rate(rig, entry.model_copy(update={"source": "0"})) == ENCODE_BITRATE / 8
    assert byte_rate(rig, entry.model_copy(update={"source": "rtsp://10.0.0.5/s"})) == STREAM_ASSUMED_BITRATE / 8
    four = [STREAM_ASSUMED_BITRATE / 8] * 4  # four network cameras: about LATE_JOIN_S of their video and figures
    assert (LATE_JOIN_S * sum(four) < late_join_bytes(four, "superintendent", 2, videos=True)
            < late_join_bytes(four, "all", 2, videos=True))
    assert late_join_bytes([1000.0], "superintendent", 1, videos=True) == MIN_SERVER_MEMORY_BYTES  # keyframes
    pictures = [25_000.0] * 2  # two shown cameras' JPEGs: no keyframe to keep, each cone's figures
    assert late_join_bytes(pictures, "superintendent", 0, videos=False) == MIN_PICTURES_SERVER_BYTES
    assert (late_join_bytes(pictures, "superintendent", 4, videos=False)
            - late_join_bytes(pictures, "superintendent", 3, videos=False)) == LATE_JOIN_S * VIEW_FIGURE_BYTES_PER_S
    kept = late_join_bytes(four, "all", 2, videos=True)
    cmd = live_viewer_command(web=True, server_bytes=kept)
    assert cmd[cmd.index("--server-memory-limit") + 1] == f"{kept}B"


def test_freeze_is_noticed_after_its_limit() -> None:
    detector = FreezeDetector()
    still = np.full((60, 80), 100, np.uint8)
    frozen = [detector.frozen(Frame(i, i / 10, still)) for i in range(15)]
    assert frozen.index(True) == round(FROZEN_AFTER_S * 10)
    assert not detector.frozen(Frame(15, 1.5, still + 1))  # the image moves again


def test_raw_frames_are_encoded_to_decodable_h264() -> None:
    import av

    encoder = H264Encoder(160, 96, fps=10)
    frames = [np.random.default_rng(i).integers(0, 255, (96, 160), np.uint8) for i in range(25)]
    packets = [encoder.encode(f) for f in frames]
    assert packets[0][1] and all(p[0].startswith(b"\x00\x00\x00\x01") for p in packets if p[0])  # Annex B
    decoder = av.CodecContext.create("h264", "r")
    decoded = [f for data, _ in packets if data for f in decoder.decode(av.Packet(data))]
    decoded += decoder.decode(None)
    assert len(decoded) == 25 and decoded[0].width == 160


@pytest.fixture
def http_streams(installation: Path, tmp_path: Path):
    """The installation's videos as MPEG-TS streams on a local HTTP server, and a rig that reads them."""
    import yaml

    for name in ("cam-ahead", "cam-port"):
        mpegts_copy(installation / f"{name}.mp4", tmp_path / f"{name}.ts")
    with serving(tmp_path) as url:
        rig = yaml.safe_load((installation / "rig.yaml").read_text())
        for cam in rig["cameras"]:
            cam["source"] = f"{url}/{cam['name']}.ts"
            cam["calibration"] = str(installation / cam["calibration"])
        (tmp_path / "rig.yaml").write_text(yaml.safe_dump(rig))
        yield tmp_path / "rig.yaml"


def test_a_stream_that_ends_is_lost_then_taken_back(http_streams: Path) -> None:
    rig = load_rig(http_streams)
    assert uses_wall_clock(rig)
    seen: list[CameraState] = []
    frames = 0
    deadline = time.time() + 60
    with LiveTracker(rig) as tracker:
        for update in tracker.updates():
            frames += len(update.results)
            seen += [e.state for e in update.events if e.camera == "cam-port"]
            if CameraState.LOST in seen and CameraState.LIVE in seen[seen.index(CameraState.LOST):]:
                break
            assert time.time() < deadline, seen
    lost = seen.index(CameraState.LOST)
    assert CameraState.LIVE in seen[:lost] and CameraState.LIVE in seen[lost:]  # taken back after the stream ended
    assert frames >= 2 * FRAMES - 2  # both streams tracked to their ends before the reconnection


ORPHAN_SCRIPT = """
import sys, time
from pathlib import Path
import tracking.live
from tracking.live import LiveTracker
from tracking.rig import load_rig
if __name__ == "__main__":
    stall = sys.argv[2] == "stall"
    if stall:
        tracking.live.QUEUE_FRAMES = 1  # the queue is full at once when nobody reads it
    with LiveTracker(load_rig(Path(sys.argv[1])), speed=1.0, loop_until=600.0) as tracker:
        for update in tracker.updates():
            if update.results:
                print(*[p.pid for p in tracker._workers], flush=True)
                break
        if stall:
            time.sleep(600)  # a main process that stopped reading: the workers wait on a full queue
        for update in tracker.updates():
            pass
"""


def running(pid: int) -> bool:
    """The process exists and is not a zombie (an orphan's exit may never be reaped in a container)."""
    try:
        return "\\tZ" not in next(line for line in Path(f"/proc/{pid}/status").read_text().splitlines()
                                  if line.startswith("State:")).replace("State:", "\t")
    except (OSError, StopIteration):
        return False


@pytest.mark.parametrize("main_state", ["reading", "stall"])
def test_workers_end_when_the_main_process_is_killed(installation: Path, tmp_path: Path, main_state: str) -> None:
    """Killed while reading, or while the workers wait on a full queue (a slow main process): none lives on,
    holding its camera."""
    script = tmp_path / "orphan.py"
    script.write_text(ORPHAN_SCRIPT)
    main = subprocess.Popen([sys.executable, str(script), str(installation / "rig.yaml"), main_state],
                            stdout=subprocess.PIPE, text=True, cwd=Path(__file__).resolve().parents[2])
    pids = [int(p) for p in main.stdout.readline().split()]
    assert len(pids) == 2 and all(running(p) for p in pids)
    if main_state == "stall":
        time.sleep(1.0)  # 15 frames per camera and second: the 2-frame queue is long full
    main.send_signal(signal.SIGKILL)  # no clean-up runs: the workers must notice on their own
    main.wait()
    deadline = time.monotonic() + 10.0
    while any(running(p) for p in pids) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not any(running(p) for p in pids)
