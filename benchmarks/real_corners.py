"""Corner accuracy on real footage without a truth: how well each frame's corners of a flat, rigid board fit one plane.

For each camera of the real caliscope sessions (../shared/data/caliscope, or other session folders), every frame
where four or more of the board's markers are found: the corners are undistorted with the session's own calibration,
a homography is fitted (least squares) from the markers' corners on the board to them, and the RMS of what it leaves
is that frame's residual, px. A perfect corner on a flat board under a perfect lens model leaves none; the lens
model's error and the print's flatness leave the same for every refinement, so the differences between rows are the
corners'. Rows: the default edge fit (tracking.corners), the same with its levels read half a cell out everywhere
(as before the blur-matched window, TIGHT_LEVEL_SIGMAS = inf), and OpenCV's own subpixel refinement.

    .venv/bin/python -m benchmarks.real_corners                 # ~1 min, writes benchmarks/results/real_corners.md
    .venv/bin/python -m benchmarks.real_corners --sessions DIR...   # other caliscope session folders, printed only
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from contextlib import AbstractContextManager as ContextManager
from contextlib import nullcontext
from pathlib import Path

import cv2
import numpy as np

from benchmarks.corners import levels_half_a_cell_out
from benchmarks.report import write_results
from tracking.caliscope import SessionCamera, read_session
from tracking.detection import MarkerDetection, MarkerDetector, Refinement
from tracking.images import frames

REAL = Path(__file__).resolve().parents[2] / "shared" / "data" / "caliscope"
SESSIONS = ("charuco_calibration", "post_optimization")
MIN_MARKERS = 4  # markers a frame needs for its homography to leave something to measure
VARIANTS = ("edges", "edges, levels half a cell out", "OpenCV subpix")


def _detectors(dictionary: str, inverted: bool) -> dict[str, tuple[MarkerDetector, Callable[[], ContextManager]]]:
    """Each variant's detector and the context it runs in."""
    edges = MarkerDetector(dictionary, Refinement.EDGES, inverted=inverted)
    return {"edges": (edges, nullcontext),
            "edges, levels half a cell out": (edges, levels_half_a_cell_out),
            "OpenCV subpix": (MarkerDetector(dictionary, Refinement.SUBPIX, inverted=inverted), nullcontext)}


def plane_residual(markers: list[MarkerDetection], on_board: dict[int, np.ndarray], cam: SessionCamera) -> float:
    """RMS (px) of what one homography from the markers' corners on the board leaves of their undistorted corners."""
    src = np.concatenate([on_board[m.id] for m in markers])
    seen = np.concatenate([m.corners for m in markers]).reshape(-1, 1, 2).astype(np.float64)
    ideal = cv2.undistortPoints(seen, cam.K, cam.dist, P=cam.K).reshape(-1, 2)
    H, _ = cv2.findHomography(src, ideal, 0)
    fitted = cv2.perspectiveTransform(src.reshape(-1, 1, 2), H).reshape(-1, 2)
    return float(np.sqrt(np.mean(np.sum((fitted - ideal) ** 2, axis=1))))


def residuals(folder: Path) -> dict[tuple[int, str], np.ndarray]:
    """Per (camera number, variant): each usable frame's homography residual (RMS, px)."""
    session = read_session(folder)
    board = session.board.opencv()
    on_board = {int(i): np.asarray(c, dtype=np.float64)[:, :2]
                for i, c in zip(np.asarray(board.getIds()).ravel(), board.getObjPoints(), strict=True)}
    detectors = _detectors(session.board.dictionary, session.board.inverted)
    out: dict[tuple[int, str], list[float]] = {}
    for cam in session.cameras:
        for frame in frames(cam.video):
            for name, (detector, variant) in detectors.items():
                with variant():
                    found = [m for m in detector.detect(frame.gray).markers if m.id in on_board]
                if len(found) >= MIN_MARKERS:
                    out.setdefault((cam.number, name), []).append(plane_residual(found, on_board, cam))
    return {k: np.array(v) for k, v in out.items()}


def table(name: str, res: dict[tuple[int, str], np.ndarray]) -> list[str]:
    """One session's rows: per camera and variant, frames, median and 90th percentile residual."""
    lines = [f"## {name}", "", "| camera | refinement | frames | median residual [px] | 90th percentile [px] |",
             "| ---: | --- | ---: | ---: | ---: |"]
    for (number, variant), r in sorted(res.items(), key=lambda kv: (kv[0][0], VARIANTS.index(kv[0][1]))):
        lines.append(f"| {number} | {variant} | {len(r)} | {np.median(r):.3f} | {np.percentile(r, 90):.3f} |")
    return [*lines, ""]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sessions", type=Path, nargs="*", default=None, help="other caliscope session folders")
    args = parser.parse_args()
    t0 = time.perf_counter()
    folders = args.sessions if args.sessions is not None else [REAL / s for s in SESSIONS]
    body = [line for f in folders for line in table(f.name, residuals(f))]
    lines = ["# Corner accuracy on real footage, without a truth", "", __doc__.split("\n\n")[1].strip(), "",
             f"Sessions: {', '.join(f.name for f in folders)}; run time {time.perf_counter() - t0:.0f} s.", "",
             *body]
    write_results("real_corners", lines, echo=True, to_file=args.sessions is None)


if __name__ == "__main__":
    main()
