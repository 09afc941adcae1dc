"""MCAP archives read back through mcap's own reader and converted by Rerun's `rerun mcap` commands."""

from __future__ import annotations

import subprocess
import sys
from collections import defaultdict
from pathlib import Path

import av
import cv2
import numpy as np
import pandas as pd
import pytest
import rerun as rr
from cryptography.hazmat.primitives import serialization
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

from tests.conftest import FRAMES, Archived
from tracking.camera import load_camera
from viewer.archive.audit import verify
from viewer.archive.manifest import load_public_key
from viewer.playback import rerun_binary, rerun_env

TOPSIDE = [sys.executable, "-m", "tracking.cli"]
CAMERAS = ("cam-ahead", "cam-port")


def run(*args: str | Path) -> subprocess.CompletedProcess:
    return subprocess.run([*TOPSIDE, *map(str, args)], capture_output=True, text=True, timeout=120)


def decoded(path: Path) -> dict[str, list]:
    """topic -> [(log_time, decoded protobuf message)] through mcap's reader and mcap-protobuf-support."""
    out: dict[str, list] = defaultdict(list)
    with path.open("rb") as f:
        for _, channel, message, proto in make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages():
            out[channel.topic].append((message.log_time, proto))
    return out


def raw(path: Path) -> tuple[dict[str, list[tuple[int, bytes]]], dict[str, bytes], dict[str, dict]]:
    """(topic -> [(log_time, data)], attachments by name, metadata by name)."""
    msgs: dict[str, list] = defaultdict(list)
    with path.open("rb") as f:
        reader = make_reader(f)
        for _, channel, message in reader.iter_messages(log_time_order=False):
            msgs[channel.topic].append((message.log_time, message.data))
        attachments = {a.name: a.data for a in reader.iter_attachments()}
        metadata = {m.name: m.metadata for m in reader.iter_metadata()}
    return msgs, attachments, metadata


def test_round_trip_through_mcap_reader(archived: Archived, installation: Path) -> None:
    msgs = decoded(archived.mcap)
    df = pd.read_csv(archived.offsets)
    for cam in CAMERAS:
        images = msgs[f"/cameras/{cam}/image"]
        assert len(images) == FRAMES
        model = load_camera(installation / "calibration" / f"{cam}.yaml")
        decoder = av.CodecContext.create("h264", "r")
        first = decoder.decode(av.Packet(images[0][1].data))
        assert first and (first[0].width, first[0].height) == model.image_size  # the camera's own H.264
        assert images[0][1].frame_id == cam and images[0][1].format == "h264"
        calib = msgs[f"/cameras/{cam}/calibration"][0][1]
        np.testing.assert_allclose(np.array(calib.K).reshape(3, 3), model.K)
        np.testing.assert_allclose(calib.D, model.dist.reshape(-1)[:5])
        assert calib.frame_id == cam and calib.distortion_model == "plumb_bob"
        detections = msgs[f"/cameras/{cam}/detections"]
        assert len(detections) == FRAMES
        assert all(sorted(t.text for t in d.texts) == ["1", "2"] if cam == "cam-ahead" else len(d.texts) == 2
                   for _, d in detections)  # both markers of the pair outlined with their ids
        health = [h for _, h in msgs[f"/cameras/{cam}/health"]]
        assert [h.markers for h in health] == [2] * FRAMES
        assert health[1].frame_interval_s == pytest.approx(1 / 15, abs=1e-3)
    offsets = msgs["/offsets/A"]
    assert len(offsets) == len(df)
    np.testing.assert_allclose([t / 1e9 for t, _ in offsets], df["time"], atol=1e-6)
    for axis in ("dx", "dy", "dz", "sdx", "sdy", "sdz"):
        np.testing.assert_allclose([getattr(o, axis) for _, o in offsets], df[axis], atol=1e-5)
    last = offsets[-1][1]
    cov = np.array(last.covariance).reshape(3, 3)
    np.testing.assert_allclose(np.sqrt(np.diag(cov)), [last.sdx, last.sdy, last.sdz])
    assert last.status in ("within ±0.15 m", "outside") and list(last.cameras) == list(CAMERAS)
    truth = pd.read_csv(installation / "truth.csv")
    assert len(msgs["/truth/A"]) == len(truth)
    np.testing.assert_allclose([m.dx for _, m in msgs["/truth/A"]], truth["cone_A_dx"])
    cameras_tf = [ft for _, m in msgs["/frames/cameras"] for ft in m.transforms]
    assert len(cameras_tf) == 2 * FRAMES and {ft.child_frame_id for ft in cameras_tf} == set(CAMERAS)
    assert {ft.parent_frame_id for ft in cameras_tf} == {"jacket"}
    markers_tf = {ft.child_frame_id: ft.parent_frame_id for _, m in msgs["/frames/markers"] for ft in m.transforms}
    assert markers_tf == {"marker_1": "jacket", "marker_2": "topside", "marker_3": "jacket", "marker_4": "topside"}
    assert msgs["/frames/topside"][-1][1].transforms[0].translation.x == pytest.approx(df["dx"].iloc[-1], abs=1e-5)
    filter_tf = msgs["/frames/filter_cameras"]  # the fused filter's cameras, once per estimate time
    assert len(filter_tf) == len(set(df["time"])) and all(m.transforms for _, m in filter_tf)
    last = {ft.child_frame_id: ft for ft in filter_tf[-1][1].transforms}
    assert set(last) == {f"filter_{cam}" for cam in CAMERAS}
    for cam in CAMERAS:
        true = truth[[f"camera_{cam}_{a}" for a in ("x", "y", "z")]].to_numpy()[-1]
        t = last[f"filter_{cam}"].translation
        assert np.linalg.norm([t.x - true[0], t.y - true[1], t.z - true[2]]) < 0.005 * np.linalg.norm(true)
    log = [m.message for _, m in msgs["/log"]]
    assert log[0].startswith("archive of") and log[-1] == "archive closed"
    assert any(line.startswith("cone A:") for line in log)


