"""Videos that end early, or whose timestamps go backwards, repeat, jump or are missing: counted, reported, and the
frames out of order dropped, with real encoded and muxed videos (PyAV)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from collections.abc import Sequence
from fractions import Fraction
from pathlib import Path

import av
import numpy as np
import pytest
import rerun as rr
import yaml

from tests.conftest import FPS, FRAMES
from tracking.images import JUMP_S, VideoHealth, frames
from tracking.pipeline import FrameResult, TrackStats, track_rig
from tracking.rig import load_rig
from viewer.readback import chunks_by_entity, component_rows
from viewer.recording import log_health

MS = Fraction(1, 1000)
LEAD_MS = 100  # presentation times start this late, so they may go back while the decode times run on
NOISE_SIZE = (64, 48)  # small frames: the counters do not look at the pixels


def noise_video(path: Path, pts_ms: Sequence[int], fmt: str | None = None, options: dict[str, str] | None = None
                ) -> None:
    """Encode len(pts_ms) frames of noise (H.264, no B-frames) and mux them at those presentation times, ms after
    LEAD_MS; decode times run on 1 ms a frame, so a container takes times that go back or repeat."""
    encoder = av.CodecContext.create("libx264", "w")
    encoder.width, encoder.height = NOISE_SIZE
    encoder.pix_fmt, encoder.time_base = "yuv420p", MS
    encoder.options = {"preset": "ultrafast"}
    rng = np.random.default_rng(0)
    packets = []
    for k in range(len(pts_ms)):
        frame = av.VideoFrame.from_ndarray(rng.integers(0, 255, (*NOISE_SIZE[::-1], 3), dtype=np.uint8), "bgr24")
        frame.pts, frame.time_base = k, MS
        packets += encoder.encode(frame)
    packets += encoder.encode(None)
    with av.open(str(path), "w", format=fmt, options=options or {}) as out:
        stream = out.add_stream("h264", rate=30)
        stream.width, stream.height = NOISE_SIZE
        stream.pix_fmt, stream.time_base = "yuv420p", MS
        stream.codec_context.extradata = encoder.extradata
        for k, packet in enumerate(packets):
            packet.stream, packet.time_base = stream, MS
            packet.pts, packet.dts = pts_ms[k] + LEAD_MS, k
            out.mux(packet)


def remux(src: Path, dst: Path, shift_from: int | None = None, shift_s: float = 0.0,
          options: dict[str, str] | None = None) -> None:
    """Copy a video's packets into another file (options: the muxer's); with shift_from, the packets from that
    one on are presented shift_s later (a gap in the presentation times)."""
    with av.open(str(src)) as inp, av.open(str(dst), "w", options=options or {}) as out:
        s_in = inp.streams.video[0]
        s_out = out.add_stream_from_template(s_in)
        k = 0
        for packet in inp.demux(s_in):
            if packet.dts is None:  # the flush packet
                continue
            if shift_from is not None and k >= shift_from:
                ticks = round(shift_s / packet.time_base)
                packet.pts, packet.dts = packet.pts + ticks, packet.dts + ticks
            packet.stream = s_out
            out.mux(packet)
            k += 1


def installation_copy(installation: Path, folder: Path, port_video: str = "cam-port.mp4") -> Path:
    """The installation's rig, calibration and cam-ahead video, with cam-port's source named port_video; its rig."""
    shutil.copytree(installation / "calibration", folder / "calibration")
    shutil.copy(installation / "cam-ahead.mp4", folder / "cam-ahead.mp4")
    rig = yaml.safe_load((installation / "rig.yaml").read_text())
    for camera in rig["cameras"]:
        if camera["name"] == "cam-port":
            camera["source"] = port_video
    (folder / "rig.yaml").write_text(yaml.safe_dump(rig, sort_keys=False))
    return folder / "rig.yaml"


def tracked(rig_path: Path, packets: bool = False) -> tuple[list[FrameResult], TrackStats]:
    """Every result of tracking the rig (packets: with their H.264, as when recording), and the run's counts."""
    stats = TrackStats()
    results = list(track_rig(load_rig(rig_path), packets=packets, stats=stats))
    for r in results:
        stats.add(r)
    return results, stats


