"""Rerun logging of the tracker's results: frames, corners, marker frames, camera frusta, offsets, truth.

Entity layout (the jacket frame is the world):
    world/jacket/markers/<id>            nominal jacket markers (static)
    world/topside                        estimated topside pose; its markers below it
    world/cameras/<camera>               camera pose as the markers place it, with its pinhole
    world/cameras/<camera>/image         the frame (the camera's own H.264 packet, or JPEG), with markers/
                                         (outlines, axes, corners) and rejected/ below it
    world/estimated/<camera>             every marker's frame as that camera estimates it (boxes by id, axes)
    world/filter/cameras/<camera>        camera pose as the fused filter has it (all cameras, over time), a frustum
    world/truth/cameras/<camera>         camera pose in the truth log (the simulator's), a frustum
    offsets/<axis>/<cone>/{estimate,truth}, errors/<axis>/<cone>, errors/<axis>/<cone>/{plus,minus}_2sigma (the
    estimate's ±2σ, about zero), uncertainty/<axis>/<cone> (1σ), key (markdown: which colour is what),
    health/<camera>/..., health/<camera>/video/<count> and .../events (a video's problems), health/<camera>/state
    (what the live tracker said of a camera: LIVE, FROZEN, LOST, ended, with why), status
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field, replace

import cv2
import numpy as np
import pandas as pd
import rerun as rr

from tracking.camera import CameraModel
from tracking.estimate import TOLERANCE_M, ConeEstimate, axes_withheld
from tracking.estimator import point_offset_matrix
from tracking.geometry import quaternions_xyzw, rotation, transform
from tracking.images import Frame, VideoHealth
from tracking.pipeline import FrameResult
from tracking.pose import Choice, MarkerPose
from tracking.rig import Rig

APP_ID = "topside"
TIMELINE = "capture_time"
JPEG_QUALITY = 80
MARKER_THICKNESS_M = 0.01
AXIS_LENGTH_M = 0.5
FRUSTUM_DEPTH_M = 5.0  # a frustum this deep shows its camera's image at installation scale (cameras 10-50 m off)
FILTER_CAMERAS = "world/filter/cameras"  # where the fused filter has each camera (the frames' own are world/cameras)
TRUTH_CAMERAS = "world/truth/cameras"  # where a truth log (the simulator's) has each camera
TRUTH_POSE_AXES = ("x", "y", "z", "rx", "ry", "rz")  # a truth log's camera_<name>_<axis> columns (the simulator's
# pose vector: position, rotation vector)
AXES = ("dx", "dy", "dz")
AXIS_COLORS = [(230, 60, 60), (60, 200, 60), (60, 120, 240)]
CONE_COLORS = [(255, 140, 0), (0, 170, 255), (200, 80, 255), (80, 220, 120), (255, 220, 0), (255, 90, 150)]
CONE_COLOR_NAMES = ("orange", "blue", "violet", "green", "yellow", "pink")  # for the plots' key, as CONE_COLORS
CAMERA_COLORS = [(230, 60, 60), (60, 200, 200), (240, 240, 240), (160, 120, 60), (120, 120, 255), (255, 160, 200)]
CAMERA_COLOR_NAMES = ("red", "cyan", "white", "brown", "lilac", "rose")
SIGMA_LIGHTEN = 0.45  # a cone's ±2σ lines: its colour this much towards white
TOLERANCE_COLOR = (255, 0, 0)
JACKET_COLOR = (255, 170, 0)
TOPSIDE_COLOR = (0, 200, 255)
REJECTED_COLOR = (200, 0, 200)
CHOICE_COLORS = {Choice.UNIQUE: (0, 255, 0), Choice.PAIR: (255, 255, 0), Choice.AMBIGUOUS: (255, 64, 0)}
STATUS_PERIOD_S = 1.0
VIDEO_COUNTS = ("decoded", "backwards", "repeated", "damaged", "jumps", "untimed")  # VideoHealth's counts, logged
# once a video has a problem


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


def log_frustum(rec: rr.RecordingStream, path: str, camera: CameraModel) -> None:
    """Static pinhole of a camera at any entity: a frustum wherever a transform puts it (without a resolution while
    the calibration has no size and no frame has given one)."""
    size = camera.image_size
    rr.log(path, rr.Pinhole(image_from_camera=camera.K, resolution=list(size) if size else None,
                            camera_xyz=rr.ViewCoordinates.RDF, image_plane_distance=FRUSTUM_DEPTH_M),
           static=True, recording=rec)


def log_camera_poses(rec: rr.RecordingStream, path: str, times: np.ndarray, T_jacket_camera: np.ndarray) -> None:
    """A camera's pose over time, (N, 4, 4) at (N,) capture times, columnar (as a matrix, which `topside export`
    reads back)."""
    if len(times):
        rr.send_columns(path, indexes=[time_column(times)],
                        columns=rr.Transform3D.columns(translation=T_jacket_camera[:, :3, 3],
                                                       mat3x3=T_jacket_camera[:, :3, :3]),
                        recording=rec)


def true_camera_poses(truth: pd.DataFrame, name: str) -> np.ndarray | None:
    """(N, 4, 4) T_jacket_camera of a camera at the truth log's times, or None when the log has no pose for it."""
    columns = [f"camera_{name}_{axis}" for axis in TRUTH_POSE_AXES]
    if not set(columns) <= set(truth.columns):
        return None
    poses = truth[columns].to_numpy(dtype=float)
    return np.array([transform(rotation(pose[3:6]), pose[:3]) for pose in poses]).reshape(-1, 4, 4)


