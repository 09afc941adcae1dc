"""Logging functions read back through rerun's own API: the topside's pose from the fused cone offsets."""

from pathlib import Path

import cv2
import numpy as np
import rerun as rr

from tracking.estimator import point_offset_matrix
from viewer.readback import chunks_by_entity, component_rows
from viewer.recording import log_topside_poses, topside_pose

CONES = {"A": np.array([0.0, 0.0, 20.0]), "B": np.array([20.0, 0.0, 20.0]), "C": np.array([20.0, 20.0, 20.0]),
         "D": np.array([0.0, 20.0, 20.0])}


def offsets_of(t: np.ndarray, omega: np.ndarray, cones: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Each cone's offset under translation t and small rotation ω, the fused filter's model."""
    return {c: point_offset_matrix(r)[:, :6] @ np.concatenate([t, omega]) for c, r in cones.items()}


def test_topside_pose_gives_back_translation_and_rotation() -> None:
    rng = np.random.default_rng(3)
    for _ in range(5):
        t, omega = rng.normal(size=3) * 0.5, rng.normal(size=3) * 2e-3
        T = topside_pose(CONES, offsets_of(t, omega, {c: CONES[c] for c in "ABC"}))  # three cones suffice
        np.testing.assert_allclose(T[:3, 3], t, atol=1e-9)
        np.testing.assert_allclose(cv2.Rodrigues(T[:3, :3])[0].reshape(3), omega, atol=1e-9)
        for c, r in CONES.items():  # every cone, seen or not, lands where its offset puts it (to second order)
            np.testing.assert_allclose(T[:3, :3] @ r + T[:3, 3], r + offsets_of(t, omega, CONES)[c], atol=1e-3)


def test_too_few_cones_for_a_rotation_give_the_mean_offset() -> None:
    line = {"A": CONES["A"], "B": CONES["B"], "E": np.array([40.0, 0.0, 20.0])}  # three cones in a line
    for cones in ({c: CONES[c] for c in "AB"}, line):
        offsets = {c: np.array([0.1, -0.2, 0.3]) + 0.01 * k for k, c in enumerate(cones)}
        T = topside_pose(cones, offsets)
        np.testing.assert_allclose(T[:3, :3], np.eye(3))
        np.testing.assert_allclose(T[:3, 3], np.mean(list(offsets.values()), axis=0))


def test_topside_poses_read_back(tmp_path: Path) -> None:
    rr.set_strict_mode(True)
    rec = rr.RecordingStream("topside")
    rec.set_sinks(rr.FileSink(tmp_path / "poses.rrd"))
    Ts = np.array([topside_pose(CONES, offsets_of(np.array([0.3, 0.1, 2.0]) * k, np.array([0.0, 0.0, 4e-3]) * k,
                                                   CONES)) for k in (1, 2)])
    log_topside_poses(rec, np.array([10.0, 10.5]), Ts)
    rec.flush()
    rec.disconnect()
    chunks = chunks_by_entity(tmp_path / "poses.rrd")["/world/topside"]
    _, translations = component_rows(chunks, "Transform3D:translation")
    _, quaternions = component_rows(chunks, "Transform3D:quaternion")
    np.testing.assert_allclose(np.array(translations).reshape(-1, 3), Ts[:, :3, 3], atol=1e-6)
    yaw = [2 * np.arctan2(q[2], q[3]) for q in np.array(quaternions).reshape(-1, 4)]  # x y z w, about z only
    np.testing.assert_allclose(yaw, [4e-3, 8e-3], atol=1e-6)
