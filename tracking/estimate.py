"""A cone's estimate: the offset (Δx, Δy, Δz) at one cone at one capture time, its σ, the cameras it rests on, and,
where the estimator withheld it, why. Every estimator (tracking.estimator.ESTIMATORS) gives these."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

TOLERANCE_M = 0.150  # concentricity requirement (paper, section I-D): the band every view and table shows
WITHHELD_SIGMA = "σ too large"  # the cameras do not see the cone well enough
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
