"""A camera frame as the archive stores it: its image (the camera's own H.264 passed through, else JPEG or H.264
re-encoded) and the annotations of what was detected in it."""

from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction

import av
import cv2
import numpy as np
from foxglove_schemas_protobuf.Color_pb2 import Color
from foxglove_schemas_protobuf.ImageAnnotations_pb2 import ImageAnnotations
from foxglove_schemas_protobuf.Point2_pb2 import Point2
from foxglove_schemas_protobuf.PointsAnnotation_pb2 import PointsAnnotation
from foxglove_schemas_protobuf.TextAnnotation_pb2 import TextAnnotation

from tracking.camera import CameraModel
from tracking.pipeline import FrameResult
from tracking.rig import Rig
from viewer.archive.messages import OUTLINE_PX, TEXT_PX, as_f32, as_f32_pose, capture_ns, color, stamp
from viewer.recording import (
    AXIS_COLORS,
    CHOICE_COLORS,
    JPEG_QUALITY,
    REJECTED_COLOR,
    camera_pose_from_markers,
    encode_jpeg,
    marker_axes_px,
)

VIDEO_FORMATS = ("jpeg", "h264")

H264_CRF = 23  # x264's default quality

H264_PRESET = "superfast"  # 10 ms per 920x600 frame on one core; veryfast: 14 ms, 15 % smaller

KEYFRAME_PERIOD_S = 1.0  # a keyframe (with SPS/PPS) every second: seeking and recovery start there

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
