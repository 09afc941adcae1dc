"""End-to-end throughput of the live path (decode, detect, poses, fusion, recording) for 1, 4 and 8 streams.

Streams are the cameras of a simulated set-down in fog and rain at 15 FPS (repeated to make 8), at 920×600 and
1920×1080. Each configuration runs through `tracking.live.LiveTracker` with a worker process per camera and a
Recorder writing the .rrd, twice:
  - flat out (files replayed as fast as they decode): frames/s over all streams, after start-up;
  - in real time (each file at its own 15 FPS): the share of frames used, searched by their worker and fused by
    the main process; the rest were recorded but skipped to keep up. Real time for N streams means 100 % used.
Beside it, in the same run, plain OpenCV: decode and `detectMarkers` with default parameters, one stream, one core.

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
from pathlib import Path

import cv2
import yaml

from benchmarks.scenes import FPS, render_scene
from tracking.cli import LIVE_ESTIMATE_PERIOD_S
from tracking.images import frames
from tracking.live import LiveTracker
from tracking.rig import load_rig
from viewer.session import Recorder

REPO = Path(__file__).resolve().parents[1]
RESULTS = REPO / "benchmarks" / "results" / "throughput.md"
SCENARIO = "config2-setdown-weather"
RESOLUTIONS = {"920×600": (920, 600), "1920×1080": (1920, 1080)}


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


def plain_opencv(scene: Path) -> float:
    """Frames/s of one stream decoded and searched by OpenCV's default detector, one core."""
    rig = load_rig(scene / "rig.yaml")
    detector = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, rig.dictionary)),
                                       cv2.aruco.DetectorParameters())
    t0 = time.perf_counter()
    n = 0
    for frame in frames(rig.resolve(rig.cameras[0].source)):
        detector.detectMarkers(frame.gray)
        n += 1
    return n / (time.perf_counter() - t0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--streams", type=int, nargs="+", default=[1, 4, 8])
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--resolutions", nargs="+", default=list(RESOLUTIONS))
    args = parser.parse_args()
    rows = []
    for label in args.resolutions:
        scene = render_scene(SCENARIO, RESOLUTIONS[label], args.seconds)
        plain = plain_opencv(scene)
        print(f"{label}: plain OpenCV detectMarkers {plain:.1f} frames/s (one core)", flush=True)
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
    write(rows, args)


def write(rows: list[tuple], args: argparse.Namespace) -> None:
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
    RESULTS.write_text("\n".join(lines) + "\n")
    print(f"wrote {RESULTS}")


if __name__ == "__main__":
    main()
