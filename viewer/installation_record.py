"""An installation's record read back for its report: the estimates, the cameras' frames and stated states, the rig's
clocks and survey, what configured the run and whether the file is whole; from a Rerun recording (.rrd, through
rerun's chunk API) or an MCAP archive (its intact chunks, as `topside verify` reads them), whichever is given.

Both give the same tables (tracking.installation_report's), so a report of a run's recording and one of its archive
agree: the recording's `archive/estimates/<cone>` and the archive's `/offsets/<cone>` hold the same estimates (the
archive says why a cone is withheld on `/log`, where its state changes), `health/<camera>/markers` and
`/cameras/<camera>/health` the same frames.
"""

from __future__ import annotations

import hashlib
import json
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
import rerun as rr
import yaml
from foxglove_schemas_protobuf.Log_pb2 import Log
from mcap.records import Channel, Message
from rerun.error_utils import RerunWarning

from tracking.errors import InputError
from tracking.estimate import ConeEstimate
from tracking.installation_report import estimates_table
from tracking.rig import Rig
from viewer.archive.audit import MAGIC, scan, verify
from viewer.archive.export import entity_rows_static, estimates
from viewer.archive.manifest import MANIFEST_NAME, SIGNATURE_NAME, load_public_key
from viewer.archive.messages import NS, CameraHealth, ConeOffset
from viewer.archive.writer import ArchiveInputs
from viewer.recording import TIMELINE

RRD_MAGIC = b"RRF2"  # the first bytes of a Rerun recording
RRD_CONTENT = ["/archive/**", "/health/**"]  # what a report reads of a recording (never the frames' pixels)
STATE_ENTITY = "state"  # health/<camera>/state: the live tracker's stated camera states (viewer.session)
FRAME_MATCH_S = 5e-4  # a frame-age sample's frame within this of a searched frame is that frame
SHORT_HASH = 16


@dataclass(frozen=True)
class Integrity:
    """Whether the file holds the whole installation untouched."""

    state: str  # whole, interrupted (its run stopped early), damaged, recovered (rebuilt from a damaged file)
    lines: tuple[str, ...] = ()  # what the check found, one line each
    signature: str = "absent"  # valid, invalid, absent, unchecked (signed, no key given), "not signed" (a recording)


@dataclass(frozen=True)
class Provenance:
    """What the record summarises: the software, the rig and calibration files (SHA-256), the run's options."""

    installation: str = ""
    software_version: str = "unknown"
    software_commit: str = "unknown"
    configuration_sha256: str = ""  # over the rig, its calibrations and the options (ArchiveInputs.config_hash)
    files: tuple[tuple[str, str], ...] = ()  # (name, sha256): the rig file first, then the calibrations
    options: str = ""
    people: tuple[tuple[str, str], ...] = ()  # vessel, operator, when the archive was written


@dataclass
class InstallationRecord:
    """One installation as a report reads it."""

    path: Path
    kind: str  # "recording" or "archive"
    estimates: pd.DataFrame  # tracking.installation_report.COLUMNS
    frames: pd.DataFrame  # time, camera, markers (NaN: recorded, not searched)
    stated: pd.DataFrame  # time, camera, state, detail: what the live tracker said of a camera
    notes: pd.DataFrame  # time, subject, text: warnings the record carries (a video's problems, events)
    provenance: Provenance
    integrity: Integrity
    rig: Rig | None = None
    cones: list[str] = field(default_factory=list)
    cameras: list[str] = field(default_factory=list)

    @property
    def span(self) -> tuple[float, float]:
        """First and last capture time of anything in the tables, s."""
        times = np.concatenate([self.estimates["time"].to_numpy(float), self.frames["time"].to_numpy(float)])
        return (float(times.min()), float(times.max())) if times.size else (0.0, 0.0)


