"""Markers against the rig: which markers' detected poses disagree with where the rig puts them, in one camera's
frames or between cameras (the pre-lift check's disagreements; tracking/check.py gathers them).

Per camera frame, each marker's pose is predicted from the other markers of its body that the frame shows and compared
with its own detected pose; the residuals' medians over the frames are tested against their σ (corner noise through
both poses, the frames' own spread and the survey's). A camera that sees one marker of each body is checked by the
topside's tilt against the jacket (it hangs near level). Two cameras that measure one cone are compared at its point.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass

import numpy as np

from tracking.camera import CameraModel
from tracking.estimator.noise import VIEW_BIAS_TAU_S
from tracking.geometry import angle, point_covariance
from tracking.offsets import MAX_PAIR_TILT_RAD
from tracking.pipeline import FrameResult
from tracking.pose import BodyPose, MarkerPose, estimate_body_pose
from tracking.rig import Rig

# A residual's σ over a check's frames: the poses' own covariances (for CORNER_SIGMA_PX, the persistent part of a
# corner's error, as estimator.noise.VIEW_BIAS_PX), its spread over the frames divided by the root of the independent
# stretches (one per VIEW_BIAS_TAU_S: a view's corner errors stay about that long), and the markers' surveys
RIG_SURVEY_SIGMA_M = 0.02  # a marker centre's survey is good to about this, m
DISAGREE_SIGMAS = 5.0  # a residual beyond this many σ disagrees ...
MIN_DISAGREE_M = 0.05  # ... when it is also this large: a third of the 150 mm tolerance (a marker's error enters the
# offsets one to one); smaller ones hide in one camera's calibration errors
MIN_NORMAL_DEG = 20.0  # a normal this far off is a wrong face or orientation (faces are 45° or 90° apart)
MIN_TURN_DEG = 3.0  # a marker turned 3° from the rig swings a marker 2 m above it by 0.1 m
MIN_FRAMES = 3  # a disagreement rests on at least this many frames
TOPSIDE_TILT_DEG = float(np.degrees(MAX_PAIR_TILT_RAD))  # the topside hangs within this of level (offsets.py)
SUGGEST_M = 0.3  # a marker that sits within this of another rig marker's place (and its normal within MIN_NORMAL_DEG)
# may carry that marker's id


@dataclass(frozen=True)
class Disagreement:
    """Markers whose detected poses disagree with the rig, in one camera's frames."""

    camera: str
    markers: tuple[int, ...]  # the marker(s) it names: one of them is mounted, surveyed or entered wrongly
    against: tuple[int, ...]  # the markers the comparison rests on
    frames: int
    reason: str  # one line
    offset_m: float = 0.0  # centre residual, m (relative checks)
    sigma_m: float = 0.0  # its σ along it, m
    normal_deg: float = 0.0  # angle between detected and rig normal (relative checks) or topside tilt (pair checks)
    turn_deg: float = 0.0  # turn about the normal, degrees


# --- markers against the rig ----------------------------------------------------------------------------------------

def _poses(pose: MarkerPose) -> list[tuple[np.ndarray, np.ndarray, float]]:
    """A marker's IPPE solutions: (T_camera_marker (4, 4), covariance (6, 6), reprojection error px)."""
    return [(s.T_camera_marker, s.covariance, s.reprojection_error) for s in pose.solutions]


def independent(times: np.ndarray) -> float:
    """How many independent stretches of corner error frames at capture times (N,) span (one per VIEW_BIAS_TAU_S)."""
    return max(1.0, float(np.ptp(times)) / VIEW_BIAS_TAU_S) if len(times) else 1.0


@dataclass(frozen=True)
class Residual:
    """One frame's comparison of a marker with its body's other markers, in the body's frame."""

    offset: np.ndarray  # (3,) detected centre minus where the others put it, m
    covariance: np.ndarray  # (3, 3) of it, m²
    normal_deg: float
    turn_deg: float  # about the normal, counter-clockwise seen facing it
    rotation_sigma_deg: np.ndarray  # (2,) σ of the normal's angle and of the turn
    T_body_marker: np.ndarray  # (4, 4) where the detected marker sits in the body's frame, by the others


