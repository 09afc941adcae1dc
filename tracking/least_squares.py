"""The sparse robust least-squares solver `topside sync` (tracking/clocks.py) and `topside survey` (tracking/survey.py)
share: minimise Σ ρ(r(x)) over parameters x, r whitened residuals (σ 1) with a sparse Jacobian.

- ρ: soft-L1 on the measurements' residuals (SoftL1: quadratic within `scale` σ, linear beyond: rain-struck corners,
  a wrong IPPE pose), plain squares on the priors' where a problem says so. A group of residuals measured together
  (a corner's u and v) shares one weight, from its norm.
- Steps: Gauss-Newton on the sparse normal equations Jᵀ W J δ = -Jᵀ W r (W the soft-L1 weights at x, i.e.
  iteratively reweighted), solved by a sparse LU; a step is kept when the robust cost falls, else retried damped
  by λ diag(Jᵀ W J) (Levenberg-Marquardt).
- σ: the inverse of the information Jᵀ W J at the solution (information_columns), each problem scaling it as it
  states.

Why not scipy.optimize.least_squares: with a sparse Jacobian it solves each step iteratively (LSMR in a
two-dimensional subspace; its 'exact' trust region and 'lm' need a dense Jacobian, gigabytes at sync's and survey's
sizes on real footage). These problems are ill-conditioned (splines padded beyond their samples held by second
differences alone, gauges held by weak priors), so LSMR needs tight tolerances and many iterations: tens of times
slower on the tests' fits (docs/method.md#clocks-and-the-marker-survey-sync-survey). The soft-L1 loss is scipy's
(ρ(z) = 2 (√(1 + z) - 1) of z = (r / scale)²), so the solution is the one scipy's converges to.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix, csc_matrix, csr_matrix, diags
from scipy.sparse.linalg import splu, spsolve

RIDGE = 1e-9  # relative damping always kept in the normal equations: a parameter nothing reaches (a gauge no prior
# fixes) stays finite instead of making the matrix singular
RIDGE_FLOOR = 1.0  # ... of its diagonal, or of this where the diagonal is smaller (a parameter nothing informs);
# sync's and the survey's parameters all have 16 or more (a spline's end knot, held by the acceleration prior alone)
FIRST_DAMPING = 1e-3  # Levenberg-Marquardt's λ, relative to the diagonal, when an undamped step raised the cost
MAX_DAMPING = 1e8  # ... it grows tenfold while steps raise the cost, up to this: then x is where it stops
MIN_DAMPING = 1e-9  # ... and shrinks tenfold after each kept step; below this it is 0 (Gauss-Newton). Steps are
# undamped until one raises the cost: damping from the start holds back the gauges' weakly determined directions
TOLERANCE = 1e-7  # relative fall of the cost at which the fit stops


@dataclass(frozen=True)
class SoftL1:
    """Soft-L1 of whitened residuals: ρ = 2 scale² (√(1 + |r_g|² / scale²) - 1) per group r_g of `group` consecutive
    residuals (|r_g|² near zero), on the first `rows` residuals (None: all); the rest count as plain squares."""

    scale: float  # σ: residual (group) norms beyond this count linearly
    rows: int | None = None
    group: int = 1

    def _norms(self, r: np.ndarray) -> tuple[np.ndarray, int]:
        """(G,) squared norms of the robust groups over scale², and the number of robust rows."""
        n = r.size if self.rows is None else self.rows
        return np.sum(r[:n].reshape(-1, self.group) ** 2, axis=1) / self.scale**2, n

    def weights(self, r: np.ndarray) -> np.ndarray:
        """(M,) IRLS weights of residuals r (M,): ρ'(z) = 1 / √(1 + z), 1 near zero, scale / |r_g| far out."""
        z, n = self._norms(r)
        w = np.ones(r.size)
        w[:n] = np.repeat(1.0 / np.sqrt(1.0 + z), self.group)
        return w

    def cost(self, r: np.ndarray) -> float:
        """Σ ρ of residuals r (M,)."""
        z, n = self._norms(r)
        return float(np.sum(2.0 * (np.sqrt(1.0 + z) - 1.0)) * self.scale**2 + r[n:] @ r[n:])


