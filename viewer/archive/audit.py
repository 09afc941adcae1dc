"""Checking an MCAP archive (CRCs, indexes, non-empty channels, manifest, signature) and recovering a killed one.

One pass over the file's records in place (mmap): every chunk is decompressed, CRC-checked and its messages
digested per channel and time block as viewer/archive/manifest.py defines; the summary's indexes and statistics are
compared with what the pass found; the stored manifest with the recomputed digests.
"""

from __future__ import annotations

import json
import mmap
import struct
import time
import zlib
from collections.abc import Callable
from dataclasses import dataclass, field
from io import BytesIO
from pathlib import Path

import zstandard
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PublicKey
from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.records import (
    Attachment,
    AttachmentIndex,
    Channel,
    Chunk,
    ChunkIndex,
    DataEnd,
    Footer,
    Header,
    Message,
    MessageIndex,
    Metadata,
    MetadataIndex,
    Schema,
    Statistics,
    SummaryOffset,
)

from tracking.errors import InputError
from viewer.archive.manifest import (
    BLOCK_S,
    CHECKPOINT_NAME,
    MANIFEST_NAME,
    NS,
    SIGNATURE_NAME,
    Chain,
    Digests,
    checkpoint_payload,
    compare,
    public_key_hex,
    signature_valid,
    time_text,
)

MAGIC = b"\x89MCAP0\r\n"
RECORD_HEAD = struct.Struct("<BQ")
CRC_PIECE = 64 * 1024 * 1024
MESSAGE_HEAD = struct.Struct("<HIQQ")  # channel id, sequence, log time, publish time
FOOTER_BODY = 8 + 8 + 4
READERS = {Opcode.HEADER: Header, Opcode.FOOTER: Footer, Opcode.SCHEMA: Schema, Opcode.CHANNEL: Channel,
           Opcode.CHUNK: Chunk, Opcode.MESSAGE_INDEX: MessageIndex, Opcode.CHUNK_INDEX: ChunkIndex,
           Opcode.ATTACHMENT: Attachment, Opcode.ATTACHMENT_INDEX: AttachmentIndex, Opcode.STATISTICS: Statistics,
           Opcode.METADATA: Metadata, Opcode.METADATA_INDEX: MetadataIndex, Opcode.SUMMARY_OFFSET: SummaryOffset,
           Opcode.DATA_END: DataEnd}


def _parse(opcode: int, body: bytes) -> object:
    stream = ReadDataStream(BytesIO(body))
    if opcode == Opcode.MESSAGE:
        return Message.read(stream, len(body))
    return READERS[opcode].read(stream)


@dataclass
class ChunkFound:
    """A chunk as the pass found it."""

    offset: int
    length: int
    record: Chunk
    ok: bool
    messages: dict[int, list[tuple[int, int]]] = field(default_factory=dict)  # channel -> (log_time, offset),
    # kept only until the chunk's message indexes are checked
    times: dict[int, tuple[int, int]] = field(default_factory=dict)  # channel -> (first, last) log time
    index_offsets: dict[int, int] = field(default_factory=dict)  # channel -> message index record offset
    index_length: int = 0
    count: int = 0  # messages


@dataclass
class Scan:
    """Everything one pass over a file found, and what was wrong with it."""

    size: int
    block_s: float
    errors: list[str] = field(default_factory=list)
    header: Header | None = None
    schemas: dict[int, Schema] = field(default_factory=dict)
    channels: dict[int, Channel] = field(default_factory=dict)
    counts: dict[int, int] = field(default_factory=dict)  # channel id -> messages
    chunks: list[ChunkFound] = field(default_factory=list)
    attachments: list[tuple[int, int, Attachment]] = field(default_factory=list)  # offset, length, record
    metadata: list[tuple[int, int, Metadata]] = field(default_factory=list)
    summary: list[object] = field(default_factory=list)
    data_end: int | None = None  # offset of the DataEnd record
    footer: Footer | None = None
    truncated_at: int | None = None  # offset of the first incomplete record
    digests: Digests = field(default_factory=Digests)
    first_ns: int | None = None
    last_ns: int | None = None
    chain: Chain = field(default_factory=Chain)  # over every message in file order
    chain_at: dict[int, tuple[str, int]] = field(default_factory=dict)  # checkpoint count -> (digest, last log time)
    targets: set[int] = field(default_factory=set)  # message counts the writer checkpointed

    def topic(self, channel_id: int) -> str:
        """A channel's topic, or its id when its channel record was lost."""
        ch = self.channels.get(channel_id)
        return ch.topic if ch else f"channel {channel_id}"

    def attachment(self, name: str) -> Attachment | None:
        """The last attachment of that name."""
        found = [a for _, _, a in self.attachments if a.name == name]
        return found[-1] if found else None


