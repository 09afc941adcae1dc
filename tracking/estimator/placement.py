"""Placing a camera and the topside in the state at first sight, from a body pose (tracking.pose).

A camera's first jacket view places it: its pose from the view's PnP pose, covariance × PLACEMENT_GAIN (it only
linearises; the same frame's corners, applied right after, carry its information), and its surveyed position, when
the rig has one, as a measurement gated against the placement. A lone far marker's view is ambiguous (two IPPE
poses): the camera waits until the evidence decides between them (tracking.estimator.hypotheses). The topside's first
view through a placed camera places it level at the view's position, σ TOPSIDE_PLACEMENT_M.
"""

from __future__ import annotations

import numpy as np

from tracking.estimator.hypotheses import (
    DECISIVE_CHI2,
    EVIDENCE_CAP,
    LEVEL_SIGMA_RAD,
    ONE_OPTION_WAIT_S,
    SAME_OPTION_CHI2,
    Hypotheses,
)
from tracking.estimator.measurements import corner_jacobian, predict_corners
from tracking.estimator.noise import (
    AMBIGUOUS_VARIANCE_GAIN,
    CORNER_GATE_CHI2,
    CORNER_NOISE_PX,
    MEASUREMENT_FLOOR_M,
    PLACEMENT_GAIN,
    ROTATION_FLOOR_RAD,
    STATE,
    SURVEY_GATE_CHI2,
    TOPSIDE_PLACEMENT_M,
    VIEW_BIAS_PX,
    VIEW_SHAPE_BIAS_PX,
    fits_its_corners,
    prior_covariance,
)
from tracking.estimator.state import CameraState, FilterState
from tracking.geometry import between, error_covariance, inverse, rotation_angle, rotvec
from tracking.offsets import MAX_PAIR_TILT_RAD, BodyObservation
from tracking.pose import BodyPose, Choice

Options = list[tuple[np.ndarray, np.ndarray]]  # a view's poses T_camera_body (4, 4), each with its (6, 6) covariance


def place_camera(s: FilterState, cam: CameraState, o: BodyObservation) -> bool:
    """First view of the jacket: the camera's pose from it; an ambiguous one settled by the evidence."""
    jb = o.jacket
    assert jb is not None
    if not fits_its_corners(jb, cam.corner_noise.sigma_px):
        cam.waiting = "its jacket view does not fit its corners (a corner off by rain or glare?)"
        return False  # a corner off: wait for a clean view
    options = [(jb.T_camera_body, jb.covariance), *jb.alternatives]
    gain = 1.0
    if jb.choice != Choice.UNIQUE and len(options) > 1:
        T_jc = settle(s, cam, o, options)
        if T_jc is None:
            return False
        options = [(inverse(T_jc), options[0][1])]
        gain = AMBIGUOUS_VARIANCE_GAIN
    T_cj, cov = options[0]
    cov_jc = camera_covariance(T_cj, cov)
    cam.T_jacket_camera = inverse(T_cj)
    floor = np.diag([ROTATION_FLOOR_RAD**2] * 3 + [MEASUREMENT_FLOOR_M**2] * 3)
    s.reset_camera(cam, gain * PLACEMENT_GAIN * cov_jc + floor)
    apply_survey(s, cam, gain * cov_jc[3:, 3:] + floor[3:, 3:])
    cam.hypotheses, cam.waiting, cam.placed_at = None, "", o.time
    return True


