"""A cone's estimate: the offset (Δx, Δy, Δz) at one cone at one capture time, its σ, the cameras it rests on, and,
where the estimator withheld it, why. Every estimator (tracking.estimator.ESTIMATORS) gives these."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

TOLERANCE_M = 0.150  # concentricity requirement (paper, section I-D): the band every view and table shows
WITHHELD_SIGMA = "σ too large"  # the cameras do not see the cone well enough
WITHHELD_WARMING = "warming up"  # σ within the limit, but not yet within the tighter one of the first seconds after the
# topside is placed (REPORT_WARMUP_S, REPORT_WARMUP_SIGMA_SIDES): the poses are new and their errors not yet Gaussian
WITHHELD_CLOCKS = "clocks not measured"  # σ within bounds but for the topside's motion over its cameras' clock σ
WITHHELD_SCALE = "rig error: marker size"  # the markers do not look the size the rig states (tracking.scale)
WITHHELD_COMPARING = "cameras not yet compared"  # two cameras see the cone and one new to it has too few frames yet to
# tell whether they disagree beyond their noise, for half a second at most (tracking.estimator.disagreement)
WITHHELD_BELOW = "rig error: through the cones"  # the offset puts the topside below its cone tips: no set-down can


@dataclass(frozen=True)
class ConeEstimate:
    """The offset at one cone at one capture time, and the cameras it rests on."""

    time: float  # s, capture time of the newest frame that contributed
    cone: str
    offset: np.ndarray  # (3,) dx, dy, dz in the jacket frame, m; NaN where no camera gives the axis
    cameras: tuple[str, ...]
    covariance: np.ndarray | None = None  # (3, 3) m², where the estimator knows it
    T_jacket_cameras: Mapping[str, np.ndarray] | None = None  # (4, 4) per placed camera, where the estimator keeps
    # the cameras' poses (the live fused filter); one mapping shared by the estimates of one time
    withheld: str = ""  # why the offset is NaN, in a few words (WITHHELD_*), where the estimator withheld it

    @property
    def sigma(self) -> np.ndarray:
        """(3,) m, 1σ per axis (NaN where the estimator states no covariance)."""
        if self.covariance is None:
            return np.full(3, np.nan)
        return np.sqrt(np.maximum(np.diagonal(self.covariance), 0.0))  # (maximum: a third of clip's cost, per CSV row)


AXIS_NAMES = ("Δx", "Δy", "Δz")


def sigma_text(sigma: np.ndarray) -> str:
    """σ per axis (3,) m as 'Δx 12 · Δy 71 · Δz 9 mm'."""
    return " · ".join(f"{a} {s * 1000:.0f}" for a, s in zip(AXIS_NAMES, sigma, strict=True)) + " mm"


def axes_withheld(offset: np.ndarray) -> str:
    """The axes an offset (3,) withholds (NaN), e.g. 'Δz' or 'Δx and Δy'; empty if none."""
    return " and ".join(a for a, v in zip(AXIS_NAMES, offset, strict=True) if not np.isfinite(v))


def axes_above(sigma: np.ndarray, limit: float) -> str:
    """The axes whose σ (3,) m exceeds limit (not those that state none), e.g. 'Δy' or 'Δx and Δz'; empty if none."""
    return " and ".join(a for a, s in zip(AXIS_NAMES, sigma, strict=True) if limit < s < np.inf)
