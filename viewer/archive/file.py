"""The MCAP file of an archive: chunks flushed to disk, metadata, attachments, checkpoints; the software's version."""

from __future__ import annotations

import subprocess
import time as wallclock
from collections.abc import Mapping
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey
from google.protobuf.message import Message
from mcap.well_known import MessageEncoding, SchemaEncoding
from mcap.writer import CompressionType, IndexType, Writer
from mcap_protobuf.schema import build_file_descriptor_set

from viewer.archive.manifest import (
    BLOCK_S,
    CHECKPOINT_NAME,
    MANIFEST_NAME,
    SIGNATURE_NAME,
    Chain,
    Digests,
    checkpoint_payload,
    encode_manifest,
    public_key_hex,
)
from viewer.archive.messages import NS

PROFILE = "topside"

CHUNK_SIZE = 4 * 1024 * 1024  # bytes of uncompressed messages before a chunk is closed

class _Unbuffered:
    """A file the MCAP writer writes straight to the OS: nothing waits in a user-space buffer for a kill."""

    def __init__(self, path: Path) -> None:
        self._f = open(path, "wb", buffering=0)

    def write(self, data: bytes) -> int:
        view = memoryview(data)
        while view:
            view = view[self._f.write(view):]
        return len(data)

    def tell(self) -> int:
        return self._f.tell()

    def flush(self) -> None:
        pass

    def close(self) -> None:
        self._f.close()

class ArchiveFile:
    """An MCAP file written incrementally, with the digests of everything in it: a checkpoint of the message chain
    at every flush, the manifest at close; both signed when a key is given."""

    def __init__(self, path: Path, chunk_size: int = CHUNK_SIZE, block_s: float = BLOCK_S,
                 library: str | None = None, key: Ed25519PrivateKey | None = None, checkpoints: bool = True) -> None:
        self.path = Path(path)
        self.key = key
        self.checkpoints = checkpoints
        self.chain = Chain()
        self._checkpointed = 0
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._stream = _Unbuffered(self.path)
        self._writer = Writer(self._stream, chunk_size=chunk_size, compression=CompressionType.ZSTD,
                              index_types=IndexType.ALL, enable_crcs=True, enable_data_crcs=True)
        self.digests = Digests(block_s)
        self.digests.header = {"profile": PROFILE, "library": library or f"topside {software_version()}"}
        self._writer.start(profile=PROFILE, library=self.digests.header["library"])
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, tuple[int, str]] = {}
        self._sequence: dict[str, int] = {}
        self.first_ns: int | None = None
        self.last_ns: int | None = None
        self.closed = False

    def schema_id(self, name: str, encoding: str, data: bytes) -> int:
        """Register a schema once."""
        if name not in self._schemas:
            self._schemas[name] = self._writer.register_schema(name=name, encoding=encoding, data=data)
            self.digests.add_schema(name, encoding, data)
        return self._schemas[name]

    def channel_id(self, topic: str, schema: str, schema_id: int, message_encoding: str,
                   metadata: Mapping[str, str] | None = None) -> int:
        """Register a channel once; a topic keeps its first schema."""
        if topic in self._channels:
            cid, known = self._channels[topic]
            if known != schema:
                raise ValueError(f"topic {topic} has schema {known}, not {schema}")
            return cid
        cid = self._writer.register_channel(topic=topic, message_encoding=message_encoding, schema_id=schema_id,
                                            metadata=dict(metadata or {}))
        self._channels[topic] = (cid, schema)
        self.digests.add_channel(topic, schema, message_encoding, dict(metadata or {}))
        return cid

    def write(self, topic: str, message: Message, ns: int) -> None:
        """One protobuf message at log time ns."""
        name = message.DESCRIPTOR.full_name
        if name not in self._schemas:
            self.schema_id(name, SchemaEncoding.Protobuf,
                           build_file_descriptor_set(type(message)).SerializeToString())
        cid = self.channel_id(topic, name, self._schemas[name], MessageEncoding.Protobuf)
        self.write_raw(cid, topic, message.SerializeToString(), ns, ns)

    def write_raw(self, channel_id: int, topic: str, data: bytes, log_time: int, publish_time: int,
                  sequence: int | None = None) -> None:
        """One serialised message on a registered channel."""
        if sequence is None:
            sequence = self._sequence.get(topic, 0)
            self._sequence[topic] = sequence + 1
        self._writer.add_message(channel_id=channel_id, log_time=log_time, data=data, publish_time=publish_time,
                                 sequence=sequence)
        self.digests.add_message(topic, log_time, publish_time, sequence, data)
        self.chain.add(topic, log_time, publish_time, sequence, data)
        self.first_ns = log_time if self.first_ns is None else min(self.first_ns, log_time)
        self.last_ns = log_time if self.last_ns is None else max(self.last_ns, log_time)

    def attach(self, name: str, media_type: str, data: bytes, log_time: int = 0, create_time: int = 0) -> None:
        """An attachment, written at once."""
        self._writer.add_attachment(create_time=create_time, log_time=log_time, name=name, media_type=media_type,
                                    data=data)
        self.digests.add_attachment(name, media_type, log_time, create_time, data)

    def metadata(self, name: str, data: Mapping[str, str]) -> None:
        """A metadata record, written at once."""
        values = {k: str(v) for k, v in data.items()}
        self._writer.add_metadata(name, values)
        self.digests.add_metadata(name, values)

    def flush(self) -> None:
        """Close the chunk in progress, then a checkpoint of the chain after it; hand everything to the OS."""
        self._writer.flush()
        if self.checkpoints and self.chain.count > self._checkpointed:
            sha = self.chain.hexdigest()
            record = {"messages": str(self.chain.count), "sha256": sha, "last_ns": str(self.last_ns)}
            if self.key is not None:
                record["signature"] = self.key.sign(checkpoint_payload(self.chain.count, sha)).hex()
            self.metadata(CHECKPOINT_NAME, record)
            self._checkpointed = self.chain.count

    def close(self, **manifest_extra: object) -> dict:
        """Seal: the last checkpoint, the manifest (and its signature) as attachments, then summary and indexes.
        Returns the manifest."""
        self.flush()
        key = self.key
        extra = dict(manifest_extra)
        if key is not None:
            extra["public_key"] = public_key_hex(key.public_key())
        manifest = self.digests.manifest(**extra)
        body = encode_manifest(manifest)
        self._writer.add_attachment(create_time=0, log_time=self.last_ns or 0, name=MANIFEST_NAME,
                                    media_type="application/json", data=body)
        if key is not None:
            self._writer.add_attachment(create_time=0, log_time=self.last_ns or 0, name=SIGNATURE_NAME,
                                        media_type="application/octet-stream", data=key.sign(body))
        self._writer.finish()
        self._stream.close()
        self.closed = True
        return manifest

