"""Viewers: served only where --bind says, refused on unreadable recordings, stopped with everything they started."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import cv2
import numpy as np
import pytest
import rerun as rr

from tracking.errors import InputError
from viewer.feed import ViewerFeed
from viewer.playback import (
    check_recording,
    live_viewer_command,
    rerun_binary,
    rerun_env,
    resolve_bind,
    start_live_viewer,
    stop_viewer,
    view_recording,
    viewer_command,
    warn_if_exposed,
    web_viewer_url,
)

TOPSIDE = [sys.executable, "-m", "tracking.cli"]
REPO = Path(__file__).resolve().parents[2]
START_TIMEOUT_S = 90.0  # the CLI's imports and the server's start on a loaded 2-core machine
STOP_TIMEOUT_S = 20.0


def free_port() -> int:
    """A TCP port nobody listens on."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def listening_addresses(port: int) -> set[str]:
    """IPv4 addresses with a socket listening on the port, from /proc/net/tcp."""
    found = set()
    for line in Path("/proc/net/tcp").read_text().splitlines()[1:]:
        local, state = line.split()[1], line.split()[3]
        address, hex_port = local.split(":")
        if state == "0A" and int(hex_port, 16) == port:  # 0A: LISTEN
            found.add(socket.inet_ntoa(bytes.fromhex(address)[::-1]))
    return found


def children(pid: int) -> list[int]:
    """Processes whose parent is pid, from /proc."""
    found = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            found.append(int(stat.parent.name))
    return found


def group_members(pgid: int) -> list[int]:
    """Processes (zombies included) in the process group, from /proc."""
    found = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[2]) == pgid:
            found.append(int(stat.parent.name))
    return found


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A small complete recording with 10 s of capture time."""
    path = tmp_path_factory.mktemp("recording") / "run.rrd"
    rec = rr.RecordingStream("topside-test")
    rec.save(path)
    for i in range(100):
        rec.set_time("capture_time", duration=i * 0.1)
        rr.log("offsets/dx/A/estimate", rr.Scalars(float(i)), recording=rec)
    rec.flush()
    rec.disconnect()
    return path


def serve(recording: Path, tmp: Path, *options: str) -> tuple[subprocess.Popen, str, int, int]:
    """`topside view --web` on free ports with its own TMPDIR: (process, the URL it printed, web port, gRPC port)."""
    web_port, grpc_port = free_port(), free_port()
    env = os.environ | {"TMPDIR": str(tmp)}
    process = subprocess.Popen([*TOPSIDE, "view", "--web", str(recording), "--web-port", str(web_port),
                                "--grpc-port", str(grpc_port), *options], cwd=REPO, env=env,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    line = process.stdout.readline()  # the URL, printed once the page answers
    if not line.startswith("http://"):
        process.kill()
        pytest.fail(f"no URL printed: {line!r} {process.communicate(timeout=STOP_TIMEOUT_S)}")
    return process, line.strip(), web_port, grpc_port


def assert_stopped(process: subprocess.Popen, tmp: Path, web_port: int, grpc_port: int, server_pid: int) -> str:
    """The command ended, its server's group is gone with its ports, its temporary folder removed: its stderr."""
    _, err = process.communicate(timeout=STOP_TIMEOUT_S)
    assert process.returncode == 130, err  # ended as Ctrl-C ends a command
    assert group_members(server_pid) == []
    assert not listening_addresses(web_port) and not listening_addresses(grpc_port)
    assert list(tmp.glob("topside-view-*")) == []
    return err


def test_web_view_prints_the_url_and_sigterm_stops_the_server_and_removes_its_files(recording: Path,
                                                                                     tmp_path: Path) -> None:
    process, url, web_port, grpc_port = serve(recording, tmp_path, "--from", "2", "--to", "5")  # a window: temp files
    try:
        assert url == web_viewer_url("127.0.0.1", grpc_port, web_port)
        assert f"?url=rerun%2Bhttp%3A%2F%2F127.0.0.1%3A{grpc_port}%2Fproxy" in url  # quoted: a query reads + as a space
        page = urllib.request.urlopen(url, timeout=10).read()
        assert b"<html" in page
        assert listening_addresses(web_port) == {"127.0.0.1"} and listening_addresses(grpc_port) == {"127.0.0.1"}
        [server] = children(process.pid)
        assert os.getpgid(server) == server  # its own group: stopped with whatever it starts
        assert list(tmp_path.glob("topside-view-*/window/*"))  # the window cut from the recording
    finally:
        process.send_signal(signal.SIGTERM)
    assert_stopped(process, tmp_path, web_port, grpc_port, server)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="PR_SET_PDEATHSIG is Linux's")
