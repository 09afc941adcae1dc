"""Foxglove: the shipped layout names only what an archive holds; `live --foxglove` streams the archive's channels."""

from __future__ import annotations

import asyncio
import base64
import json
import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import websockets
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from mcap.reader import make_reader

from tests.browser import stopped_after
from tests.conftest import Archived
from tests.viewer.test_playback import free_port, listening_addresses
from tracking.rig import load_rig
from tracking.sim.scenario import load_scenario
from tracking.sim.scene import CONE_SIGNS
from viewer.archive import ConeOffset, calibration_message, log_message
from viewer.foxglove_layout import SCRIPT_PREFIX, foxglove_layout, layout_json, rig_layout
from viewer.foxglove_live import FoxgloveStream

REPO = Path(__file__).resolve().parents[2]
LAYOUT = REPO / "docs" / "foxglove-layout.json"
DEMO_SCENARIO = "config2-procedure5"  # the demo's installation (its weather aside)
SUBPROTOCOL = "foxglove.sdk.v1"  # foxglove-sdk 0.30's; it refuses the older foxglove.websocket.v1
TOPIC_KEYS = ("imageTopic", "calibrationTopic", "topicPath", "topicToRender")
STREAM_TIMEOUT_S = 90.0
START_TIMEOUT_S = 90.0


def layout_topics(node: object) -> set[str]:
    """Every topic a layout's panels name: image, calibration, table and log topics, annotation and 3-D topic keys,
    and the topic of every plot path (its part before the first '.')."""
    found: set[str] = set()
    if isinstance(node, dict):
        for key, value in node.items():
            if key in TOPIC_KEYS and isinstance(value, str):
                found.add(value)
            elif key in ("annotations", "topics") and isinstance(value, dict):
                found |= set(value)
            elif key == "value" and isinstance(value, str) and value.startswith("/"):
                found.add(value.split(".")[0])
            if key != "userScripts":
                found |= layout_topics(value)
    elif isinstance(node, list):
        for item in node:
            found |= layout_topics(item)
    return found


def script_io(layout: dict) -> tuple[set[str], set[str], set[str]]:
    """The user scripts' input topics, output topics, and the fields of their input messages they read (m.<field>)."""
    inputs, outputs, fields = set(), set(), set()
    for script in layout.get("userScripts", {}).values():
        code = script["sourceCode"]
        inputs |= set(re.findall(r'"(/[^"]+)"', re.search(r"inputs = \[(.*?)\]", code).group(1)))
        outputs.add(re.search(r'output = "([^"]+)"', code).group(1))
        fields |= set(re.findall(r"\bm\.(\w+)", code))
    return inputs, outputs, fields


def family(topic: str) -> str:
    """A topic with its camera or cone name left out: /cameras/*/image, /offsets/*, /studio_script/bands/*."""
    topic = re.sub(r"^/cameras/[^/]+/", "/cameras/*/", topic)
    return re.sub(r"^(/offsets|/truth|" + re.escape(SCRIPT_PREFIX) + r")/[^/]+$", r"\1/*", topic)


def archive_channels(path: Path) -> dict[str, str]:
    """topic -> schema name of every channel of an MCAP file."""
    with path.open("rb") as f:
        summary = make_reader(f).get_summary()
    return {c.topic: summary.schemas[c.schema_id].name for c in summary.channels.values()}


def test_the_shipped_layout_parses_and_is_the_demo_installations() -> None:
    shipped = json.loads(LAYOUT.read_text())
    sc = load_scenario(DEMO_SCENARIO)
    expected = json.loads(layout_json(foxglove_layout([c.name for c in sc.cameras], sorted(CONE_SIGNS))))
    assert shipped == expected  # regenerated whenever the layout code changes
    assert shipped["version"] == 1 and shipped["content"]["type"] == "split"
    assert {f"/cameras/{c.name}/image" for c in sc.cameras} <= layout_topics(shipped)