def read_record(path: Path, key: Path | None = None) -> InstallationRecord:
    """A recording or an archive, told apart by its first bytes; a one-line InputError for anything else. key: the
    public key an archive's signature is checked against."""
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "file not found (expected a recording .rrd or an archive .mcap)")
    with path.open("rb") as f:
        head = f.read(len(MAGIC))
    if head.startswith(RRD_MAGIC):
        if key is not None:
            raise InputError("--key", f"{key} checks an archive's signature, and {path.name} is a recording (it is "
                                      "not signed: give its archive, or leave out --key)")
        return read_recording(path)
    if head == MAGIC:
        return read_archive(path, key)
    raise InputError(path, "not a Rerun recording or an MCAP archive (expected a .rrd written by `topside track "
                           "--rrd` or `topside live`, or a .mcap written by `topside track --mcap` or `export`)")


def rig_of(text: str) -> Rig | None:
    """The rig a record carries, for its clocks and survey; None when it no longer validates."""
    try:
        return Rig.model_validate(yaml.safe_load(text))
    except Exception:
        return None


def sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


# --- recordings --------------------------------------------------------------------------------------------------


def _entity_chunks(path: Path) -> dict[str, list[rr.chunk.Chunk]]:
    """The report's entities of a recording (RRD_CONTENT), by path; a one-line InputError when it cannot be read."""
    chunks: dict[str, list[rr.chunk.Chunk]] = {}
    try:
        with warnings.catch_warnings():  # a file without its footer is named below if it cannot be read
            warnings.simplefilter("ignore", RerunWarning)
            for chunk in rr.chunk.RrdReader(path).stream().filter(content=RRD_CONTENT):
                chunks.setdefault(chunk.entity_path, []).append(chunk)
    except Exception as exc:
        raise InputError(path, f"cannot be read as a Rerun recording ({exc}); a recording cut short cannot be read "
                               "back: report its archive instead (`topside verify --recover` rebuilds a killed "
                               "writer's)") from None
    return chunks


def _rows(chunks: list[rr.chunk.Chunk], component: str) -> list[tuple[float, object]]:
    """(capture time s, first value) of one component's temporal rows."""
    out = []
    for chunk in chunks:
        rb = chunk.to_record_batch()
        names = rb.schema.names
        if TIMELINE not in names or component not in names:
            continue
        times = rb.column(names.index(TIMELINE)).cast("int64").to_numpy() / NS
        for t, v in zip(times, rb.column(names.index(component)).to_pylist(), strict=True):
            if v:
                out.append((float(t), v[0]))
    return sorted(out, key=lambda r: r[0])


def _recording_frames(chunks: dict[str, list[rr.chunk.Chunk]], cameras: list[str]) -> pd.DataFrame:
    """Every camera's searched frames (health/<camera>/markers), and the frames its frame-age samples show that
    were recorded without being searched (markers NaN)."""
    rows: list[tuple[float, str, float]] = []
    for name in cameras:
        searched = [(t, name, float(v)) for t, v in _rows(chunks.get(f"/health/{name}/markers", []),
                                                          "Scalars:scalars")]
        known = np.array([t for t, _, _ in searched])
        for t, age in _rows(chunks.get(f"/health/{name}/frame_age_s", []), "Scalars:scalars"):
            t_frame = t - float(age)
            k = np.searchsorted(known, t_frame)
            near = [known[i] for i in (k - 1, k) if 0 <= i < known.size]
            if not near or min(abs(x - t_frame) for x in near) > FRAME_MATCH_S:
                rows.append((t_frame, name, np.nan))
        rows += searched
    frame = pd.DataFrame(rows, columns=["time", "camera", "markers"])
    return frame.drop_duplicates(["time", "camera"]).sort_values(["time", "camera"]).reset_index(drop=True)


