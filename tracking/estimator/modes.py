"""The estimators a run can use, by name: the fused filter live, the smoother on recorded runs, and the paper's.

Each takes (rig, measurements, report=None) and yields ConeEstimate in time order; report, a FilterReport, gets
what the filter found at the end of the run (the paper's and the raw mode have no filter: nothing).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator

from tracking.estimate import ConeEstimate
from tracking.estimator.filter import FilterReport, TopsideFilter
from tracking.estimator.measurements import Measurement, frames, preferred
from tracking.estimator.noise import FilterTuning
from tracking.estimator.smoother import smoothed_estimates
from tracking.offsets import PairOffset
from tracking.paper import paper_filter, raw_estimates
from tracking.rig import Rig


def fused_estimates(rig: Rig, measurements: Iterable[Measurement], tuning: FilterTuning | None = None,
                    report: FilterReport | None = None) -> Iterator[ConeEstimate]:
    """Live: after each frame with measurements, the filtered offset at every cone; report, when given, gets the
    run's findings at its end."""
    kf = TopsideFilter(rig, tuning or FilterTuning())
    for group in frames(measurements):
        yield from filter_frame(kf, group)
    if report is not None:
        report.take(kf)


def filter_frame(kf: TopsideFilter, group: list[Measurement]) -> list[ConeEstimate]:
    """One camera frame's measurements applied at its capture time; the estimate at every cone after it
    (none until something was accepted; from then on, every frame gives one)."""
    kf.predict(group[0].time, group)
    for m in preferred(group):
        kf.update(m)
    return kf.cone_estimates() if kf.last_accepted else []


def pair_offsets(measurements: Iterable[Measurement]) -> Iterator[PairOffset]:
    """The pair offsets of a measurement stream (the modes that do not fuse)."""
    return (m for m in measurements if isinstance(m, PairOffset))


ESTIMATORS: dict[str, Callable[..., Iterable[ConeEstimate]]] = {  # (rig, measurements, report=None)
    "fused": fused_estimates,  # live, the default
    "smoothed": smoothed_estimates,  # recorded runs
    "paper": lambda rig, measurements, report=None: paper_filter(rig, pair_offsets(measurements)),  # the paper's
    "raw": lambda rig, measurements, report=None: raw_estimates(pair_offsets(measurements)),  # each pair offset
}