def test_the_layout_names_only_topics_the_archive_has(archived: Archived, installation: Path) -> None:
    channels = archive_channels(archived.mcap)
    layout = json.loads(layout_json(rig_layout(load_rig(installation / "rig.yaml"))))
    topics = layout_topics(layout)
    inputs, outputs, fields = script_io(layout)
    assert topics - outputs <= set(channels), topics - outputs - set(channels)
    assert {t for t in topics if t.startswith(SCRIPT_PREFIX)} <= outputs  # every band plotted is computed
    assert inputs <= set(channels) and all(channels[t] == "topside.ConeOffset" for t in inputs)
    assert fields and fields <= {f.name for f in ConeOffset.DESCRIPTOR.fields}
    assert {"/log", "/cameras/cam-ahead/detections", "/cameras/cam-port/health"} <= topics and "/offsets/A" in inputs
    shipped = json.loads(LAYOUT.read_text())  # the demo's layout: the same kinds of topic, other names
    archive_families = {family(t) for t in channels} | {family(t) for t in outputs}
    assert {family(t) for t in layout_topics(shipped)} <= archive_families


def message_class(name: str, schema_b64: str) -> type:
    """The protobuf class of a channel advertised with a FileDescriptorSet."""
    pool = descriptor_pool.DescriptorPool()
    pending = list(descriptor_pb2.FileDescriptorSet.FromString(base64.b64decode(schema_b64)).file)
    while pending:  # dependencies first, in whatever order the set lists them
        progress = False
        for f in list(pending):
            try:
                pool.Add(f)
            except TypeError:
                continue
            pending.remove(f)
            progress = True
        assert progress, [f.name for f in pending]
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(name))


async def one_of_each_schema(url: str, wanted: set[str], wanted_topics: set[str], timeout: float
                             ) -> tuple[dict[str, object], set[str]]:
    """Subscribe to every channel the server advertises until each wanted schema has a decoded message and each
    wanted topic is advertised (or the timeout): the first message of each schema, and the topics advertised."""
    decoded: dict[str, object] = {}
    topics: set[str] = set()
    channels: dict[int, tuple[str, type]] = {}
    deadline = time.monotonic() + timeout
    async with websockets.connect(url, subprotocols=[SUBPROTOCOL], max_size=None) as ws:
        assert ws.subprotocol == SUBPROTOCOL
        while not (wanted <= set(decoded) and wanted_topics <= topics) and time.monotonic() < deadline:
            try:
                raw = await asyncio.wait_for(ws.recv(), timeout=max(0.1, deadline - time.monotonic()))
            except (TimeoutError, websockets.ConnectionClosed):  # the caller's assertions name what was missed
                break
            if isinstance(raw, str):
                msg = json.loads(raw)
                if msg["op"] == "advertise":
                    subscriptions = []
                    for c in msg["channels"]:
                        assert c["encoding"] == "protobuf" and c["schemaEncoding"] == "protobuf"
                        channels[c["id"]] = (c["schemaName"], message_class(c["schemaName"], c["schema"]))
                        topics.add(c["topic"])
                        subscriptions.append({"id": c["id"], "channelId": c["id"]})
                    await ws.send(json.dumps({"op": "subscribe", "subscriptions": subscriptions}))
            elif raw[0] == 1:  # message data: opcode, subscription id (u32), log time (u64), payload
                name, cls = channels[int.from_bytes(raw[1:5], "little")]
                decoded.setdefault(name, cls.FromString(raw[13:]))
    return decoded, topics


