"""MCAP audit archives: the tracker's stream of results in, one MCAP file out that Foxglove and Rerun open.

Channels (Foxglove schemas in protobuf encoding, log time = capture time):
    /cameras/<camera>/image          foxglove.CompressedImage (JPEG), frame_id <camera>
    /cameras/<camera>/calibration    foxglove.CameraCalibration, at the first frame and every STATIC_PERIOD_S
    /cameras/<camera>/detections     foxglove.ImageAnnotations: marker outlines, ids, reprojected axes
    /cameras/<camera>/health         topside.CameraHealth: markers, reprojection error, frame interval
    /frames/markers                  foxglove.FrameTransforms jacket -> marker_<id>, topside -> marker_<id>
    /frames/cameras                  foxglove.FrameTransforms jacket -> <camera> as the markers place it
    /frames/topside                  foxglove.FrameTransforms jacket -> topside (fitted to the cone offsets)
    /frames/filter_cameras           foxglove.FrameTransforms jacket -> filter_<camera>: where the fused filter has
                                     each camera (live mode), once per estimate time
    /offsets/<cone>                  topside.ConeOffset: dx dy dz, 1σ, covariance (3x3, m²), status, cameras
    /truth/<cone>                    topside.ConeOffset: the simulator's truth, when known
    /log                             foxglove.Log: events (start, first frame, markers lost/found, cone state)
Metadata records `topside` (installation, vessel, operator, software, configuration hash), `time_span`, and a
`topside.checkpoint` after every flushed chunk (the running SHA-256 of all messages so far, signed with a key);
attachments: the rig file, every calibration file, the offsets CSV, the manifest (viewer/manifest.py) and its
ed25519 signature. Chunks (zstd) are flushed to disk every FLUSH_PERIOD_S of capture time, so a killed writer
leaves every chunk before the last flush readable (`topside verify --recover`).
"""

from __future__ import annotations

import hashlib
import json
import subprocess
import time as wallclock
from collections.abc import Mapping
from dataclasses import dataclass
from fractions import Fraction
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

import av
import cv2
import numpy as np
import pandas as pd
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey
from foxglove_schemas_protobuf.CameraCalibration_pb2 import CameraCalibration
from foxglove_schemas_protobuf.Color_pb2 import Color
from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage
from foxglove_schemas_protobuf.CompressedVideo_pb2 import CompressedVideo
from foxglove_schemas_protobuf.FrameTransform_pb2 import FrameTransform
from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms
from foxglove_schemas_protobuf.ImageAnnotations_pb2 import ImageAnnotations
from foxglove_schemas_protobuf.Log_pb2 import Log
from foxglove_schemas_protobuf.Point2_pb2 import Point2
from foxglove_schemas_protobuf.PointsAnnotation_pb2 import PointsAnnotation
from foxglove_schemas_protobuf.TextAnnotation_pb2 import TextAnnotation
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory, timestamp_pb2
from google.protobuf.message import Message
from mcap.well_known import MessageEncoding, SchemaEncoding
from mcap.writer import CompressionType, IndexType, Writer
from mcap_protobuf.schema import build_file_descriptor_set

