"""The archive's messages: Foxglove schemas and the two of our own (topside.ConeOffset, topside.CameraHealth),
built from the tracker's results; capture times as nanoseconds."""

from __future__ import annotations

import numpy as np
from foxglove_schemas_protobuf.CameraCalibration_pb2 import CameraCalibration
from foxglove_schemas_protobuf.Color_pb2 import Color
from foxglove_schemas_protobuf.FrameTransform_pb2 import FrameTransform
from foxglove_schemas_protobuf.Log_pb2 import Log
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory, timestamp_pb2
from google.protobuf.message import Message

from tracking.camera import CameraModel
from tracking.geometry import quaternions_xyzw

OUTLINE_PX = 2.0

TEXT_PX = 14.0

NS = 1_000_000_000

DISTORTION_MODELS = {5: "plumb_bob", 8: "rational_polynomial"}

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

def as_f32(a: np.ndarray) -> np.ndarray:
    """Values rounded to float32 and back: what an .rrd stores, so both archive paths write equal numbers."""
    return np.asarray(a, dtype=np.float32).astype(np.float64)

def as_f32_pose(T: np.ndarray) -> np.ndarray:
    """A pose (4, 4) with its rotation and translation rounded as an .rrd stores them."""
    out = np.array(T, dtype=np.float64)
    out[:3, :] = as_f32(out[:3, :])
    return out

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


def log_message(ns: int, text: str, level: int = Log.INFO) -> Log:
    """An event for the log channel."""
    return Log(timestamp=stamp(ns), level=level, message=text, name="topside")
