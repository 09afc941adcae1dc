"""Markers mounted turned about their normal (rotation_deg, R, quaternion): rendered, detected, offsets right."""

from __future__ import annotations

import numpy as np
import pytest

from tests.synthetic import (
    CAMERA_EYES,
    CONE_A,
    PAPER_DIST,
    PAPER_K,
    PAPER_SIZE,
    PlacedMarker,
    face_T,
    look_at,
    marker_centres,
    render,
    rig_dict,
)
from tracking.camera import CameraModel
from tracking.detection import MarkerDetector
from tracking.estimator import TopsideFilter
from tracking.offsets import body_geometry, frame_offsets, observe_bodies, pair_geometries
from tracking.paper import paper_roles
from tracking.pose import estimate_pose
from tracking.rig import Rig

OFFSET = np.array([0.35, -0.2, 0.6])  # the topside's true offset, jacket frame, m


def turn(R: np.ndarray, degrees: float) -> np.ndarray:
    """R (3, 3) turned about its own z by degrees, counter-clockwise seen from the front (independent of rig.turned)."""
    a = np.deg2rad(degrees)
    x, y = R[:, 0], R[:, 1]
    return np.column_stack([np.cos(a) * x + np.sin(a) * y, -np.sin(a) * x + np.cos(a) * y, R[:, 2]])


def quaternion_of(R: np.ndarray) -> list[float]:
    """[w, x, y, z] of a rotation (3, 3) whose angle is below 180°."""
    w = np.sqrt(1 + np.trace(R)) / 2
    return [w, (R[2, 1] - R[1, 2]) / (4 * w), (R[0, 2] - R[2, 0]) / (4 * w), (R[1, 0] - R[0, 1]) / (4 * w)]


# the small installation's markers (1, 2 on face ahead; 3, 4 on port) as riggers mounted them, turned by these angles
TURNS = {1: 90.0, 2: 37.0, 3: -90.0, 4: 37.0}


def turned_rig(stated: bool) -> Rig:
    """The small installation with its markers turned by TURNS; stated: the rig says so (each of the three ways)."""
    data = rig_dict([])
    if stated:
        for m in data["markers"]:
            R = turn(face_T(m["face"]), TURNS[m["id"]])
            if m["id"] in (1, 2):
                m["rotation_deg"] = TURNS[m["id"]]
            elif m["id"] == 3:
                m["R"] = np.round(R, 5).tolist()
            else:
                m["quaternion"] = np.round(quaternion_of(R), 6).tolist()
    return Rig.model_validate(data)


def rendered_views() -> dict[str, np.ndarray]:
    """Each camera's frame of the turned markers with the topside at OFFSET."""
    views = {}
    for name, eye in CAMERA_EYES.items():
        T_jacket_cam = look_at(eye, CONE_A + np.array([0.0, 0.0, -0.6]))
        placed = []
        for mid, (body, face, c) in marker_centres().items():
            T = np.eye(4)
            T[:3, :3] = turn(face_T(face), TURNS[mid])
            T[:3, 3] = c + (OFFSET if body == "topside" else 0.0)
            placed.append(PlacedMarker(mid, np.linalg.inv(T_jacket_cam) @ T, 1.0))
        views[name] = render(PAPER_K, PAPER_DIST, PAPER_SIZE, placed, noise=1.0)
    return views


@pytest.fixture(scope="module")
def views() -> dict[str, np.ndarray]:
    return rendered_views()


def measured(rig: Rig, views: dict[str, np.ndarray]) -> list:
    """Every camera's pair offsets and body observation of its frame."""
    camera = CameraModel(PAPER_K, PAPER_DIST, *PAPER_SIZE)
    detector = MarkerDetector(rig.dictionary, camera=camera)
    out = []
    for name, image in views.items():
        detections = detector.detect(image).markers
        assert {d.id for d in detections} >= {1, 2} or {d.id for d in detections} >= {3, 4}, name
        poses = {d.id: estimate_pose(d, camera, rig.marker_size) for d in detections}
        out.append((name, frame_offsets(pair_geometries(rig), poses, name, 0.0),
                    observe_bodies(body_geometry(rig), poses, camera, name, 0.0, rig.marker_size)))
    return out


