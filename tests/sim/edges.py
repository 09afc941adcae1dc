"""Edge measurement for the renderer tests: where does a rendered marker edge lie, to a hundredth of a pixel.

For a near-vertical edge, each pixel row across it is an area-sampled step from the white quiet zone
to the black border; the edge's column is the window's end minus the summed normalised brightness.
That holds exactly for a straight edge with true pixel coverage, whatever its slope.
"""

from __future__ import annotations

import cv2
import numpy as np

SAMPLES_ALONG_EDGE = 400
EDGE_MIDDLE = 0.6  # use rows over the middle of each edge, away from the corners


def edge_errors(gray: np.ndarray, marker_T_cam: np.ndarray, size: float, K: np.ndarray, dist: np.ndarray,
                window: int) -> list[np.ndarray]:
    """Per edge (top, right, bottom, left): signed errors (px) of the rendered edge against the analytic one."""
    h = size / 2
    corners = np.array([[-h, h, 0], [h, h, 0], [h, -h, 0], [-h, -h, 0]], float)
    out = []
    for i in range(4):
        a, b = corners[i], corners[(i + 1) % 4]
        s = np.linspace(0, 1, SAMPLES_ALONG_EDGE)[:, None]
        pts3 = (a + s * (b - a)) @ marker_T_cam[:3, :3].T + marker_T_cam[:3, 3]
        px, _ = cv2.projectPoints(pts3, np.zeros(3), np.zeros(3), K, dist)
        px = px.reshape(-1, 2)
        centre3 = marker_T_cam[:3, 3]
        cpx, _ = cv2.projectPoints(centre3[None], np.zeros(3), np.zeros(3), K, dist)
        centre = cpx.reshape(2)
        vertical = abs(px[-1, 1] - px[0, 1]) > abs(px[-1, 0] - px[0, 0])
        img = gray if vertical else gray.T
        line = px if vertical else px[:, ::-1]
        c = centre if vertical else centre[::-1]
        order = np.argsort(line[:, 1])
        along, across = line[order, 1], line[order, 0]
        lo, hi = along[0], along[-1]
        mid, half = (lo + hi) / 2, (hi - lo) * EDGE_MIDDLE / 2
        rows, cols, sides = [], [], []
        for row in range(int(np.ceil(mid - half)), int(np.floor(mid + half)) + 1):
            u_true = float(np.interp(row, along, across))
            rows.append(row)
            cols.append(u_true)
            sides.append(u_true < c[0])
        k = np.round(cols).astype(int)
        left = np.array(sides)
        r = np.array(rows)
        outer = np.where(left, k - window - 1, k + window + 1)
        inner = np.where(left, k + window + 1, k - window - 1)
        step = np.where(left, -1, 1)
        bright = np.median(np.r_[img[r, outer], img[r, outer + step]])
        dark = np.median(np.r_[img[r, inner], img[r, inner - step]])
        errors = []
        for row, u_true, kk, lft in zip(rows, cols, k, left, strict=True):
            q = (img[row, kk - window:kk + window + 1].astype(np.float64) - dark) / (bright - dark)
            u_meas = kk - window - 0.5 + q.sum() if lft else kk + window + 0.5 - q.sum()
            errors.append(u_meas - u_true)
        out.append(np.array(errors))
    return out