def relative_residual(marker: MarkerPose, reference: BodyPose, T_body_marker: np.ndarray) -> Residual:
    """A marker's detected pose against the one its body's other markers (reference) predict with the rig's
    T_body_marker (4, 4); the IPPE options (the marker's, a lone reference's) that agree best in rotation."""
    references = [(reference.T_camera_body, reference.covariance), *reference.alternatives]
    best = None
    for T_cb, cov_b in references:
        T_pred = T_cb @ T_body_marker
        for T_cm, cov_m, error in _poses(marker):
            R_rel = T_pred[:3, :3].T @ T_cm[:3, :3]
            angle = float(np.arccos(np.clip((np.trace(R_rel) - 1) / 2, -1.0, 1.0)))
            if best is None or angle < best[0]:
                best = (angle, T_cb, cov_b, T_pred, T_cm, cov_m, error, R_rel)
    assert best is not None
    _, T_cb, cov_b, T_pred, T_cm, cov_m, error, R_rel = best
    R_bc = T_cb[:3, :3].T
    offset = R_bc @ (T_cm[:3, 3] - T_pred[:3, 3])
    cov_cam = cov_m[3:, 3:] + point_covariance(T_cb, cov_b, T_body_marker[:3, 3])
    rot_cam = cov_m[:3, :3] + cov_b[:3, :3]  # rotation vectors of both, in the camera frame (small angles)
    rot_marker = T_pred[:3, :3].T @ rot_cam @ T_pred[:3, :3]
    normal = float(np.degrees(np.arccos(np.clip(R_rel[2, 2], -1.0, 1.0))))
    turn = float(np.degrees(np.arctan2(R_rel[1, 0] - R_rel[0, 1], R_rel[0, 0] + R_rel[1, 1])))
    sigmas = np.degrees(np.sqrt([max(np.linalg.eigvalsh(rot_marker[:2, :2]).max(), 0.0), max(rot_marker[2, 2], 0.0)]))
    T_body_detected = np.linalg.inv(T_cb) @ T_cm
    return Residual(offset, R_bc @ cov_cam @ R_bc.T, normal, turn, sigmas, T_body_detected)


def _suggest(rig: Rig, marker: int, T_body_detected: np.ndarray) -> str:
    """' (it sits where the rig puts marker N: its id?)' when the detected marker is at another rig marker's place."""
    body = rig.marker_by_id[marker].body
    for m in rig.markers:
        if m.id == marker or m.body != body:
            continue
        near = np.linalg.norm(T_body_detected[:3, 3] - m.T_body_marker[:3, 3]) < SUGGEST_M
        facing = np.degrees(np.arccos(np.clip(T_body_detected[:3, 2] @ m.T_body_marker[:3, 2], -1, 1))) < MIN_NORMAL_DEG
        if near and facing:
            return f" (it sits where the rig puts marker {m.id}: its id entered wrongly?)"
    return ""


def _describe(rig: Rig, marker: int) -> str:
    m = rig.marker_by_id[marker]
    return f"marker {marker} ({m.body} {m.cone}/{m.face})"


