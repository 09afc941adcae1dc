"""Corner refinement benchmark: bias, error and IPPE depth error of every refinement on rendered markers.

Renders 1 m DICT_6X6_250 markers with tests/synthetic.py (exact, supersampled) at 10..45 m, 0/30/60 degrees
off the normal, with and without lens distortion, then degrades each frame with blur, noise and JPEG
compression, detects with every refinement and compares the corners with the exact projections.

    .venv/bin/python benchmarks/corners.py            # full run (~2-3 min), writes benchmarks/results/corners.md
    .venv/bin/python benchmarks/corners.py --quick    # a smaller grid, prints only
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import pandas as pd

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

import tracking.corners  # noqa: E402
from tests.synthetic import PAPER_K, PAPER_SIZE, PlacedMarker, render, true_corners  # noqa: E402
from tracking.camera import CameraModel  # noqa: E402
from tracking.corners import refine_corners_batch  # noqa: E402
from tracking.detection import (  # noqa: E402
    DEFAULT_REFINEMENT,
    EDGES_START,
    MarkerDetection,
    Refinement,
    detector_parameters,
)
from tracking.pose import estimate_pose  # noqa: E402

RESULTS = REPO / "benchmarks" / "results" / "corners.md"
MARKER_SIZE = 1.0  # m
DISTANCES = (10, 15, 20, 25, 30, 35, 40, 45)  # m
ANGLES = (0, 30, 60)  # degrees off the marker normal (yaw about the marker's vertical axis)
DISTORTIONS = {"none": np.zeros(5), "k1=-0.1,k2=0.05": np.array([-0.1, 0.05, 0.0, 0.0, 0.0])}
NOISES = (0.0, 2.0, 5.0)  # grey levels
BLURS = (0.0, 0.7)  # Gaussian sigma, px
COMPRESSIONS = ("none", "jpeg80")
JPEG_QUALITY = 80
SLOTS = [(u, v) for v in (150, 450) for u in (153, 460, 767)]  # one marker per slot: six placements per frame
SLOT_JITTER_PX = 40.0
ROLL_RANGE_DEG = (5.0, 40.0)  # in-plane roll, either sign: keeps edges off the pixel axes, where the
# renderer's 1/8 px supersampling would itself put the true edge up to 1/16 px off
SUBPIX_WINDOWS = (2, 3, 4, 5)
SEED = 20240611
REPORT_DISTANCES = (20, 30, 40)
CONDITIONS = {  # name: (noise, blur, compression), for the per-distance tables
    "clean": (0.0, 0.0, "none"),
    "noisy (σ 5, blur 0.7)": (5.0, 0.7, "none"),
    "JPEG 80 (σ 2, blur 0.7)": (2.0, 0.7, "jpeg80"),
}


@dataclass(frozen=True)
class Method:
    """One refinement under test: an OpenCV detector, optionally followed by the edge refinement."""

    name: str
    detector: cv2.aruco.ArucoDetector | None  # None: reuse the detections of `start`
    start: str | None = None
    camera: bool = True  # edges: fit in undistorted pixels with the true camera


def methods(dictionary: cv2.aruco.Dictionary) -> list[Method]:
    """Every refinement compared: OpenCV's, SUBPIX at several windows, and the edge fit."""
    out = []
    for refinement in (Refinement.NONE, Refinement.SUBPIX, Refinement.CONTOUR, Refinement.APRILTAG):
        windows = SUBPIX_WINDOWS if refinement == Refinement.SUBPIX else (None,)
        for win in windows:
            params = detector_parameters(refinement)
            if win is not None:
                params.cornerRefinementWinSize = win
            name = refinement.value if win is None else f"subpix{win}"
            out.append(Method(name, cv2.aruco.ArucoDetector(dictionary, params)))
    start = f"subpix{detector_parameters(EDGES_START).cornerRefinementWinSize}" \
        if EDGES_START == Refinement.SUBPIX else EDGES_START.value
    out.append(Method("edges", None, start))
    out.append(Method("edges (no camera)", None, start, camera=False))
    other = "none" if start != "none" else f"subpix{detector_parameters(Refinement.SUBPIX).cornerRefinementWinSize}"
    out.append(Method(f"edges from {other}", None, other))
    return out


