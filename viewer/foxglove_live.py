"""`topside live --foxglove`: the MCAP archive's channels streamed live through foxglove-sdk's WebSocket server.

The messages are built by viewer.archive.Archive, the one that writes `track --mcap` archives: its file is
replaced by ChannelWriter, which publishes each message on a channel of the same topic, schema and encoding
(protobuf), so the live stream and the archive cannot drift. Foxglove opens it as a "Foxglove WebSocket" connection
(ws://<address>:<port>); docs/foxglove-layout.json lays it out.
"""

from __future__ import annotations

import logging
import sys
from collections.abc import Mapping

import foxglove
from foxglove.websocket import ChannelView, Client, ServerListener
from google.protobuf.message import Message
from mcap.well_known import MessageEncoding, SchemaEncoding
from mcap_protobuf.schema import build_file_descriptor_set

from tracking.camera import CameraModel, load_camera
from tracking.estimate import ConeEstimate
from tracking.live import LiveUpdate
from tracking.pipeline import FrameResult
from tracking.rig import Rig
from viewer.archive import Archive, ArchiveInputs, frame_view

DEFAULT_PORT = 8765  # Foxglove's own default for a WebSocket connection
SERVER_NAME = "topside"
LOG_CHARS = 300  # a Foxglove log line is cut to this: a client's malformed message is not copied to the terminal
LOG_LEVEL = logging.WARNING  # the server's own notices (clients come and go) stay out of the operator's terminal


class _BoundedLine(logging.Formatter):
    """One line of at most LOG_CHARS characters, named as the server's."""

    def format(self, record: logging.LogRecord) -> str:
        text = " ".join(record.getMessage().split())
        return f"topside: foxglove: {record.levelname.lower()}: " + (
            text if len(text) <= LOG_CHARS else f"{text[:LOG_CHARS]}… ({len(text)} characters)")


class _Stderr(logging.Handler):
    """Writes to whatever sys.stderr is when a line comes (not the stream it was at start)."""

    def emit(self, record: logging.LogRecord) -> None:
        sys.stderr.write(self.format(record) + "\n")


def _bounded_foxglove_log() -> None:
    """Route foxglove-sdk's log (Python logging, logger "foxglove") to stderr as bounded single lines, once."""
    logger = logging.getLogger("foxglove")
    if any(isinstance(h.formatter, _BoundedLine) for h in logger.handlers):
        return
    handler = _Stderr()
    handler.setFormatter(_BoundedLine())
    logger.addHandler(handler)
    logger.setLevel(LOG_LEVEL)
    logger.propagate = False
LATCHED_SUFFIXES = ("/calibration", "/frames/markers", "/log")  # a client that subscribes gets the newest message at
# once: calibration and marker frames are state (the archive repeats them only every second of capture time), and the
# newest log line tells a late client where the session stands (a channel is advertised only once it has a message)


class ChannelWriter:
    """Stands in for the Archive's ArchiveFile: every message goes out on its topic's channel as it is written.

    Metadata, attachments and chunk flushes belong to the file and have no live counterpart; they are dropped.
    """

    def __init__(self, context: foxglove.Context) -> None:
        self.context = context
        self.channels: dict[str, foxglove.Channel] = {}
        self.latest: dict[str, tuple[bytes, int]] = {}  # latched topics: the newest message and its log time
        self.first_ns: int | None = None
        self.last_ns: int | None = None

    def write(self, topic: str, message: Message, ns: int) -> None:
        """One protobuf message at log time ns, on its topic's channel (advertised with the message's schema)."""
        channel = self.channels.get(topic)
        if channel is None:
            schema = foxglove.Schema(name=message.DESCRIPTOR.full_name, encoding=SchemaEncoding.Protobuf,
                                     data=build_file_descriptor_set(type(message)).SerializeToString())
            channel = foxglove.Channel(topic, schema=schema, message_encoding=MessageEncoding.Protobuf,
                                       context=self.context)
            self.channels[topic] = channel
        data = message.SerializeToString()
        if topic.endswith(LATCHED_SUFFIXES):  # latched before it goes out: Latch runs on the server's thread, so a
            self.latest[topic] = (data, ns)  # client subscribing between log() and the latch would get neither
        channel.log(data, log_time=ns)
        self.first_ns = ns if self.first_ns is None else min(self.first_ns, ns)
        self.last_ns = ns if self.last_ns is None else max(self.last_ns, ns)

    def resend(self, topic: str) -> None:
        """A latched topic's newest message again (to its subscribers, the new one among them)."""
        if topic in self.latest and topic in self.channels:
            data, ns = self.latest[topic]
            self.channels[topic].log(data, log_time=ns)

    def metadata(self, name: str, data: Mapping[str, str]) -> None:
        """A metadata record: the file's only."""

    def attach(self, name: str, media_type: str, data: bytes, log_time: int = 0, create_time: int = 0) -> None:
        """An attachment: the file's only."""

    def flush(self) -> None:
        """Nothing waits: every message went out when written."""

    def close(self, **manifest_extra: object) -> dict:
        """Close every channel (unadvertised to the clients). Returns no manifest."""
        for channel in self.channels.values():
            channel.close()
        return {}


class Latch(ServerListener):
    """On a new subscription, the latched topic's newest message (calibration, marker frames, log)."""

    def __init__(self, writer: ChannelWriter) -> None:
        self.writer = writer

    def on_subscribe(self, client: Client, channel: ChannelView) -> None:
        self.writer.resend(channel.topic)


class FoxgloveStream:
    """A live session's archive channels on a Foxglove WebSocket server bound to one address of this machine."""

    def __init__(self, rig: Rig, address: str, port: int = DEFAULT_PORT, options: Mapping[str, str] | None = None,
                 cameras: Mapping[str, CameraModel] | None = None) -> None:
        self.rig = rig
        _bounded_foxglove_log()
        self.context = foxglove.Context()
        self.writer = ChannelWriter(self.context)
        self.server = foxglove.start_server(name=f"{SERVER_NAME} {rig.name}", host=address, port=port,
                                            context=self.context, server_listener=Latch(self.writer))
        cams = dict(cameras) if cameras is not None else {
            c.name: load_camera(rig.resolve(c.calibration)) for c in rig.cameras}
        self.archive = Archive(None, rig, ArchiveInputs.from_rig(rig, options or {}), cams, file=self.writer)
        self.closed = False

    @property
    def port(self) -> int:
        """The port the server listens on (the one asked for, or the one the OS gave for 0)."""
        return self.server.port

    def on_frame(self, result: FrameResult) -> None:
        """One processed frame: image, calibration, detections, camera frame, health, events."""
        self.archive.frame(frame_view(self.rig, self.archive.cameras[result.camera], result))

    def on_estimate(self, estimate: ConeEstimate) -> None:
        """One cone estimate: offset, topside and filter camera frames, state changes."""
        self.archive.estimate(estimate)

    def on_update(self, update: LiveUpdate) -> None:
        """A live update's frames and estimates, in capture-time order."""
        for item in update.in_capture_order():
            if isinstance(item, ConeEstimate):
                self.on_estimate(item)
            else:
                self.on_frame(item)

    def close(self, stopped: str = "") -> None:
        """The archive's closing messages, then the server stops (its clients are disconnected)."""
        if self.closed:
            return
        self.closed = True
        try:
            self.archive.close()
        finally:
            self.server.stop()
