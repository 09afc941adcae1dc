"""MCAP archive size per camera-minute, write cost per frame, verify and recover speed.

Run: .venv/bin/python benchmarks/archive.py [SCENE_DIR]
(default: simulates config2-procedure5-weather, 20 s, into benchmarks/.cache/archive-scene once).
Writes benchmarks/results/archive.md.
"""

from __future__ import annotations

import json
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
from mcap.reader import make_reader

from benchmarks.report import write_results
from tracking.estimator import ESTIMATORS
from tracking.pipeline import FrameResult, track_rig
from tracking.rig import load_rig
from viewer.archive import ArchiveSink
from viewer.archive.audit import recover, verify
from viewer.archive.manifest import MANIFEST_NAME

REPO = Path(__file__).resolve().parents[1]
CACHE = REPO / "benchmarks" / ".cache" / "archive-scene"
SCENARIO = "config2-procedure5-weather"
DURATION_S = 20.0
MAX_FRAMES = 600  # all cameras together
MODES = (  # (label, frames keep the camera's packets, archive video format for frames without)
    ("camera's H.264 passed through (default)", True, "jpeg"),
    ("JPEG q80 (sources without H.264)", False, "jpeg"),
    ("JPEG re-encoded to H.264 (--video h264)", False, "h264"),
)


def scene_dir(arg: str | None) -> Path:
    """The scene to archive: the argument, or the cached simulation."""
    if arg:
        return Path(arg)
    if not (CACHE / "rig.yaml").is_file():
        from tracking.sim.command import run_simulate

        run_simulate(SCENARIO, CACHE, seed=None, duration=DURATION_S)
    return CACHE


def main() -> None:
    """Print and write the table."""
    scene = scene_dir(sys.argv[1] if len(sys.argv) > 1 else None)
    rig = load_rig(scene / "rig.yaml")
    truth = pd.read_csv(scene / "truth.csv")
    results: list[FrameResult] = []
    for r in track_rig(rig, keep_color=True, packets=True):
        results.append(r)
        if len(results) >= MAX_FRAMES:
            break
    estimates = list(ESTIMATORS["fused"](rig, (m for r in results  # as `topside track` feeds it
                                               for m in r.measurements)))
    events = sorted([(r.time, 0, i) for i, r in enumerate(results)] + [(e.time, 1, i) for i, e in enumerate(estimates)])
    span = {}
    for r in results:
        lo, hi = span.get(r.camera, (r.time, r.time))
        span[r.camera] = (min(lo, r.time), max(hi, r.time + 1 / 15))
    camera_minutes = sum(hi - lo for lo, hi in span.values()) / 60
    w, h = results[0].frame.gray.shape[1], results[0].frame.gray.shape[0]
    lines = [
        "# MCAP archive: size, write cost, verify speed",
        "",
        f"Scene `{scene.name}`: {len(rig.cameras)} cameras, {w}x{h}, first {len(results)} frames "
        f"({camera_minutes * 60:.1f} camera-seconds), {len(estimates)} fused estimates, truth.",
        "zstd chunks closed every second of capture time. Write cost per frame is the time in `ArchiveSink.on_frame`",
        "(annotations, transforms, health, digests, zstd; for JPEG the encoding; for re-encoded H.264 also decoding",
        "that JPEG and x264 `superfast` on one thread), excluding video decoding and tracking. One core of a 2-core",
        "machine shared with other jobs: treat times as upper bounds.",
        "The manifest per hour is estimated for 8 cameras and 2 cones (40 channels) from its bytes per block here.",
        "",
        "| frames | MB per camera-minute | GB per camera-hour | write ms per frame | verify MB/s (messages/s) "
        "| recover MB/s "
        "| messages recovered from 2/3 of the file | manifest per hour, 8 cameras |",
        "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |",
    ]
    for label, packets, video in MODES:
        frames = results if packets else [replace(r, frame=replace(r.frame, packet=None)) for r in results]
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "bench.mcap"
            sink = ArchiveSink(rig, path, {"mode": "fused"}, {}, truth, video=video)
            for _, kind, i in events:  # as the tracker interleaves them: by capture time
                if kind == 0:
                    sink.on_frame(frames[i])
                else:
                    sink.on_estimate(estimates[i])
            sink.close()
            size = path.stat().st_size
            report = verify(path)
            assert report.ok, report.errors
            with path.open("rb") as f:
                attachments = {a.name: a.data for a in make_reader(f).iter_attachments()}
            manifest = json.loads(attachments[MANIFEST_NAME])
            blocks = sum(len(c["blocks"]) for c in manifest["channels"].values())
            per_block = len(json.dumps(manifest["channels"])) / blocks
            cut = Path(tmp) / "cut.mcap"
            cut.write_bytes(path.read_bytes()[: size * 2 // 3])
            t1 = time.perf_counter()
            rec = recover(cut, Path(tmp) / "cut.recovered.mcap")
            recover_s = time.perf_counter() - t1
        channels_8 = 4 * 8 + 3 + 1 + 2 * 2  # 4 per camera, 3 transform topics, the log, offsets and truth of 2 cones
        lines.append(f"| {label} | {size / 1e6 / camera_minutes:.1f} | {size / 1e9 / camera_minutes * 60:.2f} | "
                     f"{1000 * sink.frame_seconds / len(results):.1f} | {report.mb_per_s:.0f} "
                     f"({report.messages / report.seconds / 1e3:.0f} k) | "
                     f"{size * 2 / 3 / 1e6 / recover_s:.0f} | {rec.messages} of {report.messages} | "
                     f"{channels_8 * 3600 * per_block / 1e6:.0f} MB |")
    write_results("archive", lines, echo=True)


if __name__ == "__main__":
    np.seterr(all="ignore")
    main()
