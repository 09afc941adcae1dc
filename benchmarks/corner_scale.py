"""Corner scale bias by cell size, blur and surround: how much too small or too large the edge fit reads a marker,
with the area edge (`--refine edges`, the default) and with the blurred-profile model (`--refine blurred`).

A marker's scale error is the least-squares factor between its corner errors and its true centre-to-corner
vectors (‰; negative = reads small = too far away). Each row renders 1 m DICT_6X6_250 markers facing the camera
with tests/synthetic.py (exact pixel coverage), at random sub-pixel positions and 5-40° of roll, with the cells
CELL_PX pixels wide, blurs them, and refines corners started 0.3 px off the truth. The surround is either the
synthetic renderer's one-cell white quiet zone on a grey background, or white all round (the simulator's plates
have two cells of quiet zone). Per id, the scale errors are averaged over PLACEMENTS renders: "ids" gives the
lowest and highest of those per-id means, and the depth column what the mean scale error makes of a marker's
depth at that cell size with the paper's camera (PAPER_K, f = 1258 px: depth = f × 0.125 m / cell).

    .venv/bin/python -m benchmarks.corner_scale    # ~2 min, writes benchmarks/results/corner_scale.md
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pandas as pd

from benchmarks.corners import marker_pose
from tests.synthetic import BACKGROUND, PAPER_K, PAPER_SIZE, WHITE, PlacedMarker, render, scale_error, true_corners
from tracking.camera import CameraModel
from tracking.corners import refine_corners

RESULTS = Path(__file__).resolve().parent / "results" / "corner_scale.md"
CELL_PX = (2.8, 3.5, 4.2, 5.3, 7.0)  # cell width in the image
BLURS = (0.0, 0.7, 1.0)  # Gaussian σ, px
SURROUNDS = {"one white cell, then grey": BACKGROUND, "white all round": WHITE}
IDS = (0, 1, 4, 7, 9, 23, 42, 101)
PLACEMENTS = 6
START_NOISE_PX = 0.3
ROLL_RANGE_DEG = (5.0, 40.0)
CELLS = 8  # cells across the black square (6x6 bits + border)
SEED = 20261122


def run() -> pd.DataFrame:
    """One row per (surround, blur, cell size, id): the mean scale error over the placements."""
    rng = np.random.default_rng(SEED)
    camera = CameraModel(K=PAPER_K, dist=np.zeros(5), width=PAPER_SIZE[0], height=PAPER_SIZE[1])
    rows = []
    for surround, background in SURROUNDS.items():
        for blur in BLURS:
            for cell in CELL_PX:
                distance = PAPER_K[0, 0] * 1.0 / CELLS / cell
                for marker_id in IDS:
                    errors = []
                    for _ in range(PLACEMENTS):
                        roll = rng.uniform(*ROLL_RANGE_DEG) * rng.choice([-1.0, 1.0])
                        u, v = rng.uniform(300, 620), rng.uniform(200, 400)
                        placed = PlacedMarker(marker_id, marker_pose(distance, 0.0, u, v, roll), 1.0)
                        gray = render(PAPER_K, np.zeros(5), PAPER_SIZE, [placed], blur=blur, background=background)
                        truth = true_corners(PAPER_K, np.zeros(5), placed)
                        start = truth + rng.normal(0, START_NOISE_PX, truth.shape)
                        errors.append([scale_error(refine_corners(gray, start, camera, blur_model=model), truth)
                                       for model in (False, True)])
                    edges, blurred = np.mean(errors, axis=0)
                    rows.append({"surround": surround, "blur px": blur, "cell px": cell, "distance m": distance,
                                 "id": marker_id, "scale": edges, "scale blurred": blurred})
    return pd.DataFrame(rows)


def report(df: pd.DataFrame, seconds: float) -> str:
    """The markdown report: per surround, blur and cell size, the scale error over ids and its depth error."""
    g = df.groupby(["surround", "blur px", "cell px"], sort=False)
    table = g.agg(distance=("distance m", "first"), mean=("scale", "mean"), low=("scale", "min"),
                  high=("scale", "max"), b_mean=("scale blurred", "mean"), b_low=("scale blurred", "min"),
                  b_high=("scale blurred", "max")).reset_index()
    lines = ["# Corner scale bias by cell size, blur and surround", "", __doc__.split("\n\n")[0].strip(), "",
             f"{len(IDS)} ids × {PLACEMENTS} placements per row; run time {seconds:.0f} s.", "",
             "| surround | blur σ px | cell px | depth m | edges: scale error ‰ (mean over ids) "
             "| ids: lowest, highest ‰ | depth error mm | blurred: scale error ‰ | ids: lowest, highest ‰ "
             "| depth error mm |",
             "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for r in table.itertuples():
        lines.append(f"| {r.surround} | {r._2:.1f} | {r._3:.1f} | {r.distance:.1f} | {r.mean * 1e3:+.2f} "
                     f"| {r.low * 1e3:+.2f}, {r.high * 1e3:+.2f} | {-r.mean * r.distance * 1e3:+.0f} "
                     f"| {r.b_mean * 1e3:+.2f} | {r.b_low * 1e3:+.2f}, {r.b_high * 1e3:+.2f} "
                     f"| {-r.b_mean * r.distance * 1e3:+.0f} |")
    return "\n".join(lines) + "\n"


def main() -> None:
    """Run, print and write the report."""
    t0 = time.perf_counter()
    df = run()
    text = report(df, time.perf_counter() - t0)
    print(text)
    RESULTS.write_text(text)


if __name__ == "__main__":
    main()
