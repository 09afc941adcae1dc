"""Verifying archives: changed bytes, changed messages, truncation and a writer killed with SIGKILL."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from cryptography.hazmat.primitives import serialization
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey
from mcap.reader import make_reader
from mcap.writer import Writer

from tests.conftest import Archived
from viewer.archive.audit import recover, scan, verify

TOPSIDE = [sys.executable, "-m", "tracking.cli"]
WRITER = [sys.executable, "-m", "tests.viewer.archive_writer"]


@pytest.fixture(scope="module")
def chunked(installation: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A closed archive of six seconds: a chunk per second."""
    out = tmp_path_factory.mktemp("chunked") / "six.mcap"
    proc = subprocess.run([*WRITER, str(installation / "rig.yaml"), str(out), "6"], capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0, proc.stderr
    return out


def test_intact_archive_verifies(chunked: Path) -> None:
    report = verify(chunked)
    assert report.ok, report.errors
    assert report.messages > 6 * 15 * 2 * 3  # images, detections, health of two cameras, 15 FPS
    assert len(scan(chunked).chunks) >= 6


def test_one_changed_byte_anywhere_is_detected(archived: Archived, tmp_path: Path) -> None:
    data = archived.mcap.read_bytes()
    positions = {*np.random.default_rng(1).choice(len(data), 80, replace=False).tolist(), 0, 9, len(data) - 1,
                 len(data) - 20, len(data) - 40}
    damaged = tmp_path / "damaged.mcap"
    for pos in sorted(positions):
        changed = bytearray(data)
        changed[pos] ^= 0x20
        damaged.write_bytes(changed)
        try:
            report = verify(damaged)
        except Exception as exc:  # InputError for a broken magic is a finding too
            assert pos < 8, f"byte {pos}: {exc!r}"
            continue
        assert not report.ok, f"byte {pos} changed without a finding"


def test_a_changed_byte_in_a_chunk_names_the_chunk_and_its_time(archived: Archived, tmp_path: Path) -> None:
    with archived.mcap.open("rb") as f:
        chunk = make_reader(f).get_summary().chunk_indexes[0]
    data = bytearray(archived.mcap.read_bytes())
    data[chunk.chunk_start_offset + chunk.chunk_length // 2] ^= 0x01
    damaged = tmp_path / "chunk.mcap"
    damaged.write_bytes(data)
    errors = verify(damaged).errors
    where = f"chunk at byte {chunk.chunk_start_offset} ({chunk.message_start_time / 1e9:.3f} s .. "
    assert any(e.startswith(where) and "CRC mismatch" in e for e in errors), errors
    assert any(e.startswith("manifest: /cameras/") for e in errors), errors  # and which channel changed


def test_a_changed_message_is_reported_with_its_channel_and_time(archived: Archived, tmp_path: Path) -> None:
    """Rewritten with valid CRCs and indexes, one JPEG re-encoded: only the manifest can tell, and it does."""
    forged = tmp_path / "forged.mcap"
    with archived.mcap.open("rb") as f, forged.open("wb") as out:
        reader = make_reader(f)
        header = reader.get_header()
        writer = Writer(out)
        writer.start(header.profile, header.library)
        schemas, channels = {}, {}
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            if schema.id not in schemas:
                schemas[schema.id] = writer.register_schema(schema.name, schema.encoding, schema.data)
            if channel.id not in channels:
                channels[channel.id] = writer.register_channel(channel.topic, channel.message_encoding,
                                                               schemas[schema.id], channel.metadata)
            data = message.data
            if channel.topic == "/cameras/cam-port/image" and message.sequence == 5:
                forged_at = message.log_time
                from foxglove_schemas_protobuf.CompressedVideo_pb2 import CompressedVideo

                video = CompressedVideo.FromString(data)
                frame = bytearray(video.data)
                frame[len(frame) // 2] ^= 0x01  # one bit of the H.264 slice: a valid message, a different picture
                video.data = bytes(frame)
                data = video.SerializeToString()
            writer.add_message(channels[channel.id], message.log_time, data, message.publish_time, message.sequence)
        for a in reader.iter_attachments():
            writer.add_attachment(a.create_time, a.log_time, a.name, a.media_type, a.data)
        for m in reader.iter_metadata():
            writer.add_metadata(m.name, m.metadata)
        writer.finish()
    errors = verify(forged).errors
    manifest = [e for e in errors if e.startswith("manifest:")]
    assert len(manifest) == 1, errors
    assert all(e.startswith("checkpoint after message") for e in errors if e not in manifest), errors  # CRCs valid
    head, _, what = manifest[0].partition(": message content changed")
    assert head.startswith("manifest: /cameras/cam-port/image at ") and what, errors
    first, last = (float(v.removesuffix(" s")) for v in head.split(" at ")[1].split(" .. "))
    assert first <= forged_at / 1e9 <= last and last - first < 1.0  # the one-second block holding the forged frame


def test_truncated_archive_is_detected_and_recovered(chunked: Path, tmp_path: Path) -> None:
    data = chunked.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[:len(data) * 2 // 3])
    report = verify(cut)
    assert any("truncated" in e for e in report.errors) and any("no manifest" in e for e in report.errors)
    kept = sum(c.count for c in scan(cut).chunks if c.ok)
    rec = recover(cut, tmp_path / "cut.recovered.mcap")
    assert rec.manifest_was_missing and rec.chunks >= 3 and rec.messages == kept
    again = verify(rec.out)
    assert again.ok, again.errors
    assert again.messages == kept and any("recovered" in n for n in again.notes)


def test_writer_killed_with_sigkill_is_recovered(installation: Path, tmp_path: Path) -> None:
    out = tmp_path / "killed.mcap"
    private, public = tmp_path / "private.pem", tmp_path / "public.pem"
    key = Ed25519PrivateKey.generate()
    private.write_bytes(key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                                          serialization.NoEncryption()))
    public.write_bytes(key.public_key().public_bytes(serialization.Encoding.PEM,
                                                     serialization.PublicFormat.SubjectPublicKeyInfo))
    proc = subprocess.Popen([*WRITER, str(installation / "rig.yaml"), str(out), "0", "--forever", "--key",
                             str(private)], stdout=subprocess.PIPE, text=True)
    try:
        for _ in range(4):  # at least three seconds (chunks) written
            assert proc.stdout.readline().startswith("second"), "writer stopped"
        time.sleep(0.05)  # it is inside the next second's chunk now
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=30)
    assert proc.returncode == -signal.SIGKILL
    broken = verify(out)
    assert not broken.ok
    found = scan(out)
    complete = sum(c.count for c in found.chunks if c.ok)
    assert len([c for c in found.chunks if c.ok]) >= 3
    cli = subprocess.run([*TOPSIDE, "verify", str(out), "--recover", "--key", str(public)], capture_output=True,
                         text=True, timeout=120)
    assert cli.returncode == 0, cli.stdout + cli.stderr
    assert "manifest was missing" in cli.stdout
    assert "writer checkpoints match" in cli.stdout and "signature valid" in cli.stdout  # the writer's own digests
    recovered = out.with_suffix(".recovered.mcap")
    report = verify(recovered)
    assert report.ok and report.messages == complete  # everything up to the last complete chunk
    with recovered.open("rb") as f:
        reader = make_reader(f)
        names = {a.name for a in reader.iter_attachments()}
        spans = [m.metadata for m in reader.iter_metadata() if m.name == "time_span"]
    assert {"rig.yaml", "manifest.json"} <= names and spans[0]["recovered"] == "true"


def test_an_archive_of_a_stopped_run_says_it_is_incomplete(installation: Path, tmp_path: Path) -> None:
    """Sealed and signed like a whole one, an interrupted run's archive fails verify with one line saying so: an
    auditor tells a part of an installation from the whole (the reason is in the signed manifest)."""
    out, private, public = tmp_path / "part.mcap", tmp_path / "private.pem", tmp_path / "public.pem"
    key = Ed25519PrivateKey.generate()
    private.write_bytes(key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                                          serialization.NoEncryption()))
    public.write_bytes(key.public_key().public_bytes(serialization.Encoding.PEM,
                                                     serialization.PublicFormat.SubjectPublicKeyInfo))
    proc = subprocess.run([*WRITER, str(installation / "rig.yaml"), str(out), "2", "--key", str(private),
                           "--stopped", "stopped by the operator"], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    cli = subprocess.run([*TOPSIDE, "verify", str(out), "--key", str(public)], capture_output=True, text=True,
                         timeout=120)
    assert cli.returncode != 0
    assert "FAIL: incomplete: the run that wrote it was stopped by the operator after 1.9 s of capture time; it does " \
           "not hold the whole installation" in cli.stdout
    assert "signature valid" in cli.stdout  # intact, only not whole