def camera_covariance(T_cj: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """(6, 6) covariance of a camera's error state (δθ, δp, jacket frame) placed by T_camera_jacket (4, 4) with the
    covariance (6, 6) of its (rvec, tvec)."""
    return error_covariance(T_cj, cov, inverse(T_cj), invert=True)


def one_option(options: Options) -> bool:
    """Whether an ambiguous view's options place the camera within each other's σ (a view near square on): then
    either places it, and its covariance (AMBIGUOUS_VARIANCE_GAIN) holds the other."""
    (T_0, cov_0), rest = options[0], options[1:]
    p_0, S_0 = inverse(T_0)[:3, 3], camera_covariance(T_0, cov_0)[3:, 3:]
    for T, cov in rest:
        d = inverse(T)[:3, 3] - p_0
        if float(d @ np.linalg.solve(S_0 + camera_covariance(T, cov)[3:, 3:], d)) > SAME_OPTION_CHI2:
            return False
    return True


def settle(s: FilterState, cam: CameraState, o: BodyObservation, options: Options) -> np.ndarray | None:
    """The pose (4, 4) T_jacket_camera that places a camera whose jacket view is ambiguous, once the evidence decides
    between its options, or they are one (tracking.estimator.hypotheses); None until then, with the reason in
    cam.waiting."""
    positions = [inverse(T)[:3, 3] for T, _ in options]
    h = cam.hypotheses
    order = h.match(positions) if h is not None else None
    if h is None or order is None:  # the first ambiguous view
        h = cam.hypotheses = Hypotheses.start(positions, o.time)
        order = list(range(len(options)))
    for j, k in enumerate(order):
        h.positions[k] = positions[j]
    candidates = [*options, (inverse(between([inverse(T) for T, _ in options])), options[0][1])]
    topside = [i for i in o.corners if i in s.topside_corners] if s.topside_placed else []
    misfits, distances = _option_fits(s, cam, o, candidates, len(options), topside)
    for j, k in enumerate(order):
        h.poses[k].append((distances[j], inverse(options[j][0])))
    h.between.append((distances[-1], inverse(candidates[-1][0])))
    h.add(_by_hypothesis(order, misfits), o.time, "its jacket corners")
    gate = CORNER_GATE_CHI2 * len(topside)  # the topside's corners fit no option: the topside's state is off, and
    if topside and min(distances[:len(options)]) <= gate:  # the frame tells nothing of which option is right
        h.add(_by_hypothesis(order, [min(d, EVIDENCE_CAP * gate) for d in distances[:len(options)]]), o.time,
              "the topside's corners")
    elif o.topside is not None and not s.topside_placed:  # the topside hangs near level under the right one
        tilts = [min(float(np.linalg.norm(rotvec(T[:3, :3].T @ T_ct[:3, :3]))) for T_ct in
                     [o.topside.T_camera_body, *(a for a, _ in o.topside.alternatives)]) for T, _ in options]
        h.add(_by_hypothesis(order, [(t / LEVEL_SIGMA_RAD) ** 2 for t in tilts]), o.time, "the topside's tilt")
    _survey_evidence(s, cam, h, o.time, positions, options, order)
    h.step(o.time)
    decided = h.decided()
    if decided is not None:
        return h.pose(decided)
    if one_option(options) and h.span >= ONE_OPTION_WAIT_S:  # near square on: between them
        return h.one()
    apart = np.degrees(rotation_angle(options[0][0][:3, :3], options[1][0][:3, :3]))
    marker = o.jacket.marker_ids[0] if o.jacket is not None else "?"
    cam.waiting = (f"its view of jacket marker {marker} is ambiguous (two poses {apart:.0f}° apart fit its corners "
                   f"alike); {', '.join(sorted(h.sources))} tell them apart by χ² {h.margin:.1f} of "
                   f"{DECISIVE_CHI2:g} so far")
    return None


def _by_hypothesis(order: list[int], values: list[float]) -> np.ndarray:
    """Per hypothesis (k,), from values per frame option (k,): option j is hypothesis order[j]."""
    out = np.zeros(len(order))
    for j, v in enumerate(values):
        out[order[j]] = v
    return out


def _option_fits(s: FilterState, cam: CameraState, o: BodyObservation, candidates: Options, n_options: int,
                 topside: list[int]) -> tuple[list[float], list[float]]:
    """Per option, the χ² of the frame's jacket corners through it; per candidate (the options, then the pose between
    them), the topside's corners' Mahalanobis distance through it (nan without topside corners)."""
    sigma2 = CORNER_NOISE_PX**2 + VIEW_BIAS_PX**2 + VIEW_SHAPE_BIAS_PX**2  # a corner's error in one frame
    zero = s.x.copy()  # the camera's error zero: its nominal pose is the candidate's
    zero[cam.index:cam.index + 6] = 0.0
    jacket = [i for i in o.corners if i in s.jacket_corners]
    misfits, distances = [], []
    for n, (T_cj, cov) in enumerate(candidates):
        T_jc = inverse(T_cj)
        if n < n_options:
            misfits.append(sum(float(np.sum((predict_corners(s, T_jc, cam.index, i, zero, o.K) -
                                             o.corners[i].reshape(-1)) ** 2)) for i in jacket) / sigma2)
        distances.append(_topside_distance(s, T_jc, cam.index, zero, o, topside, camera_covariance(T_cj, cov),
                                           sigma2) if topside else np.nan)
    return misfits, distances


def _topside_distance(s: FilterState, T_jc: np.ndarray, index: int, x: np.ndarray, o: BodyObservation,
                      markers: list[int], camera_cov: np.ndarray, sigma2: float) -> float:
    """Mahalanobis distance of a frame's topside corners from their prediction through a camera tentatively at
    T_jacket_camera (4, 4) (its error states, from index, zero in x), covariance (6, 6) camera_cov, and the topside's
    state."""
    columns = [*range(6), *range(index, index + 6)]
    ys, Js = [], []
    for i in markers:
        h_i, J_i = corner_jacobian(s, T_jc, index, i, x, o.K, columns)
        ys.append(o.corners[i].reshape(-1) - h_i)
        Js.append(J_i)
    y, J = np.concatenate(ys), np.vstack(Js)
    P = np.zeros((12, 12))
    P[:6, :6] = s.P[:6, :6]
    P[6:, 6:] = camera_cov
    S = J @ P @ J.T + sigma2 * np.eye(len(y))
    return float(y @ np.linalg.solve(S, y))


def _survey_evidence(s: FilterState, cam: CameraState, h: Hypotheses, time: float, positions: list[np.ndarray],
                     options: Options, order: list[int]) -> None:
    """The camera's surveyed position as evidence, once, and only when it fits one option and rules out another: a
    survey off by metres must not choose (it is refused when the camera is placed)."""
    if cam.name not in s.surveys or h.surveyed:
        return
    position, sigma = s.surveys[cam.name]
    survey = [float((p - position) @ np.linalg.solve(sigma**2 * np.eye(3) + camera_covariance(T, cov)[3:, 3:],
                                                     p - position))
              for p, (T, cov) in zip(positions, options, strict=True)]
    if min(survey) <= SURVEY_GATE_CHI2 and max(survey) - min(survey) >= DECISIVE_CHI2:
        h.add(_by_hypothesis(order, survey), time, "its surveyed position", once=True)
    h.surveyed = True


def apply_survey(s: FilterState, cam: CameraState, placed: np.ndarray) -> None:
    """The camera's surveyed position as a measurement of its just placed pose, gated against the placement's own
    (3, 3) position covariance (placed, without PLACEMENT_GAIN); a conflict is kept in survey_conflicts."""
    if cam.name not in s.surveys:
        return
    assert cam.T_jacket_camera is not None
    position, sigma = s.surveys[cam.name]
    y = position - (cam.T_jacket_camera[:3, 3] + s.x[cam.index + 3:cam.index + 6])
    R = sigma**2 * np.eye(3)
    if float(y @ np.linalg.solve(placed + R, y)) > SURVEY_GATE_CHI2:
        s.survey_conflicts[cam.name] = float(np.linalg.norm(y))
        return
    s.survey_conflicts.pop(cam.name, None)
    H = np.zeros((3, s.size))
    H[:, cam.index + 3:cam.index + 6] = np.eye(3)
    s.apply(H, y, R)


def place_topside(s: FilterState, cam: CameraState, topside: BodyPose) -> bool:
    """First view of the topside: its pose from the placed camera (the option hanging nearest level)."""
    if not fits_its_corners(topside, cam.corner_noise.sigma_px):
        return False
    T_jc = s.camera_pose(cam)
    poses = [T_jc @ T for T in [topside.T_camera_body, *(a for a, _ in topside.alternatives)]]
    tilts = [float(np.linalg.norm(rotvec(T[:3, :3]))) for T in poses]
    k = int(np.argmin(tilts)) if topside.choice != Choice.UNIQUE else 0
    if tilts[k] > MAX_PAIR_TILT_RAD:
        return False
    s.x[:STATE] = 0.0  # level, as the prior: one far marker's tilt is worth less than the prior's 0.05 rad
    s.x[:3] = poses[k][:3, 3]
    s.P[:STATE, :] = 0.0
    s.P[:, :STATE] = 0.0
    s.P[:STATE, :STATE] = prior_covariance(s.tuning)
    s.P[:3, :3] = np.eye(3) * TOPSIDE_PLACEMENT_M**2
    s.topside_placed = True
    s.placed_at = s.time
    return True
