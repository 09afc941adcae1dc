"""Fine passes of the edge fit: one (the default) against two, on sharp and on lens-blurred simulator pictures.

The edge fit runs a coarse pass, then ITERATIONS - 1 fine passes (tracking/corners.py). The coarse pass can land
half a pixel off on small cells, and one fine pass from there reads its black or white level on the edge's own
ramp; a second fine pass removes that. Under blur the neighbouring edges' glow in the levels is taken out (the glow
correction, benchmarks/corner_scale.py), yet one pass still does better there, for a reason not found yet.

Procedures 1 and 2 (configuration 1, fog and rain, CRF 22, 15 FPS) from the accuracy benchmark's cache, rendered
sharp (the scenarios' default) and with weather.lens_blur 0.7 px, are detected with one and with two fine passes.
Per variant: the mean outward offset of every (camera, marker, edge) over the run against truth_frames.csv (its
RMS over those edges and the largest), the mean scale error of every (camera, marker) (RMS over them; the stern
cameras' depth, hence y, follows it: 1 per mille is 30 mm at 30 m), the median of the markers' RMS corner errors,
and the live filter's e_MAE and |e|max per axis at the monitored cones (TopsideFilter on the detections).

    .venv/bin/python -m benchmarks.fine_passes    # ~2 min with the detections cached (each one not cached:
                                                  # 1-2.5 min on one core); writes benchmarks/results/fine_passes.md
"""

from __future__ import annotations

import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import pandas as pd

import tracking.corners
from benchmarks.accuracy import detect, detections_cache, measure, render, with_mounts
from benchmarks.fusion_diagnosis import errors, true_corners
from tests.synthetic import scale_error
from tracking.estimator import TopsideFilter
from tracking.rig import load_rig

RESULTS = Path(__file__).resolve().parent / "results" / "fine_passes.md"
RUNS = ("config1-procedure1", "config1-procedure2")
PICTURES = {"sharp": None, "lens blur σ 0.7 px": {"lens_blur": 0.7}}  # name: weather changed
FINE_PASSES = (1, 2)
FPS = 15.0
MIN_UNOCCLUDED = 0.99  # markers the simulator drew whole
MAX_CORNER_ERROR_PX = 1.0  # a corner further off is a failed fit, not a bias: left out of the edge statistics
MIN_FRAMES = 50  # (camera, marker) pairs seen in fewer frames are left out of the edge statistics


def detections(name: str, scene: Path, passes: int) -> tuple[list[tuple[str, float, dict[int, np.ndarray]]], bool]:
    """The scene's detections with that many fine passes (cached beside the accuracy benchmark's), and whether they
    were detected now rather than read from the cache."""
    default = tracking.corners.ITERATIONS - 1
    cache = detections_cache(scene, "" if passes == default else f"-fine{passes}")
    fresh = not cache.is_file()
    tracking.corners.ITERATIONS = passes + 1  # this worker process only
    try:
        return detect(name, scene, cache=cache), fresh
    finally:
        tracking.corners.ITERATIONS = default + 1


