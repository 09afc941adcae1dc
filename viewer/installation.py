"""The installation in 3-D, drawn from the rig: jacket legs, stabbing cones, topside legs and deck, printed markers.

Entity layout (added beside viewer/recording.py's; the jacket frame is the world):
    world/jacket/legs                    jacket legs below their cones (static)
    world/jacket/frame                   the top frame's beams between neighbouring legs (static)
    world/jacket/stabbing_cones          one cone mesh per stabbing cone (static)
    world/jacket/markers/<id>/face       the printed marker: its ArUco pattern and quiet zone as a texture (static)
    world/topside/legs, world/topside/deck, world/topside/markers/<id>/face
                                         the topside in its own frame (static): it moves with world/topside
    world/truth/topside                  the topside at its true pose (the truth log's cone offsets), a faint ghost
    world/concentricity/<cone>           the line from the jacket's cone tip to the topside's, coloured by tolerance
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import cv2
import numpy as np
import pandas as pd
import rerun as rr

from tracking.estimate import ConeEstimate
from tracking.geometry import quaternions_xyzw
from tracking.rig import (
    DEFAULT_CONE_HEIGHT_M,
    DEFAULT_LEG_DIAMETER_M,
    DEFAULT_LEG_LENGTH_M,
    DEFAULT_TOPSIDE_LEG_LENGTH_M,
    PLATE_STANDOFF_M,
    Rig,
)
from viewer.recording import AXES, TOLERANCE_M, concentricity, time_column, topside_pose

JACKET_STEEL = (230, 170, 40)  # the jacket's yellow paint
CONE_STEEL = (190, 80, 40)
TOPSIDE_STEEL = (120, 150, 175, 150)  # see-through: the cone and its concentricity line inside show
DECK_COLOR = (90, 110, 130)
GHOST_COLOR = (255, 255, 255, 60)  # the true pose: a faint white fill with its outline
WITHIN_COLOR = (40, 200, 80)
BEYOND_COLOR = (230, 40, 40)
CONE_BASE_RATIO = 0.7  # the cone's base diameter over its leg's (1.4 m on a 2.0 m leg in the simulator)
CONE_SEGMENTS = 32
BEAM_DIAMETER_M = 1.0
BEAM_DROP_M = 3.0  # the top frame's beams this far below the leg tops
DECK_MARGIN_M = 8.0  # the deck reaches this far beyond the outermost legs
DECK_DEPTH_M = 6.0
QUIET_CELLS = 1  # white cells printed around the marker's black square
TEXTURE_CELL_PX = 16
FACE_LIFT_M = 0.01  # the printed face sits this far in front of its box outline, so neither hides the other
CONCENTRICITY_RADIUS_M = 0.08
UP = np.array([0.0, 0.0, 1.0])
GHOST_PATH = "world/truth/topside"
CONCENTRICITY_PATH = "world/concentricity"


@dataclass(frozen=True)
class Dimensions:
    """What the drawing needs of the installation, m: the rig's optional fields, or their defaults."""

    leg_diameter: float
    leg_length: float
    topside_leg_length: float
    cone_height: float


def dimensions(rig: Rig) -> Dimensions:
    """The rig's drawing fields; an unset leg diameter from its markers (plates PLATE_STANDOFF_M proud of the leg)."""
    diameter = rig.leg_diameter
    if diameter is None:
        radii = [np.hypot(*(np.array(m.center[:2]) - np.array(rig.cones[m.cone][:2]))) - PLATE_STANDOFF_M
                 for m in rig.markers if m.cone in rig.cones]
        radii = [r for r in radii if r > 0]
        diameter = 2 * float(np.median(radii)) if radii else DEFAULT_LEG_DIAMETER_M
    return Dimensions(diameter, rig.leg_length or DEFAULT_LEG_LENGTH_M,
                      rig.topside_leg_length or DEFAULT_TOPSIDE_LEG_LENGTH_M, rig.cone_height or DEFAULT_CONE_HEIGHT_M)