def log_true_cameras(rec: rr.RecordingStream, truth: pd.DataFrame, cameras: dict[str, CameraModel]) -> None:
    """Every camera's true pose over time, with its frustum, where the truth log has it."""
    for name, camera in cameras.items():
        T = true_camera_poses(truth, name)
        if T is not None:
            log_frustum(rec, f"{TRUTH_CAMERAS}/{name}", camera)
            log_camera_poses(rec, f"{TRUTH_CAMERAS}/{name}", truth["time"].to_numpy(dtype=float), T)


def encode_jpeg(image: np.ndarray, quality: int = JPEG_QUALITY) -> bytes:
    """JPEG bytes of a grayscale or BGR frame."""
    ok, buf = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, quality])
    if not ok:
        raise ValueError("JPEG encoding failed")
    return buf.tobytes()


def log_image(rec: rr.RecordingStream, path: str, frame: Frame, jpeg_quality: int = JPEG_QUALITY) -> None:
    """The frame's pixels: its H.264 packet as a video-stream sample when it has one, else a JPEG."""
    if frame.packet is not None:
        rr.log(path, rr.VideoStream.from_fields(sample=frame.packet, is_keyframe=frame.keyframe), recording=rec)
        return
    image = frame.bgr if frame.bgr is not None else frame.gray
    rr.log(path, rr.EncodedImage(contents=encode_jpeg(image, jpeg_quality), media_type="image/jpeg"), recording=rec)


def log_video_codec(rec: rr.RecordingStream, name: str) -> None:
    """Static codec of a camera whose frames are recorded as their H.264 packets."""
    rr.log(f"world/cameras/{name}/image", rr.VideoStream(codec=rr.VideoCodec.H264), static=True, recording=rec)


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
    """One camera frame: image, corners, reprojected axes, camera pose, estimated marker frames."""
    log_frame_image(rec, rig, camera, result, show_rejected, jpeg_quality)
    if not result.tracked:  # recorded only, to keep up: its overlays stay as they were
        return
    name = result.camera
    base = f"world/cameras/{name}"
    T_jacket_camera = camera_pose_from_markers(rig, result)
    if T_jacket_camera is not None:
        rr.log(base, rr.Transform3D(translation=T_jacket_camera[:3, 3], mat3x3=T_jacket_camera[:3, :3]),
               recording=rec)
        log_marker_frames(rec, f"world/estimated/{name}", rig.marker_size,
                          {mid: T_jacket_camera @ pose.T_camera_marker for mid, pose in result.poses.items()},
                          [CHOICE_COLORS[pose.choice] for pose in result.poses.values()])


