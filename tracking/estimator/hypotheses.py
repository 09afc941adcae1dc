"""Which of a lone jacket marker's two IPPE poses places a camera: both options carried until the evidence decides.

A 1 m marker seen from 30-50 m has two planar poses that reproject almost alike (the camera on one side of the
marker's normal or mirrored to the other); they differ by twice the view's angle off the normal, which turns the
camera by that much about the marker and moves it metres. Every frame of an unplaced camera whose jacket view is
ambiguous adds, per option, a χ² of what that option says against what is known:

- the jacket marker's own corners (the perspective IPPE could not settle in one frame adds up over frames);
- the topside's corners, through the filter's topside state and its covariance (a Mahalanobis distance: a topside
  known to centimetres tells options that put its markers metres apart, however poorly it is known beyond that), unless
  no option fits them (then the topside's state is off), and capped at EVIDENCE_CAP times their gate;
- before the topside is placed, its tilt: it hangs near level under the right option (σ LEVEL_SIGMA_RAD);
- once, the camera's surveyed position (rig: position, position_sigma) against each option's.

Frames closer than EVIDENCE_TAU_S count in part (min(1, dt / EVIDENCE_TAU_S)): a view's corner errors last about
that long, so a burst of frames is not taken as independent evidence. The option ahead by DECISIVE_CHI2 (a likelihood
ratio of 1000) places the camera, at the pose, of that option's frames so far, that fits the topside best (a far
view's options wander by metres from one frame to the next). Options within SAME_OPTION_CHI2 of
each other (their own σ: a view near square on, whose options straddle the true pose) are one: after
ONE_OPTION_WAIT_S, the pose between a frame's options that fits the topside best (or the mean of them) places it.
Nothing here waits on a condition only the camera could bring about: its own corners keep adding evidence, and the
topside term uses whatever the other cameras know, at any σ.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from itertools import permutations

import numpy as np

from tracking.geometry import between

EVIDENCE_TAU_S = 0.5  # s: a view's corner errors stay about this long (estimator.noise.VIEW_BIAS_TAU_S)
DECISIVE_CHI2 = 13.8  # 2 ln 1000: the evidence for one option over the next that places the camera
EVIDENCE_CAP = 2.0  # a frame's topside χ² counts up to this many times its gate (χ² 99.9 % of its corners): beyond,
# the option is wrong whatever the number, and one frame of a topside just placed (and off) must not outweigh the rest;
# a frame where no option fits the topside's corners within the gate tells nothing (the topside's state is off)
SAME_OPTION_CHI2 = 9.0  # options whose camera positions lie within 3σ of each other (their placements' covariances)
# are one (a view near square on): they, or the pose between them, place the camera ...
ONE_OPTION_WAIT_S = 1.0  # ... once their frames span this long: of the poses between each frame's options, the one that
# fits the topside best, else the pose between them all
LEVEL_SIGMA_RAD = np.radians(3.0)  # a hanging topside's tilt from level, 1σ, before anything else measures it


@dataclass
class Hypotheses:
    """An unplaced camera's IPPE options of its jacket view, the evidence for each so far, and each frame's pose of
    each (with how well it fitted the topside, when that was known)."""

    positions: list[np.ndarray]  # (3,) each option's camera centre in the jacket frame, last frame (how frames match)
    evidence: np.ndarray  # (k,) accumulated χ² against each option
    first: float  # capture time of the first ambiguous view, s
    last: float  # capture time of the last evidence, s
    surveyed: bool = False  # the camera survey's χ² has been added
    frames: int = 0
    sources: set[str] = field(default_factory=set)  # what has contributed: corners, topside, level, survey
    poses: list[list[tuple[float, np.ndarray]]] = field(default_factory=list)  # per hypothesis, per frame: (its
    # misfit, T_jacket_camera (4, 4)); the misfit the topside's Mahalanobis distance where known, else nan
    between: list[tuple[float, np.ndarray]] = field(default_factory=list)  # per frame, the pose between its options

    @classmethod
    def start(cls, positions: list[np.ndarray], time: float) -> Hypotheses:
        """Hypotheses from a first ambiguous view's options (their camera centres)."""
        return cls([np.asarray(p, dtype=float) for p in positions], np.zeros(len(positions)), time, time,
                   poses=[[] for _ in positions])

    def match(self, positions: list[np.ndarray]) -> list[int] | None:
        """For a frame's options (camera centres), the kept hypothesis each is: the assignment nearest overall (a far
        view's options wander by metres from frame to frame); None when their number differs."""
        if len(positions) != len(self.positions):
            return None
        orders = [list(order) for order in permutations(range(len(positions)))]
        return min(orders, key=lambda order: sum(float(np.linalg.norm(p - self.positions[k]))
                                                 for p, k in zip(positions, order, strict=True)))

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

    @property
    def span(self) -> float:
        """Capture time from the first ambiguous view to the last, s."""
        return self.last - self.first

    def decided(self) -> int | None:
        """The hypothesis that places the camera, or None while the evidence does not decide."""
        return self.leader if self.margin >= DECISIVE_CHI2 else None

    def pose(self, k: int) -> np.ndarray:
        """(4, 4) T_jacket_camera that places the camera under hypothesis k: of its frames' poses, the one that fitted
        the topside best, else the pose between them all (frame to frame a far view's pose wanders by metres)."""
        return best_pose(self.poses[k])

    def one(self) -> np.ndarray:
        """(4, 4) T_jacket_camera between the options, for a view whose options are one, likewise."""
        return best_pose(self.between)


def best_pose(poses: list[tuple[float, np.ndarray]]) -> np.ndarray:
    """Of (misfit, T (4, 4)) per frame, the T of the least misfit, or the pose between them all without misfits."""
    scored = [(m, T) for m, T in poses if np.isfinite(m)]
    if scored:
        return min(scored, key=lambda item: item[0])[1]
    return between([T for _, T in poses])

