"""Plate textures: ArUco markers on white plates and a chessboard, as mip levels with exact cell edges.

Each level is a 2-channel float32 image (premultiplied albedo, alpha) whose cell edges fall on
texel boundaries, so bilinear sampling puts every edge exactly where it belongs.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

WHITE_ALBEDO = 0.85
BLACK_ALBEDO = 0.04
CELL_LEVELS = (1, 2, 4, 8, 16, 32, 64)  # texels per cell


@dataclass(frozen=True)
class Texture:
    """Mip levels of a plate texture and the plate's physical size."""

    levels: tuple[np.ndarray, ...]  # (H, W, 2) float32, one per CELL_LEVELS entry
    cell: float  # m per cell
    size_m: tuple[float, float]  # plate width, height in m (as the texture covers it)

    def level_for(self, superpixels_per_cell: float) -> tuple[np.ndarray, int]:
        """The level whose texel is nearest one supersampled pixel (log scale), and its texels per cell."""
        want = np.log2(max(superpixels_per_cell, 1.0))
        i = int(np.clip(np.rint(want), 0, len(CELL_LEVELS) - 1))
        return self.levels[i], CELL_LEVELS[i]


def _levels(cells: np.ndarray) -> tuple[np.ndarray, ...]:
    """Albedo cells (h, w) in [0, 1] to premultiplied 2-channel levels."""
    out = []
    for n in CELL_LEVELS:
        alb = np.kron(cells, np.ones((n, n))).astype(np.float32)
        out.append(np.dstack([alb, np.ones_like(alb)]))
    return tuple(out)


def marker_texture(dictionary: str, marker_id: int, marker_size: float, plate_size: float) -> Texture:
    """A marker (black border + bits) centred on a white plate with a quiet zone of >= 1 cell."""
    d = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, dictionary))
    n = d.markerSize + 2
    bits = cv2.aruco.generateImageMarker(d, marker_id, n, borderBits=1).astype(np.float64) / 255.0
    cell = marker_size / n
    quiet = max(1, round((plate_size - marker_size) / 2 / cell))
    cells = np.pad(bits, quiet, constant_values=1.0)
    alb = BLACK_ALBEDO + (WHITE_ALBEDO - BLACK_ALBEDO) * cells
    side = cells.shape[0] * cell
    return Texture(_levels(alb), cell, (side, side))


def chessboard_texture(inner: tuple[int, int], square: float) -> Texture:
    """A chessboard of inner[0] x inner[1] inner corners with a one-square white margin."""
    cols, rows = inner[0] + 1, inner[1] + 1
    yy, xx = np.mgrid[0:rows, 0:cols]
    board = ((xx + yy) % 2).astype(np.float64)
    cells = np.pad(board, 1, constant_values=1.0)
    alb = BLACK_ALBEDO + (WHITE_ALBEDO - BLACK_ALBEDO) * cells
    return Texture(_levels(alb), square, (cells.shape[1] * square, cells.shape[0] * square))
