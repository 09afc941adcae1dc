"""Edge-fit corner refinement against exact rendered corners, its failure modes, and the tutorial photos."""

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

import tracking.corners
from tests.synthetic import BACKGROUND, PAPER_K, PAPER_SIZE, WHITE, PlacedMarker, render, scale_error, true_corners
from tracking.camera import CameraModel
from tracking.corners import refine_corners, refine_corners_batch, try_refine_corners
from tracking.detection import MarkerDetector, Refinement
from tracking.images import read_gray

# measured by benchmarks/corners.py on clean renders at 20-40 m: |bias| <= 0.005 px, RMS 0.016-0.035 px;
# OpenCV's SUBPIX there: bias -0.25..-0.33 px
MAX_BIAS_PX = 0.03
MAX_RMS_PX = 0.08
SUBPIX_MIN_INWARD_PX = 0.1
NOISY_MAX_BIAS_PX = 0.05
NOISY_MAX_RMS_PX = 0.15
BLURRED_CELL_PX = 3.0  # the marker's cells in the image ...
BLURRED_SIGMA_PX = 1.0  # ... under this lens blur (benchmarks/results/corner_scale.md)
UNCORRECTED_MIN_SCALE = 3e-3  # the area edge without the glow correction: measured +5.6 ‰ (seeds 0-2)
GLOW_MAX_SCALE = {WHITE: 2.5e-3,  # with it, white all round: measured +1.8 ‰ (without it +5.7 ‰)
                  BACKGROUND: 1.0e-3}  # one white cell then grey: -0.19 ‰ (without it -2.3 ‰, black side only -6.8 ‰)
BLURRED_MAX_SCALE = 0.6e-3  # measured +0.18 ‰
SHADOW_CELL_PX = 8.0  # cells in the image (benchmarks/results/shadow_edges.md's worst row) ...
SHADOW_AT_CELLS = 0.5  # ... a soft shadow edge this far beyond the right border, taking half the margin's light
SHADOW_MAX_PULL_PX = 0.3  # measured -0.16 px (mean of 4 ids); with the levels half a cell out -0.72 px
SHADOW_MAX_DRAG = 0.1  # border px per px the shadow moves: measured 0.03; with the levels half a cell out 0.23
GOLD_TOLERANCE_PX = 2.0  # gold corners are OpenCV's integer contour corners, ~0.5 px inward of the edges
BARREL = np.array([-0.1, 0.05, 0.0, 0.0, 0.0])
SLOTS = [(200, 170), (700, 170), (200, 430), (700, 430)]
PHOTOS = ["singlemarkersoriginal.jpg", "gboriginal.jpg", "choriginal.jpg", "chocclusion_original.jpg"]


def _pose(distance: float, angle: float, u: float, v: float, roll: float) -> np.ndarray:
    T = np.eye(4)
    facing = cv2.Rodrigues(np.array([np.pi, 0.0, 0.0]))[0]
    yaw = cv2.Rodrigues(np.array([0.0, np.radians(angle), 0.0]))[0]
    T[:3, :3] = facing @ yaw @ cv2.Rodrigues(np.array([0.0, 0.0, np.radians(roll)]))[0]
    T[:3, 3] = [(u - PAPER_K[0, 2]) / PAPER_K[0, 0] * distance, (v - PAPER_K[1, 2]) / PAPER_K[1, 1] * distance,
                distance]
    return T


def _scene(distance: float, dist: np.ndarray, seed: int, noise: float = 0.0,
           blur: float = 0.0) -> tuple[np.ndarray, dict[int, np.ndarray]]:
    """Four markers (0 and 30 degrees off the normal, random sub-pixel placement and roll) and their true corners."""
    rng = np.random.default_rng(seed)
    placed = []
    for i, (u, v) in enumerate(SLOTS):
        roll = rng.uniform(5, 40) * rng.choice([-1.0, 1.0])
        pose = _pose(distance, 30.0 * (i % 2), u + rng.uniform(-20, 20), v + rng.uniform(-20, 20), roll)
        placed.append(PlacedMarker(i + 1, pose, 1.0))
    gray = render(PAPER_K, dist, PAPER_SIZE, placed, noise=noise, blur=blur, seed=seed)
    return gray, {m.id: true_corners(PAPER_K, dist, m) for m in placed}


