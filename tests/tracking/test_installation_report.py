"""The report's numbers from tables made here: set-down, verdicts at the tolerance's edge, NO DATA, camera spans."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from tracking.estimate import TOLERANCE_M, ConeEstimate
from tracking.installation_report import (
    GAP_S,
    LANDED_DZ_M,
    NO_ESTIMATE,
    CameraSpan,
    Verdict,
    camera_timeline,
    cone_summary,
    estimates_table,
    summarise,
)

DT = 0.1


def lowering(r: float, sigma: float, land_at: float = 5.0, end: float = 8.0, withheld: tuple[float, float] = (0, 0),
             lift: tuple[float, float] = (0, 0)) -> pd.DataFrame:
    """Cone A lowered at 0.2 m/s onto its cone at land_at, r m off in x from a second before (0.4 m before that), σ
    in x and y;
    NaN with 'σ too large' inside withheld; Δz back up at 0.3 m inside lift."""
    out = []
    for t in np.arange(0.0, end + 1e-9, DT):
        dz = max(0.0, 0.2 * (land_at - t))
        if lift[0] <= t < lift[1]:
            dz = 0.3
        offset = np.array([r if t >= land_at - 1.0 else 0.4, 0.0, dz])
        why = "σ too large" if withheld[0] <= t < withheld[1] else ""
        out.append(ConeEstimate(t, "A", np.full(3, np.nan) if why else offset, ("cam",),
                                np.diag([sigma**2, sigma**2, 1e-6]), withheld=why))
    return estimates_table(out)


@pytest.mark.parametrize(("r", "sigma", "verdict"), [(0.100, 0.010, Verdict.WITHIN),  # 100 + 20 ≤ 150
                                                     (0.140, 0.010, Verdict.EDGE),  # 140 + 20 > 150
                                                     (0.160, 0.005, Verdict.OUTSIDE)])
def test_the_verdict_rests_on_the_set_down_and_its_2_sigma(r: float, sigma: float, verdict: Verdict) -> None:
    c = cone_summary(lowering(r, sigma), "A", 0.0, 8.0)
    assert c.verdict == verdict
    assert c.landed is not None and c.landed.time == pytest.approx(5.0 - LANDED_DZ_M / 0.2, abs=DT)
    assert c.landed.concentricity == pytest.approx(r) and c.landed.sigma == pytest.approx(sigma)
    assert c.closest is not None and c.closest.time < c.landed.time and c.closest.concentricity == pytest.approx(r)
    assert c.excursion is not None and c.excursion.concentricity == pytest.approx(r)
    assert c.shown == 1.0 and not c.no_data


def test_a_hovering_cone_has_not_landed_and_a_short_dip_is_no_landing() -> None:
    assert cone_summary(lowering(0.1, 0.01, land_at=20.0), "A", 0.0, 8.0).verdict == Verdict.NOT_LANDED
    dip = cone_summary(lowering(0.1, 0.01, land_at=7.6), "A", 0.0, 8.0)  # down for the last 0.65 s only
    assert dip.verdict == Verdict.NOT_LANDED and dip.closest is not None and dip.last is not None


def test_a_cone_lifted_off_and_set_down_again_lands_at_its_last_set_down() -> None:
    c = cone_summary(lowering(0.05, 0.01, lift=(6.0, 6.5)), "A", 0.0, 8.0)
    assert c.verdict == Verdict.WITHIN
    assert c.landed is not None and c.landed.time == pytest.approx(6.5)
    assert c.closest is not None and c.closest.concentricity == pytest.approx(0.05)  # before the second set-down


def test_no_data_periods_say_why_and_a_silence_is_no_data_of_its_own() -> None:
    table = lowering(0.05, 0.01, withheld=(2.0, 3.0))
    table = table[(table["time"] < 6.0) | (table["time"] > 6.05 + GAP_S)]  # no estimate for 1.2 s
    c = cone_summary(table, "A", 0.0, 10.0)
    periods = [(round(p.start, 2), round(p.end, 2), p.what) for p in c.no_data]
    assert periods == [(2.0, 3.0, "σ too large"), (5.9, 7.1, NO_ESTIMATE), (8.0, 10.0, NO_ESTIMATE)]
    assert c.verdict == Verdict.WITHIN and c.shown == pytest.approx(1 - 10 / len(table))


def test_a_cone_flickering_at_the_limit_is_one_no_data_period() -> None:
    table = lowering(0.05, 0.01)
    flicker = (table["time"] >= 1.0) & (table["time"] < 2.0) & (np.round(table["time"] * 10) % 3 == 0)
    table.loc[flicker, ["dx", "dy", "dz"]] = np.nan
    table.loc[flicker, "withheld"] = "σ too large"
    c = cone_summary(table, "A", 0.0, 8.0)
    assert [(round(p.start, 1), round(p.end, 1), p.what) for p in c.no_data] == [(1.2, 1.9, "σ too large")]


def test_a_cone_never_shown_is_no_data_with_its_reason() -> None:
    c = cone_summary(lowering(0.05, 0.01, withheld=(0.0, 99.0)), "A", 0.0, 8.0)
    assert c.verdict == Verdict.NO_DATA and c.landed is None and c.shown == 0.0
    assert "σ too large" in c.headline


def test_camera_spans_from_frames_and_stated_states() -> None:
    t = np.concatenate([np.arange(0.0, 2.0, 0.1), np.arange(4.0, 6.0, 0.1), np.arange(8.0, 9.0, 0.1)])
    markers = np.where((t >= 1.0) & (t < 1.5), 0, 2).astype(float)
    frames = pd.DataFrame({"time": t, "camera": "cam", "markers": markers})
    stated = pd.DataFrame({"time": [6.3], "camera": ["cam"], "state": ["frozen"], "detail": ["the image does not "
                                                                                          "change"]})
    spans = [(round(p.start, 1), round(p.end, 1), p.what) for p in camera_timeline(frames, 0.0, 12.0, stated)]
    assert spans == [(0.0, 1.0, CameraSpan.LIVE), (1.0, 1.5, CameraSpan.NO_MARKERS), (1.5, 1.9, CameraSpan.LIVE),
                     (1.9, 4.0, CameraSpan.LOST), (4.0, 5.9, CameraSpan.LIVE), (5.9, 8.0, CameraSpan.FROZEN),
                     (8.0, 8.9, CameraSpan.LIVE), (8.9, 12.0, CameraSpan.ENDED)]


def test_the_summary_names_every_cone_and_its_events_in_time_order() -> None:
    table = pd.concat([lowering(0.05, 0.01), lowering(0.2, 0.01).assign(cone="B")])
    frames = pd.DataFrame({"time": np.arange(0.0, 8.0, 0.1), "camera": "cam", "markers": 2.0})
    s = summarise(table, frames, 0.0, 8.0, cones=["A", "B", "C"])
    assert [c.verdict for c in s.cones] == [Verdict.WITHIN, Verdict.OUTSIDE, Verdict.NO_DATA]
    assert s.verdict == "3 cones: 1 within tolerance, 1 OUTSIDE tolerance, 1 NO DATA"
    assert [e.time for e in s.events] == sorted(e.time for e in s.events)
    assert any(e.subject == "B" and e.what.startswith("landed: 200") for e in s.events)
    assert TOLERANCE_M == 0.150