def edge_offsets(corners: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Outward offsets (4,) of the edges k -> k+1 of corners (4, 2) from the true edges of truth (4, 2), px."""
    centre = truth.mean(axis=0)
    out = np.empty(4)
    for k in range(4):
        a, b = truth[k], truth[(k + 1) % 4]
        d = (b - a) / np.linalg.norm(b - a)
        n = np.array([d[1], -d[0]])
        n *= np.sign(n @ ((a + b) / 2 - centre))
        out[k] = ((corners[k] - a + corners[(k + 1) % 4] - b) / 2) @ n
    return out


def corner_stats(found: list, truth: dict[tuple[str, float, int], np.ndarray]) -> dict[str, float]:
    """RMS and largest of the per-(camera, marker, edge) mean edge offsets and the median RMS corner error (px), and
    the RMS of the per-(camera, marker) mean scale errors (per mille)."""
    offsets: dict[tuple[str, int], list[np.ndarray]] = {}
    scales: dict[tuple[str, int], list[float]] = {}
    rms = []
    for camera, t, markers in found:
        for marker_id, c in markers.items():
            q = truth.get((camera, round(t, 3), marker_id))
            if q is None:
                continue
            c = np.asarray(c, dtype=float).reshape(4, 2)
            if np.abs(c - q).max() > MAX_CORNER_ERROR_PX:
                continue
            rms.append(np.sqrt(np.mean((c - q) ** 2)))
            offsets.setdefault((camera, marker_id), []).append(edge_offsets(c, q))
            scales.setdefault((camera, marker_id), []).append(scale_error(c, q))
    means = np.array([np.mean(v, axis=0) for v in offsets.values() if len(v) >= MIN_FRAMES])
    scale = np.array([np.mean(v) for v in scales.values() if len(v) >= MIN_FRAMES])
    return {"edge_rms": float(np.sqrt(np.mean(means**2))), "edge_max": float(np.abs(means).max()),
            "scale_rms": float(np.sqrt(np.mean(scale**2))) * 1e3, "corner_median": float(np.median(rms))}


def run(name: str, pictures: str, passes: int) -> dict:
    """One variant of one procedure: corner statistics and the live filter's errors."""
    scene = render(name, FPS, PICTURES[pictures])
    found, fresh = detections(name, scene, passes)
    rig = with_mounts(load_rig(scene / "rig.yaml"), name)
    truth = pd.read_csv(scene / "truth.csv")
    monitored = sorted({p.cone for p in rig.all_pairs()})
    err = errors(TopsideFilter(rig), measure(rig, found), truth, monitored)
    e = err[["ex", "ey", "ez"]].abs().to_numpy() * 1e3
    stats = corner_stats(found, true_corners(scene, MIN_UNOCCLUDED))
    return {"name": name, "pictures": pictures, "passes": passes, **stats, "mae": e.mean(axis=0), "max": e.max(axis=0),
            "detected": fresh}


def table(results: list[dict]) -> str:
    """The markdown table, one row per (pictures, passes)."""
    lines = ["| pictures | fine passes | edge offsets: RMS, largest [px] | marker scale errors: RMS [‰] | "
             "median corner error [px] | "
             + " | ".join(f"{n.split('-')[1]}: e_MAE x / y / z [mm] | {n.split('-')[1]}: abs(e)max x / y / z [mm]"
                          for n in RUNS) + " |",
             "| --- | ---: | ---: | ---: | ---: |" + " ---: | ---: |" * len(RUNS)]
    for pictures in PICTURES:
        for passes in FINE_PASSES:
            rows = [r for r in results if r["pictures"] == pictures and r["passes"] == passes]
            by_run = {r["name"]: r for r in rows}
            edges = " / ".join(f"{r['edge_rms']:.3f}, {r['edge_max']:.3f}" for r in rows)
            scale = " / ".join(f"{r['scale_rms']:.2f}" for r in rows)
            corner = " / ".join(f"{r['corner_median']:.3f}" for r in rows)
            cells = " | ".join(" / ".join(f"{v:.1f}" for v in by_run[n]["mae"]) + " | "
                               + " / ".join(f"{v:.0f}" for v in by_run[n]["max"]) for n in RUNS)
            default = " (default)" if passes == tracking.corners.ITERATIONS - 1 else ""
            lines.append(f"| {pictures} | {passes}{default} | {edges} | {scale} | {corner} | {cells} |")
    return "\n".join(lines)


def main() -> None:
    """Run every variant, print and write the table."""
    start = time.perf_counter()
    jobs = [(n, p, k) for p in PICTURES for k in FINE_PASSES for n in RUNS]
    with ProcessPoolExecutor(max_workers=2) as pool:
        results = list(pool.map(run, *zip(*jobs, strict=True)))
    text = table(results)
    print(text)
    RESULTS.write_text(
        "# Fine passes of the edge fit\n\n"
        + __doc__.split("\n\n")[1].replace("\n", " ") + "\n\n" + __doc__.split("\n\n")[2].replace("\n", " ")
        + f"\n\nCorner statistics per procedure (1 / 2). Run time {time.perf_counter() - start:.0f} s, detecting "
        f"{sum(r['detected'] for r in results)} of the {len(results)} variants (the others from the cache).\n\n"
        + text + "\n")


if __name__ == "__main__":
    main()
