"""Memory and CPU of the smoothed mode over long recordings: the backward pass piece by piece against the whole run.

The simulated set-down (fog, rain, 15 FPS, 920×600, four cameras; the accuracy benchmark's render and detections)
is replayed in a loop, capture times running on, for some minutes of capture time, and smoothed
(`tracking.estimator.smoothed_estimates`) once with its pieces (SMOOTHER_SPAN_S + SMOOTHER_LAG_S) and once over the
whole run (span unbounded), each in a process of its own: peak resident memory (RSS) and CPU time. The topside jumps
back at every seam of the loop; the filter takes that as a new placement, as it would a lost and found topside.
`--cameras 8` adds a second camera beside each of the four (the same detections, half a frame later, under another
name), which doubles the filter's camera and view states as eight real cameras would.

Run: .venv/bin/python -m benchmarks.smoother_memory [--minutes 3 6 12] [--whole-up-to 6] [--cameras 8]
Results: benchmarks/results/smoother_memory.md (four cameras), smoother_memory-8cam.md
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path

from benchmarks.accuracy import detect, measure, render, with_mounts
from tracking.estimator import smoothed_estimates
from tracking.estimator.noise import SMOOTHER_LAG_S, SMOOTHER_SPAN_S
from tracking.rig import Rig, load_rig

RESULTS = Path(__file__).resolve().parent / "results" / "smoother_memory.md"
SCENE = "config2-setdown"
FPS = 15.0
SCENE_CAMERAS = 4
TWIN_SUFFIX = "-twin"  # the added cameras of --cameras 8


def with_twins(rig: Rig, detections: list[tuple[str, float, dict]]) -> tuple[Rig, list[tuple[str, float, dict]]]:
    """The rig with a twin of every camera, and the detections with each twin's: the same, half a frame later."""
    twins = [c.model_copy(update={"name": c.name + TWIN_SUFFIX}) for c in rig.cameras]
    again = [(camera + TWIN_SUFFIX, t + 0.5 / FPS, corners) for camera, t, corners in detections]
    return rig.model_copy(update={"cameras": [*rig.cameras, *twins]}), sorted(detections + again,
                                                                                key=lambda d: d[1])


def replayed(measurements: list, minutes: float) -> Iterator:
    """The measurements again and again, capture times running on, for minutes of capture time."""
    first, last = measurements[0].time, measurements[-1].time
    lap = last - first + 1 / FPS
    shift = 0.0
    while True:
        for m in measurements:
            t = m.time + shift
            if t - first >= 60 * minutes:
                return
            yield replace(m, time=t)
        shift += lap


def one(minutes: float, whole: bool, cameras: int) -> dict:
    """Smooth minutes of the replayed scene in this process: estimates, peak RSS (MB), CPU (s)."""
    scene = render(SCENE, FPS)
    rig = with_mounts(load_rig(scene / "rig.yaml"), SCENE)
    detections = detect(SCENE, scene)
    if cameras == 2 * SCENE_CAMERAS:
        rig, detections = with_twins(rig, detections)
    measurements = measure(rig, detections)
    base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    t0 = time.process_time()
    span = 1e12 if whole else SMOOTHER_SPAN_S
    n = sum(1 for _ in smoothed_estimates(rig, replayed(measurements, minutes), span_s=span))
    return {"estimates": n, "rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
            "before_mb": base, "cpu_s": time.process_time() - t0}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, nargs="+", default=[3.0, 6.0, 12.0])
    parser.add_argument("--whole-up-to", type=float, default=6.0,
                        help="the whole-run smoother only up to this many minutes")
    parser.add_argument("--cameras", type=int, choices=(SCENE_CAMERAS, 2 * SCENE_CAMERAS), default=SCENE_CAMERAS)
    parser.add_argument("--one", nargs=2, metavar=("MINUTES", "WHOLE"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one:
        print(json.dumps(one(float(args.one[0]), args.one[1] == "1", args.cameras)))
        return
    render(SCENE, FPS)  # once, before the measuring processes
    rows = []
    for minutes in args.minutes:
        for whole in (False, True):
            if whole and minutes > args.whole_up_to:
                continue
            out = subprocess.run([sys.executable, "-m", "benchmarks.smoother_memory", "--one", str(minutes),
                                  str(int(whole)), "--cameras", str(args.cameras)], capture_output=True, text=True,
                                 check=True)
            r = json.loads(out.stdout.strip().splitlines()[-1])
            rows.append((minutes, "whole run" if whole else f"pieces of {SMOOTHER_SPAN_S:g} + {SMOOTHER_LAG_S:g} s", r))
            print(f"{minutes:g} min {rows[-1][1]}: {r}", flush=True)
    lines = [
        "# Smoothed mode: memory over long recordings",
        "",
        f"`benchmarks/smoother_memory.py --cameras {args.cameras}`: the simulated set-down (15 FPS, fog and rain; "
        + ("4 cameras" if args.cameras == SCENE_CAMERAS else "its 4 cameras and a twin of each, half a frame later")
        + ") replayed in a loop and smoothed, each row in a fresh process. RSS before is the process with the scene's "
        "detections loaded; peak is the most it held while smoothing.",
        "",
        "| capture [min] | backward pass | estimates | RSS before [MB] | peak RSS [MB] | CPU [s] "
        "| CPU per capture s [ms] |",
        "|---:|---|---:|---:|---:|---:|---:|",
    ]
    for minutes, how, r in rows:
        lines.append(f"| {minutes:g} | {how} | {r['estimates']} | {r['before_mb']:.0f} | {r['rss_mb']:.0f} | "
                     f"{r['cpu_s']:.0f} | {1000 * r['cpu_s'] / (60 * minutes):.0f} |")
    out = RESULTS if args.cameras == SCENE_CAMERAS else RESULTS.with_name(f"smoother_memory-{args.cameras}cam.md")
    out.write_text("\n".join(lines) + "\n")
    print(out.read_text())


if __name__ == "__main__":
    main()
