"""The simulated world of a scenario: bodies, plates, textures, motion, light, and the rig it implies."""

from __future__ import annotations

import numpy as np

from tracking.rig import CameraEntry, Marker, Pair, Rig, SurveySigma
from tracking.sim.motion import Motion
from tracking.sim.render import FrameState, Segment
from tracking.sim.scenario import CameraSpec, Scenario
from tracking.sim.scene import (
    CONE_SIGNS,
    Body,
    attach_plates,
    jacket_body,
    marker_plate,
    topside_body,
    vessel_body,
)
from tracking.sim.textures import Texture, marker_texture
from tracking.sim.transforms import apply, make_T, rotvec_to_R
from tracking.sim.weather import Light

SLING_ALBEDO = (0.15, 0.15, 0.15)
BOOM_ALBEDO = (0.25, 0.45, 0.80)
SLING_WIDTH = 0.25  # m
BOOM_WIDTH = 3.0  # m
CRANE_PIVOTS_VESSEL = ((-34.0, 86.0, 42.0), (34.0, 86.0, 42.0))  # vessel frame, m
LIFT_POINTS = ((-14.0, -10.0), (14.0, -10.0), (14.0, 10.0), (-14.0, 10.0))  # topside frame, on the module roof
BOOM_TIP_ABOVE_HOOK = 12.0  # m
SURVEY_STREAM = 29  # seed stream of the markers' survey errors (one generator per marker id)


def survey_error(scenario: Scenario, seed: int, marker_id: int) -> tuple[np.ndarray, np.ndarray]:
    """How far one marker truly sits from its surveyed pose: displacement (3,) m and rotation vector (3,) rad, both in
    its body's frame (zero without scenario.survey_error)."""
    spec = scenario.survey_error
    if spec.position_m == 0.0 and spec.tilt_deg == 0.0:
        return np.zeros(3), np.zeros(3)
    rng = np.random.default_rng([seed, SURVEY_STREAM, marker_id])
    return rng.normal(0.0, spec.position_m, 3), rng.normal(0.0, np.radians(spec.tilt_deg), 3)