def test_the_server_ends_when_topside_is_killed(recording: Path, tmp_path: Path) -> None:
    process, _, web_port, grpc_port = serve(recording, tmp_path)
    [server] = children(process.pid)
    process.send_signal(signal.SIGKILL)  # no handler runs: the kernel tells the server its parent died
    process.communicate(timeout=STOP_TIMEOUT_S)
    deadline = time.monotonic() + STOP_TIMEOUT_S
    while group_members(server) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert group_members(server) == []
    assert not listening_addresses(web_port) and not listening_addresses(grpc_port)


def test_a_killed_view_leaves_no_temporary_folder(recording: Path, tmp_path: Path) -> None:
    """kill -9 of `view --web` on a window of a recording (a cut in its temporary folder): the folder is gone within
    5 s, and so is the process that removed it."""
    process, _, _, _ = serve(recording, tmp_path, "--from", "2", "--to", "5")
    [folder] = tmp_path.glob("topside-view-*")
    assert list(folder.glob("window/*"))
    process.send_signal(signal.SIGKILL)
    process.communicate(timeout=STOP_TIMEOUT_S)
    killed = time.monotonic()
    while folder.exists() and time.monotonic() < killed + 5.0:
        time.sleep(0.05)
    assert not folder.exists()
    wardens = [p for p in Path("/proc").glob("[0-9]*/cmdline") if str(folder).encode() in _read(p)]
    while wardens and time.monotonic() < killed + 5.0:
        time.sleep(0.05)
        wardens = [p for p in wardens if p.exists()]
    assert wardens == []


def _read(path: Path) -> bytes:
    try:
        return path.read_bytes()
    except OSError:
        return b""


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGHUP])
def test_web_view_on_localhost_stops_on_ctrl_c_twice_or_a_hangup(recording: Path, tmp_path: Path, signum: int) -> None:
    process, url, web_port, grpc_port = serve(recording, tmp_path, "--bind", "localhost")
    try:
        assert url.startswith(f"http://127.0.0.1:{web_port}/")  # the name resolved: Rerun gets an address
        assert listening_addresses(web_port) == {"127.0.0.1"}
        [server] = children(process.pid)
    finally:
        process.send_signal(signum)
        process.send_signal(signum)  # an impatient second one does not cut the cleanup short
    err = assert_stopped(process, tmp_path, web_port, grpc_port, server)
    assert "warning" not in err


@pytest.mark.parametrize("content, expected", [(cv2.imencode(".png", np.zeros((8, 8, 3), np.uint8))[1].tobytes(),
                                                 "is not a Rerun recording"), (b"", "is empty")], ids=["png", "empty"])
def test_a_file_that_is_no_recording_is_refused_in_one_line(tmp_path: Path, content: bytes, expected: str) -> None:
    bad = tmp_path / "photo.rrd"
    bad.write_bytes(content)
    proc = subprocess.run([*TOPSIDE, "view", "--web", str(bad), "--web-port", str(free_port())], cwd=REPO,
                          capture_output=True, text=True, timeout=START_TIMEOUT_S)
    assert proc.returncode == 2
    assert len(proc.stderr.strip().splitlines()) == 1 and str(bad) in proc.stderr and expected in proc.stderr
    assert proc.stdout == ""  # no URL: nothing was served


