"""Cameras as network streams for tests: a video copied to MPEG-TS (no re-encoding) and served over local HTTP."""

from __future__ import annotations

import functools
import http.server
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import av


def mpegts_copy(video: Path, out: Path) -> Path:
    """The video stream of a file remuxed into an MPEG-TS file out, packet for packet; out."""
    with av.open(str(video)) as src, av.open(str(out), "w", format="mpegts") as dst:
        stream = dst.add_stream_from_template(src.streams.video[0])
        for packet in src.demux(src.streams.video[0]):
            if packet.dts is not None:
                packet.stream = stream
                dst.mux(packet)
    return out


class _Quiet(http.server.SimpleHTTPRequestHandler):
    def log_message(self, *args: object) -> None:  # no request lines in the test's output
        pass


@contextmanager
def serving(folder: Path) -> Iterator[str]:
    """A folder served over HTTP on 127.0.0.1 (a free port) while in the block; its base URL."""
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), functools.partial(_Quiet, directory=str(folder)))
    threading.Thread(target=server.serve_forever, daemon=True).start()
    try:
        yield f"http://127.0.0.1:{server.server_address[1]}"
    finally:
        server.shutdown()
        server.server_close()