def log_frame_image(rec: rr.RecordingStream, rig: Rig, camera: CameraModel, result: FrameResult,
                    show_rejected: bool = False, jpeg_quality: int = JPEG_QUALITY, scale: float = 1.0) -> None:
    """One camera frame in 2-D, at its capture time: image, marker outlines, corners, reprojected axes; with scale
    under 1, the image a JPEG of the frame that many times its size and the overlays scaled with it (a tablet's
    budget: view_camera gives the pinhole that goes with it)."""
    name = result.camera
    set_capture_time(rec, result.time)
    rr.set_time(f"frame_{name}", sequence=result.frame.index, recording=rec)
    base = f"world/cameras/{name}"
    if scale < 1.0:
        log_scaled_image(rec, f"{base}/image", result.frame, scale, jpeg_quality)
    else:
        log_image(rec, f"{base}/image", result.frame, jpeg_quality)
    if not result.tracked:  # recorded only, to keep up: its overlays stay as they were
        return

    def px(points: np.ndarray) -> np.ndarray:  # OpenCV pixel centres at integers, in the scaled image
        return (points + 0.5) * scale - 0.5 if scale != 1.0 else points

    markers = result.detections.markers
    outlines = [px(np.vstack([m.corners, m.corners[:1]])) for m in markers]
    colors = [CHOICE_COLORS[result.poses[m.id].choice] if m.id in result.poses else REJECTED_COLOR for m in markers]
    axes = [px(seg) for pose in result.poses.values() for seg in marker_axes_px(pose, camera, rig.marker_size / 2)]
    rr.log(f"{base}/image/markers",  # one entity: outlines labelled by id, reprojected axes, corners TL TR BR BL
           rr.LineStrips2D(outlines + axes, labels=[str(m.id) for m in markers] + [""] * len(axes),
                           colors=np.array(colors + AXIS_COLORS * len(result.poses), dtype=np.uint8).reshape(-1, 3),
                           radii=1.0),
           rr.Points2D(px(np.vstack([m.corners for m in markers])) if markers else np.zeros((0, 2)), radii=2.0,
                       colors=np.array([*AXIS_COLORS, (255, 255, 255)] * len(markers), dtype=np.uint8).reshape(-1, 3)),
           recording=rec)
    if show_rejected:
        rr.log(f"{base}/image/rejected", rr.LineStrips2D(
            [px(np.vstack([c, c[:1]])) for c in result.detections.rejected], colors=REJECTED_COLOR, radii=0.5),
            recording=rec)


def log_scaled_image(rec: rr.RecordingStream, path: str, frame: Frame, scale: float, jpeg_quality: int) -> None:
    """A JPEG of the frame's pixels at scale (0, 1) of its size; nothing for a frame that kept only its packet."""
    image = frame.bgr if frame.bgr is not None else frame.gray
    if image is None:
        return
    size = (max(1, round(image.shape[1] * scale)), max(1, round(image.shape[0] * scale)))
    small = cv2.resize(image, size, interpolation=cv2.INTER_AREA)
    rr.log(path, rr.EncodedImage(contents=encode_jpeg(small, jpeg_quality), media_type="image/jpeg"), recording=rec)


def view_camera(camera: CameraModel, scale: float) -> CameraModel:
    """The camera as its images scaled by scale show it: intrinsics and size scaled (OpenCV pixel centres)."""
    if scale >= 1.0 or camera.image_size is None:
        return camera
    K = camera.K.copy()
    K[0, 0] *= scale
    K[1, 1] *= scale
    K[:2, 2] = (K[:2, 2] + 0.5) * scale - 0.5
    return replace(camera, K=K, width=max(1, round(camera.width * scale)), height=max(1, round(camera.height * scale)))


def log_health(rec: rr.RecordingStream, result: FrameResult) -> None:
    """A camera's markers found and mean reprojection error in one frame; its video's problems (see
    log_video_health)."""
    set_capture_time(rec, result.time)
    rr.log(f"health/{result.camera}/markers", rr.Scalars(len(result.poses)), recording=rec)
    if result.poses:
        rr.log(f"health/{result.camera}/reprojection_error_px",
               rr.Scalars(float(np.mean([p.reprojection_error for p in result.poses.values()]))), recording=rec)
    if result.frame.video is not None:
        log_video_health(rec, result.camera, result.frame.video)