OnRecords = Callable[[list[object]], None]  # the schemas, channels and messages of one intact chunk, in order


def scan(path: Path, block_s: float = BLOCK_S, on_records: OnRecords | None = None) -> Scan:
    """One pass over every record of an MCAP file; stops at the first incomplete record. Nothing but digests and
    offsets is kept: each intact chunk's records go to on_records, then are dropped."""
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "file not found")
    with path.open("rb") as f:
        size = f.seek(0, 2)
        if size < len(MAGIC) or not _has_magic(f):
            raise InputError(path, "not an MCAP file (expected the MCAP magic bytes at the start)")
        with mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as mm:
            return _scan(mm, size, block_s, on_records, _checkpoint_counts(mm, size))


def _has_magic(f: object) -> bool:
    f.seek(0)
    return f.read(len(MAGIC)) == MAGIC


def _checkpoint_counts(mm: mmap.mmap, size: int) -> set[int]:
    """The message counts of the writer's checkpoints: a first walk over the top-level records' heads only."""
    counts: set[int] = set()
    off = len(MAGIC)
    while off + RECORD_HEAD.size <= size:
        opcode, length = RECORD_HEAD.unpack_from(mm, off)
        end = off + RECORD_HEAD.size + length
        if end > size or opcode == Opcode.DATA_END:
            break
        if opcode == Opcode.METADATA:
            try:
                record = _parse(opcode, mm[off + RECORD_HEAD.size:end])
                if record.name == CHECKPOINT_NAME:
                    counts.add(int(record.metadata["messages"]))
            except Exception:
                pass  # the main pass reports damaged records
        off = end
    return counts


def _scan(mm: mmap.mmap, size: int, block_s: float, on_records: OnRecords | None, targets: set[int]) -> Scan:
    s = Scan(size=size, block_s=block_s, digests=Digests(block_s), targets=targets)
    off = len(MAGIC)
    in_summary = False
    while True:
        if off + RECORD_HEAD.size > size:
            s.truncated_at = off
            break
        opcode, length = RECORD_HEAD.unpack_from(mm, off)
        body_at = off + RECORD_HEAD.size
        if body_at + length > size:
            s.truncated_at = off
            break
        body = mm[body_at:body_at + length]
        try:
            record = _parse(opcode, body) if opcode in READERS or opcode == Opcode.MESSAGE else None
        except Exception as exc:  # a damaged record: report and stop, nothing after it can be trusted
            s.errors.append(f"record at byte {off} (opcode {opcode:#x}) cannot be parsed ({exc})")
            s.truncated_at = off
            break
        if isinstance(record, Header):
            s.header = record
            s.digests.header = {"profile": record.profile, "library": record.library}
        elif in_summary:
            s.summary.append(record)
            if isinstance(record, Footer):
                s.footer = record
                _check_footer(s, mm, off, record)
                break
        elif isinstance(record, Chunk):
            if s.chunks:
                s.chunks[-1].messages = {}
            s.chunks.append(_chunk(s, off, RECORD_HEAD.size + length, record, on_records))
        elif isinstance(record, MessageIndex):
            _message_index(s, off, RECORD_HEAD.size + length, record)
        elif isinstance(record, Attachment):
            if zlib.crc32(body[:-4]) != struct.unpack_from("<I", body, len(body) - 4)[0]:
                s.errors.append(f"attachment {record.name}: CRC mismatch (content changed)")
            s.attachments.append((off, RECORD_HEAD.size + length, record))
            if record.name not in (MANIFEST_NAME, SIGNATURE_NAME):
                s.digests.add_attachment(record.name, record.media_type, record.log_time, record.create_time,
                                         record.data)
        elif isinstance(record, Metadata):
            s.metadata.append((off, RECORD_HEAD.size + length, record))
            s.digests.add_metadata(record.name, record.metadata)
        elif isinstance(record, (Schema, Channel, Message)):
            _inner(s, record)
        elif isinstance(record, DataEnd):
            s.data_end = off
            if record.data_section_crc and crc32_range(mm, 0, off) != record.data_section_crc:
                s.errors.append("data section CRC mismatch: a byte before the summary changed")
            in_summary = True
        elif isinstance(record, Footer):  # a footer without a summary
            s.footer = record
            _check_footer(s, mm, off, record)
            break
        off = body_at + length
    return s