def _said(chunks: dict[str, list[rr.chunk.Chunk]], cameras: list[str]) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The live tracker's stated camera states (health/<camera>/state: 'STATE' or 'STATE: detail') and the video
    problems (health/<camera>/video/events) as notes."""
    stated, notes = [], []
    for name in cameras:
        for t, text in _rows(chunks.get(f"/health/{name}/{STATE_ENTITY}", []), "TextLog:text"):
            state, _, detail = str(text).partition(": ")
            stated.append((t, name, state, detail))
        for t, text in _rows(chunks.get(f"/health/{name}/video/events", []), "TextLog:text"):
            notes.append((t, name, str(text)))
    return (pd.DataFrame(stated, columns=["time", "camera", "state", "detail"]),
            pd.DataFrame(notes, columns=["time", "subject", "text"]))


def read_recording(path: Path) -> InstallationRecord:
    """A recording written by `topside track --rrd` or `topside live`."""
    chunks = _entity_chunks(path)
    doc = entity_rows_static(chunks.get("/archive/inputs", []), "TextDocument:text")
    if doc is None:
        raise InputError(path, "holds no rig and no estimates (expected a recording written by `topside track "
                               "--rrd` or `topside live` of this version)", "archive/inputs")
    inputs = ArchiveInputs.from_json(doc)
    rig = rig_of(inputs.rig_text.decode())
    table = estimates_table([e for _, e in estimates(chunks)])
    cameras = _cameras(rig, {p.split("/")[2] for p in chunks if p.startswith("/health/")})
    stated, notes = _said(chunks, cameras)
    provenance = Provenance(
        rig.name if rig else "", inputs.software_version, inputs.software_commit, inputs.config_hash(),
        ((inputs.rig_name, sha256(inputs.rig_text)),
         *((name, sha256(data)) for name, data in sorted(inputs.calibrations.items()))),
        json.dumps(inputs.options, sort_keys=True))
    integrity = Integrity("whole", ("a recording carries no digests or signature: `topside export` writes its "
                                    "audit archive",), "not signed")
    return InstallationRecord(path, "recording", table, _recording_frames(chunks, cameras), stated, notes,
                              provenance, integrity, rig, _cones(rig, table), cameras)


def _cameras(rig: Rig | None, seen: set[str]) -> list[str]:
    """The rig's cameras in its order, then any other the record holds."""
    named = [c.name for c in rig.cameras] if rig else []
    return named + sorted(seen - set(named))


def _cones(rig: Rig | None, table: pd.DataFrame) -> list[str]:
    """The cones of the rig and of the estimates, sorted."""
    return sorted(set(table["cone"]) | (set(rig.cones) if rig else set()))


# --- archives ----------------------------------------------------------------------------------------------------


@dataclass
class _ArchiveMessages:
    """What a report reads of an archive's messages, as the scan hands over each intact chunk."""

    topics: dict[int, str] = field(default_factory=dict)
    offsets: list[tuple[int, object]] = field(default_factory=list)
    health: list[tuple[int, object]] = field(default_factory=list)
    log: list[tuple[int, str, int]] = field(default_factory=list)  # ns, text, level

    def take(self, records: list[object]) -> None:
        for r in records:
            if isinstance(r, Channel):
                self.topics[r.id] = r.topic
            if not isinstance(r, Message):
                continue
            topic = self.topics.get(r.channel_id, "")
            if topic.startswith("/offsets/"):
                self.offsets.append((r.log_time, ConeOffset.FromString(bytes(r.data))))
            elif topic.startswith("/cameras/") and topic.endswith("/health"):
                self.health.append((r.log_time, CameraHealth.FromString(bytes(r.data))))
            elif topic == "/log":
                m = Log.FromString(bytes(r.data))
                self.log.append((r.log_time, m.message, m.level))


def _withheld(log: list[tuple[int, str, int]]) -> dict[str, list[tuple[int, str]]]:
    """Each cone's stated reasons over time from the log's 'cone C: NO DATA (why)' lines: (ns, why; '' when shown)."""
    out: dict[str, list[tuple[int, str]]] = {}
    for ns, text, _ in sorted(log, key=lambda r: r[0]):
        if text.startswith("cone ") and ": " in text:
            cone, _, state = text[len("cone "):].partition(": ")
            why = state[state.find("(") + 1:-1] if state.startswith("NO DATA (") and state.endswith(")") else ""
            out.setdefault(cone, []).append((ns, why))
    return out


