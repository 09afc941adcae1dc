"""Rerun logging of the tracker's results: frames, corners, marker frames, camera frusta, offsets, truth.

Entity layout (the jacket frame is the world):
    world/jacket/markers/<id>            nominal jacket markers (static)
    world/topside                        estimated topside pose; its markers below it
    world/cameras/<camera>               camera pose as the markers place it, with its pinhole
    world/cameras/<camera>/image         the frame (JPEG), with markers/, axes/, rejected/ below it
    world/estimated/<camera>/<id>        each marker's frame as that camera estimates it
    offsets/<axis>/<cone>/{estimate,truth}, errors/<axis>/<cone>, uncertainty/<axis>/<cone> (1σ),
    health/<camera>/..., status
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field

import cv2
import numpy as np
import pandas as pd
import rerun as rr

from tracking.camera import CameraModel
from tracking.filtering import ConeEstimate
from tracking.pipeline import FrameResult
from tracking.pose import Choice, MarkerPose
from tracking.rig import Rig

APP_ID = "topside"
TIMELINE = "capture_time"
JPEG_QUALITY = 80
TOLERANCE_M = 0.150  # concentricity requirement (paper, section I-D)
MARKER_THICKNESS_M = 0.01
AXIS_LENGTH_M = 0.5
FRUSTUM_DEPTH_M = 2.0
AXES = ("dx", "dy", "dz")
AXIS_COLORS = [(230, 60, 60), (60, 200, 60), (60, 120, 240)]
CONE_COLORS = [(255, 140, 0), (0, 170, 255), (200, 80, 255), (80, 220, 120), (255, 220, 0), (255, 90, 150)]
JACKET_COLOR = (255, 170, 0)
TOPSIDE_COLOR = (0, 200, 255)
REJECTED_COLOR = (200, 0, 200)
CHOICE_COLORS = {Choice.UNIQUE: (0, 255, 0), Choice.PAIR: (255, 255, 0), Choice.AMBIGUOUS: (255, 64, 0)}
STATUS_PERIOD_S = 1.0


def set_capture_time(rec: rr.RecordingStream, t: float) -> None:
    """Capture time on the common clock: absolute when it looks like Unix time, else seconds from start."""
    if t > 1e9:
        rr.set_time(TIMELINE, timestamp=t, recording=rec)
    else:
        rr.set_time(TIMELINE, duration=t, recording=rec)


def log_rig(rec: rr.RecordingStream, rig: Rig) -> None:
    """Static scene: world axes, cones, nominal jacket and topside markers."""
    rr.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True, recording=rec)
    rr.log("world/jacket", rr.TransformAxes3D(2.0), static=True, recording=rec)
    if rig.cones:
        rr.log("world/jacket/cones", rr.Points3D(list(rig.cones.values()), labels=list(rig.cones), radii=0.3,
                                                 colors=JACKET_COLOR), static=True, recording=rec)
    for marker in rig.markers:
        body = "jacket" if marker.body == "jacket" else "topside"
        color = JACKET_COLOR if body == "jacket" else TOPSIDE_COLOR
        path = f"world/{body}/markers/{marker.id}"
        T = marker.T_body_marker
        rr.log(path, rr.Transform3D(translation=T[:3, 3], mat3x3=T[:3, :3]), static=True, recording=rec)
        rr.log(path, rr.Boxes3D(half_sizes=[[rig.marker_size / 2, rig.marker_size / 2, MARKER_THICKNESS_M]],
                                colors=color, labels=[f"{marker.id} {marker.cone}/{marker.face}"]),
               static=True, recording=rec)


def log_camera_model(rec: rr.RecordingStream, name: str, camera: CameraModel) -> None:
    """Static pinhole of one camera."""
    rr.log(f"world/cameras/{name}", rr.Pinhole(image_from_camera=camera.K, resolution=list(camera.image_size),
                                               camera_xyz=rr.ViewCoordinates.RDF,
                                               image_plane_distance=FRUSTUM_DEPTH_M),
           static=True, recording=rec)


def encode_jpeg(image: np.ndarray, quality: int = JPEG_QUALITY) -> bytes:
    """JPEG bytes of a grayscale or BGR frame."""
    ok, buf = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, quality])
    if not ok:
        raise ValueError("JPEG encoding failed")
    return buf.tobytes()


def marker_axes_px(pose: MarkerPose, camera: CameraModel, length: float) -> list[np.ndarray]:
    """Three (2, 2) image segments: the marker's x, y, z axes reprojected."""
    pts = np.array([[0, 0, 0], [length, 0, 0], [0, length, 0], [0, 0, length]], dtype=np.float64)
    T = pose.T_camera_marker
    px, _ = cv2.projectPoints(pts, cv2.Rodrigues(T[:3, :3])[0], T[:3, 3], camera.K, camera.dist)
    px = px.reshape(-1, 2)
    return [np.array([px[0], px[i]]) for i in (1, 2, 3)]