def software_version() -> str:
    """This package's version."""
    try:
        return version("topside")
    except PackageNotFoundError:
        return "unknown"

def software_commit() -> str:
    """The git commit of the running code, '+dirty' when it has uncommitted changes; 'unknown' outside git."""
    repo = Path(__file__).resolve().parents[1]
    try:
        head = subprocess.run(["git", "-C", str(repo), "rev-parse", "HEAD"], capture_output=True, text=True,
                              timeout=10)
        if head.returncode != 0:
            return "unknown"
        dirty = subprocess.run(["git", "-C", str(repo), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, timeout=10).stdout.strip()
        return head.stdout.strip() + ("+dirty" if dirty else "")
    except (OSError, subprocess.SubprocessError):
        return "unknown"

def time_span(first_ns: int | None, last_ns: int | None, extra: Mapping[str, str] | None = None) -> dict[str, str]:
    """The time-span metadata record: first and last log time, in ns and for people."""
    from viewer.archive.manifest import time_text

    if first_ns is None or last_ns is None:
        return {"messages": "0", **(extra or {})}
    return {"start_ns": str(first_ns), "end_ns": str(last_ns), "start": time_text(first_ns), "end": time_text(last_ns),
            "duration_s": f"{(last_ns - first_ns) / NS:.3f}", "written_utc": wallclock.strftime(
                "%Y-%m-%dT%H:%M:%SZ", wallclock.gmtime()), **(extra or {})}