def log_video_health(rec: rr.RecordingStream, camera: str, video: VideoHealth) -> None:
    """At the current time, once a camera's video has had a problem: its counts (health/<camera>/video/<count>,
    steps from the first problem on; nothing for a sound video), and as warnings (health/<camera>/video/events) the
    first of each kind of problem, every jump, and an early end (with the last frame)."""
    if video.troubled():
        for name in VIDEO_COUNTS:
            rr.log(f"health/{camera}/video/{name}", rr.Scalars(float(getattr(video, name))), recording=rec)
        if video.ended and video.declared_frames is not None:  # beside decoded, at the end of a video
            rr.log(f"health/{camera}/video/declared", rr.Scalars(float(video.declared_frames)), recording=rec)
    if video.news:
        rr.log(f"health/{camera}/video/events", rr.TextLog(f"{video.source}: {'; '.join(video.news)}",
                                                          level=rr.TextLogLevel.WARN), recording=rec)


def log_camera_state(rec: rr.RecordingStream, t: float, camera: str, state: str, detail: str = "") -> None:
    """A camera's state as the live tracker states it, at capture time t: 'state' or 'state: why' (`topside report`
    names a camera's silences by it)."""
    set_capture_time(rec, t)
    level = rr.TextLogLevel.INFO if state in ("live", "starting") else rr.TextLogLevel.WARN
    rr.log(f"health/{camera}/state", rr.TextLog(f"{state}: {detail}" if detail else state, level=level), recording=rec)


def log_marker_frames(rec: rr.RecordingStream, path: str, size: float, T_jacket_marker: dict[int, np.ndarray],
                      colors: list[tuple[int, int, int]]) -> None:
    """Markers' frames as one camera estimates them (4, 4 each): boxes labelled by id and their axes, one entity."""
    Ts = np.array(list(T_jacket_marker.values())).reshape(-1, 4, 4)
    centres = Ts[:, :3, 3]
    rr.log(path, rr.Boxes3D(centers=centres, half_sizes=np.tile([size / 2, size / 2, MARKER_THICKNESS_M], (len(Ts), 1)),
                            quaternions=quaternions_xyzw(Ts[:, :3, :3]), colors=np.array(colors, dtype=np.uint8),
                            labels=[str(i) for i in T_jacket_marker]),
           rr.Arrows3D(origins=np.repeat(centres, 3, axis=0),  # each marker's x, y, z axes: the columns of R
                       vectors=(Ts[:, :3, :3].transpose(0, 2, 1) * AXIS_LENGTH_M).reshape(-1, 3),
                       colors=np.tile(np.array(AXIS_COLORS, dtype=np.uint8), (len(Ts), 1))), recording=rec)


def time_column(times: np.ndarray) -> rr.TimeColumn:
    """Capture times as a column: absolute when they look like Unix time, else seconds from start."""
    times = np.asarray(times, dtype=float)
    return (rr.TimeColumn(TIMELINE, timestamp=times) if times.size and times[0] > 1e9
            else rr.TimeColumn(TIMELINE, duration=times))


def send_scalars(rec: rr.RecordingStream, path: str, times: np.ndarray, values: np.ndarray) -> None:
    """One time series, columnar; non-finite values left out."""
    ok = np.isfinite(values)
    if ok.any():
        rr.send_columns(path, indexes=[time_column(times[ok])], columns=rr.Scalars.columns(scalars=values[ok]),
                        recording=rec)


def log_estimates(rec: rr.RecordingStream, estimates: list[ConeEstimate],
                  true_offsets: np.ndarray | None = None) -> None:
    """A batch of cone estimates, columnar: offset, 1σ and (given the (N, 3) truth) error per axis and cone."""
    for cone in sorted({e.cone for e in estimates}):
        rows = [i for i, e in enumerate(estimates) if e.cone == cone]
        times = np.array([estimates[i].time for i in rows])
        offsets = np.array([estimates[i].offset for i in rows])
        sds = np.array([estimates[i].sigma for i in rows])
        for k, axis in enumerate(AXES):
            send_scalars(rec, f"offsets/{axis}/{cone}/estimate", times, offsets[:, k])
            send_scalars(rec, f"uncertainty/{axis}/{cone}", times, sds[:, k])
            if true_offsets is not None:
                truth = true_offsets[rows]
                send_scalars(rec, f"errors/{axis}/{cone}", times, offsets[:, k] - truth[:, k])
                send_scalars(rec, f"errors/{axis}/{cone}/plus_2sigma", times, 2 * sds[:, k])
                send_scalars(rec, f"errors/{axis}/{cone}/minus_2sigma", times, -2 * sds[:, k])