class Triplets:
    """A sparse Jacobian assembled from blocks of (rows, columns, values) of any equal shape."""

    def __init__(self) -> None:
        self.rows: list[np.ndarray] = []
        self.cols: list[np.ndarray] = []
        self.vals: list[np.ndarray] = []

    def add(self, rows: np.ndarray | int, cols: np.ndarray | int, vals: np.ndarray) -> None:
        """Entries vals at (rows, cols), each broadcast to vals' shape."""
        vals = np.asarray(vals, dtype=float)
        self.rows.append(np.broadcast_to(rows, vals.shape).reshape(-1))
        self.cols.append(np.broadcast_to(cols, vals.shape).reshape(-1))
        self.vals.append(vals.reshape(-1))

    def diagonal(self, first_row: int, first_col: int, vals: np.ndarray) -> int:
        """vals (k,) on a diagonal from (first_row, first_col); returns the next free row."""
        k = np.arange(len(vals))
        self.add(first_row + k, first_col + k, vals)
        return first_row + len(vals)

    def matrix(self, rows: int, cols: int) -> csr_matrix:
        """The (rows, cols) matrix (entries at one place summed)."""
        return coo_matrix((np.concatenate(self.vals), (np.concatenate(self.rows), np.concatenate(self.cols))),
                          shape=(rows, cols)).tocsr()


def _ridged(A: csc_matrix, damping: float = 0.0) -> csc_matrix:
    """A + (damping + RIDGE) diag(max(diag A, RIDGE_FLOOR)), as a CSC matrix for the sparse LU."""
    return (A + diags((damping + RIDGE) * np.maximum(A.diagonal(), RIDGE_FLOOR))).tocsc()


def linear_step(J: csr_matrix, r: np.ndarray) -> np.ndarray:
    """The step minimising |J step + r|² (plain squares; the normal equations with the ridge): a linear problem's
    solution from its residuals r at any x."""
    return spsolve(_ridged((J.T @ J).tocsc()), -(J.T @ r))


@dataclass(frozen=True)
class Solution:
    """Where the fit stopped."""

    x: np.ndarray
    iterations: int
    cost: float  # Σ ρ there


def minimise(residuals: Callable[[np.ndarray], np.ndarray], jacobian: Callable[[np.ndarray], csr_matrix],
             x0: np.ndarray, loss: SoftL1, max_iterations: int,
             settled: Callable[[np.ndarray], bool] | None = None) -> Solution:
    """Gauss-Newton from x0 on Σ ρ(residuals(x)) (jacobian(x): d residuals / dx, sparse), damped as
    Levenberg-Marquardt where a step raises the cost, the soft-L1 weights renewed at every step. Stops after
    max_iterations, when the cost falls by TOLERANCE of itself or less, when settled(step) says the parameters that
    matter no longer move, or when no damping up to MAX_DAMPING lowers it."""
    x = np.asarray(x0, dtype=float).copy()
    r = residuals(x)
    cost = loss.cost(r)
    lam = 0.0
    it = 0
    for it in range(1, max_iterations + 1):
        w = loss.weights(r)
        J = jacobian(x)  # named, so held until the next step (freeing it at once ran slower)
        Jw = diags(np.sqrt(w)) @ J
        A = (Jw.T @ Jw).tocsc()
        g = Jw.T @ (np.sqrt(w) * r)
        while True:
            step = splu(_ridged(A, lam)).solve(-g)
            r_new = residuals(x + step)
            cost_new = loss.cost(r_new)
            if cost_new <= cost:
                break
            lam = max(10 * lam, FIRST_DAMPING)
            if lam > MAX_DAMPING:
                return Solution(x, it, cost)
        done = cost - cost_new <= TOLERANCE * cost or (settled is not None and settled(step))
        x, r, cost = x + step, r_new, cost_new
        lam = lam / 10 if lam / 10 >= MIN_DAMPING else 0.0
        if done:
            break
    return Solution(x, it, cost)


def information_columns(J: csr_matrix, weights: np.ndarray, columns: np.ndarray) -> np.ndarray:
    """(N, k) the given columns (k,) of the inverse of the information Jᵀ W J (N, N) (W: the weights the fit gave the
    residuals at its solution; the ridge as in the fit): the covariance of the parameters with them, were the
    whitened residuals' σ 1."""
    if not len(columns):
        return np.zeros((J.shape[1], 0))
    lu = splu(_ridged((J.T @ diags(weights) @ J).tocsc()))
    E = np.zeros((J.shape[1], len(columns)))
    E[columns, np.arange(len(columns))] = 1.0
    return lu.solve(E)