@contextmanager
def levels_half_a_cell_out() -> Iterator[None]:
    """Within it, the edge fit reads its levels half a cell out everywhere, as before the blur-matched window
    (tracking.corners._tight_edge never applies); the shadow and real-corner benchmarks compare the two."""
    kept = tracking.corners.TIGHT_LEVEL_SIGMAS
    tracking.corners.TIGHT_LEVEL_SIGMAS = np.inf
    try:
        yield
    finally:
        tracking.corners.TIGHT_LEVEL_SIGMAS = kept


def marker_pose(distance: float, angle: float, u: float, v: float, roll: float) -> np.ndarray:
    """T_camera_marker: the marker centre on the ray through pixel (u, v) at depth `distance`, facing the camera."""
    facing = cv2.Rodrigues(np.array([np.pi, 0.0, 0.0]))[0]
    yaw = cv2.Rodrigues(np.array([0.0, np.radians(angle), 0.0]))[0]
    spin = cv2.Rodrigues(np.array([0.0, 0.0, np.radians(roll)]))[0]
    T = np.eye(4)
    T[:3, :3] = facing @ yaw @ spin
    T[:3, 3] = [(u - PAPER_K[0, 2]) / PAPER_K[0, 0] * distance, (v - PAPER_K[1, 2]) / PAPER_K[1, 1] * distance,
                distance]
    return T