def topside_pose(cones: dict[str, np.ndarray], offsets: dict[str, np.ndarray]) -> np.ndarray:
    """T_jacket_topside (4, 4) that moves each cone's point (3,) by its offset (3,): with three cones or more not in
    a line, the least-squares small rotation ω and translation t of o = t + ω × r (the fused filter's own model,
    so its cone offsets give back its pose); with fewer, the mean offset and no rotation."""
    names = [c for c in offsets if c in cones]
    T = np.eye(4)
    if not names:
        return T
    o = np.array([offsets[c] for c in names], dtype=float)
    r = np.array([cones[c] for c in names], dtype=float)
    A = np.concatenate([point_offset_matrix(p)[:, :6] for p in r])  # o = A [t, ω]
    solution, _, rank, _ = np.linalg.lstsq(A, o.reshape(-1), rcond=1e-6)
    if rank == 6:  # three cones or more, not in a line
        t, omega = np.split(solution, 2)
        T[:3, :3] = cv2.Rodrigues(omega)[0]
        T[:3, 3] = t
    else:
        T[:3, 3] = o.mean(axis=0)
    return T


def log_topside_poses(rec: rr.RecordingStream, times: np.ndarray, T_jacket_topside: np.ndarray) -> None:
    """The topside's pose over time, (N, 4, 4) at (N,) capture times: its markers below it follow."""
    if len(times):
        rr.send_columns("world/topside", indexes=[time_column(times)],
                        columns=rr.Transform3D.columns(translation=T_jacket_topside[:, :3, 3],
                                                       quaternion=quaternions_xyzw(T_jacket_topside[:, :3, :3])),
                        recording=rec)


def log_estimate_records(rec: rr.RecordingStream, estimates: list[ConeEstimate]) -> None:
    """Whole estimates (offset, full covariance, cameras, why withheld) per cone, columnar, for `topside export`."""
    for cone in sorted({e.cone for e in estimates}):
        batch = [e for e in estimates if e.cone == cone]
        n = len(batch)
        cov = np.array([e.covariance.reshape(-1) if e.covariance is not None else np.full(9, np.nan) for e in batch])
        rr.send_columns(f"archive/estimates/{cone}", indexes=[time_column(np.array([e.time for e in batch]))],
                        columns=[*rr.AnyValues.columns(offset=np.array([e.offset for e in batch]).reshape(-1))
                                 .partition([3] * n),
                                 *rr.AnyValues.columns(covariance=cov.reshape(-1)).partition([9] * n),
                                 *rr.AnyValues.columns(cameras=[" ".join(e.cameras) for e in batch]),
                                 *rr.AnyValues.columns(withheld=[e.withheld for e in batch])],
                        recording=rec)


def log_archive_inputs(rec: rr.RecordingStream, inputs_json: str) -> None:
    """The rig and calibration files and the tracker's options (JSON), static, for `topside export`."""
    rr.log("archive/inputs", rr.TextDocument(inputs_json, media_type=rr.MediaType.TEXT), static=True, recording=rec)


def log_frame_ages(rec: rr.RecordingStream, t: float, last_capture: dict[str, float]) -> None:
    """Age of every camera's newest frame at capture time t, s: a stalled camera's age keeps growing."""
    for name, t_last in last_capture.items():
        rr.log(f"health/{name}/frame_age_s", rr.Scalars(max(0.0, t - t_last)), recording=rec)


def log_truth(rec: rr.RecordingStream, truth: pd.DataFrame, cones: Iterable[str]) -> None:
    """The ground-truth offsets of every cone, columnar, and the ±tolerance bands."""
    times = truth["time"].to_numpy(dtype=float)
    index = time_column(times)
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