def crc32_range(mm: mmap.mmap, start: int, end: int) -> int:
    """CRC-32 of mm[start:end], read in CRC_PIECE slices (no copy of a multi-GB file)."""
    crc = 0
    with memoryview(mm) as view:
        for a in range(start, end, CRC_PIECE):
            crc = zlib.crc32(view[a:min(end, a + CRC_PIECE)], crc)
    return crc


def _check_footer(s: Scan, mm: mmap.mmap, off: int, footer: Footer) -> None:
    end = off + RECORD_HEAD.size + FOOTER_BODY
    if mm[end:end + len(MAGIC)] != MAGIC:
        s.errors.append("no MCAP magic after the footer")
    if footer.summary_crc and footer.summary_start:
        crc = crc32_range(mm, footer.summary_start, off + RECORD_HEAD.size + 16)
        if crc != footer.summary_crc:
            s.errors.append("summary CRC mismatch: the summary section (indexes, statistics) changed")


def _inner(s: Scan, record: object, chunk: ChunkFound | None = None, offset: int = 0) -> None:
    if isinstance(record, Schema):
        s.schemas[record.id] = record
        s.digests.add_schema(record.name, record.encoding, record.data)
    elif isinstance(record, Channel):
        s.channels[record.id] = record
        schema = s.schemas.get(record.schema_id)
        s.digests.add_channel(record.topic, schema.name if schema else "", record.message_encoding, record.metadata)
        s.counts.setdefault(record.id, 0)
    elif isinstance(record, Message):
        s.counts[record.channel_id] = s.counts.get(record.channel_id, 0) + 1
        topic = s.topic(record.channel_id)
        s.digests.add_message(topic, record.log_time, record.publish_time, record.sequence, record.data)
        s.chain.add(topic, record.log_time, record.publish_time, record.sequence, record.data)
        if s.chain.count in s.targets:
            s.chain_at[s.chain.count] = (s.chain.hexdigest(), record.log_time)
        s.first_ns = record.log_time if s.first_ns is None else min(s.first_ns, record.log_time)
        s.last_ns = record.log_time if s.last_ns is None else max(s.last_ns, record.log_time)
        if chunk is not None:
            chunk.messages.setdefault(record.channel_id, []).append((record.log_time, offset))
            chunk.count += 1
            first, last = chunk.times.get(record.channel_id, (record.log_time, record.log_time))
            chunk.times[record.channel_id] = (min(first, record.log_time), max(last, record.log_time))


def _chunk(s: Scan, off: int, length: int, chunk: Chunk, on_records: OnRecords | None) -> ChunkFound:
    found = ChunkFound(off, length, chunk, ok=False)
    where = f"chunk at byte {off} ({time_text(chunk.message_start_time)} .. {time_text(chunk.message_end_time)})"
    try:
        if chunk.compression == "zstd":
            data = zstandard.decompress(chunk.data, max_output_size=chunk.uncompressed_size)
        elif chunk.compression == "":
            data = chunk.data
        else:
            s.errors.append(f"{where}: compression {chunk.compression!r} not supported by verify (expected zstd)")
            return found
    except zstandard.ZstdError as exc:
        s.errors.append(f"{where}: cannot be decompressed ({exc}); its messages are lost")
        return found
    crc_ok = not chunk.uncompressed_crc or zlib.crc32(data) == chunk.uncompressed_crc
    if not crc_ok:
        s.errors.append(f"{where}: CRC mismatch (content changed)")
    pos = 0
    records: list[object] = []
    view = memoryview(data)
    try:
        while pos < len(data):
            opcode, length = RECORD_HEAD.unpack_from(data, pos)
            start, end = pos + RECORD_HEAD.size, pos + RECORD_HEAD.size + length
            if end > len(data):
                raise ValueError(f"record at {pos} runs past the chunk's end")
            if opcode == Opcode.MESSAGE:
                cid, seq, log_time, publish_time = MESSAGE_HEAD.unpack_from(data, start)
                record = Message(channel_id=cid, sequence=seq, log_time=log_time, publish_time=publish_time,
                                 data=view[start + MESSAGE_HEAD.size:end])
            elif opcode in (Opcode.SCHEMA, Opcode.CHANNEL):
                record = _parse(opcode, data[start:end])
            else:
                pos = end
                continue
            _inner(s, record, found, pos)
            records.append(record)
            pos = end
    except Exception as exc:
        s.errors.append(f"{where}: records cannot be parsed ({exc})")
        return found
    found.ok = crc_ok
    if crc_ok and on_records is not None:
        on_records(records)
    return found


