"""The simulator's field realities: clocks off and markers off their survey, which the rig it writes does not know."""

from __future__ import annotations

import numpy as np
import pytest

from tracking.errors import InputError
from tracking.rig import CameraEntry
from tracking.sim.builtins import builtin_scenario
from tracking.sim.command import clock_error, run_simulate
from tracking.sim.scenario import SurveyErrorSpec
from tracking.sim.world import World


def test_realities_suffix_combines_with_weather() -> None:
    sc = builtin_scenario("config2-setdown-realities-weather")
    assert sc is not None and sc.name == "config2-setdown-realities-weather"
    assert sc.clock_error_s == 0.5
    assert sc.survey_error == SurveyErrorSpec(position_m=0.02, tilt_deg=1.0)
    assert sc.weather.fog > 0  # the -weather suffix still applied
    plain = builtin_scenario("config2-setdown")
    assert plain is not None and plain.clock_error_s == 0.0 and plain.survey_error == SurveyErrorSpec()


def test_clock_errors_stay_within_the_bound_and_are_reproducible() -> None:
    sc = builtin_scenario("config1-procedure1-realities")
    assert sc is not None
    errors = [clock_error(sc, i, seed) for seed in range(40) for i in range(5)]
    assert max(abs(e) for e in errors) <= 0.5
    assert np.std(errors) > 0.2  # uniform within ±0.5 s: σ 0.29 s
    assert clock_error(sc, 2, 7) == clock_error(sc, 2, 7)
    assert clock_error(builtin_scenario("config1-procedure1"), 2, 7) == 0.0


def test_markers_sit_off_the_rig_by_the_survey_error() -> None:
    sc = builtin_scenario("config2-setdown-realities")
    assert sc is not None
    world = World(sc, 1.0, sc.seed)
    cams = [CameraEntry(name="c", calibration="c.yaml", source="c.mp4")]
    nominal, true = world.rig(cams), world.rig(cams, true=True)
    assert nominal.survey_sigma is not None and true.survey_sigma is None
    moved = np.array([np.subtract(t.center, n.center) for n, t in zip(nominal.markers, true.markers, strict=True)])
    turned = np.array([np.degrees(np.arccos(np.clip((np.trace(n.R_body_marker.T @ t.R_body_marker) - 1) / 2, -1, 1)))
                       for n, t in zip(nominal.markers, true.markers, strict=True)])
    assert len(moved) == 8  # four pairs
    assert 0.01 < np.std(moved) < 0.03  # σ 20 mm per axis
    assert 0.5 < np.sqrt(np.mean(turned**2) / 3) < 1.6  # σ 1° per axis: the rotation's angle has RMS √3°
    # a pair's mated offset follows the markers' centres in each rig
    for rig in (nominal, true):
        by_id = rig.marker_by_id
        for p in rig.pairs:
            assert np.allclose(p.mated, np.subtract(by_id[p.topside].center, by_id[p.jacket].center), atol=1e-6)


def test_simulate_refuses_a_negative_survey_error(tmp_path) -> None:
    with pytest.raises(InputError, match="survey_error"):
        run_simulate("config2-setdown", tmp_path / "out", duration=0.1, survey_error=(-0.01, 1.0), quiet=True)
    assert not (tmp_path / "out").exists()
