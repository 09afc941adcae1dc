"""Detection speed and accuracy: OpenCV's default detectMarkers, today's MarkerDetector and the stateful MarkerTracker.

Renders two weather scenarios (config2-setdown and config1-procedure1, fog 50 %, rain 30 %) at
15 FPS, at the paper's 920×600 and at 1920×1080 (the same cameras with the focal length scaled by
1.8 and a wider field across), decodes every frame once, then runs each detector over each
camera's frames in order, single-threaded (cv2.setNumThreads(1)), timing CPU time per frame. The
accuracy columns compare the corners with the simulator's true corners (truth_frames.csv).

    .venv/bin/python -m benchmarks.detection_speed               # writes benchmarks/results/detection_speed.md
    .venv/bin/python -m benchmarks.detection_speed --quick       # 4 s clips, one repeat, prints only

Renders are cached in benchmarks/.cache/ (delete it to re-render).
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import date
from pathlib import Path

import cv2
import numpy as np
import pandas as pd

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from benchmarks.scenes import render_scene  # noqa: E402
from tracking.camera import CameraModel, load_camera  # noqa: E402
from tracking.detection import Detections, MarkerDetection, MarkerDetector  # noqa: E402
from tracking.images import video_frames  # noqa: E402
from tracking.marker_tracker import MarkerTracker  # noqa: E402
from tracking.outputs import write_text  # noqa: E402
from tracking.pose import estimate_pose  # noqa: E402
from tracking.rig import Rig, load_rig  # noqa: E402

RESULTS = REPO / "benchmarks" / "results" / "detection_speed.md"
SCENARIOS = ("config2-setdown-weather", "config1-procedure1-weather")
SECONDS = {"920x600": 20.0, "1920x1080": 12.0}
QUICK_SECONDS = 4.0
SIZES = {"920x600": (920, 600), "1920x1080": (1920, 1080)}  # scenes: benchmarks/scenes.py
WRONG_SIDES = 0.5  # a detection whose centre is this many sides from its id's true centre has a wrong id
BAD_CORNER_PX = 1.0
METHODS = ("OpenCV default", "today (MarkerDetector)", "MarkerTracker")
NOTES = """
- *OpenCV default*: `ArucoDetector(dictionary, DetectorParameters())`, one pass, OpenCV's corners.
  *today*: the stateless `MarkerDetector` (plain and rain-filtered passes, edge-fit corners).
  *MarkerTracker*: `tracking/marker_tracker.py` around a `MarkerDetector`, fed each camera's frames in order.
- 1920×1080: the same scenarios with every camera's focal length and principal point scaled by 1.8
  (1080 / 600) and the extra width added to the field of view, so markers are 1.8× larger in pixels.
- *markers found*: detections of the true id whose centre is within half a side of the true centre,
  over every marker the simulator drew (far markers of other pairs included, so no detector reaches
  100 %). *Corner RMS* and *> 1 px* are over those markers' corners against truth_frames.csv.
  *Wrong ids*: detections of an id not in the frame or more than half a side away.
- *median / 95th pct. frame*: of single frames' detection times; MarkerTracker's slow frames are its
  whole-frame searches (*whole-frame searches*: share of frames).
- Timings are CPU time of one thread on a machine shared with other jobs (its load average is stated
  above); repeats vary by ~10-20 %.
