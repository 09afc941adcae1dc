"""The manifest of an MCAP archive: SHA-256 digests of its messages per channel per time block, its attachments,
metadata, schemas and channels; optionally signed with ed25519.

A block is one channel's messages whose log time falls in one BLOCK_S-long slot; its digest runs over the
messages in file order, each as (log_time, publish_time, sequence, length, data). Six hours of 50 channels at
one-second blocks is about a million digests (~75 MB of JSON): small beside the frames it covers.
"""

from __future__ import annotations

import hashlib
import json
import struct
from dataclasses import dataclass, field
from pathlib import Path

from cryptography.exceptions import InvalidSignature
from cryptography.hazmat.primitives import serialization
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey, Ed25519PublicKey

from tracking.errors import InputError

FORMAT = "topside-manifest/1"
MANIFEST_NAME = "manifest.json"
SIGNATURE_NAME = "manifest.json.sig"
CHECKPOINT_NAME = "topside.checkpoint"
BLOCK_S = 1.0
NS = 1_000_000_000
_MESSAGE_HEAD = struct.Struct("<QQIQ")


def digest(data: bytes) -> str:
    """Hex SHA-256 of some bytes."""
    return hashlib.sha256(data).hexdigest()


def time_text(ns: int) -> str:
    """A log time for people: seconds on the recording's clock (Unix times as UTC)."""
    from datetime import UTC, datetime

    if ns > 1_000_000_000 * NS:
        return datetime.fromtimestamp(ns / NS, UTC).isoformat(timespec="milliseconds").replace("+00:00", "Z")
    return f"{ns / NS:.3f} s"


@dataclass
class Block:
    """The running digest of one channel's messages in one time block."""

    sha: hashlib._Hash = field(default_factory=hashlib.sha256)
    count: int = 0
    first_ns: int = 0
    last_ns: int = 0

    def add(self, log_time: int, publish_time: int, sequence: int, data: bytes) -> None:
        """Add one message."""
        if self.count == 0:
            self.first_ns = self.last_ns = log_time
        self.first_ns, self.last_ns = min(self.first_ns, log_time), max(self.last_ns, log_time)
        self.sha.update(_MESSAGE_HEAD.pack(log_time, publish_time, sequence, len(data)))
        self.sha.update(data)
        self.count += 1


class Digests:
    """Everything a manifest covers, accumulated as a file is written or read."""

    def __init__(self, block_s: float = BLOCK_S) -> None:
        self.block_ns = round(block_s * NS)
        self.header: dict[str, str] = {}
        self.schemas: dict[str, str] = {}  # name -> sha256 of encoding and data
        self.channels: dict[str, dict] = {}  # topic -> schema, encoding, metadata
        self.blocks: dict[str, dict[int, Block]] = {}  # topic -> block index -> block
        self.attachments: dict[str, dict] = {}
        self.metadata: list[list] = []  # [name, {key: value}] in file order

    def add_schema(self, name: str, encoding: str, data: bytes) -> None:
        """A schema, by name."""
        self.schemas[name] = digest(encoding.encode() + b"\0" + data)

    def add_channel(self, topic: str, schema: str, message_encoding: str, metadata: dict[str, str]) -> None:
        """A channel, by topic."""
        self.channels[topic] = {"schema": schema, "message_encoding": message_encoding, "metadata": dict(metadata)}
        self.blocks.setdefault(topic, {})

    def add_message(self, topic: str, log_time: int, publish_time: int, sequence: int, data: bytes) -> None:
        """One message of a channel."""
        blocks = self.blocks.setdefault(topic, {})
        k = log_time // self.block_ns
        block = blocks.get(k)
        if block is None:
            block = blocks[k] = Block()
        block.add(log_time, publish_time, sequence, data)

    def add_attachment(self, name: str, media_type: str, log_time: int, create_time: int, data: bytes) -> None:
        """An attachment (never the manifest or its signature)."""
        self.attachments[name] = {"sha256": digest(data), "size": len(data), "media_type": media_type,
                                  "log_time": log_time, "create_time": create_time}

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        """A metadata record."""
        self.metadata.append([name, dict(data)])

    def _blocks(self, topic: str) -> dict:
        blocks = sorted(self.blocks.get(topic, {}).items())
        return {"messages": sum(b.count for _, b in blocks),
                "blocks": [[k, b.count, b.sha.hexdigest()] for k, b in blocks]}

    def manifest(self, **extra: object) -> dict:
        """The manifest as a JSON-ready dict."""
        return {
            "format": FORMAT,
            "algorithm": "sha256",
            "block_ns": self.block_ns,
            "message_digest": "sha256 over each message in file order: <QQIQ log_time publish_time sequence "
                              "length, then data",
            "header": self.header,
            "schemas": self.schemas,
            "channels": {t: {**c, **self._blocks(t)} for t, c in self.channels.items()},
            "attachments": self.attachments,
            "metadata": self.metadata,
            **extra,
        }


class Chain:
    """A running SHA-256 over every message in write (= file) order, topic included: the writer's checkpoints
    (a metadata record every second, signed with --key) survive a kill, so a recovered file can still be checked
    against digests its writer made."""

    def __init__(self) -> None:
        self.sha = hashlib.sha256()
        self.count = 0

    def add(self, topic: str, log_time: int, publish_time: int, sequence: int, data: bytes) -> None:
        """Add one message."""
        self.sha.update(topic.encode() + b"\0" + _MESSAGE_HEAD.pack(log_time, publish_time, sequence, len(data)))
        self.sha.update(data)
        self.count += 1

    def hexdigest(self) -> str:
        """The digest of every message so far."""
        return self.sha.hexdigest()


def checkpoint_payload(count: int, sha256: str) -> bytes:
    """What a checkpoint's signature signs."""
    return f"{CHECKPOINT_NAME}:{count}:{sha256}".encode()


