"""topside survey's bundle adjustment on synthetic corners: markers displaced and tilted by known amounts."""

from __future__ import annotations

import numpy as np
import pytest

from tests.synthetic import CAMERA_EYES, CONE_A, JACKET_MARKER_Z, MATED_RISE, PAPER_K, look_at, rig_dict
from tracking.errors import InputError
from tracking.estimator import TopsideFilter
from tracking.geometry import rotvec
from tracking.offsets import BodyObservation
from tracking.pose import BodyPose, Choice, marker_object_points
from tracking.rig import Rig
from tracking.survey import independent_sigmas, rodrigues, survey_markers, surveyed_rig

FPS = 10.0
SECONDS = 20.0
CORNER_NOISE_PX = 0.05
# true minus surveyed pose of each non-reference marker: centre (m) and rotation vector (degrees), body frame
DISPLACED = {3: (np.array([0.015, -0.02, 0.01]), np.array([0.8, -0.5, 0.3])),
             4: (np.array([-0.01, 0.012, -0.018]), np.array([-0.4, 0.9, -0.6]))}
REFERENCES = (1, 2)  # one per body: jacket 1 and topside 2, held as the datum
EYES = {**CAMERA_EYES, "cam-corner": np.array([8.0, -32.0, 4.0])}  # the corner camera sees both faces 45° off their
# normals; the others see one face nearly square and the other too obliquely to be used (over 66°)


def topside_motion(t: float) -> np.ndarray:
    """(4, 4) T_jacket_topside: a swing and creep with a slight twist."""
    T = np.eye(4)
    T[:3, :3] = rodrigues(np.radians([0.3 * np.sin(t / 3), 0.2 * np.cos(t / 4), 0.5 * np.sin(t / 5)])[None])[0]
    T[:3, 3] = [0.2 * np.sin(t / 2), 0.05 * t - 0.5, 0.3 + 0.1 * np.cos(t / 3)]
    return T


def rig(survey: bool = True, references: tuple[int, ...] = REFERENCES) -> Rig:
    data = rig_dict([{"name": n, "calibration": f"{n}.yaml", "source": f"{n}.mp4", "mount": "drone"}
                     for n in EYES])
    for m in data["markers"]:
        m["reference"] = m["id"] in references
    if survey:
        data["survey_sigma"] = {"position_m": 0.02, "tilt_deg": 1.0}
        data["survey_tolerance"] = {"position_m": 0.05, "tilt_deg": 3.0}
    return Rig.model_validate(data)


def true_T_body_marker(the_rig: Rig, marker_id: int) -> np.ndarray:
    T = the_rig.marker_by_id[marker_id].T_body_marker.copy()
    if marker_id in DISPLACED:
        moved, turned = DISPLACED[marker_id]
        T[:3, :3] = rodrigues(np.radians(turned)[None])[0] @ T[:3, :3]
        T[:3, 3] += moved
    return T


def observations(the_rig: Rig, seed: int = 0) -> list[BodyObservation]:
    """Both cameras' frames: every marker's corners projected from where it truly is, with noise; each frame's jacket
    pose to start from as a one-frame estimate would give it (off by a little)."""
    rng = np.random.default_rng(seed)
    target = CONE_A + np.array([0.0, 0.0, JACKET_MARKER_Z + MATED_RISE / 2])
    obj = marker_object_points(the_rig.marker_size)
    out = []
    for k, t in enumerate(np.arange(0.0, SECONDS, 1 / FPS)):
        for name, eye in EYES.items():
            sway = 0.05 * np.array([np.sin(t + k), np.cos(1.3 * t), 0.0])
            T_camera_jacket = np.linalg.inv(look_at(eye + sway, target))
            corners = {}
            for m in the_rig.markers:
                T = T_camera_jacket @ (topside_motion(t) if m.body == "topside" else np.eye(4)) \
                    @ true_T_body_marker(the_rig, m.id)
                X = obj @ T[:3, :3].T + T[:3, 3]
                uv = X @ PAPER_K.T
                corners[m.id] = uv[:, :2] / uv[:, 2:] + rng.normal(0.0, CORNER_NOISE_PX, (4, 2))
            start = T_camera_jacket.copy()
            start[:3, 3] += rng.normal(0.0, 0.02, 3)
            jacket = BodyPose("jacket", (1, 3), start, 1e-4 * np.eye(6), 0.1, Choice.UNIQUE)
            out.append(BodyObservation(float(t), name, jacket, None, corners, PAPER_K))
    return out