def degrade(clean: np.ndarray, noise: float, blur: float, compression: str, seed: int) -> np.ndarray:
    """The clean render with blur, noise and compression applied (in that order)."""
    image = clean.astype(np.float64)
    if blur > 0:
        image = cv2.GaussianBlur(image, (0, 0), blur)
    if noise > 0:
        image = image + np.random.default_rng(seed).normal(0, noise, image.shape)
    out = np.clip(np.round(image), 0, 255).astype(np.uint8)
    if compression == "jpeg80":
        _, buf = cv2.imencode(".jpg", out, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
        out = cv2.imdecode(buf, cv2.IMREAD_GRAYSCALE)
    return out


def signed_radial(corners: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """(4,) corner errors along the true centre-to-corner direction: negative = inward (marker reads small)."""
    radial = truth - truth.mean(axis=0)
    radial /= np.linalg.norm(radial, axis=1, keepdims=True)
    return np.einsum("ij,ij->i", corners - truth, radial)


def evaluate_frame(gray: np.ndarray, truths: dict[int, np.ndarray], depths: dict[int, float], camera: CameraModel,
                   all_methods: list[Method], cells: int, meta: dict) -> list[dict]:
    """Rows of one frame: every method, every marker."""
    rows = []
    found: dict[str, dict[int, np.ndarray]] = {}
    for method in all_methods:
        t0 = time.perf_counter()
        if method.detector is not None:
            corners, ids, _ = method.detector.detectMarkers(gray)
            quads = {} if ids is None else {
                int(i): c.reshape(4, 2).astype(np.float64) for c, i in zip(corners, ids.reshape(-1), strict=True)}
        else:
            start = found[method.start]
            refined, _ = refine_corners_batch(gray, np.array([start[i] for i in start]).reshape(-1, 4, 2),
                                              camera if method.camera else None, cells)
            quads = dict(zip(start, refined, strict=True))
        elapsed = time.perf_counter() - t0
        found[method.name] = quads
        for marker_id, truth in truths.items():
            row = dict(method=method.name, marker=marker_id, **meta, detected=marker_id in quads,
                       time_ms=elapsed / max(len(quads), 1) * 1e3)
            if marker_id in quads:
                q = quads[marker_id]
                pose = estimate_pose(MarkerDetection(marker_id, q), camera, MARKER_SIZE)
                row |= dict(bias=float(signed_radial(q, truth).mean()),
                            sq=float(np.mean(np.sum((q - truth) ** 2, axis=1))),
                            max_err=float(np.linalg.norm(q - truth, axis=1).max()),
                            depth_mm=(pose.T_camera_marker[2, 3] - depths[marker_id]) * 1e3,
                            unchanged=method.detector is None and np.array_equal(q, found[method.start][marker_id]))
            rows.append(row)
    return rows


def run(quick: bool) -> pd.DataFrame:
    """One row per (frame condition, method, placement): corner and depth errors, time."""
    dictionary = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_6X6_250)
    cells = dictionary.markerSize + 2
    all_methods = methods(dictionary)
    rng = np.random.default_rng(SEED)
    distances = (20, 30, 40) if quick else DISTANCES
    noises = (0.0, 5.0) if quick else NOISES
    rows = []
    for dist_name, dist in DISTORTIONS.items():
        camera = CameraModel(PAPER_K, dist, *PAPER_SIZE)
        for distance in distances:
            for angle in ANGLES:
                placed = []
                for i, (u, v) in enumerate(SLOTS):
                    du, dv = rng.uniform(-SLOT_JITTER_PX, SLOT_JITTER_PX, 2)
                    roll = rng.uniform(*ROLL_RANGE_DEG) * rng.choice([-1.0, 1.0])
                    placed.append(PlacedMarker(i + 1, marker_pose(distance, angle, u + du, v + dv, roll),
                                               MARKER_SIZE))
                clean = render(PAPER_K, dist, PAPER_SIZE, placed)
                truths = {m.id: true_corners(PAPER_K, dist, m) for m in placed}
                depths = {m.id: m.T_camera_marker[2, 3] for m in placed}
                for noise in noises:
                    for blur in BLURS:
                        for compression in COMPRESSIONS:
                            gray = degrade(clean, noise, blur, compression, int(rng.integers(1 << 31)))
                            meta = dict(distortion=dist_name, distance=distance, angle=angle, noise=noise, blur=blur,
                                        compression=compression)
                            rows += evaluate_frame(gray, truths, depths, camera, all_methods, cells, meta)
    return pd.DataFrame(rows)


def summarise(df: pd.DataFrame) -> pd.DataFrame:
    """Per-method statistics of a set of rows."""
    det = df[df.detected]
    g = det.groupby("method", sort=False)
    out = pd.DataFrame({
        "detected %": df.groupby("method", sort=False).detected.mean() * 100,
        "bias px": g.bias.mean(),
        "RMS px": np.sqrt(g.sq.mean()),
        "max px": g.max_err.max(),
        "depth bias mm": g.depth_mm.mean(),
        "depth σ mm": g.depth_mm.std(),
        "kept input %": g.unchanged.mean() * 100,
    })
    timed = df.drop_duplicates(["method", "distortion", "distance", "angle", "noise", "blur", "compression"])
    out["ms/marker"] = timed.groupby("method", sort=False).time_ms.median()
    return out


def by_distance(df: pd.DataFrame, value: str, fmt: str) -> pd.DataFrame:
    """Method x distance table of one statistic."""
    det = df[df.detected]
    if value == "RMS px":
        table = np.sqrt(det.pivot_table(index="method", columns="distance", values="sq", aggfunc="mean", sort=False))
    else:
        column = {"bias px": "bias", "depth bias mm": "depth_mm"}[value]
        table = det.pivot_table(index="method", columns="distance", values=column, aggfunc="mean", sort=False)
    return table.map(lambda x: format(x, fmt))


def markdown(df: pd.DataFrame, floatfmt: str = ".3f") -> str:
    """A DataFrame as a markdown table."""
    cols = [str(c) for c in df.columns]
    lines = ["| " + " | ".join([df.index.name or "method", *cols]) + " |",
             "|" + "---|" * (len(cols) + 1)]
    for idx, row in df.iterrows():
        cells = [v if isinstance(v, str) else format(v, floatfmt) for v in row]
        lines.append("| " + " | ".join([str(idx), *cells]) + " |")
    return "\n".join(lines)


def compare(df: pd.DataFrame, a: str, b: str) -> str:
    """The headline table: method a against method b at REPORT_DISTANCES under CONDITIONS."""
    lines = [f"| condition | D m | {a} bias px | {b} bias px | {a} RMS px | {b} RMS px | "
             f"{a} depth bias mm | {b} depth bias mm | {a} depth σ mm | {b} depth σ mm |", "|" + "---|" * 10]
    for name, (noise, blur, compression) in CONDITIONS.items():
        sel = df[(df.noise == noise) & (df.blur == blur) & (df.compression == compression) & df.detected]
        for distance in REPORT_DISTANCES:
            cell = sel[sel.distance == distance]
            sa, sb = cell[cell.method == a], cell[cell.method == b]
            lines.append(
                f"| {name} | {distance} | {sa.bias.mean():+.3f} | {sb.bias.mean():+.3f} | "
                f"{np.sqrt(sa.sq.mean()):.3f} | {np.sqrt(sb.sq.mean()):.3f} | {sa.depth_mm.mean():+.0f} | "
                f"{sb.depth_mm.mean():+.0f} | {sa.depth_mm.std():.0f} | {sb.depth_mm.std():.0f} |")
    return "\n".join(lines)


def report(df: pd.DataFrame, seconds: float) -> str:
    """The markdown report."""
    n_frames = len(df.drop_duplicates(["distortion", "distance", "angle", "noise", "blur", "compression"]))
    baseline = f"subpix{detector_parameters(Refinement.SUBPIX).cornerRefinementWinSize}"
    parts = [
        "# Corner refinement benchmark",
        "",
        f"`benchmarks/corners.py`: {n_frames} rendered 920x600 frames (tests/synthetic.py, 8x8 supersampling, "
        "paper K), six 1 m DICT_6X6_250 markers per frame at random sub-pixel positions with a random "
        f"5-40° in-plane roll; distances {', '.join(map(str, sorted(df.distance.unique())))} m; "
        f"{', '.join(map(str, ANGLES))}° off the normal; distortion none and k1=-0.1, k2=0.05; "
        f"noise σ {', '.join(f'{n:g}' for n in sorted(df.noise.unique()))} grey levels; blur σ 0 / 0.7 px; "
        f"uncompressed and JPEG quality {JPEG_QUALITY}. Bias is the mean signed corner error along the true "
        "centre-to-corner direction (negative = inward = marker reads small, too far away); RMS and max are "
        "2-D corner errors; depth is t_z of IPPE_SQUARE (tracking.pose.estimate_pose, true camera) minus the "
        "true t_z. `edges` = tracking.corners.refine_corners started from OpenCV "
        f"{EDGES_START.value} (Refinement.EDGES), fitted in undistorted pixels with the true camera; "
        "`edges (no camera)` fits straight lines in the distorted image; `edges from ...` starts from "
        "another OpenCV refinement. Time is the median per marker per frame: OpenCV's columns are the whole "
        "detectMarkers call, `edges` rows only the refinement added on top. "
        f"Current DEFAULT_REFINEMENT: {DEFAULT_REFINEMENT.value}. Run time {seconds:.0f} s.",
        "",
        "## All conditions",
        "",
        markdown(summarise(df)),
        "",
        f"## {baseline} against edges",
        "",
        compare(df, baseline, "edges"),
        "",
    ]
    for name, (noise, blur, compression) in CONDITIONS.items():
        sel = df[(df.noise == noise) & (df.blur == blur) & (df.compression == compression)]
        for value, fmt in (("bias px", "+.3f"), ("RMS px", ".3f"), ("depth bias mm", "+.0f")):
            parts += [f"## {value} by distance: {name}", "", markdown(by_distance(sel, value, fmt)), ""]
    for angle in ANGLES:
        sel = df[df.angle == angle]
        parts += [f"## {angle}° off the normal, all other conditions", "", markdown(summarise(sel)), ""]
    for dist_name in DISTORTIONS:
        sel = df[df.distortion == dist_name]
        parts += [f"## distortion {dist_name}, all other conditions", "", markdown(summarise(sel)), ""]
    return "\n".join(parts)


def main() -> None:
    """Run the benchmark, print the report and (full run) write it to benchmarks/results/corners.md."""
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="fewer distances and noise levels; do not write")
    parser.add_argument("--note", default="", help="text appended to the report (e.g. the recommendation)")
    args = parser.parse_args()
    t0 = time.perf_counter()
    df = run(args.quick)
    text = report(df, time.perf_counter() - t0)
    if args.note:
        text += "\n## Recommendation\n\n" + args.note + "\n"
    print(text)
    if not args.quick:
        RESULTS.parent.mkdir(parents=True, exist_ok=True)
        RESULTS.write_text(text)


if __name__ == "__main__":
    main()