def encode_manifest(manifest: dict) -> bytes:
    """Canonical JSON bytes of a manifest: sorted keys, no spaces."""
    return json.dumps(manifest, sort_keys=True, separators=(",", ":")).encode()


@dataclass(frozen=True)
class Mismatch:
    """One difference between a file and its manifest: what, where (channel or attachment) and when."""

    what: str
    where: str
    first_ns: int | None = None
    last_ns: int | None = None

    def __str__(self) -> str:
        when = ""
        if self.first_ns is not None:
            when = f" at {time_text(self.first_ns)}"
            if self.last_ns is not None and self.last_ns != self.first_ns:
                when += f" .. {time_text(self.last_ns)}"
        return f"{self.where}{when}: {self.what}"


def compare(manifest: dict, found: Digests) -> list[Mismatch]:
    """Every difference between a stored manifest and the digests recomputed from the file."""
    out: list[Mismatch] = []
    block_ns = int(manifest.get("block_ns", found.block_ns))
    if manifest.get("header") != found.header:
        out.append(Mismatch(f"header {found.header} differs from the manifest's {manifest.get('header')}", "header"))
    for name, d in manifest.get("schemas", {}).items():
        if found.schemas.get(name) != d:
            out.append(Mismatch("schema missing" if name not in found.schemas else "schema changed", f"schema {name}"))
    for name in set(found.schemas) - set(manifest.get("schemas", {})):
        out.append(Mismatch("schema not in the manifest", f"schema {name}"))
    stored_channels = manifest.get("channels", {})
    for topic, stored in stored_channels.items():
        if topic not in found.channels:
            out.append(Mismatch(f"channel missing ({stored.get('messages', 0)} messages in the manifest)", topic))
            continue
        head = {k: stored.get(k) for k in ("schema", "message_encoding", "metadata")}
        if head != found.channels[topic]:
            out.append(Mismatch("channel definition changed", topic))
        blocks = found.blocks.get(topic, {})
        seen: set[int] = set()
        for k, count, sha in stored.get("blocks", []):
            seen.add(k)
            block = blocks.get(k)
            if block is None:
                out.append(Mismatch(f"{count} messages missing", topic, k * block_ns, (k + 1) * block_ns - 1))
            elif block.count != count or block.sha.hexdigest() != sha:
                what = (f"{block.count} messages where the manifest has {count}" if block.count != count
                        else f"message content changed ({count} messages in the block)")
                out.append(Mismatch(what, topic, block.first_ns, block.last_ns))
        for k in sorted(set(blocks) - seen):
            b = blocks[k]
            out.append(Mismatch(f"{b.count} messages not in the manifest", topic, b.first_ns, b.last_ns))
    for topic in set(found.channels) - set(stored_channels):
        out.append(Mismatch("channel not in the manifest", topic))
    stored_att = manifest.get("attachments", {})
    for name, meta in stored_att.items():
        got = found.attachments.get(name)
        if got is None:
            out.append(Mismatch("attachment missing", f"attachment {name}"))
        elif got != meta:
            fields = ", ".join(k for k in meta if got.get(k) != meta[k])
            out.append(Mismatch(f"attachment changed ({fields})", f"attachment {name}"))
    for name in set(found.attachments) - set(stored_att):
        out.append(Mismatch("attachment not in the manifest", f"attachment {name}"))
    if manifest.get("metadata") != found.metadata:
        names = {n for n, _ in manifest.get("metadata", [])} | {n for n, _ in found.metadata}
        for name in sorted(names):
            a = [d for n, d in manifest.get("metadata", []) if n == name]
            b = [d for n, d in found.metadata if n == name]
            if a != b:
                out.append(Mismatch("metadata record changed", f"metadata {name}"))
    return out


def load_private_key(path: Path) -> Ed25519PrivateKey:
    """An ed25519 private key from a PEM file; a one-line error otherwise."""
    key = _load_key(path)
    if not isinstance(key, Ed25519PrivateKey):
        raise InputError(path, "is not an ed25519 private key (expected PEM 'BEGIN PRIVATE KEY')", "key")
    return key


def load_public_key(path: Path) -> Ed25519PublicKey:
    """An ed25519 public key from a PEM file. A private key is refused: a signature checked against the key that made
    it proves nothing to an auditor (who holds it can sign any archive), and the private key belongs on the signing
    machine only; the line says how to take its public half."""
    key = _load_key(path)
    if isinstance(key, Ed25519PrivateKey):
        raise InputError(path, "is a private key; verify checks a signature against the signer's public key (make "
                               f"it where the private key lives: openssl pkey -in {path} -pubout -out public.pem)",
                         "--key")
    if not isinstance(key, Ed25519PublicKey):
        raise InputError(path, "is not an ed25519 key (expected PEM 'BEGIN PUBLIC KEY')", "key")
    return key


def _load_key(path: Path) -> object:
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "key file not found", "key")
    data = path.read_bytes()
    for loader in (lambda d: serialization.load_pem_private_key(d, password=None),
                   serialization.load_pem_public_key):
        try:
            return loader(data)
        except (ValueError, TypeError):
            continue
    raise InputError(path, "not a PEM key without password (expected an ed25519 key)", "key")


def public_key_hex(key: Ed25519PublicKey) -> str:
    """The raw 32-byte public key in hex, as stored in the manifest."""
    return key.public_bytes(serialization.Encoding.Raw, serialization.PublicFormat.Raw).hex()


def signature_valid(key: Ed25519PublicKey, manifest_bytes: bytes, signature: bytes) -> bool:
    """True when the signature is the key's over the manifest's bytes."""
    try:
        key.verify(signature, manifest_bytes)
        return True
    except InvalidSignature:
        return False