def camera_pose_from_markers(rig: Rig, result: FrameResult) -> np.ndarray | None:
    """T_jacket_camera (4, 4) from the best-seen jacket marker, or None when none is seen."""
    jacket = [p for i, p in result.poses.items() if rig.marker_by_id[i].body == "jacket"]
    if not jacket:
        return None
    best = min(jacket, key=lambda p: (p.choice != Choice.UNIQUE, p.reprojection_error))
    return rig.marker_by_id[best.id].T_body_marker @ np.linalg.inv(best.T_camera_marker)


def log_frame(rec: rr.RecordingStream, rig: Rig, camera: CameraModel, result: FrameResult,
              show_rejected: bool = False, jpeg_quality: int = JPEG_QUALITY) -> None:
    """One camera frame: image, corners, reprojected axes, camera pose, estimated marker frames, health."""
    name = result.camera
    set_capture_time(rec, result.time)
    rr.set_time(f"frame_{name}", sequence=result.frame.index, recording=rec)
    base = f"world/cameras/{name}"
    rr.log(f"world/estimated/{name}", rr.Clear(recursive=True), recording=rec)  # no stale marker frames
    image = result.frame.bgr if result.frame.bgr is not None else result.frame.gray
    rr.log(f"{base}/image", rr.EncodedImage(contents=encode_jpeg(image, jpeg_quality), media_type="image/jpeg"),
           recording=rec)
    markers = result.detections.markers
    rr.log(f"{base}/image/markers", rr.LineStrips2D(
        [np.vstack([m.corners, m.corners[:1]]) for m in markers],
        labels=[str(m.id) for m in markers],
        colors=[CHOICE_COLORS[result.poses[m.id].choice] if m.id in result.poses else REJECTED_COLOR
                for m in markers], radii=1.0), recording=rec)
    rr.log(f"{base}/image/corners", rr.Points2D(
        np.vstack([m.corners for m in markers]) if markers else np.zeros((0, 2)), radii=2.0,
        colors=[AXIS_COLORS[0], AXIS_COLORS[1], AXIS_COLORS[2], (255, 255, 255)] * len(markers)), recording=rec)
    strips, colors = [], []
    for pose in result.poses.values():
        strips += marker_axes_px(pose, camera, rig.marker_size / 2)
        colors += AXIS_COLORS
    rr.log(f"{base}/image/axes", rr.LineStrips2D(strips, colors=colors, radii=1.0), recording=rec)
    if show_rejected:
        rr.log(f"{base}/image/rejected", rr.LineStrips2D(
            [np.vstack([c, c[:1]]) for c in result.detections.rejected], colors=REJECTED_COLOR, radii=0.5),
            recording=rec)
    T_jacket_camera = camera_pose_from_markers(rig, result)
    if T_jacket_camera is not None:
        rr.log(base, rr.Transform3D(translation=T_jacket_camera[:3, 3], mat3x3=T_jacket_camera[:3, :3]),
               recording=rec)
        for mid, pose in result.poses.items():
            T = T_jacket_camera @ pose.T_camera_marker
            path = f"world/estimated/{name}/{mid}"
            rr.log(path, rr.Transform3D(translation=T[:3, 3], mat3x3=T[:3, :3]), rr.TransformAxes3D(AXIS_LENGTH_M),
                   recording=rec)
            rr.log(path, rr.Boxes3D(half_sizes=[[rig.marker_size / 2, rig.marker_size / 2, MARKER_THICKNESS_M]],
                                    colors=CHOICE_COLORS[pose.choice]), recording=rec)
    errs = [p.reprojection_error for p in result.poses.values()]
    rr.log(f"health/{name}/markers", rr.Scalars(len(result.poses)), recording=rec)
    if errs:
        rr.log(f"health/{name}/reprojection_error_px", rr.Scalars(float(np.mean(errs))), recording=rec)


