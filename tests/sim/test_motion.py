"""Motion: the sea state, the crane's speed, the hanging topside, drone jitter, stern cameras riding the vessel."""

from __future__ import annotations

import numpy as np
import pytest

from tracking.sim.builtins import builtin_scenario
from tracking.sim.motion import DT, CranePath, Motion, jonswap, vessel_motion
from tracking.sim.scenario import SeaSpec
from tracking.sim.transforms import T_to_pose


def test_jonswap_has_the_asked_significant_height() -> None:
    w = np.linspace(0.2, 4.0, 4000)
    s = jonswap(w, 1.0, 8.0, 3.3)
    assert 4 * np.sqrt(np.trapezoid(s, w)) == pytest.approx(1.0, rel=1e-6)
    assert w[np.argmax(s)] == pytest.approx(2 * np.pi / 8.0, rel=0.02)


def test_vessel_motion_is_small_for_a_crane_vessel() -> None:
    t = np.arange(0, 600, 0.1)
    m = vessel_motion(SeaSpec(), t, np.random.default_rng(0))
    std = m.std(axis=0)
    assert 0.01 < std[2] < 0.1  # heave, m
    assert np.degrees(std[3:5]).max() < 0.2  # roll and pitch, degrees


def test_crane_speed_and_smooth_start() -> None:
    path = CranePath.from_spec(builtin_scenario("config1-procedure1").motion)
    t = np.arange(0, path.length, DT)
    p = path.at(t)
    v = np.linalg.norm(np.diff(p, axis=0), axis=1) / DT
    assert v.max() == pytest.approx(0.25, rel=0.01)
    assert np.abs(np.diff(v)).max() / DT < 0.05  # m/s^2: no jerk of the load
    assert p[-1] == pytest.approx([0, 0, 2.0])


def test_waves_move_topside_and_stern_cameras() -> None:
    sc = builtin_scenario("config1-procedure3")
    motion = Motion(sc, 60.0, sc.seed)
    top = np.array([T_to_pose(motion.topside(t)) for t in np.arange(0, 60, 0.5)])
    assert 0.005 < top[:, 0].std() < 0.5 and 0.005 < top[:, 2].std() < 0.3
    cam = np.array([T_to_pose(motion.camera("stern1", t)) for t in np.arange(0, 60, 0.5)])
    assert cam[:, 2].std() > 0.005


def test_drones_jitter_more_in_wind() -> None:
    sc = builtin_scenario("config2-procedure5")
    calm = Motion(sc.model_copy(update={"motion": sc.motion.model_copy(update={"wind_knots": 0.0})}), 60, 1)
    windy = Motion(sc.model_copy(update={"motion": sc.motion.model_copy(update={"wind_knots": 30.0})}), 60, 1)
    spread = [np.array([motion.camera("drone_A", t)[:3, 3] for t in np.arange(0, 60, 0.25)]).std(axis=0).max()
              for motion in (calm, windy)]
    assert 0.01 < spread[0] < spread[1] < 1.0
