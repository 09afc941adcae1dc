"""Mirrored markers: a detection that may be another marker seen from behind or in a reflection.

A marker seen from behind (a print that shows through, a board printed on both sides) or in a mirror (wet steel,
water, a window) shows its pattern mirrored. OpenCV orders a candidate's corners clockwise before it reads the bits,
so a mirrored pattern is read like any other: as an id of the dictionary when it is close enough to one, with corners
that are not that marker's. The bits cannot tell: the mirror image of marker i is then marker j's pattern (in
DICT_4X4_1000, markers 8 and 9 are their own mirror images). Which ids can be read from a mirror is known before any
frame, from the dictionary and the rig: id j is mirror-ambiguous when the mirror image of some rig marker's pattern
reads as j (in any of its four turns, within the detector's error correction rate).

A mirror-ambiguous detection is kept only where an unambiguous marker of its body in the same frame puts it: its
corners within MIRROR_TOLERANCE of a marker side of where that marker's pose (either IPPE solution) and the rig
predict them. A frame may hold no unambiguous marker of its body (a lone topside marker whose id reads the same in a
mirror, as 8 and 9 do in DICT_4X4_*): then an unambiguous marker of the other body confirms it, more loosely, since
the bodies move apart (a mirrored view never reads as an unambiguous id, so that marker is seen the right way): the
detection (either IPPE solution) turned within MIRROR_BODY_TURN_RAD of where the rig's mated geometry puts it and
within MIRROR_BODY_REACH_SIDES of it. A mirrored reading faces the wrong way or is turned by a quarter turn or more;
a reflection in the sea sits tens of metres below. Otherwise it is dropped and counted: a marker seen from behind
never reaches the poses or the filter. Left open: a reflection in a vertical surface within a few metres of a lone
self-mirroring marker passes the loose check (the filter's gate is then the guard).
Two self-mirroring markers, and nothing else in view (a drone watching one pair of DICT_4X4_50's 8 and 47), confirm
each other where the rig's set-down explains them far better than a mirror would. Any reflector (behind the face,
beside it, the sea beneath it, tilted) shows a face as its left-right mirror image, turned; the reading turns with it,
so a mirror shows the pair's vector (the second marker from the first, in the first's frame) mirrored left-right and
turned by the reading's turn (mirror_turn: a quarter turn for 8, 9 and 47). Their relative turn agrees with the rig's
either way; the vector does not. Markers of two bodies are kept where the topside's displacement from mated that
their vector implies is a hundred times likelier under a set-down prior (MIRROR_SETDOWN_SIGMA_M: a metre sideways,
three above) than the displacement a mirror would imply (a topside metres sideways of its cone waits); two of one
body where the first puts the second's corners as `confirmed` asks. A pair whose mirror image reads as the pair (17
with 17-like unturned readings, or a pair on the one diagonal a mirror turned a quarter turn maps onto itself)
confirms nothing.
"""

from __future__ import annotations

from collections.abc import Mapping
from functools import lru_cache

import cv2
import numpy as np

from tracking.camera import CameraModel
from tracking.geometry import inverse, rotation_angle, rvec_tvec
from tracking.pose import MarkerPose, marker_object_points
from tracking.rig import Marker, Rig

MIRROR_TOLERANCE = 0.3  # mean corner distance, in marker sides, within which a prediction confirms a detection: a
# mirrored reading's corners are a side or more from their places (its corner order is mirrored, or it sits at
# another marker's place); a single marker's pose predicts a neighbour on its body within a few percent of a side
MIRROR_BODY_TURN_RAD = np.radians(20.0)  # a topside hangs within a few degrees of level and of its heading over the
# jacket; a mirrored reading is turned 90° or more, or faces away
MIRROR_BODY_REACH_SIDES = 20.0  # marker sides (20 m at 1 m markers): a topside being set down is within this of its
# cones; a reflection in the sea is twice the marker's height above it away


def seen_only_mirrored(ids: list[int]) -> str:
    """Why a camera whose every rig marker was dropped as seen mirrored is not used."""
    return (f"its rig markers ({', '.join(map(str, ids))}) were seen only mirrored (the board's back, or a reflection) "
            "and nothing confirmed them: a marker of another id in its view would")


def mirror_ambiguous(rig: Rig, correction_rate: float | None = None) -> frozenset[int]:
    """Rig ids that the mirror image of some rig marker reads as (correction_rate: the detector's, OpenCV's default
    when None)."""
    dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, rig.dictionary))
    rate = cv2.aruco.DetectorParameters().errorCorrectionRate if correction_rate is None else correction_rate
    ids = {m.id for m in rig.markers}
    out = set()
    for i in sorted(ids):
        bits = cv2.aruco.Dictionary.getBitsFromByteList(dictionary.bytesList[i:i + 1], dictionary.markerSize)
        found, j, _ = dictionary.identify(np.ascontiguousarray(bits[:, ::-1]), rate)
        if found and j in ids:
            out.add(int(j))
    return frozenset(out)