# --- the counters on real videos -------------------------------------------------------------------------------


def test_a_sound_video_reports_nothing(installation: Path) -> None:
    results, stats = tracked(installation / "rig.yaml")
    assert stats.warnings(["cam-ahead", "cam-port"]) == []
    for camera in ("cam-ahead", "cam-port"):
        video = stats.videos[camera]
        assert (video.declared_frames, video.packets, video.decoded, video.ended) == (FRAMES, FRAMES, FRAMES, True)
        assert not video.troubled() and video.news == ()
        assert [r.frame.video.decoded for r in results if r.camera == camera] == list(range(1, FRAMES + 1))


def test_a_faststart_mp4_cut_in_half_is_tracked_and_reported(installation: Path, tmp_path: Path) -> None:
    """The moov atom at the front still declares every frame: the half that is left is tracked, and said to be half."""
    remux(installation / "cam-port.mp4", tmp_path / "whole.mp4", options={"movflags": "+faststart"})
    data = (tmp_path / "whole.mp4").read_bytes()
    assert data[4:8] == b"ftyp" and data.index(b"moov") < data.index(b"mdat")  # faststart: the index comes first
    (tmp_path / "cut.mp4").write_bytes(data[:len(data) // 2])
    results, stats = tracked(installation_copy(installation, tmp_path, "cut.mp4"))
    port = [r for r in results if r.camera == "cam-port"]
    video = stats.videos["cam-port"]
    assert 0 < len(port) < FRAMES and stats.frames["cam-port"] == len(port)
    assert (video.declared_frames, video.decoded, video.ended) == (FRAMES, len(port), True)
    assert video.decoded <= video.packets < FRAMES  # the file ran out: fewer packets than its index lists
    assert stats.warnings(["cam-ahead", "cam-port"]) == [
        f"cam-port: cut.mp4 ended after {len(port)} of {FRAMES} frames ({video.packets} packets read: the file may be "
        "cut short)"]
    assert port[-1].frame.video.ended and port[-1].frame.video.news == (  # the last frame carries the end
        f"ended after {len(port)} of {FRAMES} frames ({video.packets} packets read: the file may be cut short)",)
    assert all(not r.frame.video.ended for r in port[:-1])
    assert stats.frames["cam-ahead"] == FRAMES and not stats.videos["cam-ahead"].troubled()


def test_a_video_cut_inside_its_first_frame_is_reported_with_its_counts(installation: Path, tmp_path: Path) -> None:
    """No frame to carry the health: track_rig(stats=) keeps it from the start."""
    remux(installation / "cam-port.mp4", tmp_path / "whole.mp4", options={"movflags": "+faststart"})
    with av.open(str(tmp_path / "whole.mp4")) as container:
        first = next(container.demux(video=0))
        end = first.pos + first.size // 2  # half of the first frame's bytes
    (tmp_path / "cut.mp4").write_bytes((tmp_path / "whole.mp4").read_bytes()[:end])
    rig_path = installation_copy(installation, tmp_path, "cut.mp4")
    results, stats = tracked(rig_path)
    assert {r.camera for r in results} == {"cam-ahead"} and stats.frames["cam-ahead"] == FRAMES
    assert (stats.videos["cam-port"].decoded, stats.videos["cam-port"].packets) == (0, 1)
    assert stats.warnings(["cam-ahead", "cam-port"]) == [
        f"cam-port: cut.mp4 ended after 0 of {FRAMES} frames (1 packet read: the file may be cut short)"]
    unkept = TrackStats()  # without track_rig(stats=): the camera is still named, from the names expected
    for r in track_rig(load_rig(rig_path)):
        unkept.add(r)
    assert unkept.warnings(["cam-ahead", "cam-port"]) == ["cam-port: no frame could be read"]


ONE_CORE_SCRIPT = """
import json, os, sys
os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})  # one core: the decoder runs without frame threads
from tracking.images import VideoHealth, frames
health = VideoHealth()
n = len(list(frames(sys.argv[1], health=health)))
print(json.dumps([n, health.decoded, health.packets, health.short()]))
"""


@pytest.mark.skipif(not hasattr(os, "sched_setaffinity"), reason="needs Linux CPU affinity")
def test_a_cut_file_reads_the_same_on_one_core(installation: Path, tmp_path: Path) -> None:
    """Without frame threads the decoder refuses the last, cut packet (threaded, it drops it unsaid): the same
    frames and counts either way, not an error."""
    remux(installation / "cam-port.mp4", tmp_path / "whole.mp4", options={"movflags": "+faststart"})
    data = (tmp_path / "whole.mp4").read_bytes()
    (tmp_path / "cut.mp4").write_bytes(data[:len(data) // 2])
    health = VideoHealth()
    threaded = [len(list(frames(tmp_path / "cut.mp4", health=health))), health.decoded, health.packets, True]
    out = subprocess.run([sys.executable, "-c", ONE_CORE_SCRIPT, str(tmp_path / "cut.mp4")], capture_output=True,
                         text=True, check=True, cwd=Path(__file__).resolve().parents[2])
    assert json.loads(out.stdout) == threaded and health.short()


def test_a_jump_in_the_presentation_times_is_reported_and_kept(installation: Path, tmp_path: Path) -> None:
    """A 2 s gap: counted with its size and place, and the frames after it keep their own capture times."""
    gap_s, at = 2.0, 6
    remux(installation / "cam-port.mp4", tmp_path / "jump.mp4", shift_from=at, shift_s=gap_s)
    results, stats = tracked(installation_copy(installation, tmp_path, "jump.mp4"))
    port = [r for r in results if r.camera == "cam-port"]
    video = stats.videos["cam-port"]
    assert len(port) == FRAMES and (video.jumps, video.backwards, video.repeated, video.untimed) == (1, 0, 0, 0)
    assert video.largest_jump_s == pytest.approx(gap_s + 1 / FPS, abs=2e-3)
    assert video.largest_jump_at_s == pytest.approx((at - 1) / FPS, abs=2e-3)
    times = np.array([r.time for r in port])
    assert times[at] - times[at - 1] == pytest.approx(gap_s + 1 / FPS, abs=2e-3)  # capture time = pts + offset
    assert not video.short()  # the file is whole: its index lists the frames it holds
    assert stats.warnings() == [f"cam-port: 1 jump over {JUMP_S:.2g} s (largest {gap_s + 1 / FPS:.3g} s, after "
                                f"{(at - 1) / FPS:.1f} s)"]
    assert port[at].frame.video.news == (f"jump of {gap_s + 1 / FPS:.3g} s after {(at - 1) / FPS:.1f} s",)


def test_times_that_go_back_in_a_matroska_file_are_dropped_and_counted(installation: Path, tmp_path: Path) -> None:
    """Matroska takes presentation times that go back or repeat: those frames never reach the merge by capture time,
    which stays in order, and the count says how many."""
    pts = [round(k * 1000 / FPS) for k in range(FRAMES)]
    pts[7] = pts[3]  # back by 4 frames
    pts[9] = pts[8]  # repeated
    noise_video(tmp_path / "back.mkv", pts)
    health = VideoHealth()
    fs = list(frames(tmp_path / "back.mkv", 10.0, health=health))
    assert [f.index for f in fs] == [k for k in range(FRAMES) if k not in (7, 9)]
    np.testing.assert_allclose([f.time for f in fs], [10.0 + (pts[k] + LEAD_MS) / 1000 for k in range(FRAMES)
                                                      if k not in (7, 9)])
    assert (health.decoded, health.backwards, health.repeated, health.jumps, health.untimed) == (FRAMES, 1, 1, 0, 0)
    assert health.declared_s == pytest.approx((pts[-1] + LEAD_MS) / 1000 + 1 / 30, abs=2e-3)  # Matroska: a duration
    assert not health.short()
    assert health.summary() == "1 timestamp went backwards, 1 repeated (frames dropped)"
    assert fs[7].index == 8 and fs[7].video.news == (  # told with the next frame out
        f"timestamp went back {(pts[6] - pts[3]) / 1000:.3g} s after {pts[6] / 1000:.1f} s: frame dropped",)
    assert fs[8].index == 10 and fs[8].video.news == (f"timestamp repeated after {pts[8] / 1000:.1f} s: frame dropped",)


def test_a_matroska_file_cut_short_is_measured_by_its_declared_duration(tmp_path: Path) -> None:
    noise_video(tmp_path / "whole.mkv", [round(k * 1000 / 30) for k in range(60)])
    data = (tmp_path / "whole.mkv").read_bytes()
    (tmp_path / "cut.mkv").write_bytes(data[:len(data) // 2])
    whole, cut = VideoHealth(), VideoHealth()
    n_whole = len(list(frames(tmp_path / "whole.mkv", health=whole)))
    n_cut = len(list(frames(tmp_path / "cut.mkv", health=cut)))
    assert n_whole == whole.decoded == 60 and whole.declared_frames is None and not whole.short()
    assert 0 < n_cut == cut.decoded < 60 and cut.declared_s == pytest.approx(whole.declared_s) and cut.short()
    assert cut.summary() == (f"cut.mkv ended after {n_cut} of about 60 frames (its frames stop at "
                             f"{(LEAD_MS + n_cut * 1000 / 30) / 1000:.1f} s of the 2.1 s it declares: the file may be "
                             "cut short)")  # LEAD_MS + 60 frames at 30 fps


def test_a_raw_h264_stream_has_no_timestamps_and_says_so(tmp_path: Path) -> None:
    """An elementary stream carries no times: its frames are stamped at the nominal rate (the demuxer's guess, 25 fps
    unless the stream says), and every one is counted."""
    noise_video(tmp_path / "raw.h264", [round(k * 1000 / 30) for k in range(FRAMES)], fmt="h264")
    health = VideoHealth()
    fs = list(frames(tmp_path / "raw.h264", 5.0, health=health))
    assert (len(fs), health.untimed, health.declared_frames, health.declared_s) == (FRAMES, FRAMES, None, None)
    np.testing.assert_allclose([f.time for f in fs], 5.0 + np.arange(FRAMES) * health.interval_s)
    assert health.summary() == f"{FRAMES} frames had no timestamp (stamped at the nominal 25 fps)"
    assert health.interval_s == 1 / 25
    assert fs[0].video.news == ("frame 0 has no timestamp: stamped at the nominal 25 fps",)
    assert all(f.video.news == () for f in fs[1:])  # said once; counted always


# --- the thresholds, on the counter itself ------------------------------------------------------------------------


@pytest.mark.parametrize(("fps", "two_dropped_jump"), [(30.0, False), (15.0, False), (5.0, True), (2.0, True)])
def test_a_dropped_frame_is_never_a_jump(fps: float, two_dropped_jump: bool) -> None:
    """One dropped frame (a gap of two intervals) never counts, whatever the rate; two in a row count only once the
    gap passes JUMP_S (0.6 s at 5 fps, not 0.2 s at 15 fps), or 2.5 intervals at low rates."""
    health = VideoHealth(interval_s=1 / fps)
    keep = np.ones(40, bool)
    keep[5] = False  # one dropped frame
    keep[[20, 21]] = False  # two in a row
    for t in np.flatnonzero(keep) / fps:
        assert health.stamp(float(t)) == t
    assert health.jumps == int(two_dropped_jump)
    assert health.largest_jump_at_s == (pytest.approx(19 / fps) if two_dropped_jump else 0.0)


def test_backwards_and_repeated_times_against_the_newest_kept() -> None:
    """After a frame is dropped, the next is judged against the newest kept, not the dropped one."""
    health = VideoHealth(interval_s=0.1)
    out = [health.stamp(t) for t in (0.0, 0.1, 0.2, 0.05, 0.15, 0.2, 0.3, None, 0.5)]
    assert out == [0.0, 0.1, 0.2, None, None, None, 0.3, pytest.approx(0.4), 0.5]
    assert (health.decoded, health.backwards, health.repeated, health.untimed, health.jumps) == (9, 2, 1, 1, 0)


def test_a_frame_from_a_damaged_packet_is_dropped_and_counted() -> None:
    """Its missing parts are concealed with other frames' pixels: not measured, and not taken as the newest time."""
    health = VideoHealth(interval_s=0.1)
    out = [health.stamp(0.0), health.stamp(0.1, damaged=True), health.stamp(0.2)]
    assert out == [0.0, None, 0.2] and (health.decoded, health.damaged, health.jumps) == (3, 1, 0)
    assert health.summary() == "1 frame from damaged packets dropped"
    assert health.report().news == ("frame 1 decoded from a damaged packet: dropped",)


def test_untimed_frames_follow_the_last_timed_one() -> None:
    health = VideoHealth(interval_s=0.04)
    out = [health.stamp(t) for t in (None, None, 10.0, None, None)]
    assert out == [0.0, 0.04, 10.0, 10.04, 10.08]
    assert health.jumps == 1 and health.largest_jump_s == pytest.approx(9.96)  # from the guess to the first real time


# --- the recording ------------------------------------------------------------------------------------------------


def test_the_recording_holds_the_counts_and_the_warnings(installation: Path, tmp_path: Path) -> None:
    remux(installation / "cam-port.mp4", tmp_path / "whole.mp4", options={"movflags": "+faststart"})
    data = (tmp_path / "whole.mp4").read_bytes()
    (tmp_path / "cut.mp4").write_bytes(data[:len(data) // 2])
    results, stats = tracked(installation_copy(installation, tmp_path, "cut.mp4"), packets=True)  # as --rrd: the cut
    # packet must not stop the H.264 filter either
    assert all(r.frame.packet is not None for r in results)
    rec = rr.RecordingStream("topside")
    rec.set_sinks(rr.FileSink(tmp_path / "health.rrd"))
    for r in results:
        log_health(rec, r)
    rec.flush()
    rec.disconnect()
    chunks = chunks_by_entity(tmp_path / "health.rrd")
    video = stats.videos["cam-port"]
    last = [r for r in results if r.camera == "cam-port"][-1].time
    times, decoded = component_rows(chunks["/health/cam-port/video/decoded"], "Scalars:scalars")
    assert times.tolist() == pytest.approx([last]) and decoded == [[video.decoded]]  # a sound video logs nothing
    assert component_rows(chunks["/health/cam-port/video/declared"], "Scalars:scalars")[1] == [[FRAMES]]
    times, text = component_rows(chunks["/health/cam-port/video/events"], "TextLog:text")
    assert times.tolist() == pytest.approx([last])
    assert text == [[f"cut.mp4: ended after {video.decoded} of {FRAMES} frames ({video.packets} packets read: the "
                    "file may be cut short)"]]
    assert not [e for e in chunks if e.startswith("/health/cam-ahead/video")]
    assert "/health/cam-port/markers" in chunks  # the existing series stay where they were


def test_track_says_so_in_its_summary(installation: Path, tmp_path: Path) -> None:
    """The command prints the warning line of a video cut short, and still writes what it could track."""
    import subprocess
    import sys

    remux(installation / "cam-port.mp4", tmp_path / "whole.mp4", options={"movflags": "+faststart"})
    data = (tmp_path / "whole.mp4").read_bytes()
    (tmp_path / "cut.mp4").write_bytes(data[:len(data) // 2])
    rig = installation_copy(installation, tmp_path, "cut.mp4")
    proc = subprocess.run([sys.executable, "-m", "tracking.cli", "track", "--rig", str(rig), "-o",
                           str(tmp_path / "o.csv")], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    warnings = [line for line in proc.stderr.splitlines() if line.startswith("topside: warning: cam-port: cut.mp4")]
    assert len(warnings) == 1 and f"of {FRAMES} frames" in warnings[0]