def log_estimate(rec: rr.RecordingStream, estimate: ConeEstimate) -> None:
    """One cone's offset estimate on the three axis plots."""
    set_capture_time(rec, estimate.time)
    for axis, value in zip(AXES, estimate.offset, strict=True):
        if np.isfinite(value):
            rr.log(f"offsets/{axis}/{estimate.cone}/estimate", rr.Scalars(float(value)), recording=rec)
    if estimate.covariance is not None:
        for axis, sd in zip(AXES, np.sqrt(np.diag(estimate.covariance)), strict=True):
            rr.log(f"uncertainty/{axis}/{estimate.cone}", rr.Scalars(float(sd)), recording=rec)


def log_estimate_record(rec: rr.RecordingStream, estimate: ConeEstimate) -> None:
    """The whole estimate (offset, full covariance, cameras) for `topside export`, which rebuilds the archive."""
    set_capture_time(rec, estimate.time)
    cov = estimate.covariance.reshape(-1) if estimate.covariance is not None else np.zeros(0)
    rr.log(f"archive/estimates/{estimate.cone}", rr.AnyValues(offset=estimate.offset, covariance=cov,
                                                               cameras=" ".join(estimate.cameras)), recording=rec)


def log_archive_inputs(rec: rr.RecordingStream, inputs_json: str) -> None:
    """The rig and calibration files and the tracker's options (JSON), static, for `topside export`."""
    rr.log("archive/inputs", rr.TextDocument(inputs_json, media_type=rr.MediaType.TEXT), static=True, recording=rec)


def log_topside_pose(rec: rr.RecordingStream, latest: dict[str, ConeEstimate]) -> None:
    """T_jacket_topside from the latest cone offsets: their mean translation (rotation is not estimated yet)."""
    full = [e.offset for e in latest.values() if np.all(np.isfinite(e.offset))]
    if full:
        rr.log("world/topside", rr.Transform3D(translation=np.mean(full, axis=0)), recording=rec)


def log_frame_ages(rec: rr.RecordingStream, t: float, last_capture: dict[str, float]) -> None:
    """Age of every camera's newest frame at capture time t, s: a stalled camera's age keeps growing."""
    for name, t_last in last_capture.items():
        rr.log(f"health/{name}/frame_age_s", rr.Scalars(max(0.0, t - t_last)), recording=rec)


def log_error(rec: rr.RecordingStream, estimate: ConeEstimate, true_offset: np.ndarray) -> None:
    """Estimate minus truth of one cone at the estimate's capture time."""
    for axis, value in zip(AXES, estimate.offset - true_offset, strict=True):
        if np.isfinite(value):
            rr.log(f"errors/{axis}/{estimate.cone}", rr.Scalars(float(value)), recording=rec)


