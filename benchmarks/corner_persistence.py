"""How much of a detected corner's error stays for a whole run: the evidence for estimator.noise.VIEW_SHAPE_BIAS_PX.

For every view (camera, marker) of the campaign's cached installations (benchmarks/campaign.py; rendered and detected
there, never here), each frame's detected corners against the simulator's true corners (truth_frames.csv, the same
lens): the error per corner coordinate, px. Per view over its whole run:

- persistent: the RMS over the 8 coordinates of their mean error (what no number of frames averages away; it holds
  the white part over √N, a few thousandths of a pixel);
- white: the RMS of what is left after a 1 s running mean;
- the filter's model: a bias that renews as the image travels (VIEW_BIAS_PX, VIEW_BIAS_RENEW_PX, VIEW_BIAS_TAU_S)
  keeps a whole run's mean near VIEW_BIAS_PX × √(τ/T) once the marker moves; what stays, in views whose marker moves as
  much as in still ones, is the part that renews with the image's shape (VIEW_SHAPE_BIAS_PX).

Frames whose corner is more than GROSS_PX off (a failed edge fit, a rain hit) are left out of a view's means and
counted. Views with fewer than MIN_FRAMES frames are left out.

Run: .venv/bin/python -m benchmarks.corner_persistence [--seeds 1-60,1047-1052,...] [--out FILE]
(default: every installation in the cache with detections of the current detection code).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pandas as pd

from benchmarks.accuracy import detect, detections_cache
from benchmarks.campaign import CACHE, parse_seeds
from tracking.estimator.noise import VIEW_BIAS_PX, VIEW_SHAPE_BIAS_PX
from tracking.outputs import write_text
from tracking.rig import dictionary_cells, load_rig

RESULTS = Path(__file__).resolve().parent / "results" / "corner_persistence.md"
GROSS_PX = 2.0  # a corner this far off its truth is a failed fit, not a bias
MIN_FRAMES = 30  # 2 s at 15 FPS
WINDOW = 15  # frames of the running mean that splits the white part off (1 s at 15 FPS)
STILL_PX = 0.05  # a view whose corners move less than this a frame (median) is still
TAIL_PX = 0.3  # views whose persistent error exceeds this are listed one by one
CELL_BINS = (0, 2.5, 3.5, 4.5, 6, 8, 12, 1000)  # px per code cell along the marker's shortest side
FORESHORTENING_BINS = (0, 0.6, 0.8, 0.9, 1.01)  # shortest side over longest
QUANTILES = (0.5, 0.68, 0.9, 0.95, 0.98)


def view_rows(scene: Path) -> list[dict]:
    """One row per view of an installation: its cells, foreshortening, motion, persistent and white error."""
    rig = load_rig(scene / "rig.yaml")
    cells = dictionary_cells(rig.dictionary)
    mounts = {c.name: c.mount for c in rig.cameras}
    bodies = {m.id: m.body for m in rig.markers}
    truth = pd.read_csv(scene / "truth_frames.csv").dropna(subset=["marker_id"])
    keys = zip(truth["camera"], (truth["capture_time"] * 1e4).round().astype(np.int64), truth["marker_id"].astype(int),
               strict=True)
    corners = truth[[f"c{k}{a}" for k in range(4) for a in "xy"]].to_numpy()
    true = dict(zip(keys, corners, strict=True))
    views: dict[tuple[str, int], list[tuple[np.ndarray, np.ndarray]]] = {}
    for camera, time, markers in detect(scene.name, scene):
        key = round(time * 1e4)
        for marker, c in markers.items():
            t = true.get((camera, key, int(marker)))
            if t is not None:
                views.setdefault((camera, int(marker)), []).append((np.asarray(c).reshape(-1) - t, t))
    rows = []
    for (camera, marker), v in views.items():
        if len(v) < MIN_FRAMES:
            continue
        e = np.array([a for a, _ in v])
        t = np.array([b for _, b in v])
        ok = np.abs(e).max(axis=1) < GROSS_PX
        if ok.sum() < MIN_FRAMES:
            continue
        q = t.reshape(-1, 4, 2)
        sides = np.linalg.norm(np.roll(q, -1, axis=1) - q, axis=2)
        white = e[ok] - pd.DataFrame(e[ok]).rolling(WINDOW, center=True, min_periods=WINDOW // 2).mean().to_numpy()
        rows.append({"installation": scene.name, "camera": camera, "mount": mounts.get(camera, "?"), "marker": marker,
                     "body": bodies.get(marker, "?"), "frames": len(e), "gross": float(1 - ok.mean()),
                     "cell_px": float(np.median(sides.min(axis=1)) / cells),  # along the shortest side, as the campaign
                     "foreshortening": float(np.median(sides.min(axis=1) / sides.max(axis=1))),
                     "travel_px": float(np.median(np.linalg.norm(np.diff(t, axis=0), axis=1)) / 2),
                     "persistent_px": float(np.sqrt(np.mean(e[ok].mean(axis=0) ** 2))),
                     "white_px": float(np.sqrt(np.nanmean(white**2)))})
    return rows


def _table(df: pd.DataFrame, by: str, bins: tuple) -> list[str]:
    groups = df.groupby(pd.cut(df[by], list(bins)), observed=True)["persistent_px"]
    lines = [f"| {by} | views | persistent median | 90th percentile | RMS |", "| --- | --- | --- | --- | --- |"]
    for interval, g in groups:
        lines.append(f"| {interval} | {len(g)} | {g.median():.3f} | {g.quantile(0.9):.3f} | "
                     f"{np.sqrt((g**2).mean()):.3f} |")
    return lines


def markdown(df: pd.DataFrame, seeds: str) -> str:
    """The results page of the installations of seeds (as given, or every one cached)."""
    p = df["persistent_px"]
    moving = df[df["travel_px"] >= STILL_PX]["persistent_px"]
    trimmed = p[p < TAIL_PX]
    q = " / ".join(f"{p.quantile(x):.3f}" for x in QUANTILES)
    lines = [
        "# How much of a corner's error stays for a whole run",
        "",
        f"Made by `benchmarks/corner_persistence.py --seeds {seeds}` (read its docstring for the method) from the "
        f"campaign's cached installations: {df['installation'].nunique()} installations, {len(df)} views (camera, "
        f"marker), {int(df['frames'].sum())} marker frames; "
        f"{100 * (df['gross'] * df['frames']).sum() / df['frames'].sum():.2f} % of frames with a corner more than "
        f"{GROSS_PX} px off were left out. Errors are per corner coordinate, px.",
        "",
        f"- persistent (a view's whole-run mean), quantiles {', '.join(f'{x:.0%}' for x in QUANTILES)} of the views: "
        f"{q}",
        f"- RMS over all views {np.sqrt((p**2).mean()):.3f}; over the {len(trimmed)} views under {TAIL_PX} px "
        f"{np.sqrt((trimmed**2).mean()):.3f}; over the {len(moving)} views whose marker moves "
        f"(≥ {STILL_PX} px a frame) {np.sqrt((moving**2).mean()):.3f}",
        f"- white (what a 1 s running mean leaves) median {df['white_px'].median():.3f}",
        f"- the filter: VIEW_BIAS_PX {VIEW_BIAS_PX} (renews as the image travels), VIEW_SHAPE_BIAS_PX "
        f"{VIEW_SHAPE_BIAS_PX} (renews as its shape changes: none of these runs changes it much)",
        "",
        "## By pixels per code cell",
        "",
        *_table(df, "cell_px", CELL_BINS),
        "",
        "## By foreshortening (shortest side over longest)",
        "",
        *_table(df, "foreshortening", FORESHORTENING_BINS),
        "",
        "## By mount",
        "",
        "| mount | views | persistent median | 90th percentile | RMS | white median |",
        "| --- | --- | --- | --- | --- | --- |",
    ]
    for mount, g in df.groupby("mount"):
        lines.append(f"| {mount} | {len(g)} | {g['persistent_px'].median():.3f} | "
                     f"{g['persistent_px'].quantile(0.9):.3f} | {np.sqrt((g['persistent_px'] ** 2).mean()):.3f} | "
                     f"{g['white_px'].median():.3f} |")
    lines += ["", f"## Views whose persistent error exceeds {TAIL_PX} px", "",
              "| installation | camera | marker | body | px/cell | foreshortening | travel px/frame | persistent "
              "| white |",
              "| --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for r in df[df["persistent_px"] > TAIL_PX].sort_values("persistent_px").itertuples():
        lines.append(f"| {r.installation} | {r.camera} | {r.marker} | {r.body} | {r.cell_px:.1f} | "
                     f"{r.foreshortening:.2f} | {r.travel_px:.2f} | {r.persistent_px:.3f} | {r.white_px:.3f} |")
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", help="seeds of cached installations (default: every one with detections)")
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args()
    scenes = [CACHE / f"random-{s}" for s in parse_seeds(args.seeds)] if args.seeds else sorted(CACHE.glob("random-*"))
    scenes = [s for s in scenes if (s / "truth_frames.csv").is_file() and detections_cache(s).is_file()]
    if not scenes:
        raise SystemExit(f"{CACHE}: no installation with detections of the current code; run benchmarks.campaign")
    df = pd.DataFrame([row for s in scenes for row in view_rows(s)])
    text = markdown(df, args.seeds or "(every one cached)")
    write_text(args.out, text)
    print(text)


if __name__ == "__main__":
    main()
