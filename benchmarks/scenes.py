"""Simulated scenes for the speed benchmarks: a built-in scenario at a frame rate and image size, cached.

Another image size keeps the cameras' pixel pitch scaled by the height ratio (1920×1080 from 920×600: ×1.8),
so markers are that much larger in pixels; the extra width is added evenly on both sides.
"""

from __future__ import annotations

from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
CACHE = REPO / "benchmarks" / ".cache"
FPS = 15.0


def render_scene(scenario: str, size: tuple[int, int], seconds: float, fps: float = FPS) -> Path:
    """The scenario rendered at one size and frame rate for `seconds`, into the cache (once)."""
    from tracking.sim.command import render_scenario
    from tracking.sim.scenario import load_scenario

    width, height = size
    out = CACHE / f"scene-{scenario}-{width}x{height}-{fps:g}fps-{seconds:g}s"
    if (out / "truth_frames.csv").is_file():
        return out
    sc = load_scenario(scenario)
    cams = []
    for c in sc.cameras:
        s = height / c.height
        fx, fy, cx, cy = c.K
        K = [fx * s, fy * s, cx * s + (width - c.width * s) / 2, cy * s]
        cams.append(c.model_copy(update={"fps": fps, "width": width, "height": height, "K": K}))
    out.mkdir(parents=True, exist_ok=True)
    render_scenario(sc.model_copy(update={"cameras": cams}), out, seconds, quiet=True)
    return out
