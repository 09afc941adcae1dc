"""The cameras' disagreement at a cone (tracking/estimator/disagreement.py): a floor under the cone's σ where cameras
that carry the estimate disagree beyond their noise, nothing where they agree or where a poor view disagrees alone;
and the error their calibrations state, which no number of their frames averages away."""

from __future__ import annotations

import numpy as np
import pytest

from tracking.estimator.disagreement import DISAGREEMENT_WAIT_S, LENS_SHARE, Disagreement, lens_sigmas
from tracking.estimator.state import STATE, point_offset_matrix
from tracking.geometry import inverse
from tracking.offsets import BodyObservation
from tracking.pose import BodyPose, Choice

MM = 1e-3
RATE_HZ = 15.0
X = np.zeros(STATE + 6)  # the filter's state: the topside mated (offset zero), one camera
P = np.eye(STATE + 6) * 1e-10


def cone() -> Disagreement:
    """Cone A at the topside's origin, its pair jacket marker 1 and topside marker 2: its offset is T_jacket_topside's
    translation."""
    return Disagreement(["A"], point_offset_matrix(np.zeros(3))[None], {"A": [(1, 2)]})


def view(camera: str, time: float, offset_m: np.ndarray, sigma_m: float = 0.5 * MM,
         choice: Choice = Choice.UNIQUE, model_px: float = 0.0) -> BodyObservation:
    """A camera frame 20 m from the markers (f 2000 px, its calibration model_px off) whose two fits put the topside
    offset_m (3,) from the jacket."""
    T_cj = np.eye(4)
    T_cj[:3, 3] = [0.0, 0.0, 20.0]
    T_jt = np.eye(4)
    T_jt[:3, 3] = offset_m
    cov = np.diag([1e-8] * 3 + [sigma_m**2 / 2] * 3)
    jacket = BodyPose("jacket", (1,), T_cj, cov, 0.1, Choice.UNIQUE)
    topside = BodyPose("topside", (2,), T_cj @ T_jt, cov, 0.1, choice)
    return BodyObservation(time, camera, jacket, topside, K=np.diag([2000.0, 2000.0, 1.0]), model_px=model_px)


def keep(d: Disagreement, o: BodyObservation, x: np.ndarray | None, P: np.ndarray | None = None) -> None:
    """A frame's residuals, kept as the filter keeps them (it used the frame's topside corners)."""
    d.record(d.residuals(o, x, P))


def feed(d: Disagreement, camera: str, means_mm: tuple[float, float, float], frames: int, start: float = 0.0,
         jitter_mm: float = 0.5) -> float:
    """frames views of one camera: its offsets alternate ±jitter_mm about means_mm; the time after the last."""
    t = start
    for i in range(frames):
        t = start + i / RATE_HZ
        keep(d, view(camera, t, (np.array(means_mm) + (-1) ** i * jitter_mm) * MM), X, P)
    return t


def test_cameras_that_agree_add_nothing() -> None:
    d = cone()
    feed(d, "a", (0.0, 0.0, 0.0), 30)
    t = feed(d, "b", (0.0, 0.0, 0.0), 30, start=0.5 / RATE_HZ)
    floors, pending = d.floors(t)
    assert np.array_equal(floors, np.zeros((1, 3))) and not pending[0]


def test_cameras_that_disagree_beyond_their_noise_set_the_floor_on_that_axis() -> None:
    """Two cameras 4 mm apart in x, each ±0.5 mm a frame: their errors' variance is (4 mm)² / 2, and each carries half
    the estimate, whose error's variance is then half of it: σ 2 mm in x, nothing on y and z."""
    d = cone()
    feed(d, "a", (2.0, 0.0, 0.0), 30)
    t = feed(d, "b", (-2.0, 0.0, 0.0), 30, start=0.5 / RATE_HZ)
    floors, _ = d.floors(t)
    assert np.sqrt(floors[0, 0]) == pytest.approx(2.0 * MM, rel=0.1)
    assert floors[0, 1] == floors[0, 2] == 0.0