def cone_tips(rig: Rig) -> dict[str, np.ndarray]:
    """Each cone's tip (3,): the rig's, or (no tip given) below its jacket markers by half a cone."""
    tips = {c: np.array(p, dtype=float) for c, p in rig.cones.items()}
    for cone in sorted({m.cone for m in rig.markers} - set(tips)):
        centres = np.array([m.center for m in rig.markers if m.cone == cone and m.body == "jacket"]
                           or [m.center for m in rig.markers if m.cone == cone], dtype=float)
        tips[cone] = centres.mean(axis=0)
    return tips


def cone_mesh(tip: np.ndarray, height: float, radius: float, segments: int = CONE_SEGMENTS
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A cone's sides standing on its base circle: (vertices (2N, 3), triangles (N, 3), normals (2N, 3))."""
    a = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    ring = np.column_stack([np.cos(a), np.sin(a), np.zeros(segments)])
    slope = radius / height
    normals = ring + np.array([0.0, 0.0, slope])  # outward and up, as the sides lean
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    base = tip + ring * radius - UP * height
    apex = np.repeat(tip[None], segments, axis=0)  # one apex per side, each with its side's normal
    k = np.arange(segments)
    triangles = np.column_stack([k, (k + 1) % segments, segments + k])
    return np.vstack([base, apex]), triangles, np.vstack([normals, normals])


def marker_texture(dictionary: str, marker_id: int) -> np.ndarray:
    """The printed marker (RGB): its black square with the ArUco pattern, in QUIET_CELLS white cells."""
    aruco = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, dictionary))
    cells = aruco.markerSize + 2  # the code and its black border
    square = cv2.aruco.generateImageMarker(aruco, marker_id, cells * TEXTURE_CELL_PX)
    pad = QUIET_CELLS * TEXTURE_CELL_PX
    printed = cv2.copyMakeBorder(square, pad, pad, pad, pad, cv2.BORDER_CONSTANT, value=255)
    return np.repeat(printed[:, :, None], 3, axis=2)


def log_marker_face(rec: rr.RecordingStream, path: str, rig: Rig, marker_id: int) -> None:
    """A marker's printed face in its own frame (x right, y up, z out of the face), seen from the front only."""
    aruco = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, rig.dictionary))
    h = rig.marker_size / 2 * (1 + 2 * QUIET_CELLS / (aruco.markerSize + 2))
    rr.log(path, rr.Mesh3D(
        vertex_positions=[[-h, h, FACE_LIFT_M], [h, h, FACE_LIFT_M], [h, -h, FACE_LIFT_M], [-h, -h, FACE_LIFT_M]],
        triangle_indices=[[0, 2, 1], [0, 3, 2]], vertex_normals=[[0, 0, 1]] * 4,
        vertex_texcoords=[[0, 0], [1, 0], [1, 1], [0, 1]],  # the image's top-left at the marker's top-left
        albedo_texture=marker_texture(rig.dictionary, marker_id), face_rendering=rr.components.MeshFaceRendering.Front),
        static=True, recording=rec)


def rotation_z_to(direction: np.ndarray) -> np.ndarray:
    """Quaternion x y z w turning +z onto a direction (3,)."""
    d = np.asarray(direction, dtype=float) / np.linalg.norm(direction)
    axis = np.cross([0.0, 0.0, 1.0], d)
    s, c = np.linalg.norm(axis), d[2]
    if s < 1e-12:
        return np.array([0.0, 0.0, 0.0, 1.0]) if c > 0 else np.array([1.0, 0.0, 0.0, 0.0])
    angle = np.arctan2(s, c)
    return np.concatenate([axis / s * np.sin(angle / 2), [np.cos(angle / 2)]])


def ring_order(points: Mapping[str, np.ndarray]) -> list[str]:
    """The cones in order around their centroid (the jacket's outline, for the top frame)."""
    xy = np.array([p[:2] for p in points.values()])
    centre = xy.mean(axis=0)
    angles = np.arctan2(xy[:, 1] - centre[1], xy[:, 0] - centre[0])
    return [list(points)[i] for i in np.argsort(angles)]