def test_metadata_attachments_and_summary(archived: Archived, installation: Path) -> None:
    _, attachments, metadata = raw(archived.mcap)
    assert attachments["rig.yaml"] == (installation / "rig.yaml").read_bytes()
    for cam in CAMERAS:
        assert attachments[f"calibration/{cam}.yaml"] == (installation / "calibration" / f"{cam}.yaml").read_bytes()
    assert attachments["offsets.csv"] == archived.offsets.read_bytes()
    assert "manifest.json" in attachments
    meta = metadata["topside"]
    assert (meta["vessel"], meta["operator"]) == ("Sleipnir", "J. Doe")
    assert meta["installation"] and meta["software_version"] and meta["software_commit"]
    assert len(meta["configuration_sha256"]) == 64 and '"mode": "fused"' in meta["options"]
    span = metadata["time_span"]
    times = pd.read_csv(installation / "truth.csv")["time"].tolist() + pd.read_csv(archived.offsets)["time"].tolist()
    assert int(span["start_ns"]) / 1e9 == pytest.approx(min(times), abs=1e-6)
    assert int(span["end_ns"]) / 1e9 == pytest.approx(max(times), abs=1e-6)
    assert (span["frames_cam-ahead"], span["frames_cam-port"]) == (str(FRAMES), str(FRAMES))
    with archived.mcap.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary.statistics.message_count == sum(summary.statistics.channel_message_counts.values())
    assert summary.chunk_indexes and all(c.compression == "zstd" for c in summary.chunk_indexes)
    assert all(c.message_index_offsets for c in summary.chunk_indexes)
    assert len(summary.attachment_indexes) == len(attachments)
    names = [m.name for m in summary.metadata_indexes]
    assert names[0] == "topside" and names[-1] == "time_span" and set(names[1:-1]) == {"topside.checkpoint"}


