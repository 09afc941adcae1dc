"""End-to-end throughput of the live path (decode, detect, poses, fusion, recording) for 1, 4 and 8 streams.

Streams are the cameras of a simulated set-down in fog and rain at 15 FPS (repeated to make 8), at 920×600 and
1920×1080. Each configuration runs through `tracking.live.LiveTracker` with a worker process per camera and a
Recorder writing the .rrd, twice:
  - flat out (files replayed as fast as they decode): frames/s over all streams, after start-up;
  - in real time (each file at its own 15 FPS): the share of frames used, searched by their worker and fused by
    the main process; the rest were recorded but skipped to keep up. Real time for N streams means 100 % used.
Beside it, in the same run, plain OpenCV: decode and `detectMarkers` with default parameters, one stream, one process
(the libraries' default threading, as one would run it).
And where the CPU goes: every stage run alone over the scene's cameras, CPU ms per frame (all threads of the process),
so the ceiling of 2 cores and what the targets would need can be read off.

Run: .venv/bin/python -m benchmarks.throughput [--streams 1 4 8] [--seconds 10]
Results: benchmarks/results/throughput.md (scenes: benchmarks/scenes.py).
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import cv2
import yaml

from benchmarks.report import write_results
from benchmarks.scenes import FPS, render_scene
from tracking.cli.live import LIVE_ESTIMATE_PERIOD_S
from tracking.detection import DEFAULT_REFINEMENT
from tracking.estimator import FilterTuning, TopsideFilter, filter_frame
from tracking.images import frames
from tracking.live import LiveTracker
from tracking.pipeline import CameraTracker
from tracking.rig import load_rig
from viewer.session import Recorder

SCENARIO = "config2-setdown-weather"
RESOLUTIONS = {"920×600": (920, 600), "1920×1080": (1920, 1080)}
STAGES = ("decode", "detection (search and edge fit)", "poses, pair offsets, body observations", "fusion",
          "recording", "plain detectMarkers")


def streams_rig(scene: Path, n: int, work: Path) -> Path:
    """A rig with n cameras: the scene's cameras repeated (each a separate stream and worker)."""
    rig = yaml.safe_load((scene / "rig.yaml").read_text())
    base = rig["cameras"]
    rig["cameras"] = [{**base[i % len(base)], "name": f"cam{i}",
                       "source": str(scene / base[i % len(base)]["source"]),
                       "calibration": str(scene / base[i % len(base)]["calibration"])} for i in range(n)]
    path = work / f"rig-{n}.yaml"
    path.write_text(yaml.safe_dump(rig, sort_keys=False))
    return path


def run_live(rig_path: Path, speed: float, work: Path) -> dict:
    """One live run with recording: frames, share used, frames/s after the first frame."""
    rig = load_rig(rig_path)
    recorder = Recorder(rig, work / f"run-{len(rig.cameras)}-{speed}.rrd", estimate_period_s=LIVE_ESTIMATE_PERIOD_S)
    n = used = 0
    t_first = t_last = None
    with LiveTracker(rig, speed=speed) as tracker:
        for update in tracker.updates():
            recorder.on_update(update)
            if update.results:
                t_first = t_first or time.perf_counter()
                t_last = time.perf_counter()
                n += len(update.results)
                used += sum(r.tracked for r in update.results)
    recorder.close()
    wall = (t_last - t_first) if t_first and t_last and t_last > t_first else math.nan
    return {"frames": n, "used": used / max(n, 1), "fps": n / wall, "rrd_mb": sum(
        f.stat().st_size for f in work.glob(f"run-{len(rig.cameras)}-{speed}*.rrd")) / 1e6}


def default_detector(rig_dictionary: str) -> cv2.aruco.ArucoDetector:
    """OpenCV's ArUco detector with default parameters: the plain baseline."""
    return cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, rig_dictionary)),
                                   cv2.aruco.DetectorParameters())


def plain_opencv(scene: Path) -> float:
    """Frames/s of one stream decoded and searched by OpenCV's default detector, in one process with the
    libraries' default threading (as one would run it)."""
    rig = load_rig(scene / "rig.yaml")
    detector = default_detector(rig.dictionary)
    t0 = time.perf_counter()
    n = 0
    for frame in frames(rig.resolve(rig.cameras[0].source)):
        detector.detectMarkers(frame.gray)
        n += 1
    return n / (time.perf_counter() - t0)