def test_a_camera_new_to_the_cone_holds_it_back_until_compared_and_not_for_long() -> None:
    """A second camera's first frame: its noise is not known, so the cone waits for its third frame, then its
    disagreement counts; one that never gets there (its fits ambiguous) holds it DISAGREEMENT_WAIT_S at most."""
    d = cone()
    t = feed(d, "a", (0.0, 0.0, 0.0), 30)
    keep(d, view("b", t + 0.01, np.array([0.0, 3.0, 0.0]) * MM), X, P)
    assert d.floors(t + 0.01)[1][0]
    t = feed(d, "b", (0.0, 3.0, 0.0), 3, start=t + 0.02)
    floors, pending = d.floors(t)
    assert not pending[0] and np.sqrt(floors[0, 1]) >= 1.0 * MM
    keep(d, view("c", t, np.zeros(3)), None)  # seen before it gave a residual (the topside not placed)
    assert d.floors(t)[1][0] and not d.floors(t + DISAGREEMENT_WAIT_S + 0.01)[1][0]


def test_a_poor_view_that_disagrees_alone_is_not_taken_for_the_others_error() -> None:
    """A camera whose frames scatter ±50 mm carries under a tenth of the estimate: its 30 mm of disagreement with
    the camera that carries the rest is its own error."""
    d = cone()
    feed(d, "near", (0.0, 0.0, 0.0), 60)
    t = feed(d, "far", (30.0, 0.0, 0.0), 60, start=0.5 / RATE_HZ, jitter_mm=50.0)
    floors, _ = d.floors(t)
    assert np.array_equal(floors, np.zeros((1, 3)))


def test_ambiguous_fits_and_views_of_other_pairs_give_nothing() -> None:
    d = cone()
    keep(d, view("a", 0.0, np.zeros(3), choice=Choice.AMBIGUOUS), X, P)
    other = view("b", 0.1, np.zeros(3))
    topside = BodyPose("topside", (7,), other.topside.T_camera_body, other.topside.covariance, 0.1, Choice.UNIQUE)
    keep(d, BodyObservation(0.1, "b", other.jacket, topside), X, P)
    assert not d.moments and not d.by_cone


def test_the_relative_poses_jacobian_is_the_derivative_of_the_offset_it_feeds() -> None:
    """The analytic (6, 12) Jacobian against finite differences of T_jacket_topside's translation and its rotation
    vector, for poses turned far from the identity (the fits' covariances are in their rvec, tvec)."""
    from tracking.estimator.disagreement import relative_pose_jacobian
    from tracking.geometry import from_params, inverse, numeric_jacobian, pose_params

    p0 = np.array([0.4, -1.2, 2.0, 1.5, -0.3, 22.0, 0.5, -1.1, 2.1, 1.4, 2.6, 21.0])

    def relative(p: np.ndarray) -> np.ndarray:
        T = inverse(from_params(p[:6])) @ from_params(p[6:])
        return np.concatenate([T[:3, 3], pose_params(T)[:3]])

    numeric = numeric_jacobian(relative, p0, 1e-7)
    T0 = inverse(from_params(p0[:6])) @ from_params(p0[6:])
    R0 = T0[:3, :3]  # the state's rotation vector changes by the turn ψ where the relative rotation is small; here it
    # is not, so compare turns: δR R0ᵀ of the numeric change
    turns = []
    for k in range(12):
        dp = np.zeros(12)
        dp[k] = 1e-7
        T = inverse(from_params((p0 + dp)[:6])) @ from_params((p0 + dp)[6:])
        M = (T[:3, :3] - R0) @ R0.T / 1e-7
        turns.append([M[2, 1], M[0, 2], M[1, 0]])
    analytic = relative_pose_jacobian(from_params(p0[:6]), from_params(p0[6:]))
    np.testing.assert_allclose(analytic[:3], numeric[:3], atol=2e-5)
    np.testing.assert_allclose(analytic[3:], np.array(turns).T, atol=2e-5)


