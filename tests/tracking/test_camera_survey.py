"""A camera's surveyed position (rig: position, position_sigma) as the fusion filter's prior on it."""

from __future__ import annotations

import numpy as np
import pytest

from tests.synthetic import look_at
from tests.tracking.test_fusion import CAMERA_EYES, camera_rig, observations
from tracking.estimator import TopsideFilter
from tracking.rig import Rig

FAR_TRUE = look_at(CAMERA_EYES["far"], np.array([12.0, -10.0, 0.0]))[:3, 3]  # the far camera's optical centre
SURVEY_SIGMA_M = 0.05
SECONDS = 3.0


def surveyed_rig(position: np.ndarray | None) -> Rig:
    """The four-pair rig with its far camera (35 m ahead of cone A, one marker per body) fixed, optionally surveyed."""
    data = camera_rig("fixed").model_dump(exclude_none=True)
    if position is not None:
        far = next(c for c in data["cameras"] if c["name"] == "far")
        far.update(position=np.asarray(position).tolist(), position_sigma=SURVEY_SIGMA_M)
    return Rig.model_validate(data)


def far_camera_run(position: np.ndarray | None) -> tuple[TopsideFilter, list[tuple[float, float, float, float]]]:
    """The filter after SECONDS, and after each frame once the far camera is placed: (time, its position error m, its
    position σ m (root of the covariance's trace), cone A's largest σ m)."""
    rig = surveyed_rig(position)
    kf = TopsideFilter(rig)
    trace = []
    for o in observations(rig, SECONDS):
        kf.predict(o.time)
        kf.update(o)
        far = kf.cameras["far"]
        if far.T_jacket_camera is not None and kf.topside_placed:
            assert kf.x is not None and kf.P is not None
            p = slice(far.index + 3, far.index + 6)
            error = float(np.linalg.norm(far.T_jacket_camera[:3, 3] + kf.x[p] - FAR_TRUE))
            cone_a = next(e for e in kf.cone_estimates() if e.cone == "A")
            trace.append((o.time, error, float(np.sqrt(np.trace(kf.P[p, p]))),
                          float(np.sqrt(np.diag(cone_a.covariance)).max())))
    return kf, trace


def at(trace: list[tuple[float, float, float, float]], t: float) -> tuple[float, float, float, float]:
    """The entry nearest a time."""
    return min(trace, key=lambda row: abs(row[0] - t))


@pytest.fixture(scope="module")
def unsurveyed() -> list[tuple[float, float, float, float]]:
    kf, trace = far_camera_run(None)
    assert not kf.survey_conflicts
    return trace


def test_a_surveyed_camera_is_placed_closer_and_known_better(unsurveyed: list) -> None:
    """With its position surveyed to 5 cm, the far camera is placed within centimetres at once and cone A's σ is
    several times smaller from the start (at 0.5 s: 15 mm off, position σ 65 mm, cone A σ 8.5 mm; its markers alone:
    80 mm off, σ 338 mm, cone A σ 47 mm)."""
    kf, trace = far_camera_run(FAR_TRUE)
    assert not kf.survey_conflicts
    for t in (0.5, SECONDS - 0.1):
        _, error, sigma, cone_a = at(trace, t)
        _, error0, sigma0, cone_a0 = at(unsurveyed, t)
        assert error < 0.03 and (error < 0.5 * error0 or t > 0.5), (t, error, error0)
        assert sigma < np.sqrt(3) * SURVEY_SIGMA_M and sigma < 0.4 * sigma0, (t, sigma, sigma0)
        assert cone_a < 0.5 * cone_a0, (t, cone_a, cone_a0)
    assert at(trace, 0.5)[3] < 0.010 < at(unsurveyed, 0.5)[3]  # cone A: under 10 mm at half a second, not without


def test_a_survey_beyond_its_sigma_is_not_trusted(unsurveyed: list) -> None:
    """A survey 2 m off (40 σ) is refused at placement and reported; the filter runs as if there were none."""
    kf, trace = far_camera_run(FAR_TRUE + np.array([0.0, 2.0, 0.0]))
    assert set(kf.survey_conflicts) == {"far"}
    assert kf.survey_conflicts["far"] > 1.0  # the survey's distance from the first frame's placement (2 m, within
    # that frame's error: the far camera is placed at once, between its two poses)
    assert at(trace, SECONDS - 0.1)[1:] == pytest.approx(at(unsurveyed, SECONDS - 0.1)[1:])