def _errors(found: dict[int, np.ndarray], truth: dict[int, np.ndarray]) -> tuple[float, float]:
    """Mean signed error along centre-to-corner (negative = inward) and RMS corner error, px."""
    assert sorted(found) == sorted(truth)
    signed, sq = [], []
    for i, corners in found.items():
        radial = truth[i] - truth[i].mean(axis=0)
        radial /= np.linalg.norm(radial, axis=1, keepdims=True)
        signed.extend(np.einsum("ij,ij->i", corners - truth[i], radial))
        sq.extend(np.sum((corners - truth[i]) ** 2, axis=1))
    return float(np.mean(signed)), float(np.sqrt(np.mean(sq)))


@pytest.mark.parametrize("distance", [20.0, 40.0])
@pytest.mark.parametrize("distorted", [False, True])
def test_edges_unbiased_on_clean_renders(distance: float, distorted: bool) -> None:
    dist = BARREL if distorted else np.zeros(5)
    camera = CameraModel(PAPER_K, dist, *PAPER_SIZE) if distorted else None
    gray, truth = _scene(distance, dist, seed=int(distance) + 100 * distorted)
    edges = MarkerDetector("DICT_6X6_250", Refinement.EDGES, camera=camera).detect(gray)
    bias, rms = _errors({m.id: m.corners for m in edges.markers}, truth)
    assert abs(bias) < MAX_BIAS_PX
    assert rms < MAX_RMS_PX
    subpix = MarkerDetector("DICT_6X6_250", Refinement.SUBPIX).detect(gray)
    subpix_bias, _ = _errors({m.id: m.corners for m in subpix.markers}, truth)
    assert subpix_bias < -SUBPIX_MIN_INWARD_PX  # the thresholds above would catch OpenCV's SUBPIX


def test_edges_unbiased_on_noisy_blurred_render() -> None:
    gray, truth = _scene(30.0, np.zeros(5), seed=7, noise=5.0, blur=0.7)
    edges = MarkerDetector("DICT_6X6_250", Refinement.EDGES).detect(gray)
    bias, rms = _errors({m.id: m.corners for m in edges.markers}, truth)
    assert abs(bias) < NOISY_MAX_BIAS_PX
    assert rms < NOISY_MAX_RMS_PX


def _small_blurred_markers(seed: int, background: int) -> tuple[np.ndarray, dict[int, np.ndarray]]:
    """Four 1 m markers with 3 px cells (42 m) on background under a 1 px lens blur, and their true corners."""
    rng = np.random.default_rng(seed)
    placed = [PlacedMarker(i + 1, _pose(PAPER_K[0, 0] / 8 / BLURRED_CELL_PX, 0.0, u + rng.uniform(-20, 20),
                                        v + rng.uniform(-20, 20), rng.uniform(5, 40)), 1.0)
              for i, (u, v) in enumerate(SLOTS)]
    gray = render(PAPER_K, np.zeros(5), PAPER_SIZE, placed, blur=BLURRED_SIGMA_PX, background=background)
    return gray, {m.id: true_corners(PAPER_K, np.zeros(5), m) for m in placed}


def _mean_scale(refinement: Refinement, background: int) -> float:
    """Mean scale error of the small blurred markers (seeds 0-2) as refinement reads them."""
    scales = []
    for seed in range(3):
        gray, truth = _small_blurred_markers(seed, background)
        markers = MarkerDetector("DICT_6X6_250", refinement).detect(gray).markers
        assert sorted(m.id for m in markers) == sorted(truth)
        scales += [scale_error(m.corners, truth[m.id]) for m in markers]
    return float(np.mean(scales))


@pytest.mark.parametrize("background", [WHITE, BACKGROUND])
def test_small_blurred_markers_read_at_their_size(background: int) -> None:
    """On small cells under a lens blur, both refinements read markers at their size, white all round or with one
    white cell then grey."""
    assert abs(_mean_scale(Refinement.EDGES, background)) < GLOW_MAX_SCALE[background]
    assert abs(_mean_scale(Refinement.BLURRED, background)) < BLURRED_MAX_SCALE


def test_glow_correction_is_what_keeps_small_blurred_markers_at_their_size(monkeypatch: pytest.MonkeyPatch) -> None:
    """Without the glow of the neighbouring cells taken out of its levels, the area edge reads white-surrounded
    small blurred markers large."""
    monkeypatch.setattr(tracking.corners, "_glow", lambda inner, black, white, cell: np.zeros_like(cell))
    assert _mean_scale(Refinement.EDGES, WHITE) > UNCORRECTED_MIN_SCALE