def log_truth(rec: rr.RecordingStream, truth: pd.DataFrame, cones: Iterable[str]) -> None:
    """The ground-truth offsets of every cone, columnar, and the ±tolerance bands."""
    times = truth["time"].to_numpy(dtype=float)
    index = (rr.TimeColumn(TIMELINE, timestamp=times) if times.size and times[0] > 1e9
             else rr.TimeColumn(TIMELINE, duration=times))
    for cone in cones:
        for axis in AXES:
            col = f"cone_{cone}_{axis}"
            if col in truth.columns:
                rr.send_columns(f"offsets/{axis}/{cone}/truth", indexes=[index],
                                columns=rr.Scalars.columns(scalars=truth[col].to_numpy(dtype=float)), recording=rec)
    for axis in AXES:
        for sign, label in ((1, "upper"), (-1, "lower")):
            rr.send_columns(f"errors/{axis}/tolerance_{label}", indexes=[index],
                            columns=rr.Scalars.columns(scalars=np.full(times.size, sign * TOLERANCE_M)), recording=rec)


def cone_color(index: int, lighten: float = 0.0) -> tuple[int, int, int]:
    """The colour of the index-th cone, optionally lightened towards white (0..1) for its truth."""
    c = np.array(CONE_COLORS[index % len(CONE_COLORS)], dtype=float)
    return tuple(int(v) for v in c + (255 - c) * lighten)


def log_series_styles(rec: rr.RecordingStream, cones: Iterable[str], with_truth: bool) -> None:
    """Static names and colours of every time series: a colour per cone, its truth a lighter shade."""
    for k, cone in enumerate(cones):
        for axis in AXES:
            rr.log(f"offsets/{axis}/{cone}/estimate", rr.SeriesLines(colors=cone_color(k), names=f"{cone} estimate",
                                                                     widths=2.0), static=True, recording=rec)
            if with_truth:
                rr.log(f"offsets/{axis}/{cone}/truth", rr.SeriesLines(colors=cone_color(k, 0.6), names=f"{cone} truth",
                                                                      widths=1.0), static=True, recording=rec)
                rr.log(f"errors/{axis}/{cone}", rr.SeriesLines(colors=cone_color(k), names=f"{cone} error"),
                       static=True, recording=rec)
    for axis in AXES:
        for label in ("upper", "lower"):
            rr.log(f"errors/{axis}/tolerance_{label}", rr.SeriesLines(colors=(255, 0, 0), names=f"±{TOLERANCE_M} m",
                                                                      widths=1.0), static=True, recording=rec)


def cone_state(offset: np.ndarray) -> str:
    """'NO DATA' unless every axis is known; then within or outside the concentricity tolerance."""
    if not np.all(np.isfinite(offset)):
        return "NO DATA"
    return f"within ±{TOLERANCE_M} m" if np.all(np.abs(offset) <= TOLERANCE_M) else "outside"


@dataclass
class StatusBoard:
    """The status panel's state: last estimate per cone, counts per camera; logged as markdown."""

    latest: dict[str, ConeEstimate] = field(default_factory=dict)
    frames: dict[str, int] = field(default_factory=dict)
    markers: dict[str, int] = field(default_factory=dict)
    last_logged: float = -np.inf

    def markdown(self) -> str:
        """The panel's text."""
        lines = ["## Cones", "", "| cone | dx [m] | dy [m] | dz [m] | state | cameras |",
                 "|---|---:|---:|---:|---|---|"]
        for cone, e in sorted(self.latest.items()):
            state = cone_state(e.offset)
            vals = " | ".join("—" if not np.isfinite(v) else f"{v:+.3f}" for v in e.offset)
            lines.append(f"| {cone} | {vals} | {state} | {', '.join(e.cameras)} |")
        lines += ["", "## Cameras", "", "| camera | frames | markers |", "|---|---:|---:|"]
        for cam in sorted(self.frames):
            lines.append(f"| {cam} | {self.frames[cam]} | {self.markers.get(cam, 0)} |")
        return "\n".join(lines)

    def log_if_due(self, rec: rr.RecordingStream, t: float, force: bool = False) -> None:
        """Log the panel once per STATUS_PERIOD_S of capture time."""
        if force or t - self.last_logged >= STATUS_PERIOD_S:
            set_capture_time(rec, t)
            rr.log("status", rr.TextDocument(self.markdown(), media_type=rr.MediaType.MARKDOWN), recording=rec)
            self.last_logged = t