def test_export_from_the_recording_equals_the_tracked_archive(archived: Archived, tmp_path: Path) -> None:
    out = tmp_path / "exported.mcap"
    proc = run("export", archived.rrd, "--mcap", out, "--offsets", archived.offsets, "--vessel", "Sleipnir",
               "--operator", "J. Doe")
    assert proc.returncode == 0, proc.stderr
    a_msgs, a_att, a_meta = raw(archived.mcap)
    b_msgs, b_att, b_meta = raw(out)
    assert set(a_msgs) == set(b_msgs)
    for topic in a_msgs:
        assert sorted(a_msgs[topic]) == sorted(b_msgs[topic]), topic  # every message byte-equal
    assert {k: v for k, v in a_att.items() if k != "manifest.json"} == \
        {k: v for k, v in b_att.items() if k != "manifest.json"}
    assert a_meta["topside"] == b_meta["topside"]


def test_rerun_checks_and_converts_the_archive(archived: Archived, tmp_path: Path) -> None:
    check = subprocess.run([rerun_binary(), "mcap", "check", str(archived.mcap)], capture_output=True, text=True,
                           timeout=60, env=rerun_env())
    assert check.returncode == 0, check.stderr
    rows = [line.split() for line in check.stdout.splitlines() if line.strip().startswith(("ok", "warn", "error"))]
    assert len(rows) == 15 and all(r[0] == "ok" for r in rows), check.stdout
    rrd = tmp_path / "converted.rrd"
    conv = subprocess.run([rerun_binary(), "mcap", "convert", str(archived.mcap), "-o", str(rrd),
                           "--timeline-type", "duration"], capture_output=True, text=True, timeout=60,
                          env=rerun_env())
    assert conv.returncode == 0, conv.stderr
    columns: dict[str, dict[str, list]] = defaultdict(lambda: defaultdict(list))
    for chunk in rr.chunk.RrdReader(rrd).store().stream().to_chunks():
        rb = chunk.to_record_batch()
        for name in rb.schema.names:
            columns[chunk.entity_path][name] += rb.column(name).to_pylist()
    for cam in CAMERAS:
        image = columns[f"/cameras/{cam}/image"]
        assert len([b for b in image["VideoStream:sample"] if b]) == FRAMES
        pinhole = columns[f"/cameras/{cam}/calibration"]
        assert pinhole["Pinhole:parent_frame"][0] == [cam]
        assert pinhole["Pinhole:child_frame"][0] == image["CoordinateFrame:frame"][0]  # the image sits in the pinhole
    cams = columns["/frames/cameras"]
    assert len(cams["Transform3D:translation"]) == 2 * FRAMES
    assert {f[0] for f in cams["Transform3D:child_frame"]} == set(CAMERAS)
    assert {f[0] for f in columns["/frames/filter_cameras"]["Transform3D:child_frame"]} == \
        {f"filter_{cam}" for cam in CAMERAS}
    markers = columns["/frames/markers"]
    assert {f[0]: p[0] for f, p in zip(markers["Transform3D:child_frame"], markers["Transform3D:parent_frame"],
                                       strict=True)} == {"marker_1": "jacket", "marker_2": "topside",
                                                         "marker_3": "jacket", "marker_4": "topside"}
    assert len(columns["/log"]["TextLog:text"]) >= 3


def _keys(folder: Path) -> tuple[Path, Path, Path]:
    private = Ed25519PrivateKey.generate()
    other = Ed25519PrivateKey.generate()
    paths = folder / "private.pem", folder / "public.pem", folder / "other.pem"
    paths[0].write_bytes(private.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                                               serialization.NoEncryption()))
    paths[1].write_bytes(private.public_key().public_bytes(serialization.Encoding.PEM,
                                                           serialization.PublicFormat.SubjectPublicKeyInfo))
    paths[2].write_bytes(other.public_key().public_bytes(serialization.Encoding.PEM,
                                                         serialization.PublicFormat.SubjectPublicKeyInfo))
    return paths