def relative_disagreements(rig: Rig, camera: str, results: list[FrameResult], model: CameraModel
                           ) -> list[Disagreement]:
    """Each marker against the other markers of its body in the same frames of one camera (see the module)."""
    bodies = {"jacket": {}, "topside": {}}  # body -> id -> T_body_marker
    for m in rig.markers:
        bodies[m.body][m.id] = np.asarray(m.T_body_marker)
    residuals: dict[tuple[int, tuple[int, ...]], list[Residual]] = {}
    times: dict[tuple[int, tuple[int, ...]], list[float]] = {}
    for r in results:
        for markers in bodies.values():
            ids = sorted(i for i in r.poses if i in markers)
            if len(ids) < 2:
                continue
            for i in ids:
                others = [j for j in ids if j != i]
                reference = estimate_body_pose("body", [r.poses[j] for j in others], [markers[j] for j in others],
                                               model, rig.marker_size)
                residuals.setdefault((i, tuple(others)), []).append(relative_residual(r.poses[i], reference,
                                                                                      markers[i]))
                times.setdefault((i, tuple(others)), []).append(r.time)
    out = []
    for (i, others), found in sorted(residuals.items()):
        if len(found) < MIN_FRAMES:
            continue
        offsets = np.array([f.offset for f in found])
        offset = np.median(offsets, axis=0)
        distance = float(np.linalg.norm(offset))
        u = offset / distance if distance > 0 else np.array([1.0, 0.0, 0.0])
        n = independent(np.array(times[(i, others)]))
        model_var = float(np.mean([u @ f.covariance @ u for f in found]))
        spread = float(np.std(offsets @ u))
        sigma = float(np.sqrt(model_var + spread**2 / n + 2 * RIG_SURVEY_SIGMA_M**2))
        normal = float(np.median([f.normal_deg for f in found]))
        turn = float(np.median([f.turn_deg for f in found]))
        rot_sigma = np.sqrt(np.mean([f.rotation_sigma_deg**2 for f in found], axis=0)
                            + np.std([[f.normal_deg, f.turn_deg] for f in found], axis=0) ** 2 / n)
        what = []
        if distance > max(DISAGREE_SIGMAS * sigma, MIN_DISAGREE_M):
            what.append(f"sits {distance:.2f} m from where the rig puts it (σ {sigma:.2f} m; "
                        f"off by {np.round(offset, 2).tolist()} in the {rig.marker_by_id[i].body} frame)")
        if normal > max(DISAGREE_SIGMAS * rot_sigma[0], MIN_NORMAL_DEG):
            what.append(f"faces {normal:.0f}° away from the rig's normal (σ {rot_sigma[0]:.0f}°: its face?)")
        if abs(turn) > max(DISAGREE_SIGMAS * rot_sigma[1], MIN_TURN_DEG):
            what.append(f"is turned {turn:+.0f}° about its normal from the rig's (σ {rot_sigma[1]:.1f}°: "
                        "rotation_deg?)")
        if not what:
            continue
        against = ", ".join(map(str, others))
        hint = _suggest(rig, i, found[len(found) // 2].T_body_marker)
        alone = " (either may be the wrong one)" if len(others) == 1 else ""
        out.append(Disagreement(camera, (i, *others) if len(others) == 1 else (i,), others, len(found),
                                f"{_describe(rig, i)} against marker{'s' if len(others) > 1 else ''} {against}"
                                f"{alone}: " + "; ".join(what) + hint, distance, sigma, normal, turn))
    return _merge_pairs(out)


def _merge_pairs(found: list[Disagreement]) -> list[Disagreement]:
    """Keep one of the two mirror findings of two markers checked only against each other (the larger residual)."""
    out: dict[frozenset[int], Disagreement] = {}
    for d in found:
        key = frozenset(d.markers) if len(d.against) == 1 else frozenset([d.markers[0], -1])
        if key not in out or (d.offset_m, d.normal_deg) > (out[key].offset_m, out[key].normal_deg):
            out[key] = d
    return sorted(out.values(), key=lambda d: d.markers)


def tilt_disagreements(rig: Rig, camera: str, results: list[FrameResult]) -> list[Disagreement]:
    """The topside's tilt against the jacket in one camera's frames: beyond TOPSIDE_TILT_DEG, a marker of either body
    is mounted, or entered, with a wrong face, turn or id."""
    tilts, ids = [], Counter()
    for r in results:
        o = r.observation
        if o is None or o.jacket is None or o.topside is None:
            continue
        jackets = [o.jacket.T_camera_body, *(T for T, _ in o.jacket.alternatives)]
        topsides = [o.topside.T_camera_body, *(T for T, _ in o.topside.alternatives)]
        tilt = min(angle(Tj[:3, :3].T @ Tt[:3, :3]) for Tj in jackets for Tt in topsides)
        tilts.append(np.degrees(tilt))
        ids[(o.jacket.marker_ids, o.topside.marker_ids)] += 1
    if len(tilts) < MIN_FRAMES:
        return []
    tilt = float(np.median(tilts))
    if tilt <= TOPSIDE_TILT_DEG:
        return []
    (jacket, topside), _ = ids.most_common(1)[0]
    names = ", ".join(_describe(rig, i) for i in (*jacket, *topside))
    return [Disagreement(camera, (*jacket, *topside), (), len(tilts),
                         f"its jacket markers {list(jacket)} and topside markers {list(topside)} put the topside "
                         f"{tilt:.0f}° from level (it hangs within {TOPSIDE_TILT_DEG:.0f}°): a face, turn or id of "
                         f"one of {names} is wrong", normal_deg=tilt)]


@dataclass(frozen=True)
class ConeReading:
    """One camera's pair offsets at one cone over the check, moved to the cone's point (by the topside's rotation)."""

    camera: str
    cone: str
    markers: tuple[int, ...]  # the pairs' jacket and topside markers
    times: np.ndarray  # (N,) capture times, s
    offsets: np.ndarray  # (N, 3) topside minus mated at the cone's point, jacket frame, m
    covariances: np.ndarray  # (N, 3, 3), m²


def cone_readings(rig: Rig, camera: str, results: list[FrameResult], points: dict[str, np.ndarray],
                  omega: np.ndarray) -> list[ConeReading]:
    """A camera's pair offsets per cone, each moved from its topside marker to the cone's point (3,) with the topside's
    small rotation omega (3,) (o = t + ω × r): cameras on different faces of one cone then measure the same thing."""
    by_id = rig.marker_by_id
    per: dict[str, list[tuple[float, np.ndarray, np.ndarray, tuple[int, int]]]] = {}
    for r in results:
        for o in r.offsets:
            lever = points[o.cone] - np.array(by_id[o.topside_id].center)
            per.setdefault(o.cone, []).append((o.time, o.offset + np.cross(omega, lever), o.covariance,
                                               (o.jacket_id, o.topside_id)))
    out = []
    for cone, rows in sorted(per.items()):
        rows.sort(key=lambda row: row[0])
        markers = tuple(sorted({i for row in rows for i in row[3]}))
        out.append(ConeReading(camera, cone, markers, np.array([row[0] for row in rows]),
                               np.array([row[1] for row in rows]), np.array([row[2] for row in rows])))
    return out


MATCH_S = 0.05  # frames of two cameras this close in time are compared (the topside may move during the check)


def reading_difference(a: ConeReading, b: ConeReading) -> tuple[np.ndarray, float, int]:
    """The median difference (3,) of two cameras' offsets at one cone over frames MATCH_S apart, its σ along itself (m)
    and the number of frame pairs; σ from both covariances, the frames' spread and the four markers' surveys (see
    independent)."""
    if not len(a.times) or not len(b.times):
        return np.zeros(3), np.inf, 0
    after = np.searchsorted(b.times, a.times)
    lo, hi = np.clip(after - 1, 0, len(b.times) - 1), np.clip(after, 0, len(b.times) - 1)
    k = np.where(np.abs(b.times[lo] - a.times) <= np.abs(b.times[hi] - a.times), lo, hi)  # b's nearest frame
    near = np.abs(b.times[k] - a.times) <= MATCH_S
    if near.sum() < MIN_FRAMES:
        return np.zeros(3), np.inf, int(near.sum())
    diffs = a.offsets[near] - b.offsets[k[near]]
    diff = np.median(diffs, axis=0)
    distance = float(np.linalg.norm(diff))
    u = diff / distance if distance > 0 else np.array([1.0, 0.0, 0.0])
    model = float(np.mean([u @ (ca + cb) @ u for ca, cb in zip(a.covariances[near], b.covariances[k[near]],
                                                                strict=True)]))
    spread = float(np.std(diffs @ u)) ** 2 / independent(a.times[near])
    sigma = float(np.sqrt(model + spread + 4 * RIG_SURVEY_SIGMA_M**2))
    return diff, sigma, int(near.sum())


def cross_camera_disagreements(rig: Rig, readings: list[ConeReading]) -> list[Disagreement]:
    """Cameras that measure one cone's offset through different markers and disagree beyond their σ: one of their
    markers is mounted, surveyed or entered wrongly. With three or more cameras at a cone, the one that disagrees with
    all others (who agree) is named alone."""
    out = []
    for cone in sorted({r.cone for r in readings}):
        at = [r for r in readings if r.cone == cone]
        bad: dict[tuple[str, str], tuple[np.ndarray, float, int]] = {}
        for i, a in enumerate(at):
            for b in at[i + 1:]:
                if set(a.markers) == set(b.markers):
                    continue  # the same markers: a disagreement would be the cameras', not the rig's
                diff, sigma, n = reading_difference(a, b)
                distance = float(np.linalg.norm(diff))
                if n and distance > max(DISAGREE_SIGMAS * sigma, MIN_DISAGREE_M):
                    bad[(a.camera, b.camera)] = (diff, sigma, n)
        names = [r.camera for r in at]
        odd = [c for c in names if len(names) >= 3 and all((c, o) in bad or (o, c) in bad for o in names if o != c)]
        for (ca, cb), (diff, sigma, n) in sorted(bad.items()):
            if len(odd) == 1 and odd[0] not in (ca, cb):
                continue
            a = next(r for r in at if r.camera == ca)
            b = next(r for r in at if r.camera == cb)
            suspects = a.markers if odd == [ca] else b.markers if odd == [cb] else tuple(sorted({*a.markers,
                                                                                               *b.markers}))
            camera = odd[0] if len(odd) == 1 else f"{ca}+{cb}"
            out.append(Disagreement(
                camera, suspects, tuple(sorted({*a.markers, *b.markers} - set(suspects))), n,
                f"{ca} (markers {', '.join(map(str, a.markers))}) and {cb} (markers {', '.join(map(str, b.markers))}) "
                f"disagree on cone {cone}'s offset by {float(np.linalg.norm(diff)):.2f} m (σ {sigma:.2f} m; "
                f"{np.round(diff, 2).tolist()} jacket frame): one of markers {', '.join(map(str, suspects))} is "
                "mounted, surveyed or entered wrongly", float(np.linalg.norm(diff)), sigma))
    return out
