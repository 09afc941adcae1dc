"""Rendered marker edges lie where the analytic projection puts them (clean render, no weather)."""

from __future__ import annotations

import numpy as np
import pytest

from tests.sim.edges import edge_errors
from tracking.sim.builtins import builtin_scenario
from tracking.sim.render import CameraRenderer
from tracking.sim.transforms import inv_T
from tracking.sim.world import World

EDGE_TOLERANCE_PX = 0.05


@pytest.mark.parametrize(("camera", "t"), [("stern_A", 0.0), ("drone_A", 1.7), ("drone_D2", 0.4)])
def test_marker_edges_within_a_twentieth_of_a_pixel(camera: str, t: float) -> None:
    sc = builtin_scenario("config2-procedure5-clear")
    world = World(sc, 3.0, sc.seed)
    cam = next(c for c in sc.cameras if c.name == camera)
    renderer = CameraRenderer(cam, world.bodies, world.textures, sc.weather, world.light, sc.layout.sea_z)
    state = world.frame_state(cam, t, 0)
    img, unoccluded = renderer.render(state)
    gray = img.astype(np.float64).mean(axis=2)
    cone, face = cam.watch.split("/")
    pair = [m for m in world.rig_markers() if m.cone == cone and m.face == face]
    assert len(pair) == 2
    T_cj = inv_T(state.T_jacket_camera)
    for m in pair:
        assert unoccluded[m.id] == pytest.approx(1.0)
        T_cm = T_cj @ state.T_jacket_body[m.body] @ m.T_body_marker
        width_px = cam.K[0] * sc.marker_size / T_cm[2, 3]
        window = 3 if width_px > 60 else 1
        for errors in edge_errors(gray, T_cm, sc.marker_size, renderer.K, renderer.dist, window):
            assert len(errors) > 10
            assert abs(errors.mean()) < EDGE_TOLERANCE_PX, (m.id, errors.mean())
            assert np.sqrt((errors**2).mean()) < 2 * EDGE_TOLERANCE_PX


def test_lens_blur_spreads_the_marker_edges() -> None:
    """weather.lens_blur (σ 1 px) lowers the steepest marker edge at least twofold and keeps the marker's brightness."""
    sc = builtin_scenario("config2-procedure5-clear")
    world = World(sc, 3.0, sc.seed)
    cam = next(c for c in sc.cameras if c.name == "drone_A")
    state = world.frame_state(cam, 1.7, 0)
    marker = next(m for m in world.rig_markers() if f"{m.cone}/{m.face}" == cam.watch)
    T_cm = inv_T(state.T_jacket_camera) @ state.T_jacket_body[marker.body] @ marker.T_body_marker
    u, v = cam.K[0] * T_cm[0, 3] / T_cm[2, 3] + cam.K[2], cam.K[1] * T_cm[1, 3] / T_cm[2, 3] + cam.K[3]
    half = int(cam.K[0] * sc.marker_size / T_cm[2, 3])  # a marker's width either side of its centre
    rows, cols = slice(int(v) - half, int(v) + half), slice(int(u) - half, int(u) + half)
    crops = []
    for sigma in (0.0, 1.0):
        weather = sc.weather.model_copy(update={"lens_blur": sigma})
        renderer = CameraRenderer(cam, world.bodies, world.textures, weather, world.light, sc.layout.sea_z)
        crops.append(renderer.render(state)[0].astype(np.float64).mean(axis=2)[rows, cols])
    steepest = [np.abs(np.diff(c, axis=1)).max() for c in crops]
    assert steepest[0] > 2 * steepest[1]
    assert abs(crops[0].mean() - crops[1].mean()) < 1.0
