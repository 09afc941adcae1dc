"""Helpers for the simulator tests: smaller cameras for quick runs."""

from __future__ import annotations

from tracking.sim.builtins import builtin_scenario
from tracking.sim.scenario import Scenario


def shrunk(name: str, scale: float = 0.5) -> Scenario:
    """A built-in scenario with every camera's picture (and K) scaled down."""
    sc = builtin_scenario(name)
    assert sc is not None
    cams = []
    for c in sc.cameras:
        w, h = int(c.width * scale) // 2 * 2, int(c.height * scale) // 2 * 2
        fx, fy, cx, cy = c.K
        K = [fx * scale, fy * scale, (cx + 0.5) * scale - 0.5, (cy + 0.5) * scale - 0.5]
        cams.append(c.model_copy(update={"width": w, "height": h, "K": K}))
    return sc.model_copy(update={"cameras": cams})
