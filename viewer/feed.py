"""A live viewer fed without ever waiting for it: the Rerun stream it shows, encoded in memory by Rerun's binary
sink (rr.BinaryStream, no back-pressure), written to the viewer process's standard input only as fast as it takes it.

Why not Rerun's gRPC sink: rerun 0.41 carries back-pressure from the slowest viewer to the logging process. Its
server waits for its slowest page (1024 messages or 128 MB queued), then stops reading the SDK's gRPC client, whose
queue (100 messages) then holds its sink's thread: a file sharing that stream stopped being written, and the next
segment's set_sinks waited for the old sink without end (a stuck page stopped `topside live`, issue 37). A separate
stream only moves the wait: once its 100 MB of queues are full, its log and flush calls wait too, whatever their
timeout, and disconnecting it waits as well. Here nothing waits: the bytes go out non-blocking, and a viewer that
takes nothing for VIEWER_STALL_S, or falls VIEWER_BACKLOG_BYTES behind, is cut loose (its input closed) with one
line on stderr; the recording and the offsets CSV go on.
"""

from __future__ import annotations

import fcntl
import os
import sys
import time
from collections import deque
from typing import IO

import numpy as np
import rerun as rr

VIEWER_STALL_S = 10.0  # a viewer that takes no byte for this long while some wait is stuck: a healthy one reads at
# once (with --newest-first a late page's history does not hold back the live stream)
VIEWER_BACKLOG_BYTES = 64 << 20  # at most this much waits for a viewer (~20 s of the "all" scope at 3 MB/s)
PIPE_BYTES = 1 << 20  # the pipe's buffer: Linux's largest for an unprivileged process (fs.pipe-max-size)
F_SETPIPE_SZ = getattr(fcntl, "F_SETPIPE_SZ", 1031)  # fcntl command (linux/fcntl.h), named in Python ≥ 3.10
CLOSE_POLL_S = 0.05  # at the end, what is left is offered this often


class ViewerFeed:
    """The input of one viewer process (its stdin): Rerun streams' bytes written as it takes them, never waited for.

    pipe: the write end, made non-blocking; a regular file works too (it never fills). name: how the line on
    stderr names the viewer. stall_s, backlog_bytes: when it is cut loose (VIEWER_STALL_S, VIEWER_BACKLOG_BYTES).
    """

    def __init__(self, pipe: IO[bytes], name: str = "the live viewer", stall_s: float = VIEWER_STALL_S,
                 backlog_bytes: int = VIEWER_BACKLOG_BYTES) -> None:
        self.name = name
        self.stall_s = stall_s
        self.backlog_bytes = backlog_bytes
        self._pipe = pipe
        self._fd = pipe.fileno()
        os.set_blocking(self._fd, False)
        try:
            fcntl.fcntl(self._fd, F_SETPIPE_SZ, PIPE_BYTES)
        except OSError:  # not a pipe, or a smaller limit: the default buffer only means more writes
            pass
        self._sources: list[rr.BinaryStream] = []
        self._pending: deque[memoryview] = deque()  # whole reads of the streams, in order; the first partly sent
        self._read_at: deque[float] = deque()  # the live clock when each of them was read
        self.pending_bytes = 0
        self._taken = time.monotonic()  # when the viewer last took bytes, or had nothing waiting
        self.sent = 0  # bytes the viewer took
        self.cut_reason: str | None = None  # why it was cut loose (None: it is fed)

    @property
    def alive(self) -> bool:
        """The viewer is fed (not cut loose)."""
        return self.cut_reason is None

    def stream(self, rec: rr.RecordingStream) -> rr.BinaryStream:
        """A binary sink for rec whose bytes this feed sends (pass it to rec.set_sinks beside the others)."""
        sink = rr.binary_stream(rec)
        self._sources.append(sink)
        return sink

    def pump(self, now: float = np.nan) -> None:
        """Take what the streams have encoded (read at the live clock's now) and write what the viewer takes now;
        cut it loose when it is stuck or too far behind. Once cut loose, the streams' bytes are read and dropped
        (memory stays bounded)."""
        for source in self._sources:
            data = source.read(flush=False)
            if data and self.alive:
                self._pending.append(memoryview(data))
                self._read_at.append(now)
                self.pending_bytes += len(data)
        if not self.alive:
            return
        self._write()
        now = time.monotonic()
        if not self._pending:
            self._taken = now
        elif self.pending_bytes > self.backlog_bytes:
            self.cut(f"fell {self.pending_bytes / 1e6:.0f} MB behind")
        elif now - self._taken > self.stall_s:
            self.cut(f"took nothing for {now - self._taken:.0f} s")

    def _write(self) -> None:
        """Write the waiting bytes, in order, until the viewer's input is full."""
        while self._pending and self.alive:
            try:
                n = os.write(self._fd, self._pending[0])
            except BlockingIOError:
                return
            except OSError as exc:  # EPIPE: the viewer is gone
                self.cut(f"is gone ({exc.strerror})")
                return
            self._taken = time.monotonic()
            self.sent += n
            self.pending_bytes -= n
            if n == len(self._pending[0]):
                self._pending.popleft()
                self._read_at.popleft()
            else:
                self._pending[0] = self._pending[0][n:]

    def behind(self, now: float) -> float:
        """How far the viewer's input is behind the live clock, s: how long the oldest bytes still waiting for it
        have waited (0 when it has taken everything; the viewer's own queues are not seen here)."""
        if not self._read_at or not np.isfinite(self._read_at[0]):
            return 0.0
        return max(0.0, now - self._read_at[0])

    def cut(self, why: str) -> None:
        """Stop feeding the viewer: its input closed, what waited for it dropped, one line on stderr."""
        if not self.alive:
            return
        self.cut_reason = why
        self._pending.clear()
        self._read_at.clear()
        self.pending_bytes = 0
        self._close_pipe()
        print(f"warning: {self.name} {why}: cut loose (its stream closed); the recording and the offsets CSV go on",
              file=sys.stderr, flush=True)

    def _close_pipe(self) -> None:
        """Close the viewer's input (nothing was written through the file object: no buffer to flush)."""
        try:
            self._pipe.close()
        except OSError:
            pass

    def send_now(self, timeout_s: float) -> None:
        """Encode what was logged (at most timeout_s: encoding only, a binary sink waits for no viewer) and offer
        it: at the start, the viewer's servers listen only once its input has begun."""
        for source in self._sources:
            try:
                source.flush(timeout_sec=timeout_s)
            except RuntimeError:
                pass
        self.pump()

    def close(self, timeout_s: float) -> None:
        """Send what is left within timeout_s (the streams flushed first), then close the viewer's input."""
        deadline = time.monotonic() + timeout_s
        self.send_now(timeout_s)
        while self.alive and self._pending and time.monotonic() < deadline:
            time.sleep(CLOSE_POLL_S)
            self.pump()
        if self.alive and self._pending:
            print(f"warning: {self.name} did not take the last {self.pending_bytes / 1e6:.1f} MB within "
                  f"{timeout_s:.0f} s; the recording is complete", file=sys.stderr, flush=True)
        if self.alive:
            self.cut_reason = "closed"
            self._close_pipe()