def test_signed_archive_verifies_with_its_key_only(archived: Archived, tmp_path: Path) -> None:
    private, public, other = _keys(tmp_path)
    signed = tmp_path / "signed.mcap"
    assert run("export", archived.rrd, "--mcap", signed, "--key", private).returncode == 0
    good = run("verify", signed, "--key", public)
    assert good.returncode == 0, good.stdout
    assert "signature valid" in good.stdout
    wrong = run("verify", signed, "--key", other)
    assert wrong.returncode == 1 and "signature is not valid" in wrong.stdout
    assert verify(signed).signature == "unchecked"
    unsigned = verify(archived.mcap, load_public_key(public))
    assert not unsigned.ok and any("not signed" in e for e in unsigned.errors)


def test_frames_are_the_cameras_own_h264(archived: Archived, installation: Path) -> None:
    from tracking.images import frames

    video = [m for _, m in decoded(archived.mcap)["/cameras/cam-port/image"]]
    source = [f.packet for f in frames(installation / "cam-port.mp4", packets=True)]
    assert [m.data for m in video] == source  # passed through, not re-encoded
    decoder = av.CodecContext.create("h264", "r")
    decoded_frames = [f for m in video for f in decoder.decode(av.Packet(m.data))] + decoder.decode(None)
    assert len(decoded_frames) == FRAMES


def test_tracker_and_export_write_the_same_frames(archived: Archived, installation: Path, tmp_path: Path) -> None:
    """The sink and the export both pass the camera's packets through, so their image messages are equal."""
    from tracking.pipeline import track_rig
    from tracking.rig import load_rig
    from viewer.archive import ArchiveSink

    rig = load_rig(installation / "rig.yaml")
    sink = ArchiveSink(rig, tmp_path / "sink.mcap", {"mode": "fused", "refine": "edges"})
    for i, result in enumerate(track_rig(rig, packets=True)):
        sink.on_frame(result)
        if i == 7:
            break
    sink.close()
    tracked = raw(tmp_path / "sink.mcap")[0]["/cameras/cam-ahead/image"]
    exported = raw(archived.mcap)[0]["/cameras/cam-ahead/image"]
    assert len(tracked) == 4 and tracked == exported[:4]


def test_jpeg_frames_can_be_archived_as_h264(installation: Path, tmp_path: Path) -> None:
    """Frames without packets (stills, JPEG recordings) are re-encoded with --video h264."""
    from tracking.rig import load_rig
    from viewer.archive import Archive, ArchiveInputs, FrameView

    rig = load_rig(installation / "rig.yaml")
    cameras = {c.name: load_camera(rig.resolve(c.calibration)) for c in rig.cameras}
    w, h = cameras["cam-port"].image_size
    archive = Archive(tmp_path / "j.mcap", rig, ArchiveInputs.from_rig(rig, {}), cameras, video="h264")
    for k in range(5):
        jpeg = cv2.imencode(".jpg", np.full((h, w), 40 * k, np.uint8))[1].tobytes()
        archive.frame(FrameView("cam-port", 10**9 + k * 10**8, k, jpeg, [], [], None, 0, float("nan")))
    archive.close()
    video = [m for _, m in decoded(tmp_path / "j.mcap")["/cameras/cam-port/image"]]
    assert len(video) == 5 and {m.format for m in video} == {"h264"}
    decoder = av.CodecContext.create("h264", "r")
    assert len([f for m in video for f in decoder.decode(av.Packet(m.data))] + decoder.decode(None)) == 5


def test_bad_inputs_are_one_line_errors(archived: Archived, tmp_path: Path) -> None:
    not_mcap = tmp_path / "x.mcap"
    not_mcap.write_text("hello")
    for proc, fragment in ((run("verify", not_mcap), "not an MCAP file"),
                           (run("verify", archived.mcap, "--key", archived.offsets), "key"),
                           (run("export", archived.offsets, "--mcap", tmp_path / "o.mcap"), "Rerun recording")):
        assert proc.returncode == 2, proc.stderr
        assert len(proc.stderr.strip().splitlines()) == 1 and fragment in proc.stderr, proc.stderr
