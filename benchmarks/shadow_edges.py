"""Shadow edges beside a marker's border: how far a soft shadow line on the plate's white margin pulls the edge fit.

The campaign's worst tilt and accuracy misses (docs/method.md#fusion-the-default: random-10002, 8006, 11008) vanish
when the same installations are rendered without shadows: a shadow edge lying along a border, on the white margin,
moves with the topside and drags that border's fitted line. This measures the drag on exact renders. Each row renders
1 m DICT_6X6_250 markers facing the camera (tests/synthetic.py, white all round, as the simulator's plates) with the
cells CELL_PX wide and a 0.7 px blur, darkens everything beyond a line parallel to the right border by SHADOW_DEPTH of
its brightness, the shadow's edge softened over SOFT_PX, at a distance from the border (in cells), and refines
corners started 0.3 px off the truth with the default area edge, as it is (levels read a few blur σ out where the
cells are wide against the blur: tracking.corners._tight_edge) and as it was before that (levels half a cell, at most
4 px, out). The right border's error is the mean x error of its two corners (+ = read outward, towards the shadow);
"per px" is its change per pixel the shadow moves there (what a shadow sweeping over the plate does to the corners,
frame after frame).

    .venv/bin/python -m benchmarks.shadow_edges    # ~1 min, writes benchmarks/results/shadow_edges.md
"""

from __future__ import annotations

import time

import numpy as np
import pandas as pd

from benchmarks.corners import levels_half_a_cell_out, marker_pose
from benchmarks.report import write_results
from tests.synthetic import PAPER_K, PAPER_SIZE, WHITE, PlacedMarker, render, true_corners
from tracking.camera import CameraModel
from tracking.corners import refine_corners

CELL_PX = (4.0, 8.0, 13.0)  # cell width in the image (13 px: random-10002's drone2, 107 px a side)
DISTANCES_CELLS = (0.25, 0.5, 0.75, 1.0, 1.5, 2.0, 3.0)  # shadow edge beyond the right border
SHADOW_DEPTH = 0.5  # share of the margin's brightness the shadow takes away
SOFT_PX = 1.5  # the shadow edge's softness (logistic scale), px
BLUR_PX = 0.7
STEP_PX = 0.25  # the shadow moved by this to measure the drag per pixel
IDS = (0, 7, 23, 42)
PLACEMENTS = 4
START_NOISE_PX = 0.3
CELLS = 8
SEED = 20261129


def shadowed(gray: np.ndarray, x_edge: float) -> np.ndarray:
    """The image darkened beyond the vertical line x = x_edge (px), softly."""
    x = np.arange(gray.shape[1], dtype=np.float64)
    share = SHADOW_DEPTH / (1.0 + np.exp(-(x - x_edge) / SOFT_PX))
    return np.clip(gray * (1.0 - share)[None, :], 0, 255).astype(np.uint8)


def right_border_error(gray: np.ndarray, truth: np.ndarray, start: np.ndarray, camera: CameraModel) -> float:
    """Mean x error (px) of the two corners of the right border (TR, BR)."""
    return float(np.mean(refine_corners(gray, start, camera)[[1, 2], 0] - truth[[1, 2], 0]))


def run() -> pd.DataFrame:
    """One row per (cell size, distance, id, placement): the right border's error and its drag per pixel, as the
    area edge is and with its levels half a cell out ("wide")."""
    rows = pd.concat([_run(), _run_wide()], axis=1)
    return rows.loc[:, ~rows.columns.duplicated()]


def _run_wide() -> pd.DataFrame:
    """_run with the levels half a cell out (the blur-matched window off), its columns suffixed " wide"."""
    with levels_half_a_cell_out():
        wide = _run()
    return wide.rename(columns={c: f"{c} wide" for c in ("plain", "error", "per px")})


def _run() -> pd.DataFrame:
    """One row per (cell size, distance, id, placement): the right border's error and its drag per pixel."""
    rng = np.random.default_rng(SEED)
    camera = CameraModel(K=PAPER_K, dist=np.zeros(5), width=PAPER_SIZE[0], height=PAPER_SIZE[1])
    rows = []
    for cell in CELL_PX:
        distance = PAPER_K[0, 0] * 1.0 / CELLS / cell
        for marker_id in IDS:
            for _ in range(PLACEMENTS):
                u, v = rng.uniform(400, 520), rng.uniform(260, 340)
                placed = PlacedMarker(marker_id, marker_pose(distance, 0.0, u, v, 0.0), 1.0)
                clean = render(PAPER_K, np.zeros(5), PAPER_SIZE, [placed], blur=BLUR_PX, background=WHITE)
                truth = true_corners(PAPER_K, np.zeros(5), placed)
                start = truth + rng.normal(0, START_NOISE_PX, truth.shape)
                border = float(truth[[1, 2], 0].mean())
                plain = right_border_error(clean, truth, start, camera)
                for d in DISTANCES_CELLS:
                    x = border + d * cell
                    at = right_border_error(shadowed(clean, x), truth, start, camera)
                    moved = right_border_error(shadowed(clean, x + STEP_PX), truth, start, camera)
                    rows.append({"cell px": cell, "shadow cells": d, "id": marker_id, "plain": plain,
                                 "error": at, "per px": (moved - at) / STEP_PX})
    return pd.DataFrame(rows)


def report(df: pd.DataFrame, seconds: float) -> list[str]:
    """The markdown report's lines: per cell size and shadow distance, the border's error and drag."""
    g = df.groupby(["cell px", "shadow cells"]).agg(
        plain=("plain", "mean"), error=("error", "mean"), spread=("error", "std"), drag=("per px", "mean"),
        drag_max=("per px", lambda s: s.abs().max()), error_wide=("error wide", "mean"),
        drag_wide=("per px wide", "mean"), drag_max_wide=("per px wide", lambda s: s.abs().max())).reset_index()
    lines = ["# Shadow edges beside a marker's border", "", __doc__.split("\n\n")[1].strip(), "",
             f"{len(IDS)} ids × {PLACEMENTS} placements per row; shadow depth {SHADOW_DEPTH:.0%}, softness "
             f"{SOFT_PX} px, blur σ {BLUR_PX} px; run time {seconds:.0f} s.", "",
             "| cell px | shadow edge beyond the border [cells] | border error without shadow [px] | with it [px] "
             "| spread [px] | drag per px the shadow moves (mean; largest) | levels half a cell out: with it [px] "
             "| their drag (mean; largest) |",
             "| ---: | ---: | ---: | ---: | ---: | --- | ---: | --- |"]
    for r in g.itertuples():
        lines.append(f"| {r._1:.0f} | {r._2:.2f} | {r.plain:+.3f} | {r.error:+.3f} | {r.spread:.3f} | "
                     f"{r.drag:+.3f}; {r.drag_max:.3f} | {r.error_wide:+.3f} | {r.drag_wide:+.3f}; "
                     f"{r.drag_max_wide:.3f} |")
    return lines


def main() -> None:
    """Run, print and write the report."""
    t0 = time.perf_counter()
    df = run()
    write_results("shadow_edges", report(df, time.perf_counter() - t0), echo=True)


if __name__ == "__main__":
    main()