def _message_index(s: Scan, off: int, length: int, index: MessageIndex) -> None:
    if not s.chunks:
        s.errors.append(f"message index at byte {off} before any chunk")
        return
    chunk = s.chunks[-1]
    chunk.index_offsets[index.channel_id] = off
    chunk.index_length = off + length - (chunk.offset + chunk.length)
    if chunk.ok and sorted(index.records) != sorted(chunk.messages.get(index.channel_id, [])):
        s.errors.append(f"message index of {s.topic(index.channel_id)} after the chunk at byte {chunk.offset} "
                        "disagrees with the chunk's messages")


@dataclass
class Report:
    """The outcome of `topside verify`: errors make it fail; notes only inform."""

    path: Path
    errors: list[str]
    notes: list[str]
    signature: str  # "valid", "invalid", "absent", "unchecked" (signed, no key given)
    messages: int
    channels: int
    seconds: float
    size: int

    @property
    def ok(self) -> bool:
        """True when nothing is wrong."""
        return not self.errors

    @property
    def mb_per_s(self) -> float:
        """Verify speed."""
        return self.size / 1e6 / self.seconds if self.seconds > 0 else float("inf")


def _check_summary(s: Scan) -> list[str]:
    """The summary's indexes and statistics against what the pass found."""
    errors = []
    indexes = [r for r in s.summary if isinstance(r, ChunkIndex)]
    ok_chunks = {c.offset: c for c in s.chunks}
    if len(indexes) != len(s.chunks):
        errors.append(f"chunk index lists {len(indexes)} chunks, the file holds {len(s.chunks)}")
    for ix in indexes:
        c = ok_chunks.get(ix.chunk_start_offset)
        if c is None:
            errors.append(f"chunk index points to byte {ix.chunk_start_offset}, where no chunk starts")
            continue
        if (ix.chunk_length, ix.message_start_time, ix.message_end_time, ix.compression, ix.compressed_size,
                ix.uncompressed_size) != (c.length, c.record.message_start_time, c.record.message_end_time,
                                          c.record.compression, len(c.record.data), c.record.uncompressed_size):
            errors.append(f"chunk index of the chunk at byte {c.offset} disagrees with the chunk")
        if ix.message_index_offsets != c.index_offsets:
            errors.append(f"chunk index of the chunk at byte {c.offset}: message index offsets disagree")
        if c.ok:
            for cid, (first, last) in c.times.items():
                if first < ix.message_start_time or last > ix.message_end_time:
                    errors.append(f"chunk index of the chunk at byte {c.offset}: {s.topic(cid)} outside its times")
    att_at = {o: a for o, _, a in s.attachments}
    for ix in (r for r in s.summary if isinstance(r, AttachmentIndex)):
        a = att_at.get(ix.offset)
        if a is None or (a.name, a.media_type, len(a.data), a.log_time) != (ix.name, ix.media_type, ix.data_size,
                                                                              ix.log_time):
            errors.append(f"attachment index entry {ix.name} does not match the attachment at byte {ix.offset}")
    meta_at = {o: m for o, _, m in s.metadata}
    for ix in (r for r in s.summary if isinstance(r, MetadataIndex)):
        m = meta_at.get(ix.offset)
        if m is None or m.name != ix.name:
            errors.append(f"metadata index entry {ix.name} does not match the record at byte {ix.offset}")
    stats = [r for r in s.summary if isinstance(r, Statistics)]
    if not stats:
        errors.append("summary has no statistics record")
    else:
        st = stats[0]
        found = {"message_count": sum(s.counts.values()), "chunk_count": len(s.chunks),
                 "attachment_count": len(s.attachments), "metadata_count": len(s.metadata),
                 "channel_count": len(s.channels), "schema_count": len(s.schemas)}
        for name, value in found.items():
            if getattr(st, name) != value:
                errors.append(f"statistics: {name} is {getattr(st, name)}, the file holds {value}")
        for cid, n in s.counts.items():
            if st.channel_message_counts.get(cid, 0) != n:
                errors.append(f"statistics: {s.topic(cid)} has {st.channel_message_counts.get(cid, 0)} messages, "
                              f"the file holds {n}")
        if s.first_ns is not None and (st.message_start_time, st.message_end_time) != (s.first_ns, s.last_ns):
            errors.append("statistics: message time span disagrees with the messages")
    return errors


