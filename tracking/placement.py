"""Which of a lone jacket marker's two IPPE poses places a camera: both options carried until the evidence decides.

A 1 m marker seen from 30-50 m has two planar poses that reproject almost alike (the camera on one side of the
marker's normal or mirrored to the other); they differ by twice the view's angle off the normal, which turns the
camera by that much about the marker and moves it metres. Every frame of an unplaced camera whose jacket view is
ambiguous adds, per option, a χ² of what that option says against what is known:

- the jacket marker's own corners (the perspective IPPE could not settle in one frame adds up over frames);
- the topside's corners, through the filter's topside state and its covariance (a Mahalanobis distance: a topside
  known to 70 mm tells options that put its markers metres apart, however poorly it is known beyond that);
- before the topside is placed, its tilt: it hangs near level under the right option (σ LEVEL_SIGMA_RAD);
- once, the camera's surveyed position (rig: position, position_sigma) against each option's.

Frames closer than EVIDENCE_TAU_S count in part (min(1, dt / EVIDENCE_TAU_S)): a view's corner errors last about
that long, so a burst of frames is not taken as independent evidence. The option ahead by DECISIVE_CHI2 (a likelihood
ratio of 1000) places the camera; options that place the camera within SAME_OPTION_CHI2 of each other (their own
σ) are one and place it at once.
Nothing here waits on a condition only the camera could bring about: its own corners keep adding evidence, and the
topside term uses whatever the other cameras know, at any σ.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

EVIDENCE_TAU_S = 0.5  # s: a view's corner errors stay about this long (fusion.VIEW_BIAS_TAU_S)
DECISIVE_CHI2 = 13.8  # 2 ln 1000: the evidence for one option over the next that places the camera
SAME_OPTION_CHI2 = 9.0  # options whose camera positions lie within 3σ of each other (their placements' covariances)
# are one (a view near square on): either places the camera
LEVEL_SIGMA_RAD = np.radians(3.0)  # a hanging topside's tilt from level, 1σ, before anything else measures it
MATCH_M = 1.0  # a later frame's option is the same hypothesis as a kept one when their cameras are this close, m ...
MATCH_SHARE = 0.25  # ... or within this share of the distance between the kept options (drones move)


@dataclass
class Hypotheses:
    """An unplaced camera's IPPE options of its jacket view, and the evidence for each so far."""

    positions: list[np.ndarray]  # (3,) each option's camera centre in the jacket frame (how later frames match)
    evidence: np.ndarray  # (k,) accumulated χ² against each option
    first: float  # capture time of the first ambiguous view, s
    last: float  # capture time of the last evidence, s
    surveyed: bool = False  # the camera survey's χ² has been added
    frames: int = 0
    sources: set[str] = field(default_factory=set)  # what has contributed: corners, topside, level, survey

    @classmethod
    def start(cls, positions: list[np.ndarray], time: float) -> Hypotheses:
        """Hypotheses from a first ambiguous view's options (their camera centres)."""
        return cls([np.asarray(p, dtype=float) for p in positions], np.zeros(len(positions)), time, time)

    def match(self, positions: list[np.ndarray]) -> list[int] | None:
        """For a frame's options (camera centres), the kept hypothesis each is (None: they do not match)."""
        gap = min((float(np.linalg.norm(a - b)) for i, a in enumerate(self.positions) for b in self.positions[i + 1:]),
                  default=np.inf)
        reach = max(MATCH_M, MATCH_SHARE * gap)
        out = []
        for p in positions:
            d = [float(np.linalg.norm(p - q)) for q in self.positions]
            k = int(np.argmin(d))
            if d[k] > reach or k in out:
                return None
            out.append(k)
        return out

    def add(self, chi2: np.ndarray, time: float, source: str, once: bool = False) -> None:
        """One frame's χ² per hypothesis (k,) from one source; weighed by how much of a new view it is, or in full
        (once: the survey)."""
        weight = 1.0 if once or self.frames == 0 else min(1.0, max(0.0, time - self.last) / EVIDENCE_TAU_S)
        self.evidence = self.evidence + weight * np.asarray(chi2, dtype=float)
        self.sources.add(source)

    def step(self, time: float) -> None:
        """The frame's evidence is in."""
        self.frames += 1
        self.last = time

    @property
    def margin(self) -> float:
        """χ² by which the leading hypothesis beats the next."""
        if len(self.evidence) < 2:
            return np.inf
        best, second = np.sort(self.evidence)[:2]
        return float(second - best)

    @property
    def leader(self) -> int:
        return int(np.argmin(self.evidence))

    def decided(self) -> int | None:
        """The hypothesis that places the camera, or None while the evidence does not decide."""
        return self.leader if self.margin >= DECISIVE_CHI2 else None


def rotation_angle(R_a: np.ndarray, R_b: np.ndarray) -> float:
    """Angle (rad) between two rotations (3, 3)."""
    c = (np.trace(R_a.T @ R_b) - 1.0) / 2.0
    return float(np.arccos(np.clip(c, -1.0, 1.0)))