def test_displaced_markers_are_found_within_their_sigma() -> None:
    the_rig = rig()
    fit = survey_markers(the_rig, observations(the_rig))
    assert fit.rms_px < 2 * CORNER_NOISE_PX
    by_id = {s.id: s for s in fit.markers}
    for mid in REFERENCES:
        assert by_id[mid].reference and not np.any(by_id[mid].position_m)
    for mid, (moved, turned) in DISPLACED.items():
        s = by_id[mid]
        err_mm = (s.position_m - moved) * 1e3
        err_deg = np.degrees(s.rotation_rad) - turned
        assert np.all(np.abs(err_mm) < 5.0), err_mm  # the target: 5 mm and 0.2°
        assert np.all(np.abs(err_deg) < 0.2), err_deg
        assert np.all(np.abs(err_mm) < 4 * s.sigma_m * 1e3 + 0.2), (err_mm, s.sigma_m)  # an honest σ
        assert np.all(s.sigma_m < 0.012) and s.learnt > 0.5  # told by the footage (a view's frames correlated)
        assert not s.flagged
    surveyed = surveyed_rig(the_rig, fit)
    for mid in DISPLACED:
        m = surveyed.marker_by_id[mid]
        assert np.allclose(m.center, np.add(the_rig.marker_by_id[mid].center, by_id[mid].position_m), atol=1e-6)
        assert m.correction is not None and m.sigma is not None
        angle = np.degrees(np.linalg.norm(rotvec(m.R_body_marker @ true_T_body_marker(the_rig, mid)[:3, :3].T)))
        assert angle < 0.2
    for p in surveyed.pairs:  # mated offsets follow the corrected centres
        by = surveyed.marker_by_id
        assert np.allclose(p.mated, np.subtract(by[p.topside].center, by[p.jacket].center), atol=1e-6)


def test_a_marker_moved_beyond_the_tolerance_is_flagged() -> None:
    the_rig = rig()
    data = the_rig.model_dump(exclude_none=True)
    data["survey_tolerance"] = {"position_m": 0.005, "tilt_deg": 3.0}  # the displacements are 18-25 mm
    fit = survey_markers(Rig.model_validate(data), observations(the_rig, seed=1))
    assert {s.id for s in fit.markers if s.flagged} == set(DISPLACED)


def test_without_a_survey_sigma_it_says_what_it_needs() -> None:
    the_rig = rig(survey=False)
    with pytest.raises(InputError, match="survey_sigma"):
        survey_markers(the_rig, observations(the_rig)[:40])


def with_topside(o: BodyObservation) -> BodyObservation:
    """The observation with the topside's pose from its jacket pose, as a one-frame estimate would place it."""
    assert o.jacket is not None
    T = o.jacket.T_camera_body @ topside_motion(o.time)
    topside = BodyPose("topside", (2, 4), T, 1e-4 * np.eye(6), 0.1, Choice.UNIQUE)
    return BodyObservation(o.time, o.camera, o.jacket, topside, o.corners, o.K)


