"""Unbiased sub-pixel marker corners from the four outer edges of the black square.

Each outer edge (black border against the white quiet zone) is sampled with short intensity
profiles across it. On each profile the edge is placed where the area under the normalised
profile says it is (the "area" or first-moment edge: exact for a pixel-integrated step under any
symmetric blur whose transition fits in the window), with the black and white levels read locally
at the middle of the border cell and of the quiet-zone cell. A coarse pass first re-centres the
profiles on the strongest dark-to-bright step (starts a pixel or two off are fine). A robust
straight line is fitted to each edge and adjacent lines are intersected. With a camera model the
sample positions are laid out in undistorted (ideal) pixels, where the edges are straight, and only
the image look-ups are distorted; the corners are re-distorted at the end. Every step is vectorised
over the edges of all markers of a frame.

The area edge reads its black and white levels half a cell inside and outside the edge. Where the optics blur
over more than about a sixth of a cell, the neighbouring edges (white code cells inside, the plate's edge outside
a one-cell quiet zone) reach those levels and bias the edge: the marker reads too large or too small. So each fine
profile also samples the next cells in and out (1.5 cells from the edge); how much brighter an edge's black level
reads beside its white code cells than beside its black ones gives the share of a neighbour's contrast the blur
carries to the levels (the "glow", hence the marker's blur), and each level loses that share of its neighbour's
contrast (_glow). That removes most of the bias wherever the blur is under a third of a cell; edges whose cells are
under 2.5 px across (seen edge-on) are left alone. Where instead the cells are wide against the blur, the levels
half a cell out reach past the edge's own step onto the margin, and a shadow's soft edge lying there (a beam's shadow
sweeping over the plate) moves the white level and the edge with it; so each marker's blur is measured from its
profiles' own spread and, where three of it fall short of the levels' distance (half a cell, at most 4 px) and 2.5
of it of the window's half-width, the edge is integrated again over 2.5 of it either side with its levels read 3 out
(_tight_edge). Figures: docs/method.md#detection-and-corners.
With blur_model (`--refine blurred`) the fine pass instead fits each profile with a blurred model of the marker's
cross-section (inner cell, border, quiet cell, beyond), on markers whose cells are 2 to 8 px across (see the
README).

It needs the marker's white quiet zone (one cell at least); where an edge cannot be fitted
(occlusion, no contrast, a corner moving too far) the marker keeps its input corners. Accuracy drops
where a cell is under ~2 px thick across an edge (60 degrees off the normal beyond ~35 m): see
benchmarks/corners.py.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from tracking.camera import CameraModel

DEFAULT_CELLS = 8  # cells across the black square: markerSize + 2 border cells (DICT_6X6_*)
ITERATIONS = 2  # one coarse pass, then one fine pass re-centred on its lines (a second helps sharp pictures but not
# blurred ones: docs/method.md#where-the-remaining-errors-come-from)
COARSE_REACH = 0.9  # the coarse pass looks this many cells either side of the start edge ...
COARSE_MAX_PX = 4.0  # ... but never further than this
MIN_GRADIENT = 3.0  # grey levels per pixel: weakest step the coarse pass accepts
LEVEL_AT = 0.5  # black / white levels are read this many cells inside / outside the edge
LEVEL_MAX_PX = 4.0  # ... but never further than this from the edge (large markers)
NEXT_CELL_AT = 1.5  # cells either side of the edge: the next cells, whose blur reaches the levels (_glow)
MIN_GLOW_PROFILES = 2  # profiles next to a white and to a black code cell an edge needs to measure the glow
MIN_GLOW, MAX_GLOW = 1e-4, 0.3  # the range of the share of a neighbouring cell's contrast taken for glow
MIN_GLOW_CELL_PX = 2.5  # edges with thinner cells across (seen edge-on) neither measure the glow nor lose it: their
# levels sit on their own edge's ramp, and their shares are mostly noise
TIGHT_HALF_SIGMAS = 2.5  # where a cell is wide against the blur, the edge is integrated this many blur σ either side
TIGHT_LEVEL_SIGMAS = 3.0  # ... and its levels read this far out: a shadow's soft edge on the margin then has to
# come within about 3σ of the border, not half a cell (4 px), to pull it (benchmarks/shadow_edges.py)
MAX_EXPONENT = 50.0  # exp() beyond this is a share of 0 anyway
HALF_WINDOW = 0.42  # integration half-width across the edge, in cells
HALF_WINDOW_MAX_PX = 3.0  # ... capped for large markers (wider windows only add noise)
HALF_WINDOW_MIN_PX = 0.75
PROFILE_STEP_PX = 0.5  # spacing of the samples across the edge
SAMPLE_SPACING_PX = 1.0  # spacing of the profiles along the edge
MAX_PROFILES = 24  # profiles per edge at most (large markers)
MIN_PROFILES = 4
END_MARGIN = 0.9  # profiles keep this many cells away from the corners ...
END_MARGIN_MIN_PX = 1.5  # ... and at least this many pixels
MIN_CONTRAST = 12.0  # grey levels between the local black and white levels for a usable profile
MIN_INLIER_FRACTION = 0.5  # an edge with fewer usable, consistent profiles fails
TUKEY_C = 4.685  # Tukey biweight constant, in robust sigmas
MIN_SIGMA_PX = 0.02  # floor of the robust residual scale
ROBUST_ITERATIONS = 3  # least squares, then Tukey-reweighted fits
MAX_SHIFT_PX = 2.5  # a corner moving further than this from its input is a failure ...
MAX_SHIFT_CELLS = 0.6  # ... unless it stays within this many cells (large markers)
CONVERGED_PX = 0.002  # stop early when no corner moved more than this in a fine pass
MIN_SIN_ANGLE = 0.2  # adjacent edges closer to parallel than this cannot be intersected
# the blurred-profile model (blur_model=True, `--refine blurred`)
BLUR_MODEL_CELLS = 1.4  # its profiles reach this many cells either side of the edge ...
BLUR_MODEL_MAX_PX = 5.0  # ... but no further than this
BLUR_MODEL_MAX_CELL_PX = 8.0  # edges whose cells are wider keep the area edge: the blur cannot reach their levels
BLUR_MODEL_MIN_CELL_PX = 2.0  # markers with a narrower cell across any edge (seen edge-on) keep the area edge
BLUR_MODEL_ITERATIONS = 8  # Gauss-Newton steps with the blur free per profile ...
BLUR_MODEL_POOLED_ITERATIONS = 3  # ... then with one blur per edge, the median of its profiles'
BLUR_MODEL_SIGMA0_PX = 0.8
BLUR_MODEL_SIGMA_RANGE_PX = (0.2, 4.0)
BLUR_MODEL_STEP_PX = 0.5  # largest Gauss-Newton step of the edge ...
BLUR_MODEL_SIGMA_STEP_PX = 0.3  # ... and of the blur
BLUR_MODEL_RIDGE = 1e-6  # keeps the levels of edges outside a profile's reach (zero columns) solvable
LOGISTIC_SLOPE = 1.702  # the logistic 1 / (1 + exp(-1.702 z)) is within 0.01 of the normal CDF
PROJECT_ZERO = np.zeros(3)
RATIONAL_SIZE = 8  # k1 k2 p1 p2 k3 k4 k5 k6: distortion evaluated here; longer models go to cv2.projectPoints


def _distort(camera: CameraModel, ideal: np.ndarray) -> np.ndarray:
    """Ideal pixels (..., 2) of camera.K to distorted pixels (..., 2) (OpenCV's model)."""
    K, dist = camera.K, np.asarray(camera.dist, dtype=np.float64).reshape(-1)
    x = (ideal[..., 0] - K[0, 2]) / K[0, 0]
    y = (ideal[..., 1] - K[1, 2]) / K[1, 1]
    if dist.size > RATIONAL_SIZE:  # thin prism / tilted sensor: let OpenCV do it
        rays = np.stack([x.reshape(-1), y.reshape(-1), np.ones(x.size)], axis=1)
        px, _ = cv2.projectPoints(rays, PROJECT_ZERO, PROJECT_ZERO, K, dist)
        return px.reshape(ideal.shape)
    k = np.zeros(RATIONAL_SIZE)
    k[:dist.size] = dist
    k1, k2, p1, p2, k3, k4, k5, k6 = k
    r2 = x * x + y * y
    radial = (1 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1 + r2 * (k4 + r2 * (k5 + r2 * k6)))
    xy = x * y
    xd = x * radial + 2 * p1 * xy + p2 * (r2 + 2 * x * x)
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * xy
    return np.stack([K[0, 0] * xd + K[0, 1] * yd + K[0, 2], K[1, 1] * yd + K[1, 2]], axis=-1)


def _bilinear(gray: np.ndarray, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Bilinear intensities at pts (..., 2) and a mask of the points inside the image."""
    h, w = gray.shape
    x, y = pts[..., 0], pts[..., 1]
    inside = (x >= 0) & (y >= 0) & (x <= w - 1) & (y <= h - 1)
    x = np.clip(x, 0, w - 1.000001)
    y = np.clip(y, 0, h - 1.000001)
    x0 = x.astype(np.intp)
    y0 = y.astype(np.intp)
    fx, fy = x - x0, y - y0
    flat = gray.reshape(-1)
    i = y0 * w + x0
    a, b = flat[i].astype(np.float64), flat[i + 1].astype(np.float64)
    c, d = flat[i + w].astype(np.float64), flat[i + w + 1].astype(np.float64)
    top = a + (b - a) * fx
    bottom = c + (d - c) * fx
    return top + (bottom - top) * fy, inside


def _intersect(p: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Corners (B, 4, 2) where line k-1 meets line k (p point, u unit direction), and |sin| of their angle."""
    p0, u0 = np.roll(p, 1, axis=1), np.roll(u, 1, axis=1)
    cross = u0[..., 0] * u[..., 1] - u0[..., 1] * u[..., 0]
    dp = p - p0
    safe = np.where(np.abs(cross) < 1e-12, 1e-12, cross)
    t = (dp[..., 0] * u[..., 1] - dp[..., 1] * u[..., 0]) / safe
    return p0 + t[..., None] * u0, np.abs(cross)


@dataclass(frozen=True)
class _Edges:
    """The four edges of quads (B, 4, 2) as lines to sample across: edge k runs from corner k to corner k+1."""

    start: np.ndarray  # (B, 4, 2) its first corner
    u: np.ndarray  # (B, 4, 2) unit direction along it
    normal: np.ndarray  # (B, 4, 2) unit normal, outward from the quad
    length: np.ndarray  # (B, 4) px
    sin_c: np.ndarray  # (B, 4) sine of the interior angle at corner k (floored at MIN_SIN_ANGLE)
    cos_c: np.ndarray  # (B, 4) its cosine, floored at 0
    cell_across: np.ndarray  # (B, 4) a code cell's thickness across the edge, px
    usable: np.ndarray  # (B, 4) long enough and not too acute to fit

    @classmethod
    def of(cls, ideal: np.ndarray, cells: int) -> _Edges:
        start, end = ideal, np.roll(ideal, -1, axis=1)
        along = end - start
        length = np.linalg.norm(along, axis=2)
        usable = length > 2 * END_MARGIN_MIN_PX + MIN_PROFILES * SAMPLE_SPACING_PX
        u = along / np.maximum(length, 1e-9)[..., None]
        normal = np.stack([u[..., 1], -u[..., 0]], axis=2)
        outward = np.sign(np.einsum("bij,bij->bi", (start + end) / 2 - ideal.mean(axis=1, keepdims=True), normal))
        normal *= np.where(outward == 0, 1.0, outward)[..., None]
        # interior angle at corner k, between edge k (leaving it) and edge k-1 (arriving)
        back = -np.roll(u, 1, axis=1)
        sin_c = np.abs(u[..., 0] * back[..., 1] - u[..., 1] * back[..., 0])
        cos_c = np.maximum(np.einsum("bij,bij->bi", u, back), 0.0)
        usable &= (sin_c > MIN_SIN_ANGLE) & (np.roll(sin_c, -1, axis=1) > MIN_SIN_ANGLE)
        sin_c = np.maximum(sin_c, MIN_SIN_ANGLE)
        # cell thickness across edge k: the neighbouring edges' lengths times their sine with edge k
        cell_across = (np.roll(length, 1, axis=1) * sin_c + np.roll(length * sin_c, -1, axis=1)) / (2 * cells)
        return cls(start, u, normal, length, sin_c, cos_c, cell_across, usable)

    def along(self, reach: np.ndarray, cells: int) -> tuple[np.ndarray, np.ndarray]:
        """Where profiles reaching reach (B, 4) px across sample each edge (B, 4, N), clear of the neighbouring edges
        (wider margins at acute corners), and which edges keep enough of them (B, 4)."""
        wedge = reach * (1 + self.cos_c) / self.sin_c
        floor = np.maximum(END_MARGIN * self.length / cells, END_MARGIN_MIN_PX)
        m_start = np.maximum(floor, wedge)
        m_end = np.maximum(floor, np.roll(wedge, -1, axis=1))
        span = self.length - m_start - m_end
        usable = self.usable & (span > MIN_PROFILES * SAMPLE_SPACING_PX / 2)
        span = np.maximum(span, 0.0)
        n_prof = int(np.clip(np.max(span) / SAMPLE_SPACING_PX, MIN_PROFILES, MAX_PROFILES))
        return m_start[..., None] + span[..., None] * ((np.arange(n_prof) + 0.5) / n_prof), usable

    def lines(self, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Lines (point, unit direction) (B, 4, 2) each of offset a and slope b (B, 4) from its edge."""
        direction = self.u + b[..., None] * self.normal
        direction /= np.maximum(np.linalg.norm(direction, axis=2, keepdims=True), 1e-12)
        return self.start + a[..., None] * self.normal, direction


def _fit_edges(gray: np.ndarray, ideal: np.ndarray, camera: CameraModel | None, cells: int,
               coarse: bool, blur_model: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One pass over quads (B, 4, 2): robust lines (point, unit direction) through their edges, and which fitted.

    The coarse pass puts each edge at the strongest dark-to-bright step within most of a cell either
    side (robust to a start a pixel off); the fine passes use the unbiased area edge.
    """
    g = _Edges.of(ideal, cells)
    if coarse:
        half = np.clip(COARSE_REACH * g.cell_across, HALF_WINDOW_MIN_PX, COARSE_MAX_PX)
        level = half
    else:
        half = np.clip(HALF_WINDOW * g.cell_across, HALF_WINDOW_MIN_PX, HALF_WINDOW_MAX_PX)
        level = np.minimum(LEVEL_AT * g.cell_across, LEVEL_MAX_PX)
    reach, modelled, model_reach = level, None, level
    if blur_model and not coarse:  # the edges the blurred-profile model takes, and its profiles' reach
        model_reach = np.clip(BLUR_MODEL_CELLS * g.cell_across, HALF_WINDOW_MIN_PX, BLUR_MODEL_MAX_PX)
        modelled = (g.cell_across < BLUR_MODEL_MAX_CELL_PX) \
            & (g.cell_across.min(axis=1, keepdims=True) >= BLUR_MODEL_MIN_CELL_PX)  # (B, 4)
        reach = np.where(modelled, np.maximum(level, model_reach), level)
    s, usable = g.along(reach, cells)
    n_off = int(np.ceil(np.max(half) / PROFILE_STEP_PX))
    step = half / n_off  # (B, 4) sample spacing across each edge
    d = half[..., None] * (np.arange(-n_off, n_off + 1) / n_off)  # (B, 4, M)
    beyond = (NEXT_CELL_AT * g.cell_across)[..., None]  # (B, 4, 1): the next cells in and out (code cell, quiet zone)
    offsets = d if coarse else np.concatenate([-beyond, -level[..., None], d, level[..., None], beyond], axis=2)

    def profiles(rows: np.ndarray, offsets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Samples (R, 4, N, M) at offsets (R, 4, M) across the edges of quads rows, and where all are inside."""
        pts = (g.start[rows, :, None, None, :] + s[rows, ..., None, None] * g.u[rows, :, None, None, :]
               + offsets[:, :, None, :, None] * g.normal[rows, :, None, None, :])
        values, inside = _bilinear(gray, _distort(camera, pts) if camera is not None else pts)
        return values, inside.all(axis=3)

    values, ok = profiles(np.arange(len(ideal)), offsets)
    if coarse:
        e, found = _gradient_edge(values, step)
    else:
        e, found = _area_edge(values, d, level, half, step, g.cell_across)
        found &= np.abs(e) < half[..., None]
        rows = np.flatnonzero(modelled.any(axis=1)) if modelled is not None else []
        if len(rows):  # the blurred-profile model on these markers' modelled edges
            n_off = int(np.ceil(np.max(model_reach[rows]) / PROFILE_STEP_PX))
            across = model_reach[rows, :, None] * (np.arange(-n_off, n_off + 1) / n_off)
            values_m, ok_m = profiles(rows, across)
            e_m, found_m = _model_edge(values_m, across, g.cell_across[rows], model_reach[rows])
            use = modelled[rows][..., None]
            e[rows] = np.where(use, e_m, e[rows])
            found[rows] = np.where(use, found_m, found[rows])
            ok[rows] = np.where(use, ok_m, ok[rows])
    b_count = len(ideal)
    a, b, fitted = _robust_lines(s.reshape(b_count * 4, -1), e.reshape(b_count * 4, -1),
                                 (ok & found).reshape(b_count * 4, -1))
    p, direction = g.lines(a.reshape(b_count, 4), b.reshape(b_count, 4))
    return p, direction, (usable & fitted.reshape(b_count, 4)).all(axis=1)


def _gradient_edge(values: np.ndarray, step: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Offsets (B, 4, N) of the strongest rising step in profiles (B, 4, N, M) centred on 0, and where found."""
    m = values.shape[-1]
    grad = np.diff(values, axis=-1) / step[..., None, None]  # (B, 4, N, M-1) at half-sample positions
    k = np.argmax(grad, axis=-1)[..., None]
    g0 = np.take_along_axis(grad, np.maximum(k - 1, 0), axis=-1)[..., 0]
    g1 = np.take_along_axis(grad, k, axis=-1)[..., 0]
    g2 = np.take_along_axis(grad, np.minimum(k + 1, m - 2), axis=-1)[..., 0]
    curvature = g0 - 2 * g1 + g2
    peaked = curvature < 0
    delta = np.clip(np.where(peaked, 0.5 * (g0 - g2) / np.where(peaked, curvature, -1.0), 0.0), -0.5, 0.5)
    return (k[..., 0] + 0.5 + delta - (m - 1) / 2) * step[..., None], g1 > MIN_GRADIENT


def _model_edge(values: np.ndarray, d: np.ndarray, cell: np.ndarray, reach: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
    """Edge offsets (B, 4, N) of profiles (B, 4, N, M) sampled at offsets d (B, 4, M), and which are usable.

    Each profile is fitted with a blurred model of the marker's cross-section: the inner code cell, the black
    border cell, the white quiet cell and what lies beyond, edges a cell (B, 4) apart, each level free (linear),
    the edge and the blur by Gauss-Newton; the blur is then pooled per edge. The neighbouring edges' blur, which
    biases the area edge's levels on small cells, is part of the model.
    """
    dd = np.broadcast_to(d[:, :, None, :], values.shape)
    c = np.broadcast_to(cell[:, :, None, None], values.shape)
    shape = values.shape[:-1]
    e = np.zeros(shape)
    sigma = np.full(shape, BLUR_MODEL_SIGMA0_PX)
    levels = None
    for it in range(BLUR_MODEL_ITERATIONS + BLUR_MODEL_POOLED_ITERATIONS):
        pooled = it >= BLUR_MODEL_ITERATIONS
        if it == BLUR_MODEL_ITERATIONS:
            sigma = np.broadcast_to(np.median(sigma, axis=-1, keepdims=True), shape).copy()
        s_ = sigma[..., None]
        z = np.stack([(e[..., None] + k * c - dd) / s_ for k in (-1, 0, 1)], axis=-1)  # (..., M, 3): three edges
        F = 1 / (1 + np.exp(-LOGISTIC_SLOPE * z))
        f = LOGISTIC_SLOPE * F * (1 - F)
        A = np.stack([F[..., 0], F[..., 1] - F[..., 0], F[..., 2] - F[..., 1], 1 - F[..., 2]], axis=-1)  # (..., M, 4)
        if levels is None:
            G = np.einsum("...mi,...mj->...ij", A, A) + BLUR_MODEL_RIDGE * np.eye(4)
            levels = np.linalg.solve(G, np.einsum("...mi,...m->...i", A, values)[..., None])[..., 0]
        jump = (levels[..., :3] - levels[..., 1:])[..., None, :]  # inner - black, black - white, white - beyond
        de = (jump * f).sum(axis=-1) / s_
        columns = [A, de[..., None]] if pooled else [A, de[..., None], ((jump * f * -z).sum(axis=-1) / s_)[..., None]]
        J = np.concatenate(columns, axis=-1)
        r = values - np.einsum("...mi,...i->...m", A, levels)
        G = np.einsum("...mi,...mj->...ij", J, J) + BLUR_MODEL_RIDGE * np.eye(J.shape[-1])
        delta = np.linalg.solve(G, np.einsum("...mi,...m->...i", J, r)[..., None])[..., 0]
        levels = levels + delta[..., :4]
        e = e + np.clip(delta[..., 4], -BLUR_MODEL_STEP_PX, BLUR_MODEL_STEP_PX)
        if not pooled:
            sigma = np.clip(sigma + np.clip(delta[..., 5], -BLUR_MODEL_SIGMA_STEP_PX, BLUR_MODEL_SIGMA_STEP_PX),
                            *BLUR_MODEL_SIGMA_RANGE_PX)
    ok = np.isfinite(e) & (levels[..., 2] - levels[..., 1] > MIN_CONTRAST) & (np.abs(e) < reach[..., None])
    return np.where(ok, e, 0.0), ok


def _smooth(v: np.ndarray) -> np.ndarray:
    """[1 2 1] / 4 smoothing along the last axis, with replicated ends."""
    padded = np.concatenate([v[..., :1], v, v[..., -1:]], axis=-1)
    return 0.25 * padded[..., :-2] + 0.5 * padded[..., 1:-1] + 0.25 * padded[..., 2:]


def _glow(inner: np.ndarray, black: np.ndarray, white: np.ndarray, cell: np.ndarray) -> np.ndarray:
    """Share (B, 4) of a neighbouring cell's contrast that the blur carries half a cell into each edge's levels.

    From inner cells, black and white levels (B, 4, N) and cell widths across the edges (B, 4): per edge, how much
    brighter the black level reads next to a white code cell than next to a black one, over the white cell's
    contrast (edges with at least MIN_GLOW_PROFILES of each); that share, Φ(-cell / 2σ), gives a blur σ per edge,
    their median the marker's blur, and the marker's blur each edge's share at its own cell width.
    """
    lit = (inner > 0.5 * (black + white)).reshape(-1, inner.shape[-1])
    rows, cells = black.reshape(lit.shape), inner.reshape(lit.shape)
    enough = (lit.sum(axis=1) >= MIN_GLOW_PROFILES) & ((~lit).sum(axis=1) >= MIN_GLOW_PROFILES)
    dark = np.where(enough, _masked_median(rows, ~lit), 0.0)
    lift = np.where(enough, _masked_median(rows, lit), 0.0) - dark
    contrast = np.where(enough, _masked_median(cells, lit), 1.0) - dark
    measured = (enough & (contrast > MIN_CONTRAST)).reshape(-1, 4) & (cell >= MIN_GLOW_CELL_PX)
    share = np.clip(lift / np.maximum(contrast, 1e-9), MIN_GLOW, MAX_GLOW).reshape(-1, 4)
    sigma = LOGISTIC_SLOPE * 0.5 * cell / np.log(1 / share - 1)  # logistic stand-in for the normal CDF
    blur = _masked_median(sigma, measured)
    blur = np.where(np.isfinite(blur), blur, 0.0)[:, None]
    reach = np.minimum(LOGISTIC_SLOPE * 0.5 * cell / np.maximum(blur, 1e-9), MAX_EXPONENT)  # cell / 2σ, scaled
    return np.where((blur > 0) & (cell >= MIN_GLOW_CELL_PX), 1 / (1 + np.exp(reach)), 0.0)


def _area_edge(values: np.ndarray, d: np.ndarray, level: np.ndarray, half: np.ndarray, step: np.ndarray,
               cell: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Area edge offsets (B, 4, N) from [inner, black, profile at d (B, 4, M)..., white, outer] samples
    (B, 4, N, M+4), the levels read at ∓level (B, 4), and which are usable; the levels lose the glow of the cells
    beyond them (_glow), and where the blur is small against a cell the edge is taken again closer in (_tight_edge).
    """
    inner, black, white, outer = values[..., 0], values[..., 1], values[..., -2], values[..., -1]
    glow = np.minimum(_glow(inner, black, white, cell), MAX_GLOW)[..., None]
    black = _smooth(black - glow * np.maximum(inner - black, 0.0))
    white = _smooth(white + glow * np.maximum(white - outer, 0.0))
    prof = values[..., 2:-2]
    contrast = white - black
    found = contrast > MIN_CONTRAST
    norm = (prof - black[..., None]) / np.where(found, contrast, 1.0)[..., None]
    area = step[..., None] * (norm.sum(axis=-1) - 0.5 * (norm[..., 0] + norm[..., -1]))
    e = half[..., None] - area
    return _tight_edge(values[..., 1:-1], d, level, half, e, _profile_blur(norm, d, e, found)), found


def _tight_edge(values: np.ndarray, d: np.ndarray, level: np.ndarray, half: np.ndarray, e: np.ndarray,
                blur: np.ndarray) -> np.ndarray:
    """Edge offsets (B, 4, N): the area edges e integrated again over TIGHT_HALF_SIGMAS of each marker's blur (B, 1)
    either side, their levels read TIGHT_LEVEL_SIGMAS out from the same [black, profile at d (B, 4, M)..., white]
    samples (B, 4, N, M+2) (levels at ∓level (B, 4)), on the edges where that falls short of the levels and window
    (half (B, 4)) the cell allows; e elsewhere, and where the tight levels' contrast is too low. The window (at least
    HALF_WINDOW_MIN_PX) is centred on e, kept within ±half and its levels within ±level; the glow correction is not
    applied (the next cells are far beyond those levels). What lies on the margin further out (a shadow's soft edge
    sweeping past) then no longer reaches the edge (benchmarks/shadow_edges.py).
    """
    tight_half = np.maximum(TIGHT_HALF_SIGMAS * blur, HALF_WINDOW_MIN_PX)
    tight = (TIGHT_LEVEL_SIGMAS * blur < level) & (tight_half < half)  # (B, 4)
    if not tight.any():
        return e
    xs = np.concatenate([-level[..., None], d, level[..., None]], axis=-1)  # (B, 4, M+2): the samples' offsets
    reach = np.minimum(TIGHT_LEVEL_SIGMAS * blur, level)[..., None]  # (B, 4, 1)
    centre = np.clip(e, -level[..., None] + reach, level[..., None] - reach)  # (B, 4, N)
    black = _smooth(_interp(xs, values, centre - reach))
    white = _smooth(_interp(xs, values, centre + reach))
    contrast = white - black
    found = contrast > MIN_CONTRAST
    h = tight_half[..., None]
    a = np.clip(centre - h, -half[..., None], half[..., None])
    b = np.clip(centre + h, -half[..., None], half[..., None])
    norm = (values - black[..., None]) / np.where(found, contrast, 1.0)[..., None]
    return np.where(tight[..., None] & found, b - _integral(xs, norm, a, b), e)


def _profile_blur(norm: np.ndarray, d: np.ndarray, e: np.ndarray, found: np.ndarray) -> np.ndarray:
    """Each marker's blur (B, 1), px: the median over its usable profiles of the spread (RMS width) of their
    normalised steps' gradient about their edges e (B, 4, N); profiles norm (B, 4, N, M) at offsets d (B, 4, M).
    It includes the pixels' own width and the sampling's interpolation, as the profiles do (0.3 px of optics reads
    about 0.5). Taken about e, which a shadow may have pulled, it reads wider there: a median over the four edges
    holds against one such edge, not against most of them."""
    mid = 0.5 * (d[..., 1:] + d[..., :-1])[:, :, None, :]
    rise = np.clip(np.diff(norm, axis=-1), 0.0, None)
    mass = rise.sum(axis=-1)
    var = (rise * (mid - e[..., None]) ** 2).sum(axis=-1) / np.maximum(mass, 1e-9)
    ok = (found & (mass > 0.5)).reshape(len(norm), -1)
    return np.sqrt(_masked_median(var.reshape(len(norm), -1), ok))[:, None]  # inf where no profile is usable


def _interp(xs: np.ndarray, ys: np.ndarray, at: np.ndarray) -> np.ndarray:
    """Values (B, 4, N) at offsets at (B, 4, N) of profiles ys (B, 4, N, K) sampled at increasing xs (B, 4, K)."""
    k = xs.shape[-1]
    j = np.clip((xs[:, :, None, :] <= at[..., None]).sum(axis=-1) - 1, 0, k - 2)  # (B, 4, N): interval
    grid = np.broadcast_to(xs[:, :, None, :], ys.shape)
    x0 = np.take_along_axis(grid, j[..., None], axis=-1)[..., 0]
    x1 = np.take_along_axis(grid, j[..., None] + 1, axis=-1)[..., 0]
    y0 = np.take_along_axis(ys, j[..., None], axis=-1)[..., 0]
    y1 = np.take_along_axis(ys, j[..., None] + 1, axis=-1)[..., 0]
    t = np.clip((at - x0) / np.maximum(x1 - x0, 1e-12), 0.0, 1.0)
    return y0 + t * (y1 - y0)


def _integral(xs: np.ndarray, ys: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Integrals (B, 4, N) from a to b (B, 4, N) of the piecewise-linear profiles ys (B, 4, N, K) at xs (B, 4, K)."""
    x0, x1 = xs[:, :, None, :-1], xs[:, :, None, 1:]
    lo = np.clip(a[..., None], x0, x1)
    hi = np.clip(b[..., None], x0, x1)
    width = np.maximum(x1 - x0, 1e-12)
    t = (0.5 * (lo + hi) - x0) / width  # where each interval's overlap is centred, 0..1
    y0, y1 = ys[..., :-1], ys[..., 1:]
    return ((hi - lo) * (y0 + t * (y1 - y0))).sum(axis=-1)


def _masked_median(v: np.ndarray, ok: np.ndarray) -> np.ndarray:
    """Median of each row of v (R, N) over the entries where ok (inf for rows with none)."""
    count = ok.sum(axis=1)
    ordered = np.sort(np.where(ok, v, np.inf), axis=1)
    lo = np.take_along_axis(ordered, np.maximum((count - 1) // 2, 0)[:, None], axis=1)[:, 0]
    hi = np.take_along_axis(ordered, np.maximum(count // 2, 0)[:, None], axis=1)[:, 0]
    return 0.5 * (lo + hi)


def _robust_lines(s: np.ndarray, e: np.ndarray, ok: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Tukey-weighted fits e = a + b s per row of (R, N): a, b and whether enough profiles agree."""
    need = max(MIN_PROFILES, MIN_INLIER_FRACTION * s.shape[1])
    w = ok.astype(np.float64)
    e = np.where(ok, e, 0.0)
    a = b = np.zeros(len(s))
    for i in range(ROBUST_ITERATIONS):
        sw = np.maximum(w.sum(axis=1), 1e-12)
        ms = (w * s).sum(axis=1) / sw
        me = (w * e).sum(axis=1) / sw
        ds = s - ms[:, None]
        b = (w * ds * (e - me[:, None])).sum(axis=1) / np.maximum((w * ds * ds).sum(axis=1), 1e-12)
        a = me - b * ms
        if i == ROBUST_ITERATIONS - 1:
            break
        r = e - a[:, None] - b[:, None] * s
        sigma = np.maximum(1.4826 * _masked_median(np.abs(r), ok), MIN_SIGMA_PX)
        z = r / (TUKEY_C * np.where(np.isfinite(sigma), sigma, 1.0)[:, None])
        w = np.where(ok & (np.abs(z) < 1), (1 - z * z) ** 2, 0.0)
    return a, b, (w > 0).sum(axis=1) >= need


def refine_corners_batch(gray: np.ndarray, quads: np.ndarray, camera: CameraModel | None = None,
                         cells: int = DEFAULT_CELLS, blur_model: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Refined corners (B, 4, 2) of quads (B, 4, 2) in distorted pixels, and which succeeded (others kept as given);
    blur_model: the blurred-profile model's edges on small cells instead of the area edge's."""
    quads = np.asarray(quads, dtype=np.float64).reshape(-1, 4, 2)
    count = len(quads)
    ok = np.all(np.isfinite(quads), axis=(1, 2))
    if count == 0 or gray.ndim != 2 or not ok.any():
        return quads.copy(), np.zeros(count, dtype=bool)
    gray = np.ascontiguousarray(gray)
    start = np.where(ok[:, None, None], quads, 0.0)
    ideal = camera.undistort_points(start.reshape(-1, 2)).reshape(count, 4, 2) if camera is not None else start
    for i in range(ITERATIONS):
        p, u, fitted = _fit_edges(gray, ideal, camera, cells, coarse=i == 0, blur_model=blur_model)
        corners, sin_angle = _intersect(p, u)
        fitted &= np.all(sin_angle > MIN_SIN_ANGLE, axis=1) & np.all(np.isfinite(corners), axis=(1, 2))
        ok &= fitted
        moved = np.abs(corners - ideal).max(axis=(1, 2))
        ideal = np.where(ok[:, None, None], corners, ideal)
        if i > 0 and not np.any(ok & (moved > CONVERGED_PX)):
            break
    refined = _distort(camera, ideal) if camera is not None else ideal
    cell = np.linalg.norm(np.diff(start, axis=1, append=start[:, :1]), axis=2).mean(axis=1) / cells
    limit = np.maximum(MAX_SHIFT_PX, MAX_SHIFT_CELLS * cell)
    ok &= np.all(np.isfinite(refined), axis=(1, 2)) & (np.linalg.norm(refined - quads, axis=2).max(axis=1) <= limit)
    return np.where(ok[:, None, None], refined, quads), ok


def try_refine_corners(gray: np.ndarray, corners: np.ndarray, camera: CameraModel | None = None,
                       cells: int = DEFAULT_CELLS, blur_model: bool = False) -> np.ndarray | None:
    """Refined corners (4, 2) in distorted pixels, TL TR BR BL, or None when an edge cannot be fitted."""
    refined, ok = refine_corners_batch(gray, np.asarray(corners).reshape(1, 4, 2), camera, cells, blur_model)
    return refined[0] if ok[0] else None


def refine_corners(gray: np.ndarray, corners: np.ndarray, camera: CameraModel | None = None,
                   cells: int = DEFAULT_CELLS, blur_model: bool = False) -> np.ndarray:
    """Refined corners (4, 2) in distorted pixels, or the input corners unchanged when a fit fails."""
    return refine_corners_batch(gray, np.asarray(corners).reshape(1, 4, 2), camera, cells, blur_model)[0][0]
