"""MCAP archive size per camera-minute, write cost per frame, verify and recover speed.

Run: .venv/bin/python benchmarks/archive.py [SCENE_DIR]
(default: simulates config2-procedure5-weather, 20 s, into benchmarks/.cache/archive-scene once).
Writes benchmarks/results/archive.md.
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

from tracking.fusion import ESTIMATORS
from tracking.pipeline import FrameResult, track_rig
from tracking.rig import load_rig
from viewer.archive import ArchiveSink
from viewer.audit import recover, verify
from viewer.manifest import MANIFEST_NAME

REPO = Path(__file__).resolve().parents[1]
CACHE = REPO / "benchmarks" / ".cache" / "archive-scene"
SCENARIO = "config2-procedure5-weather"
DURATION_S = 20.0
MAX_FRAMES = 600  # all cameras together


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
    for r in track_rig(rig, keep_color=True):
        results.append(r)
        if len(results) >= MAX_FRAMES:
            break
    estimates = list(ESTIMATORS["fused"](rig, (o for r in results for o in r.offsets)))
    span = {}
    for r in results:
        lo, hi = span.get(r.camera, (r.time, r.time))
        span[r.camera] = (min(lo, r.time), max(hi, r.time + 1 / 15))
    camera_minutes = sum(hi - lo for lo, hi in span.values()) / 60
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "bench.mcap"
        t0 = time.perf_counter()
        sink = ArchiveSink(rig, path, {"mode": "fused"}, {}, truth)
        for r in results:
            sink.on_frame(r)
        for e in estimates:
            sink.on_estimate(e)
        sink.close()
        total_s = time.perf_counter() - t0
        size = path.stat().st_size
        report = verify(path)
        assert report.ok, report.errors
        from mcap.reader import make_reader

        with path.open("rb") as f:
            manifest = next(a for a in make_reader(f).iter_attachments() if a.name == MANIFEST_NAME)
        cut = Path(tmp) / "cut.mcap"
        cut.write_bytes(path.read_bytes()[: size * 2 // 3])
        t1 = time.perf_counter()
        rec = recover(cut, Path(tmp) / "cut.recovered.mcap")
        recover_s = time.perf_counter() - t1
    w, h = results[0].frame.gray.shape[1], results[0].frame.gray.shape[0]
    channels = 14 + 4 * (len(rig.cameras) - 2)
    blocks_per_hour = channels * 3600
    per_block = len(manifest.data) / max(1, sum(len(c["blocks"]) for c in __import__("json").loads(manifest.data)
                                                ["channels"].values()))
    lines = [
        "# MCAP archive: size, write cost, verify speed",
        "",
        f"Scene `{scene.name}`: {len(rig.cameras)} cameras, {w}x{h}, first {len(results)} frames "
        f"({camera_minutes * 60:.1f} camera-seconds), {len(estimates)} fused estimates, truth.",
        "Frames are JPEG q80 colour (the .rrd's encoding), zstd chunks flushed every second of capture time.",
        "One core of a 2-core machine shared with other jobs: treat times as upper bounds.",
        "",
        "| measure | value |",
        "| --- | ---: |",
        f"| archive size per camera-minute | {size / 1e6 / camera_minutes:.1f} MB |",
        f"| archive size per camera-hour | {size / 1e9 / camera_minutes * 60:.2f} GB |",
        f"| write cost per frame (JPEG encode, annotations, transforms, health, digest, zstd) | "
        f"{1000 * sink.frame_seconds / len(results):.1f} ms |",
        f"| total write time per frame (frames + estimates + close) | {1000 * total_s / len(results):.1f} ms |",
        f"| verify speed (CRCs, indexes, SHA-256 of every message) | {report.mb_per_s:.0f} MB/s |",
        f"| recover speed (2/3 of the file, rewritten) | {size * 2 / 3 / 1e6 / recover_s:.0f} MB/s |",
        f"| messages recovered from the first 2/3 | {rec.messages} of {report.messages} |",
        f"| manifest size | {len(manifest.data) / 1e3:.1f} kB ({per_block:.0f} B per channel-second block) |",
        f"| manifest per hour, {channels} channels at 1 s blocks (estimate) | "
        f"{blocks_per_hour * per_block / 1e6:.1f} MB |",
        "",
    ]
    text = "\n".join(lines)
    print(text)
    (REPO / "benchmarks" / "results").mkdir(parents=True, exist_ok=True)
    (REPO / "benchmarks" / "results" / "archive.md").write_text(text)


if __name__ == "__main__":
    np.seterr(all="ignore")
    main()
