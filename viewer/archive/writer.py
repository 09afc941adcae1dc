"""The archive writer: one MCAP file from the tracker's stream of frames and estimates, and its sink for `track`."""

from __future__ import annotations

import hashlib
import json
import time as wallclock
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey
from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage
from foxglove_schemas_protobuf.CompressedVideo_pb2 import CompressedVideo
from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms
from foxglove_schemas_protobuf.Log_pb2 import Log

from tracking.camera import CameraModel
from tracking.estimate import ConeEstimate
from tracking.estimator import cone_points
from tracking.pipeline import FrameResult
from tracking.rig import Rig
from viewer.archive.file import CHUNK_SIZE, ArchiveFile, software_commit, software_version, time_span
from viewer.archive.frames import VIDEO_FORMATS, FrameView, VideoEncoder, annotations_message, frame_view
from viewer.archive.manifest import (
    BLOCK_S,
)
from viewer.archive.messages import (
    NS,
    CameraHealth,
    ConeOffset,
    as_f32_pose,
    calibration_message,
    capture_ns,
    log_message,
    stamp,
    transform,
)
from viewer.recording import (
    JPEG_QUALITY,
    cone_state,
    said_state,
    topside_pose,
)

FLUSH_PERIOD_S = 1.0  # capture time between chunks written to disk: at most this much is lost to a kill

STATIC_PERIOD_S = 1.0  # calibration and marker frames are repeated this often, so a seek finds them

FILTER_FRAME_PREFIX = "filter_"  # the fused filter's camera frames, beside the markers' own <camera> frames

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
            "cones": " ".join(rig.paired_cones()),
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
        sd = estimate.sigma
        state = cone_state(estimate.offset)
        self.file.write(f"/offsets/{estimate.cone}", ConeOffset(
            timestamp=stamp(ns), cone=estimate.cone, dx=estimate.offset[0], dy=estimate.offset[1],
            dz=estimate.offset[2], sdx=sd[0], sdy=sd[1], sdz=sd[2],
            covariance=np.asarray(cov).reshape(-1).tolist() if cov is not None else [], status=state,
            cameras=list(estimate.cameras)), ns)
        said = said_state(estimate)  # the state and why what it lacks is withheld, when known
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

    def close(self, offsets_csv: bytes | None = None, stopped: str = "") -> dict:
        """Remaining truth, the time span, the offsets CSV, then the manifest and summary. Returns the manifest.
        stopped: why the run ended before the end of its sources; the manifest (signed) and time_span say so."""
        if self.file.last_ns is not None:
            self._advance(self.file.last_ns)
            for t_ns, cone, v in self._truth[self._truth_next:]:
                self.file.write(f"/truth/{cone}", ConeOffset(timestamp=stamp(t_ns), cone=cone, dx=v[0], dy=v[1],
                                                             dz=v[2], sdx=0.0, sdy=0.0, sdz=0.0, status="truth"), t_ns)
            self.file.write("/log", log_message(self.file.last_ns, "archive closed"), self.file.last_ns)
        self.file.flush()
        if offsets_csv is not None:
            self.file.attach("offsets.csv", "text/csv", offsets_csv, log_time=self.file.last_ns or 0)
        extra = {f"frames_{k}": str(v) for k, v in sorted(self._frames.items())} | ({"stopped": stopped} if stopped
                                                                                    else {})
        self.file.metadata("time_span", time_span(self.file.first_ns, self.file.last_ns, extra))
        return self.file.close(**({"stopped": stopped} if stopped else {}))

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

    def close(self, stopped: str = "") -> None:
        """Attach the offsets CSV if it was written, then seal the file (stopped: the run's early end, said in it)."""
        csv = self.offsets_csv.read_bytes() if self.offsets_csv is not None and self.offsets_csv.is_file() else None
        self.archive.close(csv, stopped)
