"""The markers' size against the rig's marker_size (tracking.scale): what fixes it, a wrong one named, and offsets no
set-down can have refused."""

from __future__ import annotations

import numpy as np
import pytest

from tests.tracking.test_fusion import ONE_CONE_EYES, K, one_cone_rig, one_cone_topside_T
from tracking.camera import CameraModel
from tracking.detection import MarkerDetection
from tracking.estimate import WITHHELD_BELOW, WITHHELD_SCALE
from tracking.estimator import FilterReport, fused_estimates
from tracking.offsets import body_geometry, observe_bodies
from tracking.pose import estimate_pose, marker_object_points
from tracking.rig import Rig
from tracking.scale import ScaleEvidence, below_cones, separation_sample


def sized(rig: Rig, marker_size: float, **camera: dict) -> Rig:
    """The rig with another marker_size (and changes to its cameras by name)."""
    data = rig.model_dump(exclude_none=True)
    data["marker_size"] = marker_size
    for cam in data["cameras"]:
        cam.update(camera.get(cam["name"], {}))
    return Rig.model_validate(data)


AHEAD_EYES = {"stern1": np.array([15.0, -45.0, 2.0]), "stern2": np.array([9.0, -44.0, 3.0])}  # both faces of cone A
# about 45° off their normals, 34 m away


def views(truth: Rig, stated: Rig, seconds: float = 3.0, eyes: dict | None = None) -> list:
    """Cameras (cone A's two stern cameras, or eyes) filming markers of truth's size, measured with stated's (corners
    with 0.1 px noise)."""
    from tests.synthetic import look_at

    rng = np.random.default_rng(1)
    camera = CameraModel(K, np.zeros(5), 920, 600, rms=0.0)  # exact: the corners are its own projections
    geometry = body_geometry(stated)
    out = []
    for k, (name, eye) in enumerate((eyes or ONE_CONE_EYES).items()):
        T_camera_jacket = np.linalg.inv(look_at(eye, np.array([14.0, -10.8, 0.0])))
        for t in np.arange(0.0, seconds, 1 / 15) + 0.011 * k:
            poses = {}
            for m in truth.markers:
                T = T_camera_jacket @ (one_cone_topside_T(t) if m.body == "topside" else np.eye(4)) @ m.T_body_marker
                pc = (T[:3, :3] @ marker_object_points(truth.marker_size).T).T + T[:3, 3]
                px = camera.project(pc) + rng.normal(0.0, 0.1, (4, 2))
                poses[m.id] = estimate_pose(MarkerDetection(m.id, px), camera, stated.marker_size)
            o = observe_bodies(geometry, poses, camera, name, float(t), stated.marker_size)
            if o is not None:
                out.append(o)
    return sorted(out, key=lambda o: o.time)


def test_two_markers_of_a_body_measure_their_size() -> None:
    """Two markers 2.9 m apart that a camera measures 1.5 times too far apart look 1.5× their stated size; markers
    under a metre apart, or one seen 70° off its normal, tell nothing."""
    T_i, T_j = np.eye(4), np.eye(4)
    T_i[:3, :3] = T_j[:3, :3] = np.diag([1.0, -1.0, -1.0])  # facing the camera
    T_i[:3, 3], T_j[:3, 3] = [0.0, 0.0, 30.0], [4.35, 0.0, 30.0]
    cov = np.eye(3) * 1e-4
    sample = separation_sample("cam", (1, 2), T_i, T_j, cov, cov, 2.9)
    assert sample is not None and sample.ratio == pytest.approx(2.9 / 4.35)
    assert separation_sample("cam", (1, 2), T_i, T_j, cov, cov, 0.8) is None
    T_j[:3, :3] = np.diag([1.0, -1.0, -1.0]) @ np.array([[np.cos(1.2), 0, np.sin(1.2)], [0, 1, 0],
                                                          [-np.sin(1.2), 0, np.cos(1.2)]])
    assert separation_sample("cam", (1, 2), T_i, T_j, cov, cov, 2.9) is None