def test_a_frames_residual_is_its_own_offset_at_the_cone_less_the_filters() -> None:
    """A turned camera, a cone off the topside's origin, a turned topside: the residual is H [t, rvec] of the frame's
    T_jacket_topside less H x, with H the cone's offset matrix (its sign and frames, not only its variance)."""
    from tracking.geometry import from_params

    c = np.array([0.5, -0.2, 1.0])
    d = Disagreement(["A"], point_offset_matrix(c)[None], {"A": [(1, 2)]})
    T_cj = from_params(np.array([0.3, -0.4, 0.2, 0.1, 0.2, 15.0]))
    q = np.array([0.01, -0.02, 0.015, 0.02, -0.01, 0.03])  # rvec, t of the true T_jacket_topside
    o = view("a", 0.0, np.zeros(3))
    o = BodyObservation(0.0, "a", BodyPose("jacket", (1,), T_cj, o.jacket.covariance, 0.1, Choice.UNIQUE),
                        BodyPose("topside", (2,), T_cj @ from_params(q), o.topside.covariance, 0.1, Choice.UNIQUE))
    x = X.copy()
    x[:3], x[3:6] = [0.01, 0.0, 0.02], [0.0, 0.005, 0.0]
    keep(d, o, x, P)
    own = np.zeros(STATE)
    own[:3], own[3:6] = q[3:], q[:3]
    np.testing.assert_allclose(d.moments[("a", "A")].mean, point_offset_matrix(c) @ (own - x[:STATE]), atol=1e-9)


def test_a_calibrations_stated_error_floors_the_cone_across_and_along_the_line_of_sight() -> None:
    """A camera alone whose calibration misses by 0.5 px (its RMS), 20 m from its 1 m markers at f 2000 px, cone A
    5 m off its axis: the two images, each 0.5 px off an axis, apart, put the offset √2 × 5 mm × depth / 20 m off an
    axis across the line of sight to the cone, and depth / 1 m times that along it (a marker's size, 100 px, read
    0.7 % off); two such cameras with equal weight, half that variance, and once they are compared (their
    disagreement then measures what their lenses leave) across alone; a calibration stating no error, nothing."""
    point = np.array([5.0, 0.0, 0.0])  # cone A in the jacket frame; the camera looks along the jacket's z

    def off_axis() -> Disagreement:
        return Disagreement(["A"], point_offset_matrix(point)[None], {"A": [(1, 2)]}, side=1.0)

    in_camera = point + np.array([0.0, 0.0, 20.0])
    sight = in_camera / np.linalg.norm(in_camera)
    s2 = (LENS_SHARE * 0.5 * in_camera[2] / 2000.0) ** 2
    across = s2 * (1.0 - sight**2)  # s² (I - l lᵀ)'s diagonal
    expected = across + s2 * (in_camera[2] / 1.0) ** 2 * sight**2  # ... + (s Z / S)² l lᵀ's
    d = off_axis()
    t = 0.0
    for i in range(30):
        t = i / RATE_HZ
        keep(d, view("a", t, np.zeros(3), model_px=0.5), X, P)
    floors, _ = d.floors(t)
    assert floors[0] == pytest.approx(expected, rel=0.01)
    assert lens_sigmas(d, "A", t)["a"] == pytest.approx(np.sqrt(expected), rel=0.01)  # what check names
    assert d.floors(t + 60.0)[0][0] == pytest.approx(expected, rel=0.01)  # its error stays when it looks away
    pair = off_axis()
    for i in range(30):
        for camera in ("a", "b"):
            keep(pair, view(camera, i / RATE_HZ, np.zeros(3), model_px=0.5), X, P)
        if i == 1:  # two frames each: not compared yet
            assert pair.floors(i / RATE_HZ)[0][0] == pytest.approx(expected / 2, rel=0.01)
    floors, _ = pair.floors(29 / RATE_HZ)
    assert floors[0] == pytest.approx(across / 2, rel=0.01)
    exact = off_axis()
    keep(exact, view("a", 0.0, np.zeros(3)), X, P)
    assert np.array_equal(exact.floors(0.0)[0], np.zeros((1, 3)))


