"""A run's tally per cone: shown share, first shown, reasons, least σ, the cameras that measured its pair; and why a
cone never shown was not."""

from __future__ import annotations

import numpy as np

from tracking.cone_tally import ConeTallies
from tracking.estimate import WITHHELD_COMPARING, WITHHELD_SIGMA, ConeEstimate
from tracking.offsets import PairOffset
from tracking.pose import Choice

NAN3 = np.full(3, np.nan)


def estimate(t: float, cone: str, sigma_mm: tuple[float, float, float], withheld: str = "") -> ConeEstimate:
    offset = NAN3 if withheld else np.array([0.01, -0.02, 0.4])
    return ConeEstimate(t, cone, offset, ("drone1",), np.diag((np.array(sigma_mm) / 1000) ** 2), withheld=withheld)


def pair(t: float, camera: str, cone: str) -> PairOffset:
    return PairOffset(t, camera, cone, "ahead", 1, 2, np.eye(4), np.zeros(3), np.eye(3) * 1e-4, Choice.UNIQUE)


def test_a_cone_one_camera_sees_square_on_is_never_shown_and_the_tally_names_the_axis_and_the_camera() -> None:
    tally = ConeTallies()
    for k in range(30):
        t = 100.0 + k / 15
        tally.measured(pair(t, "drone1", "C"))
        tally.add(estimate(t, "C", (12.0 + 10 / (k + 1), 71.0 + 30 / (k + 1), 9.0), WITHHELD_SIGMA))
    tally.add(estimate(102.0, "C", (12.0, 75.0, 9.0), WITHHELD_COMPARING))
    cone = tally.cones["C"]
    why = cone.why_never()
    assert cone.shown == 0 and cone.estimates == 31
    assert f"{WITHHELD_SIGMA} ×30, {WITHHELD_COMPARING} ×1" in why
    assert "Δx 12 · Δy 72 · Δz 9 mm" in why  # the least σ per axis it reached (Δy: 71 + 30/30)
    assert "50 mm limit on Δy" in why and "Δx and" not in why  # only the axis above the limit is named
    assert "drone1 alone" in why and "another side" in why
    assert tally.rows() == [("C", "0%", "never", f"{WITHHELD_SIGMA} ×30, {WITHHELD_COMPARING} ×1",
                             "Δx 12 · Δy 72 · Δz 9 mm", "drone1 (30)")]


def test_a_shown_cone_has_no_warning_and_counts_from_the_runs_first_estimate() -> None:
    tally = ConeTallies()
    tally.add(estimate(10.0, "A", (60.0, 60.0, 60.0), WITHHELD_SIGMA))
    for k, cam in enumerate(("stern1", "drone2", "stern1")):
        tally.measured(pair(10.5 + k, cam, "A"))
        tally.add(estimate(10.5 + k, "A", (4.0, 5.0, 3.0)))
    assert tally.cones["A"].why_never() == ""
    assert tally.rows() == [("A", "75%", "0.5 s", f"{WITHHELD_SIGMA} ×1", "Δx 4 · Δy 5 · Δz 3 mm",
                             "drone2 (1), stern1 (2)")]


def test_a_cone_without_a_pair_says_its_offset_came_through_the_topside() -> None:
    tally = ConeTallies()
    tally.add(estimate(1.0, "B", (80.0, 20.0, 90.0), WITHHELD_SIGMA))
    why = tally.cones["B"].why_never()
    assert "Δx and Δz" in why and "no camera measured a marker pair there" in why


def test_a_mode_without_a_sigma_says_only_that_the_cone_was_never_shown() -> None:
    tally = ConeTallies()
    tally.add(ConeEstimate(1.0, "D", NAN3, ("stern1",)))  # raw mode: no covariance, no reason
    assert tally.cones["D"].why_never() == "cone D: never shown (no number ×1)"
    assert tally.rows()[0][4] == "—"