class World:
    """Bodies, textures and motion of one scenario run."""

    def __init__(self, scenario: Scenario, duration: float, seed: int) -> None:
        self.scenario = scenario
        self.layout = scenario.layout
        self.duration = duration
        self.seed = seed
        self.jacket, self.topside, self.vessel = (jacket_body(self.layout), topside_body(self.layout),
                                                  vessel_body(self.layout))
        self.textures: dict[str, Texture] = {}
        self.T_body_marker: dict[int, np.ndarray] = {}  # (4, 4) where each marker truly is in its body's frame
        self.T_surveyed: dict[int, np.ndarray] = {}  # (4, 4) where the survey puts each marker (its stated tilt)
        for pair in scenario.pairs:
            for body, mid, tilt in ((self.jacket, pair.jacket_id, pair.jacket_tilt_deg),
                                    (self.topside, pair.topside_id, pair.topside_tilt_deg)):
                plate = marker_plate(self.layout, mid, body.name, pair.cone, pair.face, scenario.marker_size)
                T = plate.T_body_plate
                T = make_T(rotvec_to_R(np.radians(tilt)) @ T[:3, :3], T[:3, 3])  # mounted off plumb, surveyed
                self.T_surveyed[mid] = T
                moved, turned = survey_error(scenario, seed, mid)
                plate.T_body_plate = make_T(rotvec_to_R(turned) @ T[:3, :3], T[:3, 3] + moved)
                self.T_body_marker[mid] = plate.T_body_plate
                attach_plates(body, [plate])
                self.textures[plate.key] = marker_texture(scenario.dictionary, mid, scenario.marker_size,
                                                          self.layout.plate_size)
        self.bodies: list[Body] = [self.vessel, self.jacket, self.topside]
        self.motion = Motion(scenario, duration, seed)
        self.light = Light(scenario.weather, seed, list(self.textures))
        self.module_top = self.layout.topside_leg_length + 20.0

    def body_poses(self, t: float) -> dict[str, np.ndarray]:
        """T_jacket_body of jacket, topside and vessel at time t."""
        return {"jacket": np.eye(4), "topside": self.motion.topside(t), "vessel": self.motion.vessel(t)}

    def segments(self, t: float, poses: dict[str, np.ndarray]) -> list[Segment]:
        """Slings from the lift points to the hook and crane booms to above the hook."""
        hook = self.motion.hook_at(t)
        segs = []
        lifts = apply(poses["topside"], np.array([[x, y, self.module_top] for x, y in LIFT_POINTS]))
        for p in lifts:
            segs.append(Segment(p, hook, SLING_WIDTH, SLING_ALBEDO))
        for pivot in apply(poses["vessel"], np.array(CRANE_PIVOTS_VESSEL)):
            tip = hook + np.array([np.sign(pivot[0]) * 6.0, 0.0, BOOM_TIP_ABOVE_HOOK])
            segs.append(Segment(pivot, tip, BOOM_WIDTH, BOOM_ALBEDO))
        return segs

    def frame_state(self, cam: CameraSpec, t: float, seed: int) -> FrameState:
        """Poses, light and blur of one camera's frame captured at time t (mid-exposure)."""
        poses = self.body_poses(t)
        T_jc = self.motion.camera(cam.name, t)
        return FrameState(time=t, T_jacket_camera=T_jc, T_jacket_body=poses, light=self.light.level(t),
                          segments=self.segments(t, poses), blur_px=self.blur(cam, t), seed=seed)

    def blur(self, cam: CameraSpec, t: float) -> tuple[float, float]:
        """Mean image motion (px) of the watched markers during the exposure."""
        if not self.scenario.weather.motion_blur:
            return (0.0, 0.0)
        h = cam.exposure / 2
        pts = self.marker_centres()
        K = np.array([[cam.K[0], 0, cam.K[2]], [0, cam.K[1], cam.K[3]], [0, 0, 1.0]])
        Pc = []
        for tt in (t - h, t + h):
            T_cj = np.linalg.inv(self.motion.camera(cam.name, tt))
            Ttop = self.motion.topside(tt)
            P = np.array([apply(Ttop if body == "topside" else np.eye(4), c[None])[0] for body, c in pts])
            Pc.append(apply(T_cj, P))
        ahead = (Pc[0][:, 2] > 1.0) & (Pc[1][:, 2] > 1.0)  # the centres in front of the camera all through the exposure
        if not ahead.any():
            return (0.0, 0.0)
        uv = []
        for P in Pc:
            q = P[ahead] @ K.T
            uv.append(q[:, :2] / q[:, 2:3])
        d = (uv[1] - uv[0]).mean(axis=0)
        return (float(d[0]), float(d[1]))

    def marker_centres(self) -> list[tuple[str, np.ndarray]]:
        """(body, centre in body frame) of every marker."""
        return [(m.body, np.array(m.center)) for m in self.rig_markers()]

    def rig_markers(self) -> list[Marker]:
        """Markers as the rig file lists them."""
        out = []
        for p in self.scenario.pairs:
            for body, mid, tilt in (("jacket", p.jacket_id, p.jacket_tilt_deg),
                                    ("topside", p.topside_id, p.topside_tilt_deg)):
                c = self.layout.marker_center(p.cone, p.face, body)
                R = {"R": self.T_surveyed[mid][:3, :3].round(9).tolist()} if any(tilt) else {}  # off plumb, surveyed
                out.append(Marker(id=mid, body=body, cone=p.cone, face=p.face, center=c.round(6).tolist(), **R))
        return out

    def true_markers(self) -> list[Marker]:
        """Markers where they truly are (their survey errors applied), as a rig would list them: R_body_marker."""
        out = []
        for m in self.rig_markers():
            T = self.T_body_marker[m.id]
            out.append(Marker(id=m.id, body=m.body, cone=m.cone, face=m.face, center=T[:3, 3].round(6).tolist(),
                              R=T[:3, :3].round(9).tolist()))
        return out

    def rig(self, cameras: list[CameraEntry], true: bool = False) -> Rig:
        """The rig file the tracker gets: cones, markers, pairs with mated offsets, cameras, and the survey's stated σ
        (the scenario's survey_error); true: the markers where they truly are (a perfect survey), benchmarks only."""
        markers = self.true_markers() if true else self.rig_markers()
        by_id = {m.id: m for m in markers}
        pairs = [Pair(cone=p.cone, face=p.face, jacket=p.jacket_id, topside=p.topside_id,
                      mated=(np.array(by_id[p.topside_id].center) - np.array(by_id[p.jacket_id].center))
                      .round(6).tolist()) for p in self.scenario.pairs]
        cones = sorted(CONE_SIGNS)  # every cone tip, as a user would survey them: the tracker reports them all
        spec = self.scenario.survey_error
        stated = None if true or (spec.position_m == 0 and spec.tilt_deg == 0) else SurveySigma(**spec.model_dump())
        return Rig(name=self.scenario.name, dictionary=self.scenario.dictionary,
                   marker_size=self.scenario.marker_size,
                   cones={c: self.layout.cone_tip(c).round(6).tolist() for c in cones},
                   markers=markers, pairs=pairs, cameras=cameras, survey_sigma=stated)