def test_live_streams_every_schema_of_the_archive_to_a_foxglove_client(installation: Path, archived: Archived,
                                                                        tmp_path: Path) -> None:
    channels = archive_channels(archived.mcap)
    live_topics = {topic for topic in channels if not topic.startswith("/truth/")}  # live knows no truth
    wanted = {channels[topic] for topic in live_topics}
    port = free_port()
    proc = subprocess.Popen([sys.executable, "-m", "tracking.cli", "live", "--rig", str(installation / "rig.yaml"),
                             "--rrd", str(tmp_path / "live.rrd"), "--foxglove", "--port", str(port),
                             "--speed", "0.05", "--loop", "--duration", "4"],  # 0.8 s of video over 16 s, again
                            # and again: the client subscribes in time, and a start starved of CPU by the tests
                            # beside it (frames recorded only, to keep up) cannot leave it without an estimate, nor
                            # without a change of the cone's state (each is a log message)
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    with stopped_after(proc) as output:
        deadline = time.monotonic() + START_TIMEOUT_S
        line = ""
        while "foxglove: ws://" not in line and time.monotonic() < deadline and proc.poll() is None:
            line = proc.stdout.readline()
        assert f"ws://127.0.0.1:{port}" in line, proc.stderr.read() if proc.poll() is not None else line
        assert listening_addresses(port) == {"127.0.0.1"}  # on this machine only, unless --bind says otherwise
        decoded, topics = asyncio.run(one_of_each_schema(f"ws://127.0.0.1:{port}", wanted, live_topics,
                                                         STREAM_TIMEOUT_S))
    assert proc.returncode in (0, 130), output[0]
    assert set(decoded) == wanted, f"{wanted - set(decoded)}; the session printed: {output[0]}"
    assert topics == live_topics  # the archive's channels, the same names and schemas
    offset = decoded["topside.ConeOffset"]
    known = np.isfinite([offset.dx, offset.dy, offset.dz]).all()
    assert offset.cone == "A" and (offset.status == "NO DATA") != known  # a number only when known, as archived
    assert decoded["foxglove.CameraCalibration"].width > 0 and len(decoded["foxglove.CameraCalibration"].K) == 9
    assert decoded["foxglove.FrameTransforms"].transforms[0].parent_frame_id in ("jacket", "topside")
    assert decoded["topside.CameraHealth"].camera in ("cam-ahead", "cam-port")
    assert not listening_addresses(port)  # the server went with the session


def test_a_client_that_joins_late_gets_the_newest_log_line_and_calibration(installation: Path) -> None:
    stream = FoxgloveStream(load_rig(installation / "rig.yaml"), "127.0.0.1", port=0)
    try:
        camera = next(iter(stream.archive.cameras))
        ns = 1_000_000_000
        stream.writer.write("/log", log_message(ns, "cone A: TRACKING"), ns)  # before any client is connected
        stream.writer.write(f"/cameras/{camera}/calibration",
                            calibration_message(camera, stream.archive.cameras[camera], ns), ns)
        decoded, topics = asyncio.run(one_of_each_schema(f"ws://127.0.0.1:{stream.port}",
                                                         {"foxglove.Log", "foxglove.CameraCalibration"}, set(), 30.0))
    finally:
        stream.close()
    assert topics == {"/log", f"/cameras/{camera}/calibration"}
    assert decoded["foxglove.Log"].message == "cone A: TRACKING"  # where the session stands, with its own time
    assert decoded["foxglove.Log"].timestamp.seconds == 1
    assert decoded["foxglove.CameraCalibration"].frame_id == camera


def test_a_malformed_client_message_is_one_bounded_line(installation: Path, capfd: pytest.CaptureFixture) -> None:
    """A client's 100 kB malformed message is named in one line on stderr, cut short, not copied to the terminal."""
    import json

    stream = FoxgloveStream(load_rig(installation / "rig.yaml"), "127.0.0.1", port=0)

    async def send() -> None:
        async with websockets.connect(f"ws://127.0.0.1:{stream.port}", subprotocols=[SUBPROTOCOL],
                                      max_size=None) as ws:
            await ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": 1, "channelId": "x" * 100_000}]}))
            await asyncio.sleep(1.0)

    try:
        asyncio.run(send())
    finally:
        stream.close()
    lines = [line for line in capfd.readouterr().err.splitlines() if "foxglove" in line]
    assert any("Invalid message" in line for line in lines)
    assert all(len(line) < 400 for line in lines)