def _archive_estimates(m: _ArchiveMessages) -> pd.DataFrame:
    reasons = _withheld(m.log)
    out = []
    for ns, o in sorted(m.offsets, key=lambda r: (r[0], r[1].cone)):
        offset = np.array([o.dx, o.dy, o.dz])
        cov = np.array(o.covariance).reshape(3, 3) if len(o.covariance) == 9 else None
        said = [why for t, why in reasons.get(o.cone, []) if t <= ns]
        withheld = (said[-1] if said else "") if not np.all(np.isfinite(offset)) else ""
        out.append(ConeEstimate(ns / NS, o.cone, offset, tuple(o.cameras), cov, None, withheld))
    return estimates_table(out)


def _archive_integrity(path: Path, key: Path | None, manifest: dict | None) -> Integrity:
    """The archive's check (`topside verify`) in a state and its lines."""
    report = verify(path, load_public_key(key) if key is not None else None)
    stopped = [e for e in report.errors if e.startswith("incomplete:")]
    damage = [e for e in report.errors if not e.startswith("incomplete:")]
    if damage:
        state = "damaged"
    elif stopped:
        state = "interrupted"
    elif manifest is not None and manifest.get("recovered"):
        state = "recovered"
    else:
        state = "whole"
    return Integrity(state, tuple(report.errors + report.notes), report.signature)


def read_archive(path: Path, key: Path | None = None) -> InstallationRecord:
    """An archive written by `topside track --mcap` or `topside export`, or what is left of one: its intact chunks."""
    m = _ArchiveMessages()
    s = scan(path, on_records=m.take)
    meta = {r.name: dict(r.metadata) for _, _, r in s.metadata if r.name != "topside.checkpoint"}
    info = meta.get("topside", {})
    manifest_att = s.attachment(MANIFEST_NAME)
    try:
        manifest = json.loads(manifest_att.data) if manifest_att is not None else None
    except ValueError:
        manifest = None
    rig_att = s.attachment(info.get("rig_file", "")) if info.get("rig_file") else None
    rig = rig_of(rig_att.data.decode(errors="replace")) if rig_att is not None else None
    skip = {MANIFEST_NAME, SIGNATURE_NAME, "offsets.csv", info.get("rig_file", "")}
    files = ([(rig_att.name, sha256(rig_att.data))] if rig_att is not None else []) + sorted(
        (a.name, sha256(a.data)) for _, _, a in s.attachments if a.name not in skip)
    written = meta.get("time_span", {}).get("written_utc", "")
    provenance = Provenance(info.get("installation", rig.name if rig else ""), info.get("software_version", "unknown"),
                            info.get("software_commit", "unknown"), info.get("configuration_sha256", ""),
                            tuple(files), info.get("options", ""),
                            tuple((k, v) for k, v in (("vessel", info.get("vessel", "")),
                                                      ("operator", info.get("operator", "")),
                                                      ("archive written", written)) if v))
    table = _archive_estimates(m)
    frames = pd.DataFrame([(ns / NS, h.camera, float(h.markers)) for ns, h in m.health],
                          columns=["time", "camera", "markers"]).sort_values(["time", "camera"]).reset_index(drop=True)
    notes = pd.DataFrame([(ns / NS, text.partition(":")[0], text) for ns, text, level in m.log
                          if level >= Log.WARNING and not text.startswith("cone ")],  # a cone's state: the plots'
                         columns=["time", "subject", "text"])
    cameras = _cameras(rig, set(frames["camera"]))
    return InstallationRecord(path, "archive", table, frames,
                              pd.DataFrame(columns=["time", "camera", "state", "detail"]), notes, provenance,
                              _archive_integrity(path, key, manifest), rig, _cones(rig, table), cameras)