@pytest.mark.parametrize("stated", [1.5, 0.7])
def test_a_wrong_marker_size_is_named_and_never_shown(stated: float) -> None:
    """Markers of 1 m in a rig that says otherwise, seen two at a time (both faces of cone A, 45° off their normals):
    the run names the ratio and shows no offset; the right size shows them."""
    truth = one_cone_rig()
    report = FilterReport()
    wrong = list(fused_estimates(sized(truth, stated), views(truth, sized(truth, stated), eyes=AHEAD_EYES),
                                 report=report))
    assert report.scale.fixed and report.scale.mismatch
    assert report.scale.ratio == pytest.approx(1.0 / stated, rel=0.02)
    assert f"{report.scale.ratio:.2f}× their stated size" in report.scale.message()  # the ratio named, as measured
    assert not any(np.isfinite(e.offset).any() for e in wrong)  # the cameras' corners do not fit the rig either:
    assert {e.withheld for e in wrong} <= {WITHHELD_SCALE}  # they are never placed, or their offsets are withheld
    right = FilterReport()
    shown = [e for e in fused_estimates(truth, views(truth, truth, eyes=AHEAD_EYES), report=right)
             if np.isfinite(e.offset).all()]
    assert right.scale.fixed and not right.scale.mismatch and shown


def test_a_surveyed_camera_names_a_wrong_marker_size() -> None:
    """One camera's surveyed position (5 cm) against its distance to a jacket marker: a rig saying 1.5 m for 1 m markers
    is named though no camera sees two markers of one body."""
    from tests.synthetic import look_at

    truth = one_cone_rig()
    far_face = {i for i, m in enumerate(truth.markers) if m.face == "starboard-ahead"}
    lone = Rig.model_validate({**truth.model_dump(exclude_none=True),
                               "markers": [m.model_dump(exclude_none=True) for i, m in enumerate(truth.markers)
                                           if i not in far_face]})
    eye = look_at(ONE_CONE_EYES["stern1"], np.array([14.0, -10.8, 0.0]))[:3, 3]
    stated = sized(lone, 1.5, stern1={"position": eye.tolist(), "position_sigma": 0.05})
    report = FilterReport()
    list(fused_estimates(stated, views(lone, stated), report=report))
    assert report.scale.mismatch and "surveyed position" in report.scale.message()
    assert report.scale.ratio == pytest.approx(1 / 1.5, rel=0.02)


def test_nothing_fixes_the_scale_and_the_topside_through_its_cones_is_refused() -> None:
    """One camera per face, one marker per body each (nothing fixes the scale): a rig saying 0.4 m for 1 m markers puts
    the topside through its cones, and those offsets are withheld as a rig error."""
    truth = one_cone_rig()
    only = {"port-ahead"}
    lone = Rig.model_validate({**truth.model_dump(exclude_none=True),
                               "markers": [m.model_dump(exclude_none=True) for m in truth.markers if m.face in only],
                               "cameras": [c.model_dump(exclude_none=True) for c in truth.cameras
                                           if c.name == "stern1"]})
    report = FilterReport()
    est = list(fused_estimates(sized(lone, 0.4), views(lone, sized(lone, 0.4)), report=report))
    assert not report.scale.fixed and "nothing fixes the scale" in report.scale.message()
    assert report.below[0] > 0 and report.below[1] < -0.3  # 0.4 (2 + 2) - 2 = -0.4 m
    assert any(e.withheld == WITHHELD_BELOW for e in est)
    assert not any(np.isfinite(e.offset).all() and e.offset[2] < -0.1 for e in est)


def test_the_evidence_pools_frames_as_the_views_renew() -> None:
    """Frames of one view 0.1 s apart count as a fifth of one each; the pooled ratio is the weighted mean."""
    from tracking.scale import ScaleSample

    evidence = ScaleEvidence()
    for k in range(5):
        evidence.add(ScaleSample(1.5, 0.01, "cam", "markers 1 and 2", 3.0, 2.0), 0.1 * k)
    assert evidence.information == pytest.approx((1 + 4 * 0.2) / 0.01**2)
    assert evidence.ratio == pytest.approx(1.5) and evidence.mismatch
    assert below_cones(-0.2, 0.02) and not below_cones(-0.05, 0.02) and not below_cones(0.5, 0.01)