def test_offsets_of_turned_markers_are_right(views: dict[str, np.ndarray]) -> None:
    """Markers turned 90°, 37° and -90° (by rotation_deg, R and quaternion): pair offsets and both bodies' poses."""
    rig = turned_rig(stated=True)
    found = 0
    for name, offsets, observation in measured(rig, views):
        for o in offsets:
            normal = face_T(o.face)[:, 2]
            err = o.offset - OFFSET
            lateral = err - (err @ normal) * normal
            assert np.linalg.norm(lateral) < 0.03, (name, o.face, err)  # in the face's plane: well measured
            assert abs(err @ normal) < 0.15, (name, o.face, err)  # depth: loosely
            found += 1
        assert observation is not None and observation.jacket is not None and observation.topside is not None
        T_jacket_topside = np.linalg.inv(observation.jacket.T_camera_body) @ observation.topside.T_camera_body
        assert np.degrees(np.linalg.norm(cv_rotvec(T_jacket_topside[:3, :3]))) < 3.0  # the topside is level
        assert np.linalg.norm(T_jacket_topside[:3, 3] - OFFSET) < 0.15, name
    assert found >= 2


def test_unstated_turns_put_the_offsets_far_off(views: dict[str, np.ndarray]) -> None:
    """The same frames read with a rig that keeps its markers upright: the pair geometry no longer fits (the test is
    sensitive to the rotation it checks)."""
    rig = turned_rig(stated=False)
    for name, offsets, observation in measured(rig, views):
        errors = [np.linalg.norm(o.offset - OFFSET) for o in offsets]
        assert not errors or max(errors) > 0.3, (name, errors)
        if observation is not None and observation.jacket is not None and observation.topside is not None:
            T = np.linalg.inv(observation.jacket.T_camera_body) @ observation.topside.T_camera_body
            assert np.degrees(np.linalg.norm(cv_rotvec(T[:3, :3]))) > 20.0  # the topside would hang tilted


def test_the_filter_tracks_turned_markers(views: dict[str, np.ndarray]) -> None:
    """The fusion filter, fed the turned markers' corners for a second, places both cameras and the topside."""
    rig = turned_rig(stated=True)
    rig = Rig.model_validate({**rig.model_dump(exclude_none=True),
                              "cameras": [{"name": n, "calibration": "c.yaml", "source": "v.mp4", "mount": "fixed"}
                                          for n in CAMERA_EYES]})
    frames = measured(rig, views)
    kf = TopsideFilter(rig)
    for k in range(15):
        for i, (name, _, observation) in enumerate(frames):
            t = k / 15 + 0.01 * i
            o = type(observation)(t, name, observation.jacket, observation.topside, observation.corners, observation.K)
            kf.predict(t, [o])
            kf.update(o)
    (estimate,) = kf.cone_estimates()
    err = estimate.offset - OFFSET
    assert np.isfinite(estimate.offset).all() and np.abs(err).max() < 0.03, err


def test_paper_roles_follow_the_face_normal_not_the_turned_x_axis() -> None:
    """The paper's camera 1 (dx) is the face whose normal runs along y, however the marker on it is turned (here both
    jacket markers turned 90°, their x axes vertical, and the port pair listed first)."""
    data = rig_dict([])
    vertical_x = {"ahead": [[0, -1, 0], [0, 0, -1], [1, 0, 0]], "port": [[0, 0, 1], [0, -1, 0], [1, 0, 0]]}
    for m in data["markers"]:
        m["R"] = vertical_x[m["face"]]  # turned 90°: x straight up, exactly
    data["pairs"].reverse()
    for rig in (Rig.model_validate(data), turned_rig(stated=True), turned_rig(stated=False)):
        assert paper_roles(rig) == {("A", "ahead"): "x", ("A", "port"): "y"}


def cv_rotvec(R: np.ndarray) -> np.ndarray:
    """(3,) rotation vector of a rotation (3, 3)."""
    import cv2

    return cv2.Rodrigues(np.asarray(R, dtype=np.float64))[0].reshape(3)
