"""Offsets (eq. 12–16) recovered from rendered frames with known poses."""

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
from tracking.offsets import PairGeometry, frame_offsets, offset_jacobian, pair_geometries, relative_pose
from tracking.pose import estimate_pose
from tracking.rig import Rig


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


def test_offset_jacobian_matches_finite_differences() -> None:
    import cv2

    rng = np.random.default_rng(7)
    T_W_S_mated = np.eye(4)
    T_W_S_mated[:3, 3] = [0.0, 3.0, 0.0]
    geometry = PairGeometry(None, T_W_S_mated, cv2.Rodrigues(rng.normal(size=3))[0])  # type: ignore[arg-type]

    def offset(params: np.ndarray) -> np.ndarray:
        """The offset from (rvec_W, tvec_W, rvec_S, tvec_S), the way pair_offset computes it."""
        T_cw, T_cs = np.eye(4), np.eye(4)
        T_cw[:3, :3], T_cw[:3, 3] = cv2.Rodrigues(params[0:3])[0], params[3:6]
        T_cs[:3, :3], T_cs[:3, 3] = cv2.Rodrigues(params[6:9])[0], params[9:12]
        return geometry.R_jacket_W @ (relative_pose(T_cw, T_cs)[:3, 3] - T_W_S_mated[:3, 3])

    for _ in range(5):
        params = np.concatenate([rng.normal(size=3), rng.normal(size=3) * 10, rng.normal(size=3),
                                 rng.normal(size=3) * 10])
        numeric = np.stack([(offset(params + h) - offset(params - h)) / 2e-6 for h in np.eye(12) * 1e-6], axis=1)
        T_cw, T_cs = np.eye(4), np.eye(4)
        T_cw[:3, :3], T_cw[:3, 3] = cv2.Rodrigues(params[0:3])[0], params[3:6]
        T_cs[:3, :3], T_cs[:3, 3] = cv2.Rodrigues(params[6:9])[0], params[9:12]
        np.testing.assert_allclose(offset_jacobian(geometry, T_cw, T_cs), numeric, atol=1e-6)


@pytest.mark.parametrize("offset", [[0.0, 0.0, 0.0], [0.35, -0.2, 0.6], [-1.2, 0.8, 2.5]])
def test_pair_offsets_from_rendered_frames(offset: list[float]) -> None:
    rig = Rig.model_validate(rig_dict([]))
    camera = CameraModel(PAPER_K, PAPER_DIST, *PAPER_SIZE)
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
        image = render(PAPER_K, PAPER_DIST, PAPER_SIZE, placed, noise=1.0)
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
