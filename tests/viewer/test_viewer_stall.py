"""No viewer can stop the monitor: `topside live --web` records while a page stops reading its stream, as a stuck
browser does (its gRPC-web request open, its socket never read); every segment and every CSV row still comes on
time, and the session ends by itself (issue 37, item 0)."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from tests.conftest import FPS, REPO, T0
from tests.viewer.test_playback import free_port
from viewer.readback import chunks_by_entity, component_rows

CAPTURE_S = 20.0  # capture time a session runs (--duration, the clip looped): before the fix ("all" scope), recording
# and CSV stopped 10 s in (1 s segments; 18 s with 5 s segments), at the first segment boundary after the viewer's
# server had stopped taking data (1024 messages or 128 MB queued for the stuck page)
START_S = 30.0  # the session's start (workers loading, the viewer's server listening), on a loaded 2-core machine
LATE_S = 4.0  # a segment's file may open this much after its capture time is due (CPU on 2 cores, compactions)
CSV_GAP_S = 8.0  # the CSV is flushed every 100 rows, ~3.3 s at 30 rows/s: a longer silence is a stalled CSV
END_S = 20.0  # after its capture ends, the session closes its files and stops the viewer within this
READ_WINDOW = 65536  # the stuck page's receive buffer, bytes: it fills at once
POLL_S = 0.25  # the test samples the session's files this often
READ_MESSAGES = "/rerun.sdk_comms.v1alpha1.MessageProxyService/ReadMessages"  # what Rerun's web viewer calls


def stuck_page(port: int, timeout: float = START_S) -> socket.socket:
    """A web viewer's data request (gRPC-web over HTTP/1.1, as a browser sends it) to the viewer's server, answered,
    then never read again: the server's queue to it fills as a stuck page's does. Waits until the server listens."""
    deadline = time.monotonic() + timeout
    while True:
        s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, READ_WINDOW)
        try:
            s.connect(("127.0.0.1", port))
            break
        except OSError:
            s.close()
            if time.monotonic() > deadline:
                raise
            time.sleep(POLL_S)
    body = b"\x00\x00\x00\x00\x00"  # one gRPC-web frame: an empty ReadMessagesRequest
    s.sendall((f"POST {READ_MESSAGES} HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\n"
               "Content-Type: application/grpc-web+proto\r\nAccept: application/grpc-web+proto\r\nX-Grpc-Web: 1\r\n"
               f"Content-Length: {len(body)}\r\n\r\n").encode() + body)
    s.settimeout(timeout)
    assert s.recv(12).startswith(b"HTTP/1.1 200")  # the server streams to it from now on
    return s


def segments_opened(folder: Path) -> int:
    """Segment files the session has opened so far (each written first under a temporary name)."""
    return len({p.name.split(".")[0] for p in folder.glob("live-*.rrd")})


def csv_bytes(folder: Path) -> int:
    """Size of the offsets CSV being written (under its temporary name until the session ends)."""
    return sum(p.stat().st_size for p in folder.glob("offsets*.csv"))


def run_with_stuck_page(folder: Path, rig: Path, scope: str, segment_s: float
                        ) -> tuple[list[tuple[float, int, int]], subprocess.CompletedProcess]:
    """`topside live --web --loop` for CAPTURE_S with a stuck page attached: its files sampled every POLL_S as (wall
    time, segments opened, CSV bytes), and how it ended (killed when it outlives its capture by END_S)."""
    grpc_port, web_port = free_port(), free_port()
    cmd = [sys.executable, "-m", "tracking.cli", "live", "--rig", str(rig), "--rrd", str(folder / "live.rrd"),
           "-o", str(folder / "offsets.csv"), "--web", "--grpc-port", str(grpc_port), "--web-port", str(web_port),
           "--viewer-scope", scope, "--segment-minutes", str(segment_s / 60), "--duration", str(CAPTURE_S), "--loop"]
    proc = subprocess.Popen(cmd, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)
    samples: list[tuple[float, int, int]] = []
    page = None
    try:
        page = stuck_page(grpc_port)
        deadline = time.monotonic() + START_S + CAPTURE_S + END_S
        while proc.poll() is None and time.monotonic() < deadline:
            samples.append((time.monotonic(), segments_opened(folder), csv_bytes(folder)))
            time.sleep(POLL_S)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)  # the session and the viewer it started
        out, err = proc.communicate()
        if page is not None:
            page.close()
    return samples, subprocess.CompletedProcess(cmd, proc.returncode, out, err)


def longest_wait(samples: list[tuple[float, int, int]], column: int) -> tuple[float, float]:
    """The longest wall time a sampled count stayed the same once it had begun to grow: (seconds, since when)."""
    start = next((k for k in range(1, len(samples)) if samples[k][column] > samples[0][column]), None)
    if start is None:
        return float("inf"), samples[0][0]
    longest, since, changed = 0.0, samples[start][0], samples[start][0]
    for k in range(start + 1, len(samples)):
        if samples[k][column] != samples[k - 1][column]:
            changed = samples[k][0]
        if samples[k][0] - changed > longest:
            longest, since = samples[k][0] - changed, changed
    return longest, since


@pytest.mark.parametrize(("scope", "segment_s"), [("all", 1.0), ("superintendent", 2.0)])  # the 1 s segments cross
# most boundaries; the superintendent scope has its own stream
def test_a_stuck_page_stops_neither_the_recording_nor_the_csv(installation: Path, tmp_path: Path, scope: str,
                                                             segment_s: float) -> None:
    samples, proc = run_with_stuck_page(tmp_path, installation / "rig.yaml", scope, segment_s)
    t0 = samples[0][0]
    where = [(round(t - t0, 1), n, size) for t, n, size in samples[-3:]]
    wait, since = longest_wait(samples, 1)
    assert wait <= segment_s + LATE_S, f"no new segment for {wait:.1f} s from {since - t0:.1f} s: {where}"
    wait, since = longest_wait(samples, 2)
    assert wait <= CSV_GAP_S, f"the CSV stood still for {wait:.1f} s from {since - t0:.1f} s: {where}"
    assert proc.returncode == 0, f"the session outlived its capture by {END_S} s (killed): last samples {where}"
    index = pd.read_csv(tmp_path / "live.segments.csv")
    assert len(index) >= CAPTURE_S / segment_s - 1
    assert index["end"].iloc[-1] >= T0 + CAPTURE_S - 1.0  # recorded to the end of its capture
    assert all((tmp_path / name).is_file() for name in index["file"])  # every segment under its final name
    rows = pd.read_csv(tmp_path / "offsets.csv")
    assert rows["time"].max() >= T0 + CAPTURE_S - 1.0
    assert len(rows) >= 0.8 * CAPTURE_S * 2 * FPS  # a row a frame of either camera, less the first frames'
    assert proc.stderr.count("cut loose") <= 1  # a viewer that falls behind is cut loose once, with one line


STALL_S = 1.0  # the test's feed cuts a viewer loose after this (the tool's: viewer.feed.VIEWER_STALL_S)
LAPS = 5  # the clip replayed this often in real time: ~4.5 s, the stall seen several times over


@pytest.mark.parametrize("how", ["stopped", "gone"])
def test_a_stopped_or_gone_viewer_is_cut_loose_and_the_recording_goes_on(
        installation: Path, tmp_path: Path, capfd: pytest.CaptureFixture[str], how: str) -> None:
    """The tool's own web viewer, SIGSTOPped (its input never read again) or killed (its input closed), fed the whole
    recording ("all"): cut loose once, with one line on stderr; no update waits for it; every frame is in the file."""
    from dataclasses import replace

    import rerun as rr

    from tracking.live import LiveUpdate
    from tracking.pipeline import track_rig
    from tracking.rig import load_rig
    from viewer.feed import ViewerFeed
    from viewer.playback import start_live_viewer, stop_viewer
    from viewer.session import Recorder

    rr.set_strict_mode(True)
    rig = load_rig(installation / "rig.yaml")
    results = list(track_rig(rig, packets=True))
    span = max(r.time for r in results) - min(r.time for r in results) + 1 / FPS
    process = start_live_viewer(web=True, grpc_port=free_port(), web_port=free_port())
    try:
        feed = ViewerFeed(process.stdin, stall_s=STALL_S)
        recorder = Recorder(rig, tmp_path / "live.rrd", viewer=feed, segment_s=0.5, layout="superintendent",
                            viewer_scope="all")
        os.killpg(process.pid, signal.SIGSTOP if how == "stopped" else signal.SIGKILL)
        slowest = 0.0
        for k in range(LAPS):
            lap = [replace(r, frame=replace(r.frame, time=r.time + k * span, index=r.frame.index + k * 100))
                   for r in results]
            for r in lap:  # one update a frame, at the frames' own pace
                start = time.monotonic()
                recorder.on_update(LiveUpdate(now=r.time, results=[r]))
                slowest = max(slowest, time.monotonic() - start)
                time.sleep(max(0.0, 1 / (2 * FPS) - (time.monotonic() - start)))
        start = time.monotonic()
        recorder.close()
        closing = time.monotonic() - start
    finally:
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGCONT)  # so that it can end
        stop_viewer(process)
    assert feed.cut_reason is not None and feed.cut_reason.startswith("took nothing" if how == "stopped" else "is")
    assert capfd.readouterr().err.count("cut loose") == 1
    assert slowest < 0.5 and closing < 5.0  # nobody waited for the viewer
    frames = 0
    for name in pd.read_csv(tmp_path / "live.segments.csv")["file"]:
        chunks = chunks_by_entity(tmp_path / name)
        frames += len(component_rows(chunks["/world/cameras/cam-port/image"], "VideoStream:sample")[0])
    assert frames >= LAPS * sum(r.camera == "cam-port" for r in results)  # segments open with their GOP: >=
    with capfd.disabled():  # the numbers, for `pytest -s`
        print(f"\n{how}: cut loose ({feed.cut_reason}) after {feed.sent / 1e6:.1f} MB taken; slowest update "
              f"{slowest * 1e3:.0f} ms, close {closing:.2f} s")


def test_a_view_behind_the_live_clock_says_so(installation: Path, tmp_path: Path) -> None:
    """The superintendent's own stream, its viewer not reading for 9 s of capture (then reading again): the cone
    panels it gets while its input is more than VIEW_BEHIND_S behind are grey, "behind by N s"; the file's are not."""
    import threading
    from dataclasses import replace

    import rerun as rr

    from tracking.estimate import ConeEstimate
    from tracking.live import LiveUpdate
    from tracking.pipeline import track_rig
    from tracking.rig import load_rig
    from viewer.feed import ViewerFeed
    from viewer.playback import rerun_binary, rerun_env
    from viewer.session import BATCH_TICK_S, Recorder
    from viewer.superintendent import VIEW_BEHIND_S

    rr.set_strict_mode(True)
    rig = load_rig(installation / "rig.yaml")
    results = list(track_rig(rig, packets=True))
    span = max(r.time for r in results) - min(r.time for r in results) + 1 / FPS
    read, write = os.pipe()
    feed = ViewerFeed(os.fdopen(write, "wb"), stall_s=600.0)  # slow, not stuck: never cut loose here
    recorder = Recorder(rig, tmp_path / "live.rrd", viewer=feed, segment_s=2.0, layout="superintendent")
    for k in range(10):  # the live clock runs 9 s ahead of what the unread pipe took
        time.sleep(BATCH_TICK_S + 0.1)  # a lap's rows reach the viewer's bytes (in wall time) before the next lap
        for r in results:
            r = replace(r, frame=replace(r.frame, time=r.time + k * span, index=r.frame.index + k * 100))
            estimate = ConeEstimate(r.time, "A", np.full(3, 0.01), (r.camera,), np.eye(3) * 1e-6)
            recorder.on_update(LiveUpdate(now=r.time, results=[r], estimates=[estimate], last_measurement=r.time))
    assert feed.alive and feed.behind(results[-1].time + 9 * span) > VIEW_BEHIND_S
    view = tmp_path / "view.rrd"
    with view.open("wb") as out:  # the viewer reads again
        reader = threading.Thread(target=lambda: out.write(os.fdopen(read, "rb").read()))
        reader.start()
        recorder.close()
        reader.join(30.0)
    subprocess.run([rerun_binary(), "rrd", "merge", str(view), "-o", str(tmp_path / "merged.rrd")], check=True,
                   capture_output=True, env=rerun_env())
    shown = [t[0] for t in component_rows(chunks_by_entity(tmp_path / "merged.rrd")["/superintendent/cones/A"],
                                          "TextDocument:text")[1]]
    assert any("NO DATA" in t and "behind the live clock" in t for t in shown)
    assert any("14 mm" in t and "0.00 s old at" in t for t in shown)  # figures while it kept up
    recorded = [t[0] for name in pd.read_csv(tmp_path / "live.segments.csv")["file"]
                for t in component_rows(chunks_by_entity(tmp_path / name)["/superintendent/cones/A"],
                                        "TextDocument:text")[1]]
    assert recorded and not any("behind" in t for t in recorded)  # the record says what was measured
