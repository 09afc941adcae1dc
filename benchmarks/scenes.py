"""Simulated scenes for the speed benchmarks: a built-in scenario at a frame rate and image size, cached.

Another image size keeps the cameras' pixel pitch scaled by the height ratio (1920×1080 from 920×600: ×1.8),
so markers are that much larger in pixels; the extra width is added evenly on both sides.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from tracking.sim.scenario import Scenario

REPO = Path(__file__).resolve().parents[1]
CACHE = REPO / "benchmarks" / ".cache"
FPS = 15.0


def exact_calibrations(scene: Path) -> Path:
    """A cached render, its calibrations stating their error as the simulator's do now (0 px: they are the true
    cameras). One made before would state none, which the tracker takes as camera.UNSTATED_RMS_PX: numbers that
    depend on how old a cache is."""
    from tracking.camera import RMS_KEY

    for path in (scene / "calibration").glob("*.yaml"):
        text = path.read_text()
        if RMS_KEY not in text:
            partial = path.with_name(f"{path.stem}.partial{path.suffix}")
            partial.write_text(f"{text.rstrip()}\n{RMS_KEY}: 0.\n")
            partial.replace(path)
    return scene


def render_scene(scenario: str, size: tuple[int, int], seconds: float, fps: float = FPS) -> Path:
    """The scenario rendered at one size and frame rate for `seconds`, into the cache (once)."""
    from tracking.sim.scenario import load_scenario

    width, height = size
    out = CACHE / f"scene-{scenario}-{width}x{height}-{fps:g}fps-{seconds:g}s"
    if (out / "truth_frames.csv").is_file():
        return exact_calibrations(out)
    return _render(load_scenario(scenario), out, size, seconds, fps)


LONG_NAME = "long-8cam"
LONG_MOVE_DWELL_S = 30.0  # the long installation's topside rests this long between moves (a real lift waits on
# the weather, the riggers and the crane for minutes; moves take 20-30 s)
LONG_TWIN_SHIFT_M = (-6.0, 4.0, -4.0, 4.0)  # the second camera of each pair sits this far along x (stern) or
# sideways (drones) from the first, looking at the same point: 8 cameras, every pair seen twice


def long_installation(seconds: float) -> Scenario:
    """A long installation with eight cameras: configuration 2's (`config2-procedure5-weather`) and a twin beside
    each, the topside going 5 m ahead and back in a 1 m sea, resting LONG_MOVE_DWELL_S between moves, for
    `seconds`."""
    from tracking.sim.builtins import builtin_scenario
    from tracking.sim.scenario import SeaSpec

    base = builtin_scenario("config2-procedure5-weather")
    assert base is not None
    cams = list(base.cameras)
    for cam, shift in zip(base.cameras, LONG_TWIN_SHIFT_M, strict=True):
        pos = np.array(cam.position, float)
        along = np.array([1.0, 0.0, 0.0]) if cam.kind == "stern" else np.cross(
            np.array(cam.look_at) - pos, [0.0, 0.0, 1.0])
        pos = pos + shift * along / np.linalg.norm(along) + np.array([0.0, 0.0, 1.0 if cam.kind == "drone" else 0.0])
        cams.append(cam.model_copy(update={"name": f"{cam.name}_b", "position": pos.round(3).tolist()}))
    moves = max(2, int(seconds // (LONG_MOVE_DWELL_S + 25.0)) + 2)
    waypoints = [[0.0, -5.0 if k % 2 == 0 else 0.0] for k in range(moves)]
    motion = base.motion.model_copy(update={"waypoints": waypoints, "dwell": LONG_MOVE_DWELL_S, "sea": SeaSpec()})
    return base.model_copy(update={"name": LONG_NAME, "cameras": cams, "motion": motion,
                                   "description": "configuration 2 and a twin of each camera, 5 m ahead and back "
                                                  "in a 1 m sea, for as long as asked"})


def render_long(seconds: float, size: tuple[int, int] = (920, 600), fps: float = FPS) -> Path:
    """The long 8-camera installation (long_installation) rendered for `seconds`, into the cache (once)."""
    width, height = size
    out = CACHE / f"scene-{LONG_NAME}-{width}x{height}-{fps:g}fps-{seconds:g}s"
    if (out / "truth_frames.csv").is_file():
        return exact_calibrations(out)
    return _render(long_installation(seconds), out, size, seconds, fps)


def _render(sc: Scenario, out: Path, size: tuple[int, int], seconds: float, fps: float) -> Path:
    """A scenario rendered at size and fps for `seconds` into out, its cameras' pixel pitch scaled by the height."""
    from tracking.sim.command import render_scenario

    width, height = size
    cams = []
    for c in sc.cameras:
        s = height / c.height
        fx, fy, cx, cy = c.K
        K = [fx * s, fy * s, cx * s + (width - c.width * s) / 2, cy * s]
        cams.append(c.model_copy(update={"fps": fps, "width": width, "height": height, "K": K}))
    out.mkdir(parents=True, exist_ok=True)
    render_scenario(sc.model_copy(update={"cameras": cams}), out, seconds, quiet=True)
    return out