def topside_legs(tips: Mapping[str, np.ndarray], dims: Dimensions, color: tuple[int, ...],
                 fill: rr.components.FillMode = rr.components.FillMode.Solid) -> rr.Cylinders3D:
    """The topside's legs in its own frame: from the cone bases (where they rest when mated) up to the deck."""
    centres = [tip + UP * (dims.topside_leg_length / 2 - dims.cone_height) for tip in tips.values()]
    return rr.Cylinders3D(lengths=[dims.topside_leg_length] * len(tips), radii=dims.leg_diameter / 2,
                          centers=centres, colors=[color], fill_mode=fill)


def topside_deck(tips: Mapping[str, np.ndarray], dims: Dimensions, color: tuple[int, ...],
                 fill: rr.components.FillMode = rr.components.FillMode.Solid) -> rr.Boxes3D | None:
    """The deck on the topside's legs, DECK_MARGIN_M beyond them; None with fewer than three cones."""
    if len(tips) < 3:
        return None
    p = np.array(list(tips.values()))
    margin = np.array([DECK_MARGIN_M, DECK_MARGIN_M, 0.0])
    low, high = p.min(axis=0) - margin, p.max(axis=0) + margin
    bottom = p[:, 2].max() - dims.cone_height + dims.topside_leg_length
    return rr.Boxes3D(mins=[[low[0], low[1], bottom]], sizes=[[high[0] - low[0], high[1] - low[1], DECK_DEPTH_M]],
                      colors=[color], fill_mode=fill)


def log_installation(rec: rr.RecordingStream, rig: Rig) -> None:
    """Static geometry from the rig: jacket legs, top frame and stabbing cones; topside legs and deck (in the
    topside's frame); every marker's printed face on its leg."""
    tips = cone_tips(rig)
    dims = dimensions(rig)
    if tips:
        leg_top = {c: tip - UP * dims.cone_height for c, tip in tips.items()}
        rr.log("world/jacket/legs", rr.Cylinders3D(
            lengths=[dims.leg_length] * len(tips), radii=dims.leg_diameter / 2,
            centers=[p - UP * (dims.leg_length / 2) for p in leg_top.values()], colors=[JACKET_STEEL],
            fill_mode=rr.components.FillMode.Solid), static=True, recording=rec)
        meshes = [cone_mesh(tip, dims.cone_height, CONE_BASE_RATIO * dims.leg_diameter / 2) for tip in tips.values()]
        n = len(meshes[0][0])
        rr.log("world/jacket/stabbing_cones", rr.Mesh3D(
            vertex_positions=np.vstack([m[0] for m in meshes]),
            triangle_indices=np.vstack([m[1] + k * n for k, m in enumerate(meshes)]),
            vertex_normals=np.vstack([m[2] for m in meshes]), albedo_factor=CONE_STEEL), static=True, recording=rec)
        if len(tips) >= 3:
            order = ring_order(leg_top)
            ends = [(leg_top[a], leg_top[b]) for a, b in zip(order, order[1:] + order[:1], strict=True)]
            rr.log("world/jacket/frame", rr.Cylinders3D(
                lengths=[np.linalg.norm(b - a) - dims.leg_diameter for a, b in ends], radii=BEAM_DIAMETER_M / 2,
                centers=[(a + b) / 2 - UP * BEAM_DROP_M for a, b in ends],
                quaternions=[rotation_z_to(b - a) for a, b in ends],
                colors=[JACKET_STEEL], fill_mode=rr.components.FillMode.Solid), static=True, recording=rec)
        rr.log("world/topside/legs", topside_legs(tips, dims, TOPSIDE_STEEL), static=True, recording=rec)
        deck = topside_deck(tips, dims, DECK_COLOR)
        if deck is not None:
            rr.log("world/topside/deck", deck, static=True, recording=rec)
    for marker in rig.markers:
        body = "jacket" if marker.body == "jacket" else "topside"
        log_marker_face(rec, f"world/{body}/markers/{marker.id}/face", rig, marker.id)


