"""Checks of a scenario's camera placement: distances and whether each camera sees its whole pair."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from tracking.sim.command import effective_duration
from tracking.sim.render import CameraRenderer
from tracking.sim.scenario import Scenario
from tracking.sim.transforms import apply, inv_T
from tracking.sim.truth import marker_corners
from tracking.sim.world import World

IMAGE_MARGIN_PX = 2.0
FULLY_VISIBLE = 0.99


@dataclass(frozen=True)
class CameraCheck:
    """How one camera sees the pair it watches over a run."""

    camera: str
    watch: str
    min_distance: float  # m, camera to the nearer marker of its pair
    max_distance: float
    seen_fraction: float  # of sampled times with both markers fully in view


def check_cameras(scenario: Scenario, step: float = 5.0, duration: float | None = None) -> list[CameraCheck]:
    """Sample the run every `step` seconds and check every camera that has a `watch`."""
    total = effective_duration(scenario, duration)
    world = World(scenario, total, scenario.seed)
    times = np.unique(np.r_[np.arange(0.0, total, step), total])
    markers = {(m.cone, m.face, m.body): m for m in world.rig_markers()}
    out = []
    for cam in scenario.cameras:
        if not cam.watch:
            continue
        cone, face = cam.watch.split("/")
        pair = [markers[(cone, face, "jacket")], markers[(cone, face, "topside")]]
        r = CameraRenderer(cam, world.bodies, world.textures, scenario.weather, world.light, scenario.layout.sea_z)
        dists, seen = [], 0
        for t in times:
            state = world.frame_state(cam, float(t), 0)
            frac = r.visibility(state)
            T_cj = inv_T(state.T_jacket_camera)
            ok = True
            for m in pair:
                T_cm = T_cj @ state.T_jacket_body[m.body] @ m.T_body_marker
                dists.append(float(np.linalg.norm(T_cm[:3, 3])))
                P = apply(T_cm, marker_corners(scenario.marker_size))
                px, _ = cv2.projectPoints(P, np.zeros(3), np.zeros(3), r.K, r.dist)
                px = px.reshape(-1, 2)
                inside = (px.min() >= IMAGE_MARGIN_PX and (px[:, 0] <= cam.width - 1 - IMAGE_MARGIN_PX).all()
                          and (px[:, 1] <= cam.height - 1 - IMAGE_MARGIN_PX).all())
                ok &= bool(inside and (P[:, 2] > 0).all() and frac.get(m.id, 0.0) >= FULLY_VISIBLE)
            seen += ok
        out.append(CameraCheck(cam.name, cam.watch, min(dists), max(dists), seen / len(times)))
    return out
