"""A recording session: the tracker's stream of results in, a Rerun .rrd file out."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np
import pandas as pd
import rerun as rr

from tracking.camera import CameraModel, load_camera
from tracking.evaluate import truth_at
from tracking.filtering import ConeEstimate
from tracking.pipeline import FrameResult
from tracking.rig import Rig
from viewer.archive import ArchiveInputs
from viewer.blueprint import analysis_blueprint
from viewer.recording import (
    APP_ID,
    JPEG_QUALITY,
    StatusBoard,
    log_archive_inputs,
    log_camera_model,
    log_error,
    log_estimate,
    log_estimate_record,
    log_frame,
    log_frame_ages,
    log_rig,
    log_series_styles,
    log_topside_pose,
    log_truth,
)


class Recorder:
    """Logs frames and estimates of one tracked installation into a Rerun recording."""

    def __init__(self, rig: Rig, rrd: Path | None = None, truth: pd.DataFrame | None = None,
                 show_rejected: bool = False, recording_id: str | None = None,
                 jpeg_quality: int = JPEG_QUALITY, options: Mapping[str, str] | None = None) -> None:
        self.rig = rig
        self.truth = truth
        self.show_rejected = show_rejected
        self.jpeg_quality = jpeg_quality
        self.rec = rr.RecordingStream(APP_ID, recording_id=recording_id)
        self.cameras: dict[str, CameraModel] = {c.name: load_camera(rig.resolve(c.calibration)) for c in rig.cameras}
        self.status = StatusBoard()
        self._truth_cones = {c[len("cone_"):-len("_dx")] for c in truth.columns
                             if c.startswith("cone_") and c.endswith("_dx")} if truth is not None else set()
        self._last_time = 0.0
        self._last_capture: dict[str, float] = {}
        if rrd is not None:
            Path(rrd).parent.mkdir(parents=True, exist_ok=True)
            self.rec.save(rrd, default_blueprint=analysis_blueprint(rig, truth is not None))
        cones = sorted({p.cone for p in rig.all_pairs()} | set(rig.cones))
        log_rig(self.rec, rig)
        log_archive_inputs(self.rec, ArchiveInputs.from_rig(rig, options or {}).to_json())
        for name, cam in self.cameras.items():
            log_camera_model(self.rec, name, cam)
        log_series_styles(self.rec, cones, truth is not None)
        if truth is not None:
            log_truth(self.rec, truth, cones)

    def on_frame(self, result: FrameResult) -> None:
        """Log one processed frame."""
        log_frame(self.rec, self.rig, self.cameras[result.camera], result, self.show_rejected, self.jpeg_quality)
        self.status.frames[result.camera] = self.status.frames.get(result.camera, 0) + 1
        self.status.markers[result.camera] = self.status.markers.get(result.camera, 0) + len(result.poses)
        self._last_time = max(self._last_time, result.time)
        self._last_capture[result.camera] = result.time
        log_frame_ages(self.rec, result.time, self._last_capture)

    def on_estimate(self, estimate: ConeEstimate) -> None:
        """Log one cone estimate, its error against the truth, and the status panel when due."""
        log_estimate(self.rec, estimate)
        log_estimate_record(self.rec, estimate)
        if self.truth is not None and estimate.cone in self._truth_cones:
            log_error(self.rec, estimate, truth_at(self.truth, estimate.cone, np.array([estimate.time]))[0])
        self.status.latest[estimate.cone] = estimate
        log_topside_pose(self.rec, self.status.latest)
        self.status.log_if_due(self.rec, estimate.time)

    def close(self) -> None:
        """Final status and flush to disk."""
        self.status.log_if_due(self.rec, self._last_time, force=True)
        self.rec.flush()
        self.rec.disconnect()