"""


@dataclass
class Stats:
    """Timings and accuracy counts of one method on one resolution."""

    cpu_ms: list[float] = field(default_factory=list)  # detection, mean CPU ms per frame, one per repeat
    pose_ms: list[float] = field(default_factory=list)  # poses of the rig's markers, the same way
    frame_ms: list[list[float]] = field(default_factory=list)  # detection ms of every frame, per repeat
    frames: int = 0
    truth: int = 0  # true markers in the frames
    found: int = 0
    wrong: int = 0
    sq_err: float = 0.0  # sum of squared corner errors, px^2
    corners: int = 0
    bad: int = 0  # markers with a corner more than BAD_CORNER_PX off
    full_searches: int = 0


def opencv_default(rig: Rig, camera: CameraModel) -> Callable[[np.ndarray], Detections]:
    """Plain OpenCV: DetectorParameters() defaults, one pass, no refinement of ours."""
    detector = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, rig.dictionary)),
                                       cv2.aruco.DetectorParameters())

    def detect(gray: np.ndarray) -> Detections:
        corners, ids, _ = detector.detectMarkers(gray)
        ids = [] if ids is None else ids.reshape(-1)
        return Detections([MarkerDetection(int(i), c.reshape(4, 2).astype(float)) for c, i in zip(corners, ids,
                                                                                                   strict=True)])
    return detect


def make(method: str, rig: Rig, camera: CameraModel) -> tuple[Callable[[np.ndarray], Detections], object]:
    """A fresh detector for one camera's clip, and the object holding its state."""
    if method == METHODS[0]:
        return opencv_default(rig, camera), None
    detector = MarkerDetector(rig.dictionary, camera=camera)
    if method == METHODS[1]:
        return detector.detect, detector
    tracker = MarkerTracker(detector)
    return tracker.detect, tracker


def truth_by_frame(folder: Path) -> dict[tuple[str, int], dict[int, np.ndarray]]:
    """True corners (4, 2) by (camera, frame index) and marker id."""
    df = pd.read_csv(folder / "truth_frames.csv").dropna(subset=["marker_id"])
    cols = [f"c{i}{a}" for i in range(4) for a in "xy"]
    out: dict[tuple[str, int], dict[int, np.ndarray]] = {}
    for row, corners in zip(df[["camera", "frame_index", "marker_id"]].itertuples(index=False),
                            df[cols].to_numpy().reshape(-1, 4, 2), strict=True):
        out.setdefault((row.camera, int(row.frame_index)), {})[int(row.marker_id)] = corners
    return out


def score(stats: Stats, found: list[Detections], truth: dict[tuple[str, int], dict[int, np.ndarray]],
          camera: str) -> None:
    """Add one clip's accuracy counts."""
    for k, det in enumerate(found):
        true = truth.get((camera, k), {})
        stats.truth += len(true)
        for m in det.markers:
            if m.id not in true:
                stats.wrong += 1
                continue
            side = np.linalg.norm(true[m.id] - np.roll(true[m.id], -1, axis=0), axis=1).mean()
            if np.linalg.norm(m.corners.mean(axis=0) - true[m.id].mean(axis=0)) > WRONG_SIDES * side:
                stats.wrong += 1
                continue
            err = np.linalg.norm(m.corners - true[m.id], axis=1)
            stats.found += 1
            stats.sq_err += float((err ** 2).sum())
            stats.corners += 4
            stats.bad += int(err.max() > BAD_CORNER_PX)


def run_clip(method: str, rig: Rig, camera: CameraModel, frames: list[np.ndarray]
             ) -> tuple[float, float, list[Detections], int, list[float]]:
    """CPU ms per frame for detection and for poses of the rig's markers, detections, full searches, ms per frame."""
    detect, state = make(method, rig, camera)
    known = rig.marker_by_id
    found, per_frame = [], []
    t0 = time.process_time()
    for g in frames:
        t = time.process_time()
        found.append(detect(g))
        per_frame.append(1000 * (time.process_time() - t))
    t1 = time.process_time()
    for det in found:
        for m in det.markers:
            if m.id in known:
                estimate_pose(m, camera, rig.marker_size)
    t2 = time.process_time()
    n = max(len(frames), 1)
    return 1000 * (t1 - t0) / n, 1000 * (t2 - t1) / n, found, getattr(state, "full_searches", 0), per_frame


