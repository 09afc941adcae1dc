"""Offsets (eq. 12–16) recovered from rendered frames with known poses."""

import numpy as np
import pytest

from tests.synthetic import (
    CAMERA_EYES,
    CONE_A,
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
from tracking.offsets import frame_offsets, pair_geometries, relative_pose
from tracking.pose import estimate_pose
from tracking.rig import Rig

DIST = np.array([-0.08, 0.03, 0.0, 0.0, 0.0])


def test_relative_pose_is_inverse_composition() -> None:
    rng = np.random.default_rng(1)
    import cv2

    Ts = []
    for _ in range(2):
        T = np.eye(4)
        T[:3, :3] = cv2.Rodrigues(rng.normal(size=3))[0]
        T[:3, 3] = rng.normal(size=3) * 10
        Ts.append(T)
    np.testing.assert_allclose(relative_pose(*Ts), np.linalg.inv(Ts[0]) @ Ts[1], atol=1e-12)


@pytest.mark.parametrize("offset", [[0.0, 0.0, 0.0], [0.35, -0.2, 0.6], [-1.2, 0.8, 2.5]])
def test_pair_offsets_from_rendered_frames(offset: list[float]) -> None:
    rig = Rig.model_validate(rig_dict([]))
    camera = CameraModel(PAPER_K, DIST, *PAPER_SIZE)
    detector = MarkerDetector(rig.dictionary)
    d = np.array(offset)
    for name, eye in CAMERA_EYES.items():
        T_jacket_cam = look_at(eye, CONE_A + np.array([0.0, 0.0, -0.6]))
        placed = []
        for mid, (body, face, c) in marker_centres().items():
            T = np.eye(4)
            T[:3, :3] = face_T(face)
            T[:3, 3] = c + (d if body == "topside" else 0.0)
            placed.append(PlacedMarker(mid, np.linalg.inv(T_jacket_cam) @ T, 1.0))
        image = render(PAPER_K, DIST, PAPER_SIZE, placed, noise=1.0)
        poses = {m.id: estimate_pose(m, camera, rig.marker_size) for m in detector.detect(image).markers}
        offsets = frame_offsets(pair_geometries(rig), poses, name, time=1.5)
        faces = {o.face for o in offsets}
        assert offsets and all(o.time == 1.5 and o.camera == name for o in offsets)
        for o in offsets:
            # the face's in-plane axes (lateral and up) are measured well; depth (its normal) loosely
            normal = face_T(o.face)[:, 2]
            err = o.offset - d
            lateral = err - (err @ normal) * normal
            assert np.linalg.norm(lateral) < 0.03, (name, o.face, err)
            assert abs(err @ normal) < 0.15, (name, o.face, err)
        assert faces  # each camera sees at least one full pair
