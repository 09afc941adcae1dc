"""Simulator speed: rendered frames per second at 920 x 600 on one core, with and without H.264 encoding.

Run: .venv/bin/python benchmarks/sim_speed.py [--seconds 4]
Prints a table and writes benchmarks/results/sim_speed.md.
"""

from __future__ import annotations

import argparse
import os
import platform
import tempfile
import time
from pathlib import Path

import cv2
from rich.console import Console
from rich.table import Table

from benchmarks.report import write_results
from tracking.sim.builtins import builtin_scenario
from tracking.sim.command import plan_frames, render_scenario
from tracking.sim.render import CameraRenderer
from tracking.sim.world import World

SCENARIOS = ("config2-procedure5-clear", "config2-procedure5", "config2-procedure5-weather", "config1-procedure3")


def render_only(name: str, seconds: float) -> tuple[int, float]:
    """Frames rendered (all cameras) and the time spent, no encoding."""
    sc = builtin_scenario(name)
    world = World(sc, seconds, sc.seed)
    frames, spent = 0, 0.0
    for i, cam in enumerate(sc.cameras):
        r = CameraRenderer(cam, world.bodies, world.textures, sc.weather, world.light, sc.layout.sea_z, seed=i)
        r.maps  # noqa: B018 - built once per camera, not per frame
        for t in plan_frames(cam, i, seconds, sc.seed).capture_times:
            t0 = time.perf_counter()
            r.render(world.frame_state(cam, float(t), frames))
            spent += time.perf_counter() - t0
            frames += 1
    return frames, spent


def full_run(name: str, seconds: float) -> tuple[int, float, float, float]:
    """Frames, wall time of the whole command, render time and encode time."""
    sc = builtin_scenario(name)
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        stats = render_scenario(sc, Path(tmp), seconds, quiet=True)
        wall = time.perf_counter() - t0
    return int(stats["frames"]), wall, stats["render_s"], stats["encode_s"]


def main() -> None:
    """Measure every scenario and write the table."""
    parser = argparse.ArgumentParser()
    parser.add_argument("--seconds", type=float, default=4.0, help="simulated seconds per scenario")
    args = parser.parse_args()
    cv2.setNumThreads(1)
    table = Table(title=f"simulator speed, 920 x 600, one core ({args.seconds:g} s per scenario)")
    cols = ("scenario", "cameras", "frames", "render only [frames/s]", "render [ms/frame]",
            "encode [ms/frame]", "whole command [frames/s]")
    for c in cols:
        table.add_column(c, justify="left" if c == "scenario" else "right")
    rows = []
    for name in SCENARIOS:
        n, spent = render_only(name, args.seconds)
        frames, wall, render_s, encode_s = full_run(name, args.seconds)
        row = (name, str(len(builtin_scenario(name).cameras)), str(frames), f"{n / spent:.1f}",
               f"{1000 * render_s / frames:.1f}", f"{1000 * encode_s / frames:.1f}", f"{frames / wall:.1f}")
        rows.append(row)
        table.add_row(*row)
    Console().print(table)
    lines = [f"# Simulator speed\n\nMeasured by `benchmarks/sim_speed.py --seconds {args.seconds:g}` with "
             f"`cv2.setNumThreads(1)` and x264 `threads=1` on {platform.processor() or platform.machine()} "
             f"({os.cpu_count()} CPUs visible), {time.strftime('%Y-%m-%d')}. Frames are counted over all cameras; "
             "\"whole command\" includes world set-up, truth logs and H.264 encoding (veryfast, CRF 20).\n",
             "| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    write_results("sim_speed", lines)


if __name__ == "__main__":
    main()
