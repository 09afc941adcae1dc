"""Soak test: a long installation replayed through the live path, accelerated; memory and recording size over time.

A simulated set-down in fog and rain (15 FPS, 920×600) is replayed in a loop, capture times running on, for
--hours of capture time, as fast as the machine decodes and tracks it (no frame skipped), through
`tracking.live.LiveTracker` and a Recorder writing 1-minute segments (as `topside live`). Every 10 s of capture time
the resident memory (RSS) of the main process and of the camera workers is sampled. Pass: RSS grows by less than
50 MB after the first minute, and the recording stays under 1 GB per camera-hour.

Run: .venv/bin/python -m benchmarks.soak [--hours 6] [--cameras 4]    Results: benchmarks/results/soak-<N>cam.md
"""

from __future__ import annotations

import argparse
import math
import os
import tempfile
import time
from pathlib import Path

from benchmarks.scenes import CACHE, render_scene
from benchmarks.throughput import SCENARIO, streams_rig
from tracking.cli.live import LIVE_ESTIMATE_PERIOD_S
from tracking.live import LiveTracker
from tracking.rig import load_rig
from viewer.session import BACKLOG_TIMEOUT_S, Recorder

RESULTS = Path(__file__).resolve().parent / "results"
CLIP_S = 20.0
SEGMENT_S = 60.0  # as `topside live` (LIVE_SEGMENT_MIN)
SAMPLE_S = 10.0
GROWTH_LIMIT_MB = 50.0
SIZE_LIMIT_GB = 1.0


def rss_mb(pid: int) -> float:
    """Resident memory of a process, MB (Linux /proc)."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    except OSError:
        pass
    return math.nan


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--hours", type=float, default=6.0)
    parser.add_argument("--cameras", type=int, default=4)
    args = parser.parse_args()
    scene = render_scene(SCENARIO, (920, 600), CLIP_S)
    samples: list[tuple[float, float, float, float]] = []  # capture minute, wall s, main MB, workers MB
    frames = 0
    with tempfile.TemporaryDirectory(dir=CACHE) as tmp:
        work = Path(tmp)
        rig = load_rig(streams_rig(scene, args.cameras, work))
        recorder = Recorder(rig, work / "soak.rrd", segment_s=SEGMENT_S, estimate_period_s=LIVE_ESTIMATE_PERIOD_S)
        t_wall = time.perf_counter()
        next_sample = None
        with LiveTracker(rig, speed=math.inf, loop_until=args.hours * 3600) as tracker:
            pids = [p.pid for p in tracker._workers]
            for update in tracker.updates():
                recorder.on_update(update)
                frames += len(update.results)
                if not update.results:
                    continue
                t = update.results[-1].time
                next_sample = t if next_sample is None else next_sample
                if t >= next_sample:
                    samples.append((t / 60, time.perf_counter() - t_wall, rss_mb(os.getpid()),
                                    sum(rss_mb(p) for p in pids)))
                    print(f"minute {t / 60:6.1f}: main {samples[-1][2]:7.1f} MB, workers {samples[-1][3]:7.1f} MB, "
                          f"{frames / samples[-1][1]:.0f} frames/s", flush=True)
                    next_sample += SAMPLE_S
                    if len(samples) % 6 == 0:  # the table so far: a run cut short still leaves its numbers
                        write(samples, args, frames, time.perf_counter() - t_wall, segments_gb(work),
                              len(list(work.glob("soak-*.rrd"))), recorder.backlog_timeouts, done=False)
        recorder.close()
        size_gb = segments_gb(work)
        n_segments = len(list(work.glob("soak-*.rrd")))
    wall = time.perf_counter() - t_wall
    write(samples, args, frames, wall, size_gb, n_segments, recorder.backlog_timeouts)


def segments_gb(work: Path) -> float:
    """Size of the recording's segment files so far, GB."""
    return sum(f.stat().st_size for f in work.glob("soak-*.rrd")) / 1e9


def write(samples: list[tuple[float, float, float, float]], args: argparse.Namespace, frames: int, wall: float,
          size_gb: float, n_segments: int, backlog_timeouts: int, done: bool = True) -> None:
    """The RSS table and verdicts as markdown (done=False: a run still going, or cut short)."""
    hours = samples[-1][0] / 60 if samples else 0.0  # capture time of the last sample
    base = next((s for s in samples if s[0] >= 1.0), samples[0])
    growth_main = max(s[2] for s in samples) - base[2]
    growth_workers = max(s[3] for s in samples) - base[3]
    per_camera_hour = size_gb / args.cameras / max(hours, 1e-9)
    flat = max(growth_main, growth_workers) < GROWTH_LIMIT_MB
    lines = ["# Soak: the live path over a long installation", "",
             f"`benchmarks/soak.py --hours {args.hours:g} --cameras {args.cameras}`: {CLIP_S:g} s of a simulated "
             "set-down (fog, rain, 15 FPS, 920×600) replayed in a loop as fast as it tracks; every frame searched "
             f"and recorded in {SEGMENT_S / 60:g}-minute segments.", "",
             *([] if done else ["**Run not finished: the numbers so far.**", ""]),
             f"- capture time covered: {hours:.2f} h per camera ({frames} frames in {wall / 60:.1f} min of wall "
             f"time, {frames / wall:.0f} frames/s)",
             f"- RSS growth after the first minute: main {growth_main:+.1f} MB, workers {growth_workers:+.1f} MB "
             f"(limit {GROWTH_LIMIT_MB:g} MB): {'pass' if flat else 'FAIL'}",
             f"- recording: {size_gb:.2f} GB in {n_segments} segments, {per_camera_hour:.2f} GB per camera-hour "
             f"(limit {SIZE_LIMIT_GB:g}): {'pass' if per_camera_hour < SIZE_LIMIT_GB else 'FAIL'}",
             f"- waits for the recording's sinks that timed out ({BACKLOG_TIMEOUT_S:g} s): {backlog_timeouts}", "",
             "| capture minute | wall [s] | main RSS [MB] | workers RSS [MB] |", "|---:|---:|---:|---:|"]
    step = max(1, len(samples) // 40)
    for s in samples[::step] + ([samples[-1]] if (len(samples) - 1) % step else []):
        lines.append(f"| {s[0]:.0f} | {s[1]:.0f} | {s[2]:.1f} | {s[3]:.1f} |")
    path = RESULTS / f"soak-{args.cameras}cam.md"
    path.write_text("\n".join(lines) + "\n")
    if done:
        print(f"wrote {path}")


if __name__ == "__main__":
    main()
