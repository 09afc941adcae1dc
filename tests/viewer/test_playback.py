"""Live viewers: the web viewer a tablet on the stern opens, served only where --bind says."""

from __future__ import annotations

import socket
import time
import urllib.request
from pathlib import Path

import rerun as rr

from viewer.playback import start_live_viewer, stop_viewer, warn_if_exposed


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


def test_web_viewer_serves_the_page_and_takes_the_stream_on_localhost_only() -> None:
    grpc_port, web_port = free_port(), free_port()
    url, process = start_live_viewer(web=True, bind="127.0.0.1", grpc_port=grpc_port, web_port=web_port)
    try:
        page = b""
        for _ in range(150):
            try:
                page = urllib.request.urlopen(f"http://127.0.0.1:{web_port}/", timeout=1).read()
                break
            except OSError:
                time.sleep(0.2)
        assert b"<html" in page and b"Rerun" in page
        assert listening_addresses(web_port) == {"127.0.0.1"}  # not on the vessel's network unless --bind
        rec = rr.RecordingStream("topside-test")
        rec.set_sinks(rr.GrpcSink(url))
        rr.log("offsets/dx/A/estimate", rr.Scalars(0.01), recording=rec)
        rec.flush(timeout_sec=10.0)  # raises if the viewer's server does not take it
        assert process.poll() is None
    finally:
        stop_viewer(process)
    deadline = time.monotonic() + 10.0  # the server went with it (its sockets close as it exits)
    while (listening_addresses(web_port) or listening_addresses(grpc_port)) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not listening_addresses(web_port) and not listening_addresses(grpc_port)


def test_exposing_the_viewer_warns(capsys) -> None:
    warn_if_exposed("0.0.0.0")
    assert "0.0.0.0" in capsys.readouterr().err
    warn_if_exposed("127.0.0.1")
    assert capsys.readouterr().err == ""
