"""Ground truth: the simulation log (truth.csv) and the true image corners per frame (truth_frames.csv).

truth.csv, one row per common-clock time at a uniform rate:
    time,
    topside_{x,y,z,rx,ry,rz}   T_jacket_topside (m, rotation vector in rad)
    jacket_{...}               T_jacket_jacket (identity: the jacket frame is the reference)
    vessel_{...}               T_jacket_vessel (midship waterline)
    camera_<name>_{...}        T_jacket_camera (OpenCV camera frame)
    marker_<id>_{...}          T_jacket_marker (OpenCV ArUco marker frame), where the marker truly is (survey_error)
    cone_<C>_{dx,dy,dz}        topside cone point minus jacket cone point (the cone tip), jacket frame
    pair_<j>_<t>_{dx,dy,dz}    topside marker centre minus its mated position, jacket frame

A camera's true clock offset is capture_time - pts of its rows in truth_frames.csv (the rig's time_offset is off by
the scenario's clock error); truth_rig.yaml is the rig with the true clocks and marker poses (benchmarks only).

truth_frames.csv, one row per visible marker per video frame (a frame with none has one row with
an empty marker_id):
    camera, frame_index (in the file), pts (s, PTS x time base), capture_time (common clock, s),
    marker_id, c0x, c0y, ..., c3x, c3y (corners TL TR BR BL, distorted pixels, OpenCV convention:
    pixel centres at integers), unoccluded (fraction of the black square not hidden)
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pandas as pd

from tracking.rig import Marker
from tracking.sim.scene import CONES
from tracking.sim.transforms import T_to_pose, apply, inv_T

POSE_FIELDS = ("x", "y", "z", "rx", "ry", "rz")
OFFSET_FIELDS = ("dx", "dy", "dz")
FRAME_COLUMNS = ["camera", "frame_index", "pts", "capture_time", "marker_id",
                 *[f"c{i}{a}" for i in range(4) for a in "xy"], "unoccluded"]
MIN_UNOCCLUDED = 0.01


def marker_corners(size: float) -> np.ndarray:
    """(4, 3) corners TL, TR, BR, BL in the marker frame."""
    h = size / 2
    return np.array([[-h, h, 0], [h, h, 0], [h, -h, 0], [-h, -h, 0]], float)


def truth_table(world, times: np.ndarray) -> pd.DataFrame:  # world: tracking.sim.world.World
    """The simulation log at the given common-clock times."""
    markers: list[Marker] = world.rig_markers()
    cams = [c.name for c in world.scenario.cameras]
    pairs = world.scenario.pairs
    by_id = {m.id: m for m in markers}
    rows = []
    for t in times:
        poses = world.body_poses(float(t))
        T_top = poses["topside"]
        row: list[float] = [float(t)]
        for T in (T_top, poses["jacket"], poses["vessel"]):
            row += T_to_pose(T).tolist()
        for name in cams:
            row += T_to_pose(world.motion.camera(name, float(t))).tolist()
        for m in markers:
            row += T_to_pose(poses[m.body] @ world.T_body_marker[m.id]).tolist()
        for c in CONES:
            tip = world.layout.cone_tip(c)
            row += (apply(T_top, tip[None])[0] - tip).tolist()
        for p in pairs:
            c = world.T_body_marker[by_id[p.topside_id].id][:3, 3]
            row += (apply(T_top, c[None])[0] - c).tolist()
        rows.append(row)
    cols = ["time"]
    for prefix in ("topside", "jacket", "vessel", *[f"camera_{n}" for n in cams], *[f"marker_{m.id}" for m in markers]):
        cols += [f"{prefix}_{f}" for f in POSE_FIELDS]
    for c in CONES:
        cols += [f"cone_{c}_{f}" for f in OFFSET_FIELDS]
    for p in pairs:
        cols += [f"pair_{p.jacket_id}_{p.topside_id}_{f}" for f in OFFSET_FIELDS]
    return pd.DataFrame(rows, columns=cols)


def frame_rows(world, cam, K: np.ndarray, dist: np.ndarray, T_jacket_camera: np.ndarray,
               poses: dict[str, np.ndarray], unoccluded: dict[int, float], frame_index: int, pts: float,
               capture_time: float) -> list[list]:
    """truth_frames rows of one frame: the true corners of every marker in view."""
    T_cj = inv_T(T_jacket_camera)
    rows = []
    corners = marker_corners(world.scenario.marker_size)
    for m in world.rig_markers():
        frac = unoccluded.get(m.id, 0.0)
        if frac < MIN_UNOCCLUDED:
            continue
        T_cm = T_cj @ poses[m.body] @ world.T_body_marker[m.id]
        P = apply(T_cm, corners)
        if (P[:, 2] <= 0).any():
            continue
        px, _ = cv2.projectPoints(P, np.zeros(3), np.zeros(3), K, dist)
        px = px.reshape(4, 2)
        if (px < -0.5).any() or (px[:, 0] > cam.width - 0.5).any() or (px[:, 1] > cam.height - 0.5).any():
            continue
        rows.append([cam.name, frame_index, pts, capture_time, m.id, *px.reshape(-1).tolist(), round(frac, 4)])
    if not rows:
        rows.append([cam.name, frame_index, pts, capture_time, None, *[None] * 8, None])
    return rows


def write_frames(path: Path, rows: list[list]) -> None:
    """Write truth_frames.csv."""
    df = pd.DataFrame(rows, columns=FRAME_COLUMNS)
    df["marker_id"] = df["marker_id"].astype("Int64")
    df.to_csv(path, index=False, float_format="%.6f")