def test_a_truncated_recording_is_refused_in_one_line(recording: Path, tmp_path: Path) -> None:
    cut = tmp_path / "cut.rrd"
    cut.write_bytes(recording.read_bytes()[: recording.stat().st_size * 2 // 3])
    proc = subprocess.run([*TOPSIDE, "view", "--web", str(cut), "--web-port", str(free_port())], cwd=REPO,
                          capture_output=True, text=True, timeout=START_TIMEOUT_S)
    assert proc.returncode == 2
    assert len(proc.stderr.strip().splitlines()) == 1 and str(cut) in proc.stderr and "incomplete" in proc.stderr
    with pytest.raises(InputError, match="no data"):  # a bare header, as a writer leaves it before its first chunk
        (tmp_path / "header.rrd").write_bytes(recording.read_bytes()[:12])
        check_recording(tmp_path / "header.rrd")
    check_recording(recording)  # the complete file passes


def test_an_address_that_does_not_resolve_or_is_not_this_machines_is_refused(recording: Path) -> None:
    proc = subprocess.run([*TOPSIDE, "view", "--web", str(recording), "--bind", "no.such.host.invalid"], cwd=REPO,
                          capture_output=True, text=True, timeout=START_TIMEOUT_S)
    assert proc.returncode == 2
    assert len(proc.stderr.strip().splitlines()) == 1 and "--bind" in proc.stderr and "does not resolve" in proc.stderr
    with pytest.raises(InputError, match="not an address of this machine"):
        resolve_bind("192.0.2.1")  # TEST-NET-1: never one of ours
    assert resolve_bind("localhost") == "127.0.0.1"


def test_a_port_in_use_is_refused_before_anything_starts(recording: Path) -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        with pytest.raises(InputError, match="--web-port"):
            view_recording(recording, web=True, web_port=port, grpc_port=free_port())
        with pytest.raises(InputError, match="--grpc-port"):
            view_recording(recording, web=True, web_port=free_port(), grpc_port=port)


def test_every_viewer_command_binds_the_address_it_is_given(recording: Path) -> None:
    for cmd in (viewer_command(recording, web=True), viewer_command(recording, web=False),
                live_viewer_command(web=True), live_viewer_command(web=False)):
        assert cmd[cmd.index("--bind") + 1] == "127.0.0.1"  # Rerun's own default is every interface
    native = viewer_command(recording, web=False, address="10.1.2.3")
    assert native[native.index("--bind") + 1] == "10.1.2.3"


def test_rerun_runs_with_its_analytics_off(recording: Path) -> None:
    env = rerun_env() | {"RUST_LOG": "re_analytics=debug"}
    proc = subprocess.run([rerun_binary(), "rrd", "stats", "--no-decode", str(recording)], env=env,
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert "Analytics disabled" in proc.stderr and "Sending analytics" not in proc.stderr


def test_web_viewer_serves_the_page_and_takes_the_stream_on_localhost_only() -> None:
    grpc_port, web_port = free_port(), free_port()
    process = start_live_viewer(web=True, bind="127.0.0.1", grpc_port=grpc_port, web_port=web_port)
    try:
        feed = ViewerFeed(process.stdin)  # its servers start once their input has begun
        rec = rr.RecordingStream("topside-test")
        rec.set_sinks(feed.stream(rec))
        rr.log("offsets/dx/A/estimate", rr.Scalars(0.01), recording=rec)
        feed.send_now(10.0)
        page = b""
        for _ in range(150):
            try:
                page = urllib.request.urlopen(f"http://127.0.0.1:{web_port}/", timeout=1).read()
                break
            except OSError:
                time.sleep(0.2)
        assert b"<html" in page and b"Rerun" in page
        assert listening_addresses(web_port) == {"127.0.0.1"}  # not on the vessel's network unless --bind
        rr.log("offsets/dx/A/estimate", rr.Scalars(0.02), recording=rec)
        feed.close(10.0)
        assert feed.sent > 0 and feed.cut_reason == "closed"  # the server took it all; never cut loose
        assert process.poll() is None
    finally:
        stop_viewer(process)
    assert group_members(process.pid) == []  # the server went with it, its sockets closed
    assert not listening_addresses(web_port) and not listening_addresses(grpc_port)


def test_exposing_the_viewer_warns(capsys: pytest.CaptureFixture[str]) -> None:
    warn_if_exposed("0.0.0.0")
    assert "0.0.0.0" in capsys.readouterr().err
    warn_if_exposed("127.0.0.1")
    warn_if_exposed("::1")
    assert capsys.readouterr().err == ""