def log_series_styles(rec: rr.RecordingStream, cones: Iterable[str], with_truth: bool,
                      cameras: Iterable[str] = ()) -> None:
    """Static names and colours of every time series: a colour per cone (its truth and ±2σ lighter shades), a
    colour per camera for the health plots."""
    for k, cone in enumerate(cones):
        for axis in AXES:
            rr.log(f"offsets/{axis}/{cone}/estimate", rr.SeriesLines(colors=cone_color(k), names=f"{cone} estimate",
                                                                     widths=2.0), static=True, recording=rec)
            if with_truth:
                rr.log(f"offsets/{axis}/{cone}/truth", rr.SeriesLines(colors=cone_color(k, 0.6), names=f"{cone} truth",
                                                                      widths=1.0), static=True, recording=rec)
                rr.log(f"errors/{axis}/{cone}", rr.SeriesLines(colors=cone_color(k), names=f"{cone} error",
                                                               widths=1.5), static=True, recording=rec)
                for side in ("plus", "minus"):
                    rr.log(f"errors/{axis}/{cone}/{side}_2sigma", rr.SeriesLines(
                        colors=cone_color(k, SIGMA_LIGHTEN), names=f"{cone} ±2σ", widths=0.75), static=True,
                        recording=rec)
    for axis in AXES:
        for label in ("upper", "lower"):
            rr.log(f"errors/{axis}/tolerance_{label}", rr.SeriesLines(colors=TOLERANCE_COLOR,
                                                                      names=f"±{TOLERANCE_M * 1000:.0f} mm",
                                                                      widths=1.0), static=True, recording=rec)
    for k, camera in enumerate(cameras):
        for series in ("markers", "reprojection_error_px", "frame_age_s"):
            rr.log(f"health/{camera}/{series}", rr.SeriesLines(colors=CAMERA_COLORS[k % len(CAMERA_COLORS)],
                                                               names=camera), static=True, recording=rec)


def log_plot_key(rec: rr.RecordingStream, cones: Iterable[str], cameras: Iterable[str], with_truth: bool) -> None:
    """Static key of the plots' colours (markdown): the plots carry no legend, which would cover their data."""
    cones_text = " · ".join(f"{c} {CONE_COLOR_NAMES[k % len(CONE_COLOR_NAMES)]}" for k, c in enumerate(cones))
    cameras_text = " · ".join(f"{c} {CAMERA_COLOR_NAMES[k % len(CAMERA_COLOR_NAMES)]}" for k, c in enumerate(cameras))
    lines = [f"**Cones:** {cones_text}" + (" — thick: estimate, thin pale: truth" if with_truth else "")]
    if with_truth:
        lines.append(f"**Errors:** red ±{TOLERANCE_M * 1000:.0f} mm tolerance · pale ±2σ of the estimate")
    if cameras_text:
        lines.append(f"**Cameras (health):** {cameras_text}")
    rr.log("key", rr.TextDocument("  \n".join(lines), media_type=rr.MediaType.MARKDOWN), static=True, recording=rec)


def concentricity(offset: np.ndarray) -> float:
    """Horizontal distance of a cone from its target, m: what the tolerance applies to (Δz is the approach)."""
    return float(np.hypot(offset[0], offset[1]))


def cone_state(offset: np.ndarray) -> str:
    """'NO DATA' unless the horizontal offset (dx, dy) is known; then within or outside the concentricity tolerance
    (a height withheld alone leaves it standing, as on the tablet)."""
    if not np.all(np.isfinite(offset[:2])):
        return "NO DATA"
    return f"within ±{TOLERANCE_M} m" if concentricity(offset) <= TOLERANCE_M else "outside"


def said_state(estimate: ConeEstimate) -> str:
    """A cone's state and why what it lacks is withheld: 'within ±0.15 m (Δz withheld: σ too large)', 'NO DATA (σ too
    large)' when every axis is."""
    state = cone_state(estimate.offset)
    if not estimate.withheld:
        return state
    if np.isfinite(estimate.offset).any():  # some axes shown: name the others
        return f"{state} ({axes_withheld(estimate.offset)} withheld: {estimate.withheld})"
    return f"{state} ({estimate.withheld})"


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
            state = said_state(e)
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
