"""Recording size per camera-minute and logging cost per frame, for the ways of storing frames.

Run: .venv/bin/python benchmarks/recording.py [SCENE_DIR]   (default: recordings/demo from `make demo`)
Writes benchmarks/results/recording.md.
"""

from __future__ import annotations

import dataclasses
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

from benchmarks.report import write_results
from tracking.paper import paper_filter
from tracking.pipeline import FrameResult, track_rig
from tracking.rig import load_rig
from viewer.session import Recorder

REPO = Path(__file__).resolve().parents[1]
MAX_FRAMES = 600  # per variant, all cameras together
VARIANTS = [  # (name, JPEG quality, colour)
    ("JPEG q95 colour", 95, True),
    ("JPEG q80 colour", 80, True),
    ("JPEG q60 colour", 60, True),
    ("JPEG q80 grey", 80, False),
]


def frames(scene: Path, limit: int) -> list[FrameResult]:
    """The first processed frames of a scene, kept in memory so every variant logs the same ones."""
    out = []
    for result in track_rig(load_rig(scene / "rig.yaml"), keep_color=True):
        out.append(result)
        if len(out) >= limit:
            break
    return out


def run_variant(scene: Path, results: list[FrameResult], quality: int, colour: bool) -> tuple[float, float, float]:
    """(MB per camera-minute, logging ms per frame, seconds of video covered)."""
    rig = load_rig(scene / "rig.yaml")
    truth = pd.read_csv(scene / "truth.csv")
    with tempfile.TemporaryDirectory() as tmp:
        rrd = Path(tmp) / "bench.rrd"
        recorder = Recorder(rig, rrd, truth, jpeg_quality=quality)
        t0 = time.perf_counter()
        for r in results:
            frame = r.frame if colour else dataclasses.replace(r.frame, bgr=None)
            recorder.on_frame(dataclasses.replace(r, frame=frame))
        for e in paper_filter(rig, (o for r in results for o in r.offsets)):
            recorder.on_estimate(e)
        recorder.close()
        elapsed = time.perf_counter() - t0
        size_mb = rrd.stat().st_size / 1e6
    per_cam_s = {}
    for r in results:
        lo, hi = per_cam_s.get(r.camera, (r.time, r.time))
        per_cam_s[r.camera] = (min(lo, r.time), max(hi, r.time))
    camera_minutes = sum(hi - lo for lo, hi in per_cam_s.values()) / 60.0
    return size_mb / camera_minutes, 1000 * elapsed / len(results), camera_minutes * 60


def main() -> None:
    """Print and write the table."""
    scene = Path(sys.argv[1]) if len(sys.argv) > 1 else REPO / "recordings" / "demo"
    if not (scene / "rig.yaml").is_file():
        sys.exit(f"{scene}/rig.yaml not found: run `make demo` first or pass a simulated scene folder")
    results = frames(scene, MAX_FRAMES)
    w, h = results[0].frame.gray.shape[1], results[0].frame.gray.shape[0]
    rows = []
    for name, quality, colour in VARIANTS:
        mb_per_cam_min, ms, seconds = run_variant(scene, results, quality, colour)
        rows.append((name, mb_per_cam_min, mb_per_cam_min * 60 / 1000, ms))
    mp4 = sum(p.stat().st_size for p in scene.glob("*.mp4")) / 1e6
    video_s = pd.read_csv(scene / "truth.csv")["time"].max()
    n_cams = len(list(scene.glob("*.mp4")))
    lines = [
        "# Recording size and logging cost",
        "",
        f"Scene `{scene.name}`: {n_cams} cameras, {w}x{h}, first {len(results)} frames ({seconds:.1f} camera-seconds).",
        "Logging cost is the time spent in `Recorder.on_frame` / `on_estimate` (JPEG encoding, corners, axes,",
        "frusta, marker frames, health, offsets), excluding decoding and tracking. One core.",
        "",
        "| frames stored as | MB per camera-minute | GB per camera-hour | logging ms per frame |",
        "| --- | ---: | ---: | ---: |",
        *[f"| {n} | {mb:.1f} | {gb:.2f} | {ms:.1f} |" for n, mb, gb, ms in rows],
        f"| (for scale) the simulator's H.264 videos | {mp4 / (n_cams * video_s / 60):.1f} | "
        f"{mp4 / (n_cams * video_s / 60) * 60 / 1000:.2f} | — |",
        "",
    ]
    write_results("recording", lines, echo=True)


if __name__ == "__main__":
    np.seterr(all="ignore")
    main()