def benchmark(size: str, seconds: float, repeats: int) -> dict[str, Stats]:
    """Every method on every camera of both scenarios at one size; timings per repeat over all clips."""
    stats = {m: Stats(cpu_ms=[0.0] * repeats, pose_ms=[0.0] * repeats, frame_ms=[[] for _ in range(repeats)])
             for m in METHODS}
    for name in SCENARIOS:
        folder = render_scene(name, SIZES[size], seconds)
        rig = load_rig(folder / "rig.yaml")
        truth = truth_by_frame(folder)
        for entry in rig.cameras:
            camera = load_camera(rig.resolve(entry.calibration))
            frames = [f.gray for f in video_frames(rig.resolve(entry.source))]
            for r in range(repeats):
                for method in METHODS:
                    det_ms, pose_ms, found, full, per_frame = run_clip(method, rig, camera, frames)
                    s = stats[method]
                    s.cpu_ms[r] += det_ms * len(frames)  # summed here, divided by all frames below
                    s.pose_ms[r] += pose_ms * len(frames)
                    s.frame_ms[r] += per_frame
                    if r == 0:
                        score(s, found, truth, entry.name)
                        s.frames += len(frames)
                        s.full_searches += full
    for s in stats.values():
        s.cpu_ms = [t / s.frames for t in s.cpu_ms]
        s.pose_ms = [t / s.frames for t in s.pose_ms]
    return stats


def table(results: dict[str, dict[str, Stats]]) -> str:
    """Markdown table: one row per resolution and method."""
    lines = ["| frame | method | detection [ms/frame] | + poses [ms/frame] | median / 95th pct. frame [ms] | "
             "speed-up vs OpenCV default | "
             "markers found | corner RMS [px] | markers with a corner > 1 px | wrong ids | whole-frame searches |",
             "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for size, stats in results.items():
        base = statistics.median(stats[METHODS[0]].cpu_ms)
        for method, s in stats.items():
            det = statistics.median(s.cpu_ms)
            pose = statistics.median(s.pose_ms)
            rms = np.sqrt(s.sq_err / max(s.corners, 1))
            full = f"{s.full_searches / max(s.frames, 1):.0%}" if method == METHODS[2] else "100 %"
            median = statistics.median(float(np.median(f)) for f in s.frame_ms)
            p95 = statistics.median(float(np.percentile(f, 95)) for f in s.frame_ms)
            lines.append(f"| {size} | {method} | {det:.2f} | {det + pose:.2f} | {median:.2f} / {p95:.1f} | "
                         f"{base / det:.1f}x | "
                         f"{s.found / max(s.truth, 1):.1%} | {rms:.3f} | {s.bad / max(s.found, 1):.1%} | "
                         f"{s.wrong} | {full} |")
    return "\n".join(lines)


def main() -> None:
    """Run, print, and write the results file."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="4 s clips, one repeat, print only")
    parser.add_argument("--repeats", type=int, default=3, help="timing repeats (the median is reported)")
    args = parser.parse_args()
    cv2.setNumThreads(1)
    repeats = 1 if args.quick else args.repeats
    results = {}
    for size, seconds in SECONDS.items():
        results[size] = benchmark(size, QUICK_SECONDS if args.quick else seconds, repeats)
        print(f"{size}: {results[size][METHODS[0]].frames} frames", flush=True)
    text = table(results)
    print(text)
    if args.quick:
        return
    frames = ", ".join(f"{s}: {r[METHODS[0]].frames} frames" for s, r in results.items())
    write_text(RESULTS,
        "# Detection speed and accuracy\n\n"
        f"Measured by `benchmarks/detection_speed.py` on {platform.machine()} ({len(os.sched_getaffinity(0))} "
        f"CPUs visible, shared; load average {os.getloadavg()[1]:.1f} over the last 5 minutes), "
        f"{date.today().isoformat()}: {', '.join(SCENARIOS)} at 15 FPS ({frames}), "
        f"single-threaded OpenCV, CPU time per frame (median of {repeats} repeats). Frames are decoded "
        "beforehand (decoding is not timed); '+ poses' adds IPPE poses of the rig's markers.\n\n"
        f"{text}\n{NOTES}")


if __name__ == "__main__":
    main()
