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
A rig whose ids have no mirror among them (DICT_6X6_250 below id 250 has none) is not affected at all.
"""

from __future__ import annotations

from collections.abc import Mapping

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
                  size: float, camera: CameraModel) -> tuple[dict[int, MarkerPose], list[int]]:
    """The frame's poses without the mirror-ambiguous ones nothing confirms, and the ids dropped."""
    if not ambiguous or not ambiguous & poses.keys():
        return poses, []
    dropped = [i for i in sorted(ambiguous & poses.keys())
               if not confirmed(poses[i], poses, markers, ambiguous, size, camera)
               and not confirmed_by_other_body(poses[i], poses, markers, ambiguous, size)]
    return {i: p for i, p in poses.items() if i not in dropped}, dropped