def _shadow_pull(shift_px: float = 0.0) -> float:
    """Mean x error (px) of the right border (TR, BR) of four sharp markers with SHADOW_CELL_PX cells under a soft
    shadow edge SHADOW_AT_CELLS beyond it (plus shift_px), refined from starts 0.3 px off."""
    rng = np.random.default_rng(11)
    errors = []
    for marker_id in (0, 7, 23, 42):
        placed = PlacedMarker(marker_id, _pose(PAPER_K[0, 0] / 8 / SHADOW_CELL_PX, 0.0, rng.uniform(400, 520),
                                               rng.uniform(260, 340), 0.0), 1.0)
        gray = render(PAPER_K, np.zeros(5), PAPER_SIZE, [placed], blur=0.7, background=WHITE)
        truth = true_corners(PAPER_K, np.zeros(5), placed)
        edge = truth[[1, 2], 0].mean() + SHADOW_AT_CELLS * SHADOW_CELL_PX + shift_px
        shade = 0.5 / (1.0 + np.exp(-(np.arange(gray.shape[1]) - edge) / 1.5))
        shaded = np.clip(gray * (1.0 - shade)[None, :], 0, 255).astype(np.uint8)
        found = refine_corners(shaded, truth + rng.normal(0, 0.3, truth.shape))
        errors.append(np.mean(found[[1, 2], 0] - truth[[1, 2], 0]))
    return float(np.mean(errors))


def test_a_shadow_edge_on_the_margin_hardly_pulls_the_border() -> None:
    """A shadow's soft edge half a cell beyond a border (a beam's shadow sweeping over the plate) neither pulls the
    border far nor drags it along as it moves: the edge's levels are read a few blur σ out, not half a cell."""
    pull = _shadow_pull()
    assert abs(pull) < SHADOW_MAX_PULL_PX
    assert abs(_shadow_pull(0.5) - pull) / 0.5 < SHADOW_MAX_DRAG


def test_levels_half_a_cell_out_follow_the_shadow(monkeypatch: pytest.MonkeyPatch) -> None:
    """Without the blur-matched window the same shadow pulls the border beyond the bound above."""
    monkeypatch.setattr(tracking.corners, "TIGHT_LEVEL_SIGMAS", np.inf)
    assert abs(_shadow_pull()) > SHADOW_MAX_PULL_PX


def test_fails_gracefully() -> None:
    gray, truth = _scene(20.0, np.zeros(5), seed=3)
    start = truth[1] + np.array([[0.4, 0.3], [-0.3, 0.4], [-0.4, -0.3], [0.3, -0.4]])  # about 0.5 px inward
    flat = np.full_like(gray, 128)
    assert try_refine_corners(flat, start) is None
    np.testing.assert_array_equal(refine_corners(flat, start), start)
    occluded = gray.copy()
    x0, y0 = np.floor(truth[1].min(axis=0)).astype(int) - 5
    x1, y1 = np.ceil(truth[1].max(axis=0)).astype(int) + 5
    occluded[y0:y1, (x0 + x1) // 2:x1] = 90  # right half of the marker covered by background
    np.testing.assert_array_equal(refine_corners(occluded, start), start)
    nan = start.copy()
    nan[2, 0] = np.nan
    quads = np.stack([start, nan, truth[2]])
    refined, ok = refine_corners_batch(gray, quads)
    assert ok.tolist() == [True, False, True]
    np.testing.assert_array_equal(refined[1], nan)
    assert np.abs(refined[0] - truth[1]).max() < MAX_RMS_PX
    assert refine_corners_batch(gray, np.zeros((0, 4, 2)))[0].shape == (0, 4, 2)


@pytest.mark.parametrize("photo", PHOTOS)
def test_edges_keeps_gold_ids(shared_data: Path, photo: str) -> None:
    folder = shared_data / "aruco/opencv-tutorial"
    entry = json.loads((folder / "gold_corners.json").read_text())[photo]
    dictionary = entry["dictionary"] if entry["dictionary"].startswith("DICT_") else str(folder / entry["dictionary"])
    gold = {int(k): np.array(v, dtype=float) for k, v in entry["markers"].items()}
    found = MarkerDetector(dictionary, Refinement.EDGES).detect(read_gray(folder / photo))
    assert sorted(found.ids) == sorted(gold)
    for m in found.markers:
        assert np.abs(m.corners - gold[m.id]).max() <= GOLD_TOLERANCE_PX