def verify(path: Path, key: Ed25519PublicKey | None = None) -> Report:
    """Check an archive: CRCs, indexes, non-empty channels, the manifest's digests, the signature."""
    t0 = time.perf_counter()
    s = scan(path)
    manifest_att = s.attachment(MANIFEST_NAME)
    manifest = None
    if manifest_att is not None:
        try:
            manifest = json.loads(manifest_att.data)
        except ValueError:
            s.errors.append(f"attachment {MANIFEST_NAME} is not valid JSON")
    if manifest is not None and int(manifest.get("block_ns", 0)) not in (0, s.digests.block_ns):
        s = scan(path, int(manifest["block_ns"]) / NS)
    errors, notes = list(s.errors), []
    if s.header is None:
        errors.append("no header record")
    if s.truncated_at is not None:
        errors.append(f"file ends inside a record at byte {s.truncated_at} of {s.size}: truncated (the writer did "
                      "not finish); `topside verify --recover` keeps every complete chunk")
    elif s.footer is None:
        errors.append("no footer: the writer did not finish")
    if s.data_end is None:
        errors.append("no data-end record: summary and indexes missing")
    else:
        errors += _check_summary(s)
    for cid, ch in s.channels.items():
        if s.counts.get(cid, 0) == 0:
            errors.append(f"channel {ch.topic} is empty")
    if not s.channels:
        errors.append("the file holds no channels")
    signature = "absent"
    if manifest is None:
        errors.append(f"no manifest ({MANIFEST_NAME} attachment): contents cannot be checked against digests")
    else:
        errors += [f"manifest: {m}" for m in compare(manifest, s.digests)]
        if manifest.get("recovered"):
            notes.append(f"recovered file: {manifest['recovered'].get('note', '')}")
        if manifest.get("stopped"):  # sealed whole, but the run that wrote it ended before its sources did
            span = f" after {(s.last_ns - s.first_ns) / NS:.1f} s of capture time" if s.first_ns is not None and \
                s.last_ns is not None else ""
            errors.append(f"incomplete: the run that wrote it was {manifest['stopped']}{span}; it does not hold the "
                          "whole installation")
        sig = s.attachment(SIGNATURE_NAME)
        if sig is not None and key is None:
            signature = "unchecked"
            notes.append(f"signed by key {manifest.get('public_key', '?')[:16]}..; pass --key PUBLIC.pem to check")
        elif sig is not None and key is not None:
            signature = "valid" if signature_valid(key, manifest_att.data, sig.data) else "invalid"
            if signature == "invalid":
                errors.append(f"signature is not valid for the key {public_key_hex(key)[:16]}..")
        elif key is not None and not manifest.get("recovered"):
            errors.append("--key given but the archive is not signed")
    signature = _check_checkpoints(s, key, manifest, errors, notes, signature)
    return Report(Path(path), errors, notes, signature, sum(s.counts.values()), len(s.channels),
                  time.perf_counter() - t0, s.size)


def _check_checkpoints(s: Scan, key: Ed25519PublicKey | None, manifest: dict | None, errors: list[str],
                       notes: list[str], signature: str) -> str:
    """The writer's checkpoints against the chain of the file's messages; returns the signature state."""
    total = s.chain.count
    checkpoints = [m.metadata for _, _, m in s.metadata if m.name == CHECKPOINT_NAME]
    matched, last_ns, signed_ok, signed_bad = 0, None, 0, 0
    for cp in checkpoints:
        n, sha = int(cp.get("messages", 0)), cp.get("sha256", "")
        if n > total:
            errors.append(f"checkpoint after message {n}: the file holds only {total} messages")
            continue
        found, t = s.chain_at.get(n, ("", None))
        if found != sha:
            errors.append(f"checkpoint after message {n} (up to {time_text(int(cp.get('last_ns', 0) or 0))}): the "
                          "messages before it are not the ones the writer wrote")
            continue
        matched, last_ns = max(matched, n), t
        if key is not None and "signature" in cp:
            try:
                ok = signature_valid(key, checkpoint_payload(n, sha), bytes.fromhex(cp["signature"]))
            except ValueError:
                ok = False
            signed_ok, signed_bad = signed_ok + ok, signed_bad + (not ok)
    if signed_bad:
        errors.append(f"{signed_bad} checkpoint signatures are not valid for the key {public_key_hex(key)[:16]}..")
    if checkpoints and matched:
        notes.append(f"{len(checkpoints)} writer checkpoints match: messages 1..{matched} up to "
                     f"{time_text(last_ns)} are as written" + (f"; {total - matched} later messages are covered "
                                                                f"by no writer digest" if matched < total else ""))
    if manifest is not None and manifest.get("recovered") and key is not None:
        if signed_ok and not signed_bad:
            signature = "valid"
            notes.append(f"the recovered file's manifest is the recovery's own; {signed_ok} signed writer "
                         "checkpoints are valid for the key")
        elif not signed_bad:
            errors.append("--key given but the recovered file has no signed writer checkpoints")
    return signature