MIRROR_READ_PX = 60  # side of the generated marker whose mirror image OpenCV reads to learn how a reading turns
MIRROR_VIEW = np.diag([-1.0, 1.0])  # a face as any reflector shows it, up to a turn (which the reading shares)
MIRROR_SETDOWN_SIGMA_M = np.array([1.0, 1.0, 3.0])  # jacket x, y, z: a topside near its cones is within a metre or
# two sideways and hangs up to several metres above them (random-4001 hovers 2.7 m up, swinging 0.7 m)
MIRROR_EVIDENCE_CHI2 = 9.21  # 2 ln 100: the rig's reading a hundred times likelier than the mirror's


@lru_cache(maxsize=64)
def _mirror_turn(dictionary: str, marker_id: int) -> tuple[tuple[float, ...], ...] | None:
    dictionary_ = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, dictionary))
    margin = MIRROR_READ_PX // 3
    image = cv2.copyMakeBorder(cv2.aruco.generateImageMarker(dictionary_, marker_id, MIRROR_READ_PX),
                               margin, margin, margin, margin, cv2.BORDER_CONSTANT, value=255)
    corners, ids, _ = cv2.aruco.ArucoDetector(dictionary_).detectMarkers(np.ascontiguousarray(image[:, ::-1]))
    if ids is None or int(ids.reshape(-1)[0]) != marker_id:
        return None
    centre = (image.shape[1] - 1) / 2.0
    seen = corners[0].reshape(4, 2) - centre
    seen[:, 1] *= -1.0  # image (right, up)
    read = marker_object_points(2.0)[:, :2]  # the reading's corners in its own frame (x right, y up)
    turn = np.linalg.lstsq(read, seen, rcond=None)[0].T  # seen = turn @ read, up to scale
    return tuple(map(tuple, np.round(turn / np.abs(turn).max())))


def mirror_turn(dictionary: str, marker_id: int) -> np.ndarray | None:
    """(2, 2) the in-plane map from a mirrored reading of a self-mirroring marker (its mirror image read as itself)
    to the face's mirror image as seen (right, up), learnt by having OpenCV read the marker's generated image flipped,
    so that its corner order holds: a quarter turn for DICT_4X4_50's 8, 9 and 47, none for its 17; None when the
    mirror image reads as another id."""
    turn = _mirror_turn(dictionary, marker_id)
    return None if turn is None else np.array(turn)


def mirror_turns(rig: Rig) -> dict[int, np.ndarray]:
    """id -> mirror_turn for the rig's self-mirroring markers (the only ones a pair of readings can confirm)."""
    out = {}
    for i in sorted(mirror_ambiguous(rig)):
        turn = mirror_turn(rig.dictionary, i)
        if turn is not None:
            out[i] = turn
    return out


def _setdown_d2(R_body_marker: np.ndarray, shift: np.ndarray) -> float:
    """Squared Mahalanobis distance of an in-plane shift (2,) of a marker, in its frame, under the set-down prior."""
    d = R_body_marker[:, :2] @ shift / MIRROR_SETDOWN_SIGMA_M
    return float(d @ d)


def confirmed_by_each_other(a: MarkerPose, b: MarkerPose, markers: Mapping[int, Marker],
                            turns: Mapping[int, np.ndarray], size: float, camera: CameraModel) -> bool:
    """Whether two self-mirroring readings confirm each other. Of two bodies: b's reading, in a's, turned within
    MIRROR_BODY_TURN_RAD of where the mated rig puts it and within MIRROR_BODY_REACH_SIDES, with the displacement from
    mated its in-plane vector implies MIRROR_EVIDENCE_CHI2 nearer the set-down prior (MIRROR_SETDOWN_SIGMA_M) than the
    one a mirror (MIRROR_VIEW through a's mirror_turn) implies, for either IPPE solution of each. Of one
    body: a puts b's corners within MIRROR_TOLERANCE (as `confirmed`), where a mirror would put them elsewhere."""
    T_a_b = inverse(markers[a.id].T_body_marker) @ markers[b.id].T_body_marker  # body frames coincide when mated
    rig_vector = T_a_b[:2, 3]
    G = turns[a.id].T @ MIRROR_VIEW  # a true vector in a's face as a mirrored reading of a shows it
    if markers[a.id].body == markers[b.id].body:
        if np.linalg.norm(G @ rig_vector - rig_vector) < 2 * MIRROR_TOLERANCE * size:
            return False
        corners = np.asarray(b.corners, dtype=float)
        side = float(np.mean(np.linalg.norm(corners - np.roll(corners, 1, axis=0), axis=1)))
        return any(np.mean(np.linalg.norm(predicted - corners, axis=1)) < MIRROR_TOLERANCE * side for predicted in
                   _predicted_corners(a, markers[a.id].T_body_marker, markers[b.id].T_body_marker, size, camera))
    R = markers[a.id].T_body_marker[:3, :3]
    for sa in a.solutions:
        for sb in b.solutions:
            T = inverse(sa.T_camera_marker) @ sb.T_camera_marker
            if rotation_angle(T[:3, :3], T_a_b[:3, :3]) >= MIRROR_BODY_TURN_RAD or \
                    np.linalg.norm(T[:3, 3] - T_a_b[:3, 3]) >= MIRROR_BODY_REACH_SIDES * size:
                continue
            seen = T[:2, 3]
            rig_d2, mirror_d2 = _setdown_d2(R, seen - rig_vector), _setdown_d2(R, G.T @ seen - rig_vector)
            if mirror_d2 - rig_d2 >= MIRROR_EVIDENCE_CHI2:
                return True
    return False


