"""What a run showed at each cone, for the summary `track` prints: the share of its estimates shown, when the first
was, why the others were withheld, the least σ per axis it reached and the cameras that measured its marker pair.

The least σ says why a cone that was never shown was not: an axis whose σ never came under the report limit
(REPORT_MAX_SIGMA_M) is one its cameras do not see well enough. A lone camera's worst axis is its line of sight (the
depth of two markers from their sizes, and the jacket marker's tilt over the lever to the topside marker); a camera
that sees the cone from another side measures that axis across its picture.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from tracking.estimate import AXIS_NAMES, ConeEstimate, axes_above, sigma_text
from tracking.offsets import PairOffset

if TYPE_CHECKING:  # the estimator's package is the CLI's heaviest import: `track` loads it when it fuses
    from tracking.estimator.measurements import Measurement

@dataclass
class ConeTally:
    """One cone's estimates counted as they come."""

    cone: str
    estimates: int = 0
    shown: int = 0
    first_shown: float = np.nan  # s, capture time
    withheld: Counter = field(default_factory=Counter)  # reason -> estimates withheld for it
    least_sigma: np.ndarray = field(default_factory=lambda: np.full(3, np.inf))  # (3,) m, per axis over the estimates
    pair_frames: Counter = field(default_factory=Counter)  # camera -> its frames that measured a pair at the cone
    axes_shown: np.ndarray = field(default_factory=lambda: np.zeros(3, dtype=int))  # (3,) estimates showing each axis

    def add(self, e: ConeEstimate) -> None:
        """Count one estimate of this cone."""
        self.estimates += 1
        self.least_sigma = np.fmin(self.least_sigma, e.sigma)  # NaN (no covariance) leaves it
        finite = np.isfinite(e.offset)
        self.axes_shown += finite
        if finite.all():
            self.shown += 1
            if not np.isfinite(self.first_shown):
                self.first_shown = e.time
        else:
            self.withheld[e.withheld or "no number"] += 1

    def sigma_text(self) -> str:
        """The least σ per axis in mm, e.g. 'Δx 12 · Δy 71 · Δz 9 mm' ('—' where no estimate stated one)."""
        return sigma_text(self.least_sigma) if np.isfinite(self.least_sigma).any() else "—"

    def reasons(self) -> str:
        """Why its estimates were withheld, most often first: 'σ too large ×30, cameras not yet compared ×1'."""
        return ", ".join(f"{why} ×{n}" for why, n in self.withheld.most_common())

    def why_never(self) -> str:
        """Why a cone never shown was not, in one line (empty once it was shown)."""
        from tracking.estimator.noise import REPORT_MAX_SIGMA_M

        if self.shown:
            return ""
        reasons = self.reasons() or "no estimate"
        along = axes_above(self.least_sigma, REPORT_MAX_SIGMA_M)
        if not along:
            return f"cone {self.cone}: never shown ({reasons})"
        cams = sorted(self.pair_frames)
        head = (f"cone {self.cone}: never shown ({reasons}): its σ came no lower than {self.sigma_text()}, above the "
                f"{REPORT_MAX_SIGMA_M * 1000:.0f} mm limit on {along}")
        if self.axes_shown.any():  # the axes within the limit were shown on their own
            head += "; " + ", ".join(f"{a} shown {n / max(self.estimates, 1):.0%}" for a, n in
                                     zip(AXIS_NAMES, self.axes_shown, strict=True) if n)
        if not cams:
            return f"{head}: no camera measured a marker pair there (its offset came through the topside alone)"
        if len(cams) == 1:
            return (f"{head}: {cams[0]} alone measured its pair and does not see it well enough along {along}; a "
                    "camera seeing it from another side would measure that across its picture")
        return f"{head}: its cameras ({', '.join(cams)}) do not see it well enough along {along}"


@dataclass
class ConeTallies:
    """Every cone's tally, and the capture time of the run's first estimate (first-shown times count from it)."""

    cones: dict[str, ConeTally] = field(default_factory=dict)
    start: float = np.nan

    def add(self, e: ConeEstimate) -> None:
        """Count one estimate."""
        if not np.isfinite(self.start):
            self.start = e.time
        self.cones.setdefault(e.cone, ConeTally(e.cone)).add(e)

    def measured(self, m: Measurement) -> None:
        """Count a camera's frame that measured a marker pair (other measurements say nothing of a cone)."""
        if isinstance(m, PairOffset):
            self.cones.setdefault(m.cone, ConeTally(m.cone)).pair_frames[m.camera] += 1

    def rows(self) -> list[tuple[str, ...]]:
        """Per cone: cone, shown share, first shown (s from the start), withheld reasons, least σ, the cameras that
        measured its pair (with their frames)."""
        out = []
        for name in sorted(self.cones):
            t = self.cones[name]
            first = f"{t.first_shown - self.start:.1f} s" if np.isfinite(t.first_shown) else "never"
            out.append((name, f"{t.shown / max(t.estimates, 1):.0%}", first, t.reasons() or "—", t.sigma_text(),
                        ", ".join(f"{c} ({n})" for c, n in sorted(t.pair_frames.items())) or "—"))
        return out