def stage_costs(scene: Path) -> dict[str, float]:
    """CPU ms per frame of each stage of the live path run alone, over every camera of the scene, and of OpenCV's
    default detectMarkers on the same frames (process CPU time: decoder and recorder threads included)."""
    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)  # as in the workers
    rig = load_rig(scene / "rig.yaml")
    detector = default_detector(rig.dictionary)
    cpu = dict.fromkeys(STAGES, 0.0)
    results = []
    n = 0
    for entry in rig.cameras:
        tracker = CameraTracker.from_rig(rig, entry, DEFAULT_REFINEMENT, packets=True, roi_tracking=True)
        t = time.process_time()
        for _ in frames(rig.resolve(entry.source), entry.time_offset, packets=True):
            pass  # streaming, as the workers decode
        cpu["decode"] += time.process_time() - t
        decoded = list(frames(rig.resolve(entry.source), entry.time_offset, packets=True))
        t = time.process_time()
        detections = [tracker.detector.detect(f.gray) for f in decoded]
        cpu["detection (search and edge fit)"] += time.process_time() - t
        t = time.process_time()
        results += [tracker.measure(f, d) for f, d in zip(decoded, detections, strict=True)]
        cpu["poses, pair offsets, body observations"] += time.process_time() - t
        t = time.process_time()
        for f in decoded:
            detector.detectMarkers(f.gray)
        cpu["plain detectMarkers"] += time.process_time() - t
        n += len(decoded)
    results.sort(key=lambda r: r.time)
    kf = TopsideFilter(rig, FilterTuning())
    t = time.process_time()
    estimates = [filter_frame(kf, r.measurements) if r.measurements else [] for r in results]
    cpu["fusion"] = time.process_time() - t
    with tempfile.TemporaryDirectory() as tmp:
        recorder = Recorder(rig, Path(tmp) / "stages.rrd", estimate_period_s=LIVE_ESTIMATE_PERIOD_S)
        t = time.process_time()
        for r, es in zip(results, estimates, strict=True):
            recorder.on_frame(replace(r, frame=replace(r.frame, gray=None)))  # as the workers ship them
            for e in es:
                recorder.on_estimate(e)
        recorder.close()
        cpu["recording"] = time.process_time() - t
    cv2.setNumThreads(threads)  # the plain baseline runs with OpenCV's defaults
    return {k: v / n * 1e3 for k, v in cpu.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--streams", type=int, nargs="+", default=[1, 4, 8])
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--resolutions", nargs="+", default=list(RESOLUTIONS))
    args = parser.parse_args()
    rows = []
    costs = {}
    for label in args.resolutions:
        scene = render_scene(SCENARIO, RESOLUTIONS[label], args.seconds)
        costs[label] = stage_costs(scene)
        print(f"{label}: " + ", ".join(f"{k} {v:.2f}" for k, v in costs[label].items()) + " ms/frame", flush=True)
        plain = plain_opencv(scene)
        print(f"{label}: plain OpenCV detectMarkers {plain:.1f} frames/s (one process)", flush=True)
        for n in args.streams:
            with tempfile.TemporaryDirectory() as tmp:
                work = Path(tmp)
                rig = streams_rig(scene, n, work)
                flat = run_live(rig, math.inf, work)
                real = run_live(rig, 1.0, work)
            gb_per_camera_hour = flat["rrd_mb"] / n / args.seconds * 3600 / 1000
            row = (label, n, flat["fps"], flat["fps"] / plain, real["used"], gb_per_camera_hour)
            rows.append(row)
            print(f"{label} {n} streams: {flat['fps']:.1f} frames/s flat out ({row[3]:.1f}× plain), "
                  f"real time {real['used']:.0%} used", flush=True)
        rows.append((label, "plain", plain, 1.0, math.nan, math.nan))
    write(rows, costs, args)


def write(rows: list[tuple], costs: dict[str, dict[str, float]], args: argparse.Namespace) -> None:
    """The results table as markdown."""
    lines = ["# Throughput of the live path", "",
             f"`benchmarks/throughput.py`, {args.seconds:g} s of `{SCENARIO}` at {FPS:g} FPS per stream, "
             f"{os.cpu_count()} cores ({platform.processor() or platform.machine()}), "
             f"python {platform.python_version()}. End to end: decode, detection, poses, fusion, and the Rerun "
             "recording (the cameras' H.264 passed through). Flat out: files as fast as they decode. Real time: "
             "files at 15 FPS each; frames that could not be searched and fused in time are recorded only.", "",
             "| resolution | streams | frames/s flat out | × plain OpenCV | used in real time "
             "| GB per camera-hour |",
             "|---|---:|---:|---:|---:|---:|"]
    for label, n, fps, ratio, used, gb in rows:
        if n == "plain":
            lines.append(f"| {label} | plain `detectMarkers`, 1 stream | {fps:.1f} | 1.0 | — | — |")
        else:
            lines.append(f"| {label} | {n} | {fps:.1f} | {ratio:.1f} | {used:.0%} | {gb:.2f} |")
    labels = list(costs)
    plain_fps = {label: fps for label, n, fps, *_ in rows if n == "plain"}
    budget_ms = 2000 / (8 * FPS)  # 2 cores, 8 streams
    lines += ["", "## Where the CPU goes", "",
              "Each stage alone over the scene's cameras, CPU ms per frame (all threads of the process; the "
              "recorder's own threads included).", "",
              "| stage | " + " | ".join(labels) + " |", "|---|" + "---:|" * len(labels)]
    ours = [s for s in STAGES if s != "plain detectMarkers"]
    for stage in STAGES:
        lines.append(f"| {stage} | " + " | ".join(f"{costs[k][stage]:.2f}" for k in labels) + " |")
    total = {k: sum(costs[k][s] for s in ours) for k in labels}
    plain = {k: costs[k]["decode"] + costs[k]["plain detectMarkers"] for k in labels}
    lines += ["| **live path, total** | " + " | ".join(f"**{total[k]:.2f}**" for k in labels) + " |",
              "| plain OpenCV (decode and detectMarkers, one thread) | " + " | ".join(f"{plain[k]:.2f}" for k in labels)
              + " |",
              "| ceiling of 2 cores, frames/s (2000 / total) | " + " | ".join(f"{2000 / total[k]:.0f}" for k in labels)
              + " |",
              f"| 8 × {FPS:g} FPS would need, ms per frame at most | " + " | ".join(f"{budget_ms:.2f}" for _ in labels)
              + " |",
              "| 3× plain (its frames/s above) would need, ms per frame at most | "
              + " | ".join(f"{2000 / (3 * plain_fps[k]):.2f}" for k in labels) + " |"]
    write_results("throughput", lines)


if __name__ == "__main__":
    main()