def log_true_topside(rec: rr.RecordingStream, rig: Rig, times: np.ndarray, T_jacket_topside: np.ndarray) -> None:
    """The topside's true pose over time, (N, 4, 4) at (N,) capture times, as a ghost of its legs and deck."""
    tips = cone_tips(rig)
    if not len(times) or not tips:
        return
    dims = dimensions(rig)
    fill = rr.components.FillMode.TransparentFillMajorWireframe
    rr.log(f"{GHOST_PATH}/legs", topside_legs(tips, dims, GHOST_COLOR, fill), static=True, recording=rec)
    deck = topside_deck(tips, dims, GHOST_COLOR, fill)
    if deck is not None:
        rr.log(f"{GHOST_PATH}/deck", deck, static=True, recording=rec)
    rr.send_columns(GHOST_PATH, indexes=[time_column(times)],
                    columns=rr.Transform3D.columns(translation=T_jacket_topside[:, :3, 3],
                                                   quaternion=quaternions_xyzw(T_jacket_topside[:, :3, :3])),
                    recording=rec)


def true_topside_poses(truth: pd.DataFrame, points: Mapping[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """(N,) times and (N, 4, 4) T_jacket_topside fitted to the truth log's cone offsets (rows with every cone)."""
    cones = [c for c in points if all(f"cone_{c}_{a}" in truth.columns for a in AXES)]
    if not cones:
        return np.zeros(0), np.zeros((0, 4, 4))
    values = {c: truth[[f"cone_{c}_{a}" for a in AXES]].to_numpy(dtype=float) for c in cones}
    ok = np.all([np.isfinite(v).all(axis=1) for v in values.values()], axis=0)
    times = truth["time"].to_numpy(dtype=float)[ok]
    poses = [topside_pose({c: points[c] for c in cones}, {c: values[c][i] for c in cones}) for i in np.flatnonzero(ok)]
    return times, np.array(poses).reshape(-1, 4, 4)


def concentricity_label(cone: str, estimate: ConeEstimate) -> str:
    """The line's label: the cone, its concentricity and (where the estimator has one) its 2σ, in mm."""
    r = concentricity(estimate.offset)
    if estimate.covariance is None:
        return f"{cone} {r * 1000:.0f} mm (σ unknown)"
    d = np.asarray(estimate.offset[:2], dtype=float)
    u = d / r if r > 0 else np.array([1.0, 0.0])
    sigma = float(np.sqrt(max(u @ estimate.covariance[:2, :2] @ u, 0.0)))
    return f"{cone} {r * 1000:.0f} ± {2 * sigma * 1000:.0f} mm (2σ)"


def log_concentricity(rec: rr.RecordingStream, points: Mapping[str, np.ndarray], estimates: list[ConeEstimate]
                      ) -> None:
    """Each cone's line from its point on the jacket (the tip: tracking.estimator.cone_points) to the topside's (point +
    offset) over time, columnar: green within the tolerance, red beyond; estimates without every axis left out."""
    for cone in sorted({e.cone for e in estimates} & set(points)):
        batch = [e for e in estimates if e.cone == cone and np.all(np.isfinite(e.offset))]
        if not batch:
            continue
        tip = np.asarray(points[cone], dtype=float)
        rr.send_columns(f"{CONCENTRICITY_PATH}/{cone}", indexes=[time_column(np.array([e.time for e in batch]))],
                        columns=rr.LineStrips3D.columns(
                            strips=[np.array([tip, tip + e.offset]) for e in batch],
                            colors=[WITHIN_COLOR if concentricity(e.offset) <= TOLERANCE_M else BEYOND_COLOR
                                    for e in batch],
                            radii=[CONCENTRICITY_RADIUS_M] * len(batch),
                            labels=[concentricity_label(cone, e) for e in batch]),
                        recording=rec)
