"""Random installations: drawn from a seed, within the ranges they promise, seen by their cameras, rendered as any
scenario (topside simulate --random, random-SEED, random: SEED)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from tracking.errors import InputError
from tracking.rig import FACE_NORMALS, load_rig
from tracking.sim.installations import DISTANCE_M, MAX_ANGLE_DEG, MAX_TILT_DEG, random_scenario
from tracking.sim.motion import camera_rest_pose
from tracking.sim.scenario import dump_scenario, load_scenario
from tracking.sim.transforms import apply, inv_T
from tracking.sim.world import World

SEEDS = range(8)
REPO = Path(__file__).resolve().parents[2]


def run_cli(args: list[str]) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "tracking.cli", *args], capture_output=True, text=True, cwd=REPO)


@pytest.fixture(scope="module")
def drawn() -> dict[int, object]:
    return {seed: random_scenario(seed) for seed in SEEDS}


def test_the_same_seed_draws_the_same_installation(drawn: dict) -> None:
    for seed in SEEDS[:3]:
        assert dump_scenario(random_scenario(seed)) == dump_scenario(drawn[seed])
    assert len({dump_scenario(sc) for sc in drawn.values()}) == len(SEEDS)


def test_cameras_stand_where_the_ranges_say_and_see_their_pair(drawn: dict) -> None:
    kinds, angles = set(), []
    for sc in drawn.values():
        assert 1 <= len(sc.cameras) <= 6 and 1 <= len({p.cone for p in sc.pairs}) <= 4
        assert 20 <= sc.duration <= 30
        world = World(sc, sc.duration, sc.seed)
        for cam in sc.cameras:
            kinds.add(cam.kind)
            cone, face = cam.watch.split("/")
            pair = next(p for p in sc.pairs if (p.cone, p.face) == (cone, face))
            jacket = world.T_body_marker[pair.jacket_id]
            line = np.array(cam.position) - jacket[:3, 3]
            distance = float(np.linalg.norm(line))
            assert DISTANCE_M[0] - 0.5 <= distance <= DISTANCE_M[1] + 0.5
            angle = float(np.degrees(np.arccos(line @ np.array(FACE_NORMALS[face]) / distance)))
            assert angle <= MAX_ANGLE_DEG + 0.5
            angles.append(angle)
            corners = apply(inv_T(camera_rest_pose(cam)) @ jacket, np.array([[-0.5, 0.5, 0], [0.5, -0.5, 0]]))
            assert (corners[:, 2] > 0).all()  # in front of the camera
    assert {"stern", "drone"} <= kinds
    assert min(angles) < 10.0  # square-on views are drawn


def test_markers_are_off_plumb_as_the_rig_states(drawn: dict, tmp_path: Path) -> None:
    sc = drawn[0]
    world = World(sc, sc.duration, sc.seed)
    for marker in world.true_markers():
        tilt = np.degrees(np.arccos(np.clip(marker.R_body_marker[:, 2] @ np.array(FACE_NORMALS[marker.face]), -1, 1)))
        assert tilt <= MAX_TILT_DEG + 1e-6
    stated = {m.id: m.R_body_marker for m in world.rig_markers()}
    assert all(np.allclose(stated[m.id], m.R_body_marker, atol=1e-8) for m in world.true_markers())


def test_a_scenario_file_draws_with_random_and_overrides(tmp_path: Path) -> None:
    path = tmp_path / "s.yaml"
    path.write_text("random: 3\nduration: 5\nweather: {fog: 0.2}\n")
    sc = load_scenario(path)
    base = random_scenario(3)
    assert (sc.duration, sc.weather.fog, sc.cameras) == (5.0, 0.2, base.cameras)
    assert load_scenario("random-3") == base
    path.write_text("random: -1\n")
    with pytest.raises(InputError, match="random"):
        load_scenario(path)


def test_simulate_random_writes_a_rig_the_tracker_reads(tmp_path: Path) -> None:
    out = tmp_path / "r"
    result = run_cli(["simulate", "--random", "2", "-o", str(out), "--duration", "1"])
    assert result.returncode == 0, result.stderr
    rig = load_rig(out / "rig.yaml")
    sc = yaml.safe_load((out / "scenario.yaml").read_text())
    assert sc["name"] == "random-2" and {c.name for c in rig.cameras} == {c["name"] for c in sc["cameras"]}
    mounts = {c["name"]: {"stern": "vessel", "fixed": "fixed", "drone": "drone"}[c["kind"]] for c in sc["cameras"]}
    assert {c.name: c.mount for c in rig.cameras} == mounts
    assert all((out / c.source).is_file() for c in rig.cameras)
    both = run_cli(["simulate", "random-2", "--random", "2", "-o", str(tmp_path / "x")])
    assert both.returncode == 2 and "exactly one" in both.stderr


def test_motion_blur_is_drawn_while_a_marker_crosses_a_cameras_plane() -> None:
    """random-3001: a topside marker passes the plane of fixed2's lens during an exposure (in front at its start,
    not at its end); the blur is the motion of the markers in front all through it (it stopped the render)."""
    from tracking.sim.command import plan_frames

    sc = random_scenario(3001)
    world = World(sc, float(sc.duration), sc.seed)
    (i, cam), = [(i, c) for i, c in enumerate(sc.cameras) if c.name == "fixed2"]
    plan = plan_frames(cam, i, float(sc.duration), sc.seed)
    cam = cam.model_copy(update={"time_offset": plan.time_offset})
    blur = [world.blur(cam, float(t)) for t in plan.capture_times if 12.5 < t < 13.2]
    assert len(blur) >= 8 and np.isfinite(blur).all()