def _predicted_corners(anchor: MarkerPose, T_body_anchor: np.ndarray, T_body_marker: np.ndarray, size: float,
                       camera: CameraModel) -> list[np.ndarray]:
    """(4, 2) distorted pixels of a marker's corners as each IPPE solution of an anchor marker on its body puts them."""
    obj = marker_object_points(size)
    T_anchor_marker = inverse(T_body_anchor) @ T_body_marker
    out = []
    for s in anchor.solutions:
        px, _ = cv2.projectPoints(obj, *rvec_tvec(s.T_camera_marker @ T_anchor_marker), camera.K, camera.dist)
        out.append(px.reshape(4, 2))
    return out


def confirmed(pose: MarkerPose, poses: Mapping[int, MarkerPose], markers: Mapping[int, Marker],
              ambiguous: frozenset[int], size: float, camera: CameraModel) -> bool:
    """Whether an unambiguous marker of the same body in the frame puts a mirror-ambiguous marker where it was seen."""
    corners = np.asarray(pose.corners, dtype=float)
    side = float(np.mean(np.linalg.norm(corners - np.roll(corners, 1, axis=0), axis=1)))
    body = markers[pose.id].body
    for k, anchor in poses.items():
        if k in ambiguous or markers[k].body != body:
            continue
        for predicted in _predicted_corners(anchor, markers[k].T_body_marker, markers[pose.id].T_body_marker, size,
                                            camera):
            if np.mean(np.linalg.norm(predicted - corners, axis=1)) < MIRROR_TOLERANCE * side:
                return True
    return False


def confirmed_by_other_body(pose: MarkerPose, poses: Mapping[int, MarkerPose], markers: Mapping[int, Marker],
                            ambiguous: frozenset[int], size: float) -> bool:
    """Whether an unambiguous marker of the other body puts a mirror-ambiguous marker, as the rig's mated geometry
    would, within MIRROR_BODY_TURN_RAD and MIRROR_BODY_REACH_SIDES of one of its IPPE solutions."""
    body = markers[pose.id].body
    T_body_marker = markers[pose.id].T_body_marker
    for k, anchor in poses.items():
        if k in ambiguous or markers[k].body == body:
            continue
        T_anchor_marker = inverse(markers[k].T_body_marker) @ T_body_marker  # body frames coincide when mated
        for a in anchor.solutions:
            T = a.T_camera_marker @ T_anchor_marker
            for s in pose.solutions:
                if rotation_angle(T[:3, :3], s.T_camera_marker[:3, :3]) < MIRROR_BODY_TURN_RAD and \
                        np.linalg.norm(T[:3, 3] - s.T_camera_marker[:3, 3]) < MIRROR_BODY_REACH_SIDES * size:
                    return True
    return False


def drop_mirrored(poses: dict[int, MarkerPose], markers: Mapping[int, Marker], ambiguous: frozenset[int],
                  size: float, camera: CameraModel, turns: Mapping[int, np.ndarray] | None = None
                  ) -> tuple[dict[int, MarkerPose], list[int]]:
    """The frame's poses without the mirror-ambiguous ones nothing confirms, and the ids dropped; turns: the rig's
    mirror_turns, with which two self-mirroring readings may confirm each other."""
    if not ambiguous or not ambiguous & poses.keys():
        return poses, []
    dropped = [i for i in sorted(ambiguous & poses.keys())
               if not confirmed(poses[i], poses, markers, ambiguous, size, camera)
               and not confirmed_by_other_body(poses[i], poses, markers, ambiguous, size)]
    if turns:
        pairs = [(i, j) for i in dropped for j in dropped if i < j and i in turns and j in turns]
        mutual: set[int] = set()
        for i, j in pairs:  # either way round: each reads the pair in its first marker's frame
            if confirmed_by_each_other(poses[i], poses[j], markers, turns, size, camera) or \
                    confirmed_by_each_other(poses[j], poses[i], markers, turns, size, camera):
                mutual |= {i, j}
        dropped = [i for i in dropped if i not in mutual]
    return {i: p for i, p in poses.items() if i not in dropped}, dropped