from tracking.camera import CameraModel
from tracking.estimator import cone_points
from tracking.filtering import ConeEstimate
from tracking.geometry import quaternions_xyzw
from tracking.pipeline import FrameResult
from tracking.rig import Rig
from viewer.manifest import (
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
from viewer.recording import (
    AXIS_COLORS,
    CHOICE_COLORS,
    JPEG_QUALITY,
    REJECTED_COLOR,
    camera_pose_from_markers,
    cone_state,
    encode_jpeg,
    marker_axes_px,
    topside_pose,
)

PROFILE = "topside"
CHUNK_SIZE = 4 * 1024 * 1024  # bytes of uncompressed messages before a chunk is closed
FLUSH_PERIOD_S = 1.0  # capture time between chunks written to disk: at most this much is lost to a kill
STATIC_PERIOD_S = 1.0  # calibration and marker frames are repeated this often, so a seek finds them
OUTLINE_PX = 2.0
TEXT_PX = 14.0
NS = 1_000_000_000
DISTORTION_MODELS = {5: "plumb_bob", 8: "rational_polynomial"}
VIDEO_FORMATS = ("jpeg", "h264")
FILTER_FRAME_PREFIX = "filter_"  # the fused filter's camera frames, beside the markers' own <camera> frames
H264_CRF = 23  # x264's default quality
H264_PRESET = "superfast"  # 10 ms per 920x600 frame on one core; veryfast: 14 ms, 15 % smaller
KEYFRAME_PERIOD_S = 1.0  # a keyframe (with SPS/PPS) every second: seeking and recovery start there


def _topside_schemas() -> dict[str, type[Message]]:
    """The two message types Foxglove has no schema for, built from a descriptor (no protoc step)."""
    fdp = descriptor_pb2.FileDescriptorProto(name="topside/archive.proto", package="topside", syntax="proto3",
                                             dependency=["google/protobuf/timestamp.proto"])
    D = descriptor_pb2.FieldDescriptorProto
    fields = {
        "ConeOffset": [("timestamp", D.TYPE_MESSAGE), ("cone", D.TYPE_STRING), ("dx", D.TYPE_DOUBLE),
                       ("dy", D.TYPE_DOUBLE), ("dz", D.TYPE_DOUBLE), ("sdx", D.TYPE_DOUBLE), ("sdy", D.TYPE_DOUBLE),
                       ("sdz", D.TYPE_DOUBLE), ("covariance", -D.TYPE_DOUBLE), ("status", D.TYPE_STRING),
                       ("cameras", -D.TYPE_STRING)],
        "CameraHealth": [("timestamp", D.TYPE_MESSAGE), ("camera", D.TYPE_STRING), ("frame", D.TYPE_UINT64),
                         ("markers", D.TYPE_UINT32), ("reprojection_error_px", D.TYPE_DOUBLE),
                         ("frame_interval_s", D.TYPE_DOUBLE), ("unknown_ids", -D.TYPE_UINT32)],
    }
    for name, spec in fields.items():
        msg = fdp.message_type.add(name=name)
        for number, (field_name, ftype) in enumerate(spec, start=1):
            f = msg.field.add(name=field_name, number=number, type=abs(ftype),
                              label=D.LABEL_REPEATED if ftype < 0 else D.LABEL_OPTIONAL)
            if abs(ftype) == D.TYPE_MESSAGE:
                f.type_name = ".google.protobuf.Timestamp"
    pool = descriptor_pool.Default()
    try:
        pool.FindFileByName(fdp.name)
    except KeyError:
        pool.Add(fdp)
    return {name: message_factory.GetMessageClass(pool.FindMessageTypeByName(f"topside.{name}")) for name in fields}


_SCHEMAS = _topside_schemas()
ConeOffset = _SCHEMAS["ConeOffset"]
CameraHealth = _SCHEMAS["CameraHealth"]


def capture_ns(t: float) -> int:
    """Capture time in s to log time in ns, rounded as rerun rounds it (so .rrd and .mcap agree)."""
    return round(1e9 * float(t))


def stamp(ns: int) -> timestamp_pb2.Timestamp:
    """A protobuf Timestamp."""
    ts = timestamp_pb2.Timestamp()
    ts.FromNanoseconds(ns)
    return ts


def color(rgb: tuple[int, int, int]) -> Color:
    """A Foxglove colour from 0..255 RGB."""
    return Color(r=rgb[0] / 255, g=rgb[1] / 255, b=rgb[2] / 255, a=1.0)


def transform(parent: str, child: str, T: np.ndarray, ns: int) -> FrameTransform:
    """T_parent_child (4, 4) as a FrameTransform."""
    q = quaternions_xyzw(T[None, :3, :3])[0]
    ft = FrameTransform(timestamp=stamp(ns), parent_frame_id=parent, child_frame_id=child)
    ft.translation.x, ft.translation.y, ft.translation.z = (float(v) for v in T[:3, 3])
    ft.rotation.x, ft.rotation.y, ft.rotation.z, ft.rotation.w = (float(v) for v in q)
    return ft


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


@dataclass(frozen=True)
class ArchiveInputs:
    """What configured a run: the rig and calibration files as bytes, the tracker's options, the software."""

    rig_name: str
    rig_text: bytes
    calibrations: dict[str, bytes]  # path relative to the rig file -> content
    options: dict[str, str]
    software_version: str
    software_commit: str

    @classmethod
    def from_rig(cls, rig: Rig, options: Mapping[str, str]) -> ArchiveInputs:
        """Read the rig's files from disk; the software is the running one."""
        cal = {c.calibration: rig.resolve(c.calibration).read_bytes() for c in rig.cameras}
        return cls(rig.path.name, rig.path.read_bytes(), cal, {k: str(v) for k, v in options.items()},
                   software_version(), software_commit())

    def config_hash(self) -> str:
        """SHA-256 over the rig file, every calibration file (by path) and the tracker's options."""
        h = hashlib.sha256(self.rig_text)
        for name in sorted(self.calibrations):
            h.update(name.encode() + b"\0" + self.calibrations[name])
        h.update(json.dumps(self.options, sort_keys=True).encode())
        return h.hexdigest()

    def to_json(self) -> str:
        """For the .rrd (so `topside export` can rebuild the archive from a recording)."""
        return json.dumps({"rig_name": self.rig_name, "rig_text": self.rig_text.decode(),
                           "calibrations": {k: v.decode() for k, v in self.calibrations.items()},
                           "options": self.options, "software_version": self.software_version,
                           "software_commit": self.software_commit})

    @classmethod
    def from_json(cls, text: str) -> ArchiveInputs:
        """Back from to_json."""
        d = json.loads(text)
        return cls(d["rig_name"], d["rig_text"].encode(), {k: v.encode() for k, v in d["calibrations"].items()},
                   d["options"], d["software_version"], d["software_commit"])


@dataclass(frozen=True)
class FrameView:
    """What the archive keeps of one processed frame (from the tracker, or read back from an .rrd)."""

    camera: str
    ns: int  # capture time, ns
    index: int  # frame number in its source
    image: bytes  # the frame as the recording keeps it: the camera's H.264 access unit, or a JPEG
    outlines: list[tuple[int, np.ndarray, tuple[int, int, int]]]  # (marker id, (4, 2) corners px, colour)
    axes: list[tuple[np.ndarray, tuple[int, int, int]]]  # ((2, 2) segment px, colour)
    T_jacket_camera: np.ndarray | None  # (4, 4)
    markers: int  # rig markers with a pose
    reprojection_error_px: float  # mean over those markers, NaN when none
    format: str = "jpeg"  # of image: "jpeg" or "h264"

    def pixels(self) -> np.ndarray:
        """The frame as (H, W, 3) BGR, decoded from the JPEG (so both archive paths encode the same pixels)."""
        return cv2.imdecode(np.frombuffer(self.image, np.uint8), cv2.IMREAD_COLOR)


class VideoEncoder:
    """H.264 (Annex B) for one camera with libx264: no B-frames and no look-ahead, so every frame in gives one
    access unit out at once; a keyframe with its SPS/PPS every KEYFRAME_PERIOD_S."""

    def __init__(self, width: int, height: int, fps: float = 15.0, crf: int = H264_CRF) -> None:
        self.ctx = av.CodecContext.create("libx264", "w")
        self.ctx.width, self.ctx.height = width + width % 2, height + height % 2
        self.ctx.pix_fmt = "yuv420p"
        self.ctx.time_base = Fraction(1, 1000)
        self.ctx.framerate = Fraction(fps).limit_denominator(1000)
        self.ctx.gop_size = max(1, round(fps * KEYFRAME_PERIOD_S))
        self.ctx.max_b_frames = 0
        self.ctx.thread_count = 1  # deterministic, and the tracker owns the cores
        self.ctx.options = {"preset": H264_PRESET, "tune": "zerolatency", "crf": str(crf)}
        self.first_ns: int | None = None

    def encode(self, bgr: np.ndarray, ns: int) -> bytes:
        """One frame's access unit (b"" while the encoder holds it back, which zerolatency never does)."""
        if self.first_ns is None:
            self.first_ns = ns
        h, w = bgr.shape[:2]
        if (w, h) != (self.ctx.width, self.ctx.height):
            bgr = cv2.copyMakeBorder(bgr, 0, self.ctx.height - h, 0, self.ctx.width - w, cv2.BORDER_REPLICATE)
        frame = av.VideoFrame.from_ndarray(np.ascontiguousarray(bgr), format="bgr24")
        frame.pts = (ns - self.first_ns) // 1_000_000
        return b"".join(bytes(p) for p in self.ctx.encode(frame))


def as_f32(a: np.ndarray) -> np.ndarray:
    """Values rounded to float32 and back: what an .rrd stores, so both archive paths write equal numbers."""
    return np.asarray(a, dtype=np.float32).astype(np.float64)


def as_f32_pose(T: np.ndarray) -> np.ndarray:
    """A pose (4, 4) with its rotation and translation rounded as an .rrd stores them."""
    out = np.array(T, dtype=np.float64)
    out[:3, :] = as_f32(out[:3, :])
    return out


def frame_view(rig: Rig, camera: CameraModel, result: FrameResult, jpeg_quality: int = JPEG_QUALITY) -> FrameView:
    """The archive's view of a tracker result: the same image, outlines and axes that viewer/recording.py logs."""
    if result.frame.packet is not None:
        data, fmt = result.frame.packet, "h264"
    else:
        data, fmt = encode_jpeg(result.frame.bgr if result.frame.bgr is not None else result.frame.gray,
                                jpeg_quality), "jpeg"
    outlines = [(m.id, as_f32(m.corners), CHOICE_COLORS[result.poses[m.id].choice] if m.id in result.poses
                 else REJECTED_COLOR) for m in result.detections.markers]
    axes = []
    for pose in result.poses.values():
        axes += [(as_f32(seg), c) for seg, c in zip(marker_axes_px(pose, camera, rig.marker_size / 2), AXIS_COLORS,
                                                    strict=True)]
    T = camera_pose_from_markers(rig, result)
    if T is not None:
        T = as_f32_pose(T)
    errs = [p.reprojection_error for p in result.poses.values()]
    return FrameView(result.camera, capture_ns(result.time), result.frame.index, data,
                     outlines, axes, T, len(result.poses), float(np.mean(errs)) if errs else float("nan"), fmt)


def calibration_message(name: str, camera: CameraModel, ns: int) -> CameraCalibration:
    """The camera's intrinsics and OpenCV distortion as a Foxglove CameraCalibration."""
    K = camera.K
    d = [float(v) for v in camera.dist.reshape(-1)]
    model = DISTORTION_MODELS.get(len(d), "rational_polynomial" if len(d) > 5 else "plumb_bob")
    if model == "plumb_bob":
        d = (d + [0.0] * 5)[:5]
    P = np.hstack([K, np.zeros((3, 1))])
    return CameraCalibration(timestamp=stamp(ns), frame_id=name, width=camera.width, height=camera.height,
                             distortion_model=model, D=d, K=K.reshape(-1).tolist(),
                             R=np.eye(3).reshape(-1).tolist(), P=P.reshape(-1).tolist())


def annotations_message(view: FrameView, ns: int) -> ImageAnnotations:
    """Marker outlines with their ids and the reprojected marker axes."""
    ann = ImageAnnotations()
    for mid, corners, rgb in view.outlines:
        ann.points.append(PointsAnnotation(timestamp=stamp(ns), type=PointsAnnotation.LINE_LOOP,
                                           points=[Point2(x=float(x), y=float(y)) for x, y in corners],
                                           outline_color=color(rgb), thickness=OUTLINE_PX))
        ann.texts.append(TextAnnotation(timestamp=stamp(ns), position=Point2(x=float(corners[0, 0]),
                                                                             y=float(corners[0, 1])),
                                        text=str(mid), font_size=TEXT_PX, text_color=color(rgb),
                                        background_color=Color(a=0.6)))
    if view.axes:
        ann.points.append(PointsAnnotation(
            timestamp=stamp(ns), type=PointsAnnotation.LINE_LIST, thickness=OUTLINE_PX,
            points=[Point2(x=float(x), y=float(y)) for seg, _ in view.axes for x, y in seg],
            outline_colors=[color(c) for _, c in view.axes for _ in range(2)]))
    return ann


def log_message(ns: int, text: str, level: int = Log.INFO) -> Log:
    """An event for the log channel."""
    return Log(timestamp=stamp(ns), level=level, message=text, name="topside")


def truth_rows(truth: pd.DataFrame | None) -> list[tuple[int, str, np.ndarray]]:
    """(log time ns, cone, (3,) offset) of every truth row; ns truncated as rerun's time columns are."""
    if truth is None:
        return []
    cones = sorted({c[len("cone_"):-len("_dx")] for c in truth.columns if c.startswith("cone_") and c.endswith("_dx")})
    ns = (truth["time"].to_numpy(dtype=float) * 1e9).astype("timedelta64[ns]").astype(np.int64)
    rows = []
    for cone in cones:
        values = truth[[f"cone_{cone}_{a}" for a in ("dx", "dy", "dz")]].to_numpy(dtype=float)
        rows += [(int(t), cone, v) for t, v in zip(ns, values, strict=True)]
    return rows


class Archive:
    """The archive of one tracked installation, fed frame views and estimates in capture-time order."""

    def __init__(self, path: Path, rig: Rig, inputs: ArchiveInputs, cameras: Mapping[str, CameraModel],
                 info: Mapping[str, str] | None = None, truth: list[tuple[int, str, np.ndarray]] | None = None,
                 key: Ed25519PrivateKey | None = None, chunk_size: int = CHUNK_SIZE, block_s: float = BLOCK_S,
                 video: str = "jpeg", file: ArchiveFile | None = None) -> None:
        if video not in VIDEO_FORMATS:
            raise ValueError(f"video format {video!r} (expected one of {', '.join(VIDEO_FORMATS)})")
        self.video = video
        self._encoders: dict[str, VideoEncoder] = {}
        self.rig = rig
        self._cone_points = cone_points(rig)
        self.inputs = inputs
        self.cameras = dict(cameras)
        self.key = key
        # file: where the messages go (default: an MCAP file at path); viewer/foxglove_live.py streams them instead
        self.file = file if file is not None else ArchiveFile(path, chunk_size=chunk_size, block_s=block_s, key=key)
        self.file.metadata("topside", {
            "installation": rig.name, **{k: v for k, v in (info or {}).items() if v},
            "software_version": inputs.software_version, "software_commit": inputs.software_commit,
            "configuration_sha256": inputs.config_hash(), "rig_file": inputs.rig_name,
            "cameras": " ".join(c.name for c in rig.cameras),
            "cones": " ".join(sorted({p.cone for p in rig.all_pairs()})),
            "options": json.dumps(inputs.options, sort_keys=True), "archive_format": "topside-mcap/1",
            "frames": "foxglove.CompressedVideo h264" if video == "h264" else "foxglove.CompressedImage jpeg"})
        self.file.attach(inputs.rig_name, "application/yaml", inputs.rig_text)
        for name, data in sorted(inputs.calibrations.items()):
            self.file.attach(name, "application/yaml", data)
        self.file.flush()
        self._truth = sorted(truth or [], key=lambda r: (r[0], r[1]))
        self._truth_next = 0
        self._last_static: int | None = None
        self._last_calibration: dict[str, int] = {}
        self._last_frame: dict[str, int] = {}
        self._markers_seen: dict[str, bool] = {}
        self._cone_state: dict[str, str] = {}
        self._latest: dict[str, np.ndarray] = {}
        self._last_flush: int | None = None
        self._frames: dict[str, int] = {}
        self._filter_cameras_ns: int | None = None

    def _advance(self, ns: int) -> int:
        """Before anything at capture time ns: static frames when due, truth up to ns, a chunk to disk when due."""
        if self.file.first_ns is None:
            self.file.write("/log", log_message(ns, f"archive of {self.rig.name} started"), ns)
        if self._last_static is None or ns - self._last_static >= STATIC_PERIOD_S * NS:
            self._last_static = ns
            self.file.write("/frames/markers", FrameTransforms(transforms=[
                transform("jacket" if m.body == "jacket" else "topside", f"marker_{m.id}", m.T_body_marker, ns)
                for m in self.rig.markers]), ns)
        while self._truth_next < len(self._truth) and self._truth[self._truth_next][0] <= ns:
            t_ns, cone, v = self._truth[self._truth_next]
            self.file.write(f"/truth/{cone}", ConeOffset(timestamp=stamp(t_ns), cone=cone, dx=v[0], dy=v[1], dz=v[2],
                                                         sdx=0.0, sdy=0.0, sdz=0.0, status="truth"), t_ns)
            self._truth_next += 1
        if self._last_flush is None:
            self._last_flush = ns
        elif ns - self._last_flush >= FLUSH_PERIOD_S * NS:
            self.file.flush()
            self._last_flush = ns
        return ns

    def frame(self, view: FrameView) -> None:
        """One camera frame: calibration when due, image, detections, camera frame, health, events."""
        ns = self._advance(view.ns)
        name = view.camera
        base = f"/cameras/{name}"
        if name not in self._last_frame:
            self.file.write("/log", log_message(ns, f"{name}: first frame ({view.index})"), ns)
        if name not in self._last_calibration or ns - self._last_calibration[name] >= STATIC_PERIOD_S * NS:
            self._last_calibration[name] = ns
            self.file.write(f"{base}/calibration", calibration_message(name, self.cameras[name], ns), ns)
        if view.format == "h264":  # the camera's own H.264, passed through
            self.file.write(f"{base}/image", CompressedVideo(timestamp=stamp(ns), frame_id=name, data=view.image,
                                                             format="h264"), ns)
        elif self.video == "h264":
            cam = self.cameras[name]
            encoder = self._encoders.setdefault(name, VideoEncoder(cam.width, cam.height))
            data = encoder.encode(view.pixels(), ns)
            if data:
                self.file.write(f"{base}/image", CompressedVideo(timestamp=stamp(ns), frame_id=name, data=data,
                                                                 format="h264"), ns)
        else:
            self.file.write(f"{base}/image", CompressedImage(timestamp=stamp(ns), frame_id=name, data=view.image,
                                                             format="jpeg"), ns)
        self.file.write(f"{base}/detections", annotations_message(view, ns), ns)
        if view.T_jacket_camera is not None:
            self.file.write("/frames/cameras", FrameTransforms(transforms=[
                transform("jacket", name, view.T_jacket_camera, ns)]), ns)
        interval = (ns - self._last_frame[name]) / NS if name in self._last_frame else float("nan")
        self.file.write(f"{base}/health", CameraHealth(
            timestamp=stamp(ns), camera=name, frame=view.index, markers=view.markers,
            reprojection_error_px=view.reprojection_error_px, frame_interval_s=interval), ns)
        seen = view.markers > 0
        if name in self._markers_seen and seen != self._markers_seen[name]:
            self.file.write("/log", log_message(ns, f"{name}: markers found again ({view.markers})" if seen else
                                                f"{name}: no markers", Log.INFO if seen else Log.WARNING), ns)
        self._markers_seen[name] = seen
        self._last_frame[name] = ns
        self._frames[name] = self._frames.get(name, 0) + 1

    def estimate(self, estimate: ConeEstimate, ns: int | None = None) -> None:
        """One cone's offset with covariance and status (at ns, default its capture time); the topside frame; the
        filter's camera frames; a log line when the cone's state changes."""
        ns = self._advance(capture_ns(estimate.time) if ns is None else ns)
        cov = estimate.covariance
        sd = np.sqrt(np.diag(cov)) if cov is not None else np.full(3, np.nan)
        state = cone_state(estimate.offset)
        self.file.write(f"/offsets/{estimate.cone}", ConeOffset(
            timestamp=stamp(ns), cone=estimate.cone, dx=estimate.offset[0], dy=estimate.offset[1],
            dz=estimate.offset[2], sdx=sd[0], sdy=sd[1], sdz=sd[2],
            covariance=np.asarray(cov).reshape(-1).tolist() if cov is not None else [], status=state,
            cameras=list(estimate.cameras)), ns)
        said = f"{state} ({estimate.withheld})" if estimate.withheld else state  # why it is withheld, when known
        if self._cone_state.get(estimate.cone) != said:
            level = Log.WARNING if state == "outside" else Log.INFO
            self.file.write("/log", log_message(ns, f"cone {estimate.cone}: {said}", level), ns)
            self._cone_state[estimate.cone] = said
        self._latest[estimate.cone] = estimate.offset
        full = {c: o for c, o in self._latest.items() if np.all(np.isfinite(o))}
        if full:
            T = as_f32_pose(topside_pose(self._cone_points, full))  # as the .rrd's world/topside
            self.file.write("/frames/topside", FrameTransforms(transforms=[transform("jacket", "topside", T, ns)]), ns)
        if estimate.T_jacket_cameras and ns != self._filter_cameras_ns:  # one mapping per time, shared by its cones
            self._filter_cameras_ns = ns
            self.file.write("/frames/filter_cameras", FrameTransforms(transforms=[
                transform("jacket", f"{FILTER_FRAME_PREFIX}{name}", as_f32_pose(T), ns)
                for name, T in sorted(estimate.T_jacket_cameras.items())]), ns)

    def close(self, offsets_csv: bytes | None = None) -> dict:
        """Remaining truth, the time span, the offsets CSV, then the manifest and summary. Returns the manifest."""
        if self.file.last_ns is not None:
            self._advance(self.file.last_ns)
            for t_ns, cone, v in self._truth[self._truth_next:]:
                self.file.write(f"/truth/{cone}", ConeOffset(timestamp=stamp(t_ns), cone=cone, dx=v[0], dy=v[1],
                                                             dz=v[2], sdx=0.0, sdy=0.0, sdz=0.0, status="truth"), t_ns)
            self.file.write("/log", log_message(self.file.last_ns, "archive closed"), self.file.last_ns)
        self.file.flush()
        if offsets_csv is not None:
            self.file.attach("offsets.csv", "text/csv", offsets_csv, log_time=self.file.last_ns or 0)
        self.file.metadata("time_span", time_span(self.file.first_ns, self.file.last_ns,
                                                  {f"frames_{k}": str(v) for k, v in sorted(self._frames.items())}))
        return self.file.close()


def time_span(first_ns: int | None, last_ns: int | None, extra: Mapping[str, str] | None = None) -> dict[str, str]:
    """The time-span metadata record: first and last log time, in ns and for people."""
    from viewer.manifest import time_text

    if first_ns is None or last_ns is None:
        return {"messages": "0", **(extra or {})}
    return {"start_ns": str(first_ns), "end_ns": str(last_ns), "start": time_text(first_ns), "end": time_text(last_ns),
            "duration_s": f"{(last_ns - first_ns) / NS:.3f}", "written_utc": wallclock.strftime(
                "%Y-%m-%dT%H:%M:%SZ", wallclock.gmtime()), **(extra or {})}


class ArchiveSink:
    """Recorder-like sink (on_frame, on_estimate, close) that writes an MCAP archive from the tracker's stream."""

    def __init__(self, rig: Rig, path: Path, options: Mapping[str, str], info: Mapping[str, str] | None = None,
                 truth: pd.DataFrame | None = None, key: Ed25519PrivateKey | None = None,
                 offsets_csv: Path | None = None, jpeg_quality: int = JPEG_QUALITY,
                 cameras: Mapping[str, CameraModel] | None = None, video: str = "jpeg") -> None:
        from tracking.camera import load_camera

        self.rig = rig
        self.offsets_csv = offsets_csv
        self.jpeg_quality = jpeg_quality
        cams = dict(cameras) if cameras is not None else {
            c.name: load_camera(rig.resolve(c.calibration)) for c in rig.cameras}
        self.archive = Archive(path, rig, ArchiveInputs.from_rig(rig, options), cams, info, truth_rows(truth), key,
                               video=video)
        self.frame_seconds = 0.0  # wall time spent per frame in on_frame, summed (for the benchmark)

    def on_frame(self, result: FrameResult) -> None:
        """Archive one processed frame."""
        t0 = wallclock.perf_counter()
        self.archive.frame(frame_view(self.rig, self.archive.cameras[result.camera], result, self.jpeg_quality))
        self.frame_seconds += wallclock.perf_counter() - t0

    def on_estimate(self, estimate: ConeEstimate) -> None:
        """Archive one cone estimate."""
        self.archive.estimate(estimate)

    def close(self) -> None:
        """Attach the offsets CSV if it was written, then seal the file."""
        csv = self.offsets_csv.read_bytes() if self.offsets_csv is not None and self.offsets_csv.is_file() else None
        self.archive.close(csv)

