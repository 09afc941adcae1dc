"""The Rauch-Tung-Striebel smoother of a recorded run: the filter forward, then passes backward over spans of it.

The backward pass runs whenever the kept steps span SMOOTHER_SPAN_S + SMOOTHER_LAG_S, so memory holds that much of
the run, not all of it. The cameras' nominal poses move as the filter runs; the backward pass treats their errors
about the nominal of each step as the state, which holds to first order.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass

import numpy as np

from tracking.estimate import ConeEstimate
from tracking.estimator.filter import FilterReport, TopsideFilter
from tracking.estimator.measurements import Measurement, frames
from tracking.estimator.noise import SMOOTHER_LAG_S, SMOOTHER_SPAN_S, FilterTuning
from tracking.estimator.process import Transition
from tracking.rig import Rig


@dataclass
class FilterStep:
    """One time step of the filter, kept for the smoother (its predicted covariance follows from the previous step's P
    and F: not kept, it would double the memory)."""

    time: float
    x_pred: np.ndarray
    x: np.ndarray
    P32: np.ndarray  # the step's covariance in single precision: half the memory, and the smoothed offsets within
    # 0.0005 mm of double precision's on three campaign installations; read it as P
    F: Transition
    cameras: tuple[str, ...]
    warming: bool  # within REPORT_WARMUP_S of the topside's (last) placement
    floors: tuple[np.ndarray, np.ndarray]  # the cameras' disagreement at each cone (estimator.disagreement): the
    # variance it adds (C, 3) and the cones whose cameras are not yet compared (C,)
    measured: frozenset[str] = frozenset()  # the cones whose pair a camera saw then (TopsideFilter.measured)
    seen: frozenset[int] = frozenset()  # the topside markers measured then (TopsideFilter.seen_topside)
    replaced: bool = False  # a camera was placed again in this step (TopsideFilter.replacements): no linear
    # transition leads into it, so the backward pass starts afresh before it

    @property
    def P(self) -> np.ndarray:
        """(n, n) the step's covariance, in double precision."""
        return self.P32.astype(np.float64)


def smoothed_estimates(rig: Rig, measurements: Iterable[Measurement], tuning: FilterTuning | None = None,
                       span_s: float = SMOOTHER_SPAN_S, lag_s: float = SMOOTHER_LAG_S,
                       report: FilterReport | None = None) -> Iterator[ConeEstimate]:
    """Recorded: the filter forward, then Rauch-Tung-Striebel passes backward; the offset at every cone, in time order.

    The backward pass runs whenever the kept steps span span_s + lag_s: from the newest step back, it gives the steps
    older than lag_s before the newest and lets them go, so memory holds span_s + lag_s of the run, not all of it.
    The cameras' nominal poses move as the filter runs; the backward pass treats their errors about
    the nominal of each step as the state, which holds to first order. A cone is shown where the live filter showed
    it at that step (its σ limit and warm-up), with the live filter's covariance: the smoothed covariance counts the
    frames after a step as independent of those before it, but a view's persistent corner errors are in both, so it
    understates σ at cones far from every marker (evidence in docs/method.md#fusion-the-default).
    """
    kf = TopsideFilter(rig, tuning or FilterTuning())
    steps: list[FilterStep] = []
    for group in frames(measurements):
        replacements = kf.replacements
        F = kf.predict(group[0].time, group)
        x_pred = kf.x.copy()
        for m in group:
            kf.update(m)
        if kf.last_accepted:
            now = group[0].time if kf.time is None else kf.time  # predict set it
            steps.append(FilterStep(now, x_pred, kf.x.copy(), kf.P.astype(np.float32), F, kf.contributing(),
                                    kf.warming(), kf.disagreement.floors(now), kf.measured(),
                                    kf.seen_topside(), kf.replacements != replacements))
            if steps[-1].time - steps[0].time >= span_s + lag_s:
                yield from _smooth_back(kf, steps, steps[-1].time - lag_s)
    yield from _smooth_back(kf, steps, np.inf)
    if report is not None:
        report.take(kf)


def _smooth_back(kf: TopsideFilter, steps: list[FilterStep], until: float) -> Iterator[ConeEstimate]:
    """One backward (RTS) pass from the newest of steps: the estimates of the steps before until, which leave steps;
    each with its step's forward covariance (smoothed_estimates says why), so the smoothed covariance is not kept."""
    if not steps:
        return
    nxt = steps[-1]
    x_s = nxt.x
    out = [kf.cone_estimates(x_s, nxt.P, nxt.time, nxt.cameras, nxt.warming, nxt.floors, nxt.measured, nxt.seen)
           ] if nxt.time < until else []
    for step in reversed(steps[:-1]):
        P = step.P
        if nxt.replaced:  # a camera's nominal pose jumped within nxt: its errors before and after are not one state
            x_s = step.x
        else:
            n = step.x.size  # views first seen after this step are independent of it: their states drop out
            P_pred = nxt.F.covariance(P)
            C = np.linalg.solve(P_pred, nxt.F.apply(P)).T  # P Fᵀ P_pred⁻¹ (P_pred symmetric)
            x_s = step.x + C @ (x_s[:n] - nxt.x_pred)
            x_s[kf.consider.indices] = 0.0  # considered, not estimated (FilterState.apply)
        if step.time < until:
            out.append(kf.cone_estimates(x_s, P, step.time, step.cameras, step.warming, step.floors,
                                          step.measured, step.seen))
        nxt = step
    del steps[:len(out)]  # the smoothed ones are the oldest: the rest waits for more of the future
    for estimates in reversed(out):
        yield from estimates
