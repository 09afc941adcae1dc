"""The fused filter's CPU cost per frame on the demo's scene, against earlier revisions of the code in the same run.

Scene: `config2-procedure5-weather` (the demo's: three drones and a stern camera, fog 50 %, rain 30 %), 40 s at 15
FPS, 920×600, cached by benchmarks/scenes.py (the scene of benchmarks/scale.py). Its measurements are made once
(detection, poses, pair offsets and body observations, as `topside track` makes them) and handed to each revision's
estimator, which alone is timed: CPU seconds over the frames, in one thread (BLAS held to one). Each revision given
with --against runs from a temporary git worktree in a process of its own; the rounds alternate between revisions, so
a busy machine slows them alike. The estimates of every revision are compared with this tree's (offsets and
covariances, largest difference).

Run: .venv/bin/python -m benchmarks.fusion_cost [--against REV ...] [--rounds 7] [--mode fused]
Results: benchmarks/results/fusion_cost.md
"""

from __future__ import annotations

import argparse
import os
import pickle
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.report import write_results
from benchmarks.scenes import render_scene

SCENARIO = "config2-procedure5-weather"
SIZE = (920, 600)
FPS = 15.0
SECONDS = 40.0
TARGET_MS = 0.4  # issue 35: the fused filter's cost per frame on the demo rig
REPO = Path(__file__).resolve().parents[1]

# Run in each revision's own tree: only APIs every revision since the estimators' registry has (load_rig, ESTIMATORS).
RUNNER = """
import pickle, sys, time
from pathlib import Path
import numpy as np
from tracking.rig import load_rig
from tracking.estimator import ESTIMATORS
rig_path, measurements_path, mode, out_path = sys.argv[1:5]
measurements, frames = pickle.loads(Path(measurements_path).read_bytes())
rig = load_rig(Path(rig_path))
t = time.process_time()
out = list(ESTIMATORS[mode](rig, iter(measurements)))
ms = 1000 * (time.process_time() - t) / frames
rows = np.array([np.concatenate([e.offset, np.full(9, np.nan) if e.covariance is None else np.ravel(e.covariance)])
                 for e in out])
Path(out_path).write_bytes(pickle.dumps((ms, rows)))
"""


def measurements_of(rig_path: Path, out: Path) -> int:
    """The scene's measurements pickled to out (with the count of camera frames); that count."""
    from tracking.parallel import InPlace, track_chunks
    from tracking.rig import load_rig

    results = list(track_chunks(load_rig(rig_path), InPlace()))
    out.write_bytes(pickle.dumps(([m for r in results for m in r.measurements], len(results))))
    return len(results)


def time_once(tree: Path, rig_path: Path, measurements: Path, mode: str, tmp: Path) -> tuple[float, np.ndarray]:
    """One timed run of the estimator of the code in tree: ms per frame and its estimates' rows (N, 12)."""
    out = tmp / "out.pkl"
    env = {**os.environ, "PYTHONPATH": str(tree), "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
    subprocess.run([sys.executable, "-c", RUNNER, str(rig_path), str(measurements), mode, str(out)], env=env,
                   cwd=tree, check=True)
    ms, rows = pickle.loads(out.read_bytes())
    out.unlink()
    return ms, rows


def largest_difference(a: np.ndarray, b: np.ndarray) -> str:
    """Largest difference between two runs' estimate rows, or why they cannot be compared."""
    if a.shape != b.shape:
        return f"{len(a)} against {len(b)} estimates"
    if not np.array_equal(np.isnan(a[:, :3]), np.isnan(b[:, :3])):
        return "withheld at other times"
    if np.array_equal(a, b, equal_nan=True):
        return "identical"
    offsets = 1000 * np.nanmax(np.abs(a[:, :3] - b[:, :3]), initial=0.0)
    sigma = 1000 * np.nanmax(np.abs(np.sqrt(a[:, 3::4]) - np.sqrt(b[:, 3::4])), initial=0.0)
    return f"offsets up to {offsets:.2g} mm apart, σ up to {sigma:.2g} mm"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--against", nargs="*", default=[], help="Git revisions to time beside this tree.")
    parser.add_argument("--rounds", type=int, default=7)
    parser.add_argument("--mode", default="fused")
    args = parser.parse_args()
    scene = render_scene(SCENARIO, SIZE, SECONDS, FPS)
    rig_path = scene / "rig.yaml"
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        frames = measurements_of(rig_path, tmp / "measurements.pkl")
        trees: dict[str, Path] = {}
        for rev in args.against:
            commit = subprocess.run(["git", "rev-parse", "--short", rev], cwd=REPO, check=True, capture_output=True,
                                    text=True).stdout.strip()
            trees[commit] = tmp / f"tree-{commit}"
            subprocess.run(["git", "worktree", "add", "--detach", str(trees[commit]), commit], cwd=REPO, check=True,
                           capture_output=True)
        trees["this tree"] = REPO
        try:
            times: dict[str, list[float]] = {name: [] for name in trees}
            rows: dict[str, np.ndarray] = {}
            for k in range(args.rounds):
                for name, tree in trees.items():
                    ms, rows[name] = time_once(tree, rig_path, tmp / "measurements.pkl", args.mode, tmp)
                    times[name].append(ms)
                print(f"round {k + 1}: " + ", ".join(f"{n} {t[-1]:.3f} ms" for n, t in times.items()), flush=True)
        finally:
            for tree in trees.values():
                if tree != REPO:
                    subprocess.run(["git", "worktree", "remove", "--force", str(tree)], cwd=REPO, check=False)
    best = min(times["this tree"])
    lines = [
        "# The fused filter's cost per frame",
        "",
        f"`benchmarks/fusion_cost.py`, {time.strftime('%Y-%m-%d %H:%M')}, {platform.machine()}, {os.cpu_count()} "
        f"cores, python {platform.python_version()}: the {args.mode} estimator on the measurements of {SECONDS:g} s of "
        f"`{SCENARIO}` (the demo's scene: 4 cameras, {frames} camera frames), CPU ms per camera frame in one thread, "
        f"{args.rounds} rounds alternating between revisions (best; median). Target (issue 35, the fused mode): at "
        f"most {TARGET_MS} ms a frame.",
        "",
        "| code | ms/frame (best; median) | × this tree | its estimates against this tree's |",
        "|---|---:|---:|---|",
    ]
    for name, t in times.items():
        lines.append(f"| {name} | {min(t):.3f}; {statistics.median(t):.3f} | {min(t) / best:.2f} | "
                     f"{largest_difference(rows[name], rows['this tree'])} |")
    lines += ["", "Identical estimates: the cuts between those revisions changed the cost alone; where they differ, "
                  "the revisions between changed the model too (`git log` says how)."]
    if args.mode == "fused":
        lines += ["", f"Target: **{best:.3f} ms** a frame ({'met' if best <= TARGET_MS else 'NOT met'}; median "
                      f"{statistics.median(times['this tree']):.3f})."]
    write_results(f"fusion_cost-{args.mode}" if args.mode != "fused" else "fusion_cost", lines, echo=True)


if __name__ == "__main__":
    main()
