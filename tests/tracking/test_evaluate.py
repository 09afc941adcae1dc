"""Accuracy measures on synthetic series with known errors, delays and gaps."""

import numpy as np
import pandas as pd
import pytest

from tracking.evaluate import availability, errors, evaluate_runs, lag, summary

T = np.arange(0.0, 30.0, 1 / 30)


def truth() -> pd.DataFrame:
    s_curve = 5 * (1 - np.cos(np.pi * T / T[-1])) / 2  # crane move: accelerates, then brakes
    return pd.DataFrame({"time": T, "cone_A_dx": 0.5 * np.sin(0.4 * T), "cone_A_dy": -5 + s_curve,
                         "cone_A_dz": np.full(T.size, 2.0)})


def offsets(delay: float = 0.0, bias: float = 0.0, keep: np.ndarray | None = None) -> pd.DataFrame:
    t = T[::2]
    tr = truth()
    rows = pd.DataFrame({"time": t, "cone": "A", **{a: np.interp(t - delay, T, tr[f"cone_A_{a}"]) for a in
                                                     ("dx", "dy", "dz")}})
    rows["dx"] += bias
    return rows if keep is None else rows[keep]


def test_paper_table_of_a_known_bias() -> None:
    stats = summary(errors(offsets(bias=0.02), truth()))
    assert stats["x"].mean == pytest.approx(0.02, abs=1e-9)
    assert stats["x"].mae == pytest.approx(0.02, abs=1e-9)
    assert stats["x"].std == pytest.approx(0.0, abs=1e-9)
    assert stats["y"].max_abs == pytest.approx(0.0, abs=1e-9)


@pytest.mark.parametrize("delay", [0.0, 0.3, 0.7])
def test_lag_by_cross_correlation(delay: float) -> None:
    assert lag(offsets(delay=delay), truth()) == pytest.approx(delay, abs=0.021)


def test_constant_speed_ramp_has_no_lag() -> None:
    from tracking.evaluate import estimate_lag

    assert np.isnan(estimate_lag(T, 0.2 * T, T, 0.2 * T))


def test_availability_counts_gaps() -> None:
    t = T[::2]
    keep = ~((t > 10) & (t < 20))  # ten seconds without an estimate
    share = availability(offsets(keep=keep), truth())
    assert share == pytest.approx(1 - (10 - 0.5) / 30, abs=0.02)  # estimates count for 0.5 s after they come


def test_nan_estimates_are_unavailable() -> None:
    rows = offsets()
    rows.loc[rows["time"] > 15, ["dx", "dy", "dz"]] = np.nan
    assert availability(rows, truth()) == pytest.approx(0.5 + 0.5 / 30, abs=0.02)


def test_runs_pool_into_one_group() -> None:
    ev = evaluate_runs("two runs", [(offsets(bias=0.01), truth()), (offsets(bias=0.03), truth())])
    assert ev.axes["x"].mean == pytest.approx(0.02, abs=1e-9)
    assert ev.axes["x"].n == 2 * len(offsets())
    assert ev.availability == pytest.approx(1.0, abs=0.01)