def test_the_filter_carries_the_survey_sigma_and_holds_the_error_inside_it() -> None:
    from tracking.estimator import fused_estimates

    obs = [with_topside(o) for o in observations(rig())]  # markers 3 and 4 truly 18-25 mm and about 1° off the rig
    exact = TopsideFilter(rig(survey=False))
    assert exact.consider.prior.size == 0  # a rig without survey σ: the filter as before
    held = rig()  # references 1 and 2 exact, 3 and 4 known to 20 mm and 1°
    kf = TopsideFilter(held)
    assert set(kf.consider.markers) == set(DISPLACED)
    estimates = {False: [], True: []}
    for surveyed in estimates:
        for e in fused_estimates(held if surveyed else rig(survey=False), obs):
            if e.time > SECONDS / 2:
                estimates[surveyed].append(e)
    T = topside_motion(estimates[True][-1].time)
    tip = np.array(held.cones["A"])
    truth = T[:3, :3] @ tip + T[:3, 3] - tip
    last = {surveyed: es[-1] for surveyed, es in estimates.items()}
    sd, blind = (np.sqrt(np.diag(last[k].covariance)) for k in (True, False))
    error, blind_error = (last[k].offset - truth for k in (True, False))
    assert np.all(np.abs(error) < 2 * sd), (error, sd)
    # without the survey σ the filter took the displaced markers as exact: 23-25 mm off at σ 2 mm; with it, it leans on
    # the exact references (1 and 2) and is off by 2 mm at most
    assert np.any(np.abs(blind_error) > 3 * blind), (blind_error, blind)
    assert np.linalg.norm(error) < np.linalg.norm(blind_error) / 5
    # with no reference the survey's error cannot be told from the footage: it stays in σ however long they look
    unreferenced = list(fused_estimates(rig(references=()), obs))[-1]
    assert np.all(np.sqrt(np.diag(unreferenced.covariance)) > 0.01)


def test_consider_states_are_never_estimated() -> None:
    kf = TopsideFilter(rig(references=()))
    c = kf.consider.indices
    prior = kf.P[c, c].copy()
    for o in map(with_topside, observations(rig())[:60]):
        kf.predict(o.time, [o])
        kf.update(o)
    assert kf.topside_placed
    assert np.array_equal(kf.P[c, c], prior) and not kf.x[c].any()  # Schmidt: the survey stays as the rig states it
    assert np.abs(kf.P[:6, c]).max() > 0  # ... and is carried to the topside


def test_without_a_datum_the_surveyed_rig_keeps_what_no_footage_can_tell() -> None:
    from tracking.estimator import fused_estimates

    the_rig = rig(references=())  # markers 3 and 4 truly 18-25 mm and about 1° off; no marker held as a datum
    obs = observations(the_rig)
    fit = survey_markers(the_rig, obs)
    surveyed = surveyed_rig(the_rig, fit)
    for body in ("jacket", "topside"):  # a shift common to a body's markers films like the body moved: its σ stays
        held = np.array([s.held_m for s in fit.markers if s.body == body])  # the survey's (20 mm) over √2 markers
        assert np.all(np.sqrt(np.sum(held**2, axis=0)) / len(held) >= 0.9 * 0.02 / np.sqrt(len(held))), held
    z = []
    for e in fused_estimates(surveyed, [with_topside(o) for o in obs]):
        if e.time > SECONDS / 2:
            T = topside_motion(e.time)
            tip = np.array(surveyed.cones["A"])
            z.append(np.abs(e.offset - (T[:3, :3] @ tip + T[:3, 3] - tip)) / np.sqrt(np.diag(e.covariance)))
    assert np.mean(np.array(z) <= 2, axis=0).min() >= 0.9, np.mean(np.array(z) <= 2, axis=0)


def test_independent_sigmas_hold_a_common_error_and_keep_what_is_independent() -> None:
    prior = np.full(4, 0.02)
    common = 0.009**2 * np.ones((4, 4)) + 0.003**2 * np.eye(4)  # four markers that move together by 9 mm (their
    # mean is as uncertain as the survey left it: 20 mm over √4)
    held = independent_sigmas(common, prior)
    assert np.linalg.eigvalsh(np.diag(held**-2) @ common).max() <= 1 + 1e-6  # diag(held²) ⪰ the joint covariance
    assert np.all(held <= prior + 1e-12) and np.all(held > np.sqrt(np.diag(common)))  # widened, never past the survey
    apart = np.diag([0.004, 0.006, 0.02, 0.01]) ** 2  # independent already: their own σ
    assert np.allclose(independent_sigmas(apart, prior), [0.004, 0.006, 0.02, 0.01])
