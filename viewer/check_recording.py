"""The installation as `topside check` understood it, as a Rerun recording (`topside check --rrd`).

Entity layout (viewer/recording.py's and viewer/installation.py's, the jacket frame the world):
    world/jacket/markers/<id>, world/jacket/...   the rig's markers and the installation (static)
    world/topside                                 where the fusion filter has the topside after the check's seconds
    world/cameras/<camera>                        each camera placed by its own markers, its frustum, and its first
                                                  frame below it (image)
    world/estimated/<camera>                      the markers that camera sees, where it puts them (red: named by a
                                                  disagreement with the rig, green: agreeing)
    check                                         the findings and each cone's verdict (markdown)
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import rerun as rr

from viewer.installation import log_installation
from viewer.recording import APP_ID, log_frustum, log_image, log_marker_frames, log_rig, set_capture_time

if TYPE_CHECKING:
    from tracking.check import CameraCheck, CheckReport

WRONG_COLOR = (230, 40, 40)  # a marker a disagreement names
AGREEING_COLOR = (40, 200, 80)


def record_check(report: CheckReport, path: Path) -> None:
    """Write the check's recording to path: the rig's markers and cones, the topside where the filter has it, every
    camera placed by its own markers with its first frame and the markers it sees, and the findings."""
    rec = rr.RecordingStream(APP_ID)
    rec.save(str(path))
    log_rig(rec, report.rig)
    log_installation(rec, report.rig)
    if report.T_jacket_topside is not None:
        _log_pose(rec, "world/topside", report.T_jacket_topside)
    wrong = set(report.disagreeing_markers)
    for c in report.cameras:
        _log_camera(rec, c, report.rig.marker_size, wrong)
    rr.log("check", rr.TextDocument(check_markdown(report), media_type=rr.MediaType.MARKDOWN), static=True,
           recording=rec)
    rec.flush(timeout_sec=1e38)
    rec.disconnect()


def _log_pose(rec: rr.RecordingStream, path: str, T: np.ndarray) -> None:
    """A static (4, 4) pose at path."""
    rr.log(path, rr.Transform3D(translation=T[:3, 3], mat3x3=T[:3, :3]), static=True, recording=rec)


def _log_camera(rec: rr.RecordingStream, c: CameraCheck, marker_size: float, wrong: set[int]) -> None:
    """One camera where the check placed it (nothing when it was not placed): its frustum, the markers it sees and
    its first frame."""
    if c.T_jacket_camera is None or c.model is None:
        return
    base = f"world/cameras/{c.camera}"
    _log_pose(rec, base, c.T_jacket_camera)
    log_frustum(rec, base, c.model)
    if c.T_jacket_markers:
        log_marker_frames(rec, f"world/estimated/{c.camera}", marker_size, c.T_jacket_markers,
                          [WRONG_COLOR if i in wrong else AGREEING_COLOR for i in c.T_jacket_markers])
    if c.first_frame is not None and c.first_frame.gray is not None:
        set_capture_time(rec, c.first_frame.time)
        log_image(rec, f"{base}/image", c.first_frame)


def check_markdown(report: CheckReport) -> str:
    """The check's findings (or READY) and a table of the cones' verdicts, as markdown."""
    lines = ["# topside check", "", *(f"- {line}" for line in report.problems() or ["READY"]), "", "| cone | verdict |",
             "|---|---|", *(f"| {c.cone} | {c.verdict}: {c.reason} |" for c in report.cones)]
    return "\n".join(lines)