def test_a_second_camera_at_right_angles_carries_the_first_ones_depth() -> None:
    """Two cameras 20 m from cone A, one looking along the jacket's z and one along its x, their calibrations 0.5 px
    off: each alone leaves its depth off by 20 times its cross-sight error. Fused, each one's depth error goes by its
    fits' information there (20 times looser, as a marker's size reads it): next to nothing, where by its share it
    would be a quarter of 400 s². Their cross-sight errors go by their shares, as they always have: a quarter of s²
    each (the exact first-order sum would be four times that on the two depth axes, see docs/method.md). Before they
    are compared: after, their disagreement measures it; check names the same σ (lens_sigmas)."""
    along_x = np.eye(4)
    along_x[:3, :3] = [[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]]  # the camera's z is the jacket's x
    along_x[:3, 3] = [0.0, 0.0, 20.0]
    s2 = (LENS_SHARE * 0.5 * 20.0 / 2000.0) ** 2  # across the line of sight, m²
    fused = cone()
    fused.side = 1.0
    alone = {"a": cone(), "b": cone()}
    for i in range(2):  # two frames each: not compared yet
        t = i / RATE_HZ
        for camera, T in (("a", np.eye(4)), ("b", along_x)):
            frame = looking(view(camera, t, np.zeros(3), model_px=0.5), T, depth_sd_m=0.01)
            alone[camera].side = 1.0
            keep(alone[camera], frame, X, P)
            keep(fused, frame, X, P)
    np.testing.assert_allclose(alone["a"].floors(t)[0][0], [s2, s2, 400 * s2], rtol=0.01)  # its depth: the jacket z
    np.testing.assert_allclose(alone["b"].floors(t)[0][0], [400 * s2, s2, s2], rtol=0.01)
    floor = fused.floors(t)[0][0]
    np.testing.assert_allclose(floor, [s2 / 4, s2 / 2, s2 / 4], rtol=0.05)  # x, z: one camera's across; y: both
    named = lens_sigmas(fused, "A", t)
    np.testing.assert_allclose(named["a"] ** 2 + named["b"] ** 2, floor, rtol=1e-6)
    assert lens_sigmas(alone["a"], "A", t)["a"][2] == pytest.approx(20 * np.sqrt(s2), rel=0.01)  # alone: its depth


def test_a_camera_compared_against_one_too_poor_to_count_keeps_its_depth_floor() -> None:
    """Camera a steady, camera b scattering 40 mm a frame (its frames carry under a tenth of the estimate, so the
    disagreement compares nothing): a's depth error is still assumed, as if alone, not dropped for a comparison that
    never happened."""
    d = cone()
    d.side = 1.0
    s2 = (LENS_SHARE * 0.5 * 20.0 / 2000.0) ** 2
    t = 0.0
    for i in range(30):
        t = i / RATE_HZ
        keep(d, view("a", t, np.zeros(3), model_px=0.5), X, P)
        keep(d, view("b", t + 0.01, np.full(3, (-1) ** i * 40 * MM), sigma_m=40 * MM), X, P)
    assert d.floors(t)[0][0][2] > 50 * s2  # a's depth (400 s² alone), not its cross-sight alone


def looking(o: BodyObservation, R_view: np.ndarray, depth_sd_m: float) -> BodyObservation:
    """The frame o seen by a camera turned by R_view (4, 4: T_camera_jacket's rotation, 20 m off), its fits' position
    σ along its line of sight depth_sd_m (a marker's size reads depth 20 times looser than it reads the image)."""
    from dataclasses import replace

    assert o.jacket is not None and o.topside is not None
    cov = np.diag([1e-8] * 3 + [(0.5 * MM) ** 2 / 2] * 2 + [depth_sd_m**2 / 2])  # in the camera: its z is depth
    T_cj = R_view.copy()
    T_cj[:3, 3] = [0.0, 0.0, 20.0]
    T_jt = inverse(o.jacket.T_camera_body) @ o.topside.T_camera_body
    return replace(o, jacket=replace(o.jacket, T_camera_body=T_cj, covariance=cov),
                   topside=replace(o.topside, T_camera_body=T_cj @ T_jt, covariance=cov))


def test_a_cameras_lens_error_is_what_its_fits_leave_where_that_is_more() -> None:
    """The lens floor takes what a camera's calibration states, or what its own fits of the markers leave where that is
    more (caliscope's cam_0: 0.19 px stated, 0.4 px left); an exact calibration (0 px) stays exact, its fits' corner
    noise averaging over frames; before three fits, the statement alone."""
    from tracking.estimator.noise import CornerNoise, lens_px

    noise = CornerNoise()
    assert lens_px(0.19, noise) == 0.19  # no fits yet
    noise.samples.extend([0.4**2] * 5)
    assert lens_px(0.19, noise) == pytest.approx(0.4)
    assert lens_px(0.6, noise) == 0.6
    assert lens_px(0.0, noise) == 0.0