def is_intact(path: Path) -> bool:
    """True when a finished writer's file checks whole (summary, indexes, manifest): there is nothing to recover.
    A one-line InputError when it is not an MCAP file."""
    return verify(path).ok


@dataclass(frozen=True)
class Recovery:
    """What `verify --recover` kept and lost."""

    out: Path
    messages: int
    chunks: int
    chunks_damaged: int
    last_ns: int | None
    bytes_dropped: int
    manifest_was_missing: bool


def scan_header(path: Path) -> Header | None:
    """The header record of an MCAP file, if it has one."""
    with Path(path).open("rb") as f:
        head = f.read(len(MAGIC) + RECORD_HEAD.size)
        if head[:len(MAGIC)] != MAGIC or len(head) < len(MAGIC) + RECORD_HEAD.size:
            return None
        opcode, length = RECORD_HEAD.unpack_from(head, len(MAGIC))
        if opcode != Opcode.HEADER or length > 1 << 20:
            return None
        body = f.read(length)
    try:
        return _parse(opcode, body)
    except Exception:
        return None


def recover(path: Path, out: Path) -> Recovery:
    """Rewrite every complete, intact chunk, attachment and metadata record of a damaged file into a valid one."""
    from viewer.archive.file import ArchiveFile, time_span

    path, out = Path(path), Path(out)
    if path.resolve() == out.resolve():
        raise InputError(out, "must differ from the file being recovered", "--out")
    header = scan_header(path)
    f = ArchiveFile(out, library=header.library if header else None, checkpoints=False)
    channel_ids: dict[int, int] = {}
    schemas: dict[int, Schema] = {}

    def copy(records: list[object]) -> None:
        for r in records:
            if isinstance(r, Schema):
                schemas[r.id] = r
            elif isinstance(r, Channel):
                schema = schemas.get(r.schema_id)
                sid = f.schema_id(schema.name, schema.encoding, schema.data) if schema else 0
                channel_ids[r.id] = f.channel_id(r.topic, schema.name if schema else "", sid, r.message_encoding,
                                                 r.metadata)
                topics[r.id] = r.topic
            elif isinstance(r, Message) and r.channel_id in channel_ids:
                f.write_raw(channel_ids[r.channel_id], topics[r.channel_id], bytes(r.data), r.log_time,
                            r.publish_time, r.sequence)

    topics: dict[int, str] = {}
    s = scan(path, on_records=copy)
    manifest_missing = s.attachment(MANIFEST_NAME) is None
    kept = sum(c.ok for c in s.chunks)
    damaged = len(s.chunks) - kept
    for _, _, a in s.attachments:
        if a.name not in (MANIFEST_NAME, SIGNATURE_NAME):
            f.attach(a.name, a.media_type, a.data, a.log_time, a.create_time)
    names = set()
    for _, _, m in s.metadata:
        f.metadata(m.name, m.metadata)
        names.add(m.name)
    if "time_span" not in names:
        f.metadata("time_span", {**time_span(f.first_ns, f.last_ns), "recovered": "true"})
    end = s.truncated_at if s.truncated_at is not None else s.size
    last_good = max((c.offset + c.length + c.index_length for c in s.chunks if c.ok), default=0)
    note = (f"rebuilt by `topside verify --recover` from {path.name}: {kept} intact chunks kept, {damaged} damaged "
            f"dropped, {max(0, end - last_good)} bytes after the last intact chunk dropped; "
            + ("the writer's manifest was missing (it did not close), so this manifest is the recovery's own: it "
               "proves the file unchanged since recovery, not since recording" if manifest_missing else
               "the writer's manifest is kept out: its digests covered the lost data"))
    f.close(recovered={"from": path.name, "note": note})
    return Recovery(out, sum(f.digests.blocks[t][k].count for t in f.digests.blocks for k in f.digests.blocks[t]),
                    kept, damaged, f.last_ns, max(0, s.size - last_good), manifest_missing)
