"""Random installations: a whole scenario drawn from one seed, from the ranges a real project would meet.

`random_scenario(seed)` draws, reproducibly per seed:

- the structure: leg spacing 16-36 m by 14-30 m, legs 1.5-2.5 m across, the deck 10-24 m wider than the legs, the
  crane vessel's stern 6-25 m beyond the deck's edge (and beyond the topside's start); markers 0.8-2.5 m below the
  leg tops and above the topside's leg bottoms;
- 1-4 cones with marker pairs (no more cones than cameras), one or two faces each (faces that look outward from the
  jacket; at most one pair more than cameras), ids drawn from the
  dictionary (DICT_6X6_250, sometimes DICT_5X5_100 or DICT_4X4_50); every marker mounted 0-2° off plumb about a
  horizontal axis, which the rig states (a surveyed R);
- 1-6 cameras, each placed for one pair (every pair gets one before any gets a second): on the vessel's stern
  (`stern`, riding the waves), on a platform (`fixed`, still; half of them with a surveyed position, 2-10 cm), or
  flying (`drone`, jitter by the wind). 12-50 m from the pair's jacket marker, 0-70° off its normal, a third of them
  within 5° (square-on views are common from a stern); 920×600, 1280×720 or 1920×1080, the lens zoomed so that the
  pair's travel fills 50-100 % of the picture; 10-25 frames a second. Each camera is drawn again until it sees both
  markers of its pair, unoccluded and inside its picture, at every sampled time of the run;
- the lift: an approach (a horizontal move of 0.3-5 m to above the cones), a set-down (aligned from 0.2-1 m off, then
  lowered), or a hold, at 0.5-3 m above mated, with the crane at 0.15-0.35 m/s, a pendulum of 30-80 m swinging up
  to 0.5 m, a twist of up to 0.5°, waves in two runs of five (Hs 0.5-2.5 m) and wind up to 30 knots; 20-30 s long;
- the weather: fog (up to 70 % of the contrast lost at 40 m), rain, sensor noise, shadows, a lens blur in half of
  them (σ 0.3-0.9 px), H.264 at CRF 16-20 (the field guide asks for well above 2 Mbit/s at 920×600).

The scenario is written as every other (`topside simulate random-SEED -o DIR`, or `topside simulate --random SEED`,
or a scenario file with `random: SEED` and overrides), with its truth; the tracker gets nothing else.
"""

from __future__ import annotations

import cv2
import numpy as np

from tracking.rig import FACE_NORMALS
from tracking.sim.builtins import aim_point
from tracking.sim.motion import camera_rest_pose
from tracking.sim.render import CameraRenderer, FrameState
from tracking.sim.scenario import (
    DEFAULT_DIST,
    CameraSpec,
    MotionSpec,
    PairSpec,
    Scenario,
    SeaSpec,
    WeatherSpec,
)
from tracking.sim.scene import CONE_SIGNS, CONES, Layout
from tracking.sim.transforms import apply, inv_T
from tracking.sim.truth import marker_corners
from tracking.sim.world import World

RANDOM_STREAM = 37  # seed stream of random installations
DISTANCE_M = (12.0, 50.0)  # camera to its pair's jacket marker
MAX_ANGLE_DEG = 70.0  # off the marker's normal
SQUARE_ON_DEG = 5.0  # a third of the cameras are placed within this of the normal
SQUARE_ON_SHARE = 1 / 3
MAX_TILT_DEG = 2.0  # markers mounted off plumb
SIZES = ((920, 600), (1280, 720), (1920, 1080))
SIZE_WEIGHTS = (0.4, 0.35, 0.25)
FPS = (10.0, 15.0, 15.0, 15.0, 20.0, 25.0)
KINDS = ("stern", "fixed", "drone")
KIND_WEIGHTS = (0.35, 0.2, 0.45)
CAMERA_COUNTS = (1, 2, 3, 4, 5, 6)
CAMERA_WEIGHTS = (0.1, 0.25, 0.25, 0.2, 0.1, 0.1)
CONE_COUNTS = (1, 2, 3, 4)
CONE_WEIGHTS = (0.25, 0.35, 0.2, 0.2)
DICTIONARIES = ("DICT_6X6_250", "DICT_5X5_100", "DICT_4X4_50")
DICTIONARY_WEIGHTS = (0.6, 0.2, 0.2)
VESSEL_HALF_BEAM_M = 50.0  # stern cameras sit within this of the vessel's centre line
STERN_CAMERA_Z = (-1.0, 18.0)  # m, jacket frame: on the deck (22 m above the sea, z = -3) to crane pedestals
FILL = (0.5, 1.0)  # share of the picture the pair's travel fills
PAIR_MARGIN_M = 1.2  # around the marker centres: half a plate, and some swing
PLACEMENT_TRIES = 60  # draws per camera before it takes another kind, then another pair
VISIBILITY_STEP_S = 2.5  # the run is sampled this often for each camera's view of its pair
IMAGE_MARGIN_PX = 4.0
FULLY_VISIBLE = 0.999  # of the black square unhidden at every sampled time: 0.99 let cones and legs hide a sliver of a
# jacket marker, which corrupts its corners (benchmarks/scenarios/partial-occlusion-*.yaml)
DURATION_S = (20.0, 30.0)


def _outward_faces(cone: str) -> list[str]:
    """Faces whose normal looks away from the jacket's centre (or along its side) at a cone's leg."""
    out = np.array(CONE_SIGNS[cone], dtype=float) / np.sqrt(2.0)
    return [f for f, n in FACE_NORMALS.items() if np.dot(n[:2], out) >= -1e-9]


def _tilt(rng: np.random.Generator) -> list[float]:
    """Rotation vector (degrees) of a marker mounted off plumb: 0-MAX_TILT_DEG about a random horizontal axis."""
    a, angle = rng.uniform(0, 2 * np.pi), rng.uniform(0, MAX_TILT_DEG)
    return [round(angle * np.cos(a), 4), round(angle * np.sin(a), 4), 0.0]


def _layout(rng: np.random.Generator, start_y: float) -> Layout:
    lx, ly = rng.uniform(16, 36), rng.uniform(14, 30)
    leg = rng.uniform(1.5, 2.5)
    deck = (lx + rng.uniform(10, 24), ly + rng.uniform(10, 20))
    stern_y = min(-deck[1] / 2, -deck[1] / 2 + start_y) - rng.uniform(6, 25)
    return Layout(leg_spacing_x=round(lx, 2), leg_spacing_y=round(ly, 2), jacket_leg_diameter=round(leg, 2),
                  topside_leg_diameter=round(leg, 2), deck_size=(round(deck[0], 2), round(deck[1], 2)),
                  stern_y=round(stern_y, 2), jacket_marker_z=round(-rng.uniform(0.8, 2.5), 2),
                  topside_marker_z=round(rng.uniform(0.8, 2.5), 2))


def _motion(rng: np.random.Generator) -> MotionSpec:
    hover = round(rng.uniform(0.5, 3.0), 2)
    kind = rng.choice(["approach", "setdown", "hold"], p=[0.45, 0.35, 0.2])
    a = rng.uniform(0, 2 * np.pi)
    far = rng.uniform(0.3, 5.0) if kind == "approach" else rng.uniform(0.2, 1.0)
    start = [round(far * np.cos(a), 2), round(far * np.sin(a), 2), hover]
    waypoints = {"approach": [start, [0.0, 0.0, hover]], "setdown": [start, [0.0, 0.0, hover], [0.0, 0.0, 0.0]],
                 "hold": [start]}[str(kind)]
    sea = None
    if rng.random() < 0.4 or kind == "hold":
        sea = SeaSpec(hs=round(rng.uniform(0.5, 2.5), 2), tp=round(rng.uniform(6, 11), 2),
                      heading=round(rng.uniform(0, 360), 1))
    return MotionSpec(waypoints=waypoints, hover=hover, speed=round(rng.uniform(0.15, 0.35), 3),
                      lower_speed=round(rng.uniform(0.03, 0.08), 3), ramp_time=round(rng.uniform(4, 10), 2),
                      dwell=round(rng.uniform(0, 4), 2), pendulum_length=round(rng.uniform(30, 80), 1),
                      initial_swing=round(rng.uniform(0, 0.5), 3), twist_amplitude=round(rng.uniform(0, 0.5), 3),
                      sea=sea, wind_knots=round(rng.uniform(0, 30), 1))


def _weather(rng: np.random.Generator) -> WeatherSpec:
    return WeatherSpec(fog=0.0 if rng.random() < 0.4 else round(rng.uniform(0.1, 0.7), 2),
                       rain=0.0 if rng.random() < 0.5 else round(rng.uniform(0.1, 0.5), 2),
                       noise=round(rng.uniform(0.5, 3.5), 2), light_variation=round(rng.uniform(0, 0.3), 2),
                       shadows=round(rng.uniform(0, 0.8), 2), sun_azimuth=round(rng.uniform(0, 360), 1),
                       sun_elevation=round(rng.uniform(10, 70), 1),
                       lens_blur=0.0 if rng.random() < 0.5 else round(rng.uniform(0.3, 0.9), 2),
                       crf=int(rng.integers(16, 21)))


def _pairs(rng: np.random.Generator, dictionary: str, cameras: int) -> list[PairSpec]:
    """Pairs at up to as many cones as there are cameras, at most one more pair than cameras."""
    cones = sorted(rng.choice(CONES, min(cameras, int(rng.choice(CONE_COUNTS, p=CONE_WEIGHTS))),
                              replace=False).tolist())
    sides = []
    for cone in cones:
        faces = _outward_faces(cone)
        two = rng.random() < 0.35 and len(sides) + len(cones) <= cameras
        sides += [(cone, f) for f in rng.choice(faces, 2 if two else 1, replace=False).tolist()]
    count = int(cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, dictionary)).bytesList.shape[0])
    ids = rng.choice(count, 2 * len(sides), replace=False).tolist()
    return [PairSpec(cone=c, face=f, jacket_id=ids[2 * k], topside_id=ids[2 * k + 1], jacket_tilt_deg=_tilt(rng),
                     topside_tilt_deg=_tilt(rng)) for k, (c, f) in enumerate(sides)]


def _direction(rng: np.random.Generator, normal: np.ndarray, angle: float, up: float) -> np.ndarray:
    """(3,) unit vector angle (rad) off a horizontal normal (3,), turned about the vertical, then raised by up (rad)."""
    side = rng.choice([-1.0, 1.0]) * angle
    c, s = np.cos(side), np.sin(side)
    h = np.array([c * normal[0] - s * normal[1], s * normal[0] + c * normal[1], 0.0])
    return np.cos(up) * h + np.array([0.0, 0.0, np.sin(up)])


def _off_normal(rng: np.random.Generator) -> float:
    limit = SQUARE_ON_DEG if rng.random() < SQUARE_ON_SHARE else MAX_ANGLE_DEG
    return float(np.radians(rng.uniform(0, limit)))


def _position(rng: np.random.Generator, kind: str, layout: Layout, jacket: np.ndarray, normal: np.ndarray
              ) -> np.ndarray | None:
    """Where a camera of a kind sits to watch a pair whose jacket marker is at jacket (3,) facing normal (3,)."""
    if kind == "stern":
        d = _direction(rng, normal, _off_normal(rng), 0.0)
        if d[1] >= -1e-6:
            return None
        along = (layout.stern_y - jacket[1]) / d[1]
        z = rng.uniform(*STERN_CAMERA_Z)
        pos = np.array([jacket[0] + along * d[0], layout.stern_y, z])
        if abs(pos[0]) > VESSEL_HALF_BEAM_M:
            return None
    else:
        up = np.radians(rng.uniform(-10, 30) if kind == "drone" else rng.uniform(-20, 20))
        pos = jacket + rng.uniform(*DISTANCE_M) * _direction(rng, normal, _off_normal(rng), up)
    line = pos - jacket
    distance = float(np.linalg.norm(line))
    angle = float(np.degrees(np.arccos(np.clip(line @ normal / distance, -1, 1))))
    if not DISTANCE_M[0] <= distance <= DISTANCE_M[1] or angle > MAX_ANGLE_DEG:
        return None
    if pos[2] < layout.sea_z + 3.0:
        return None
    half = np.array(layout.deck_size) / 2 + 2.0
    if pos[2] > layout.topside_leg_length - 2.0 and (np.abs(pos[:2]) < half + 5.0).all():
        return None  # inside the topside's deck and its travel
    legs = np.array([layout.leg_spacing_x, layout.leg_spacing_y]) / 2 + 2.0
    if (np.abs(pos[:2]) < legs).all():
        return None  # among the jacket's legs and braces
    return pos


def _camera(rng: np.random.Generator, name: str, kind: str, pos: np.ndarray, aim: np.ndarray,
            points: np.ndarray, sea: bool) -> CameraSpec:
    """A camera at pos looking at aim (3,), its lens zoomed so that the pair's travel (points (N, 3)) fills a drawn
    share of the picture."""
    width, height = SIZES[int(rng.choice(len(SIZES), p=SIZE_WEIGHTS))]
    look = aim + rng.normal(0.0, 0.3, 3)
    roll = float(rng.uniform(-2, 2))
    T = camera_rest_pose(CameraSpec(name=name, kind=kind, position=pos.tolist(), look_at=look.tolist(), roll=roll))
    P = apply(inv_T(T), points)
    spread = max(float(np.abs(P[:, 0] / P[:, 2]).max()) / (width / 2), float(np.abs(P[:, 1] / P[:, 2]).max())
                 / (height / 2))
    f = float(np.clip(rng.uniform(*FILL) / spread, 0.45 * width, 6.0 * width))
    fov = 2 * np.degrees(np.arctan(width / 2 / f))
    dist = (np.array(DEFAULT_DIST) * rng.uniform(0, 1.5) * min(1.0, (fov / 40.0) ** 2)).round(4).tolist()
    K = [round(f, 2), round(f * rng.uniform(0.998, 1.002), 2), round(width / 2 + rng.uniform(-0.02, 0.02) * width, 2),
         round(height / 2 + rng.uniform(-0.02, 0.02) * height, 2)]
    surveyed = (kind == "fixed" and rng.random() < 0.5) or (kind == "stern" and not sea and rng.random() < 0.2)
    return CameraSpec(name=name, kind=kind, position=pos.round(3).tolist(), look_at=look.round(3).tolist(),
                      roll=round(roll, 3), width=width, height=height, K=K, dist=dist,
                      fps=float(rng.choice(FPS)), exposure=1 / 200 if kind == "drone" else round(
                          1 / rng.uniform(100, 500), 5), drop_rate=0.002 if kind == "drone" else 0.0,
                      position_sigma=round(rng.uniform(0.02, 0.1), 3) if surveyed else None)


def _sees(world: World, cam: CameraSpec, pair: PairSpec, times: np.ndarray) -> bool:
    """Whether a camera at rest sees both markers of a pair, whole and in its picture, at every time (N,)."""
    quiet = world.scenario.weather.model_copy(update={"noise": 0.0})
    renderer = CameraRenderer(cam, world.bodies, world.textures, quiet, world.light, world.layout.sea_z)
    T_cj = inv_T(camera_rest_pose(cam))
    for t in times:
        poses = world.body_poses(float(t))
        state = FrameState(float(t), inv_T(T_cj), poses, 1.0)
        seen = renderer.visibility(state)
        for body, mid in (("jacket", pair.jacket_id), ("topside", pair.topside_id)):
            P = apply(T_cj @ poses[body] @ world.T_body_marker[mid], marker_corners(world.scenario.marker_size))
            if (P[:, 2] <= 1.0).any() or seen.get(mid, 0.0) < FULLY_VISIBLE:
                return False
            px = cv2.projectPoints(P, np.zeros(3), np.zeros(3), renderer.K, renderer.dist)[0].reshape(-1, 2)
            if px.min() < IMAGE_MARGIN_PX or (px[:, 0] > cam.width - 1 - IMAGE_MARGIN_PX).any() or \
                    (px[:, 1] > cam.height - 1 - IMAGE_MARGIN_PX).any():
                return False
    return True


def _travel(scenario: Scenario, pair: PairSpec) -> np.ndarray:
    """(N, 3) points a camera of a pair must hold in its picture: both markers over the moves, with a margin."""
    layout, motion = scenario.layout, scenario.motion
    jacket = layout.marker_center(pair.cone, pair.face, "jacket")
    top = layout.marker_center(pair.cone, pair.face, "topside")
    centres = [jacket] + [top + np.array([w[0], w[1], w[2] if len(w) == 3 else motion.hover])
                          for w in motion.waypoints]
    box = np.array([[dx, dy, dz] for dx in (-1, 1) for dy in (-1, 1) for dz in (-1, 1)]) * PAIR_MARGIN_M
    return np.array([c + b for c in centres for b in box])


def random_scenario(seed: int, duration: float | None = None) -> Scenario:
    """A whole installation drawn from seed (see the module); its duration drawn too unless given."""
    rng = np.random.default_rng([seed, RANDOM_STREAM])
    motion = _motion(rng)
    start_y = min(0.0, min(w[1] for w in motion.waypoints))
    layout = _layout(rng, start_y)
    dictionary = str(rng.choice(DICTIONARIES, p=DICTIONARY_WEIGHTS))
    n_cameras = int(rng.choice(CAMERA_COUNTS, p=CAMERA_WEIGHTS))
    pairs = _pairs(rng, dictionary, n_cameras)
    weather = _weather(rng)
    length = round(float(rng.uniform(*DURATION_S)), 1) if duration is None else duration
    placeholder = CameraSpec(name="placeholder", kind="fixed", position=[0.0, -60.0, 5.0], look_at=[0.0, 0.0, 0.0])
    draft = Scenario(name=f"random-{seed}", seed=seed, duration=length, dictionary=dictionary, layout=layout,
                     pairs=pairs, cameras=[placeholder], motion=motion, weather=weather)
    world = World(draft, length, seed)
    times = np.unique(np.r_[np.arange(0.0, length, VISIBILITY_STEP_S), length])
    cameras: list[CameraSpec] = []
    for k in range(n_cameras):
        order = [pairs[k]] if k < len(pairs) else []
        order += [pairs[i] for i in rng.permutation(len(pairs))]
        kinds = [str(rng.choice(KINDS, p=KIND_WEIGHTS))]
        kinds += [x for x in ("drone", "fixed", "stern") if x not in kinds]
        cam = None
        for pair in order:
            jacket = layout.marker_center(pair.cone, pair.face, "jacket")
            normal = np.array(FACE_NORMALS[pair.face])
            aim = aim_point(layout, pair.cone, pair.face, motion.waypoints, motion.hover)
            for kind in kinds:
                for _ in range(PLACEMENT_TRIES):
                    pos = _position(rng, kind, layout, jacket, normal)
                    if pos is None:
                        continue
                    trial = _camera(rng, f"{kind}{k + 1}", kind, pos, aim, _travel(draft, pair), motion.sea is not None)
                    if _sees(world, trial, pair, times):
                        cam = trial.model_copy(update={"watch": f"{pair.cone}/{pair.face}"})
                        break
                if cam is not None:
                    break
            if cam is not None:
                break
        if cam is not None:
            cameras.append(cam)
    if not cameras:  # nothing could see anything: another draw
        return random_scenario(seed + 1_000_003, duration)
    description = (f"Random installation {seed}: {len(pairs)} pair(s) at cones "
                   f"{', '.join(sorted({p.cone for p in pairs}))}; cameras "
                   f"{', '.join(c.name for c in cameras)}; {len(motion.waypoints)} waypoint(s).")
    return draft.model_copy(update={"cameras": cameras, "description": description})
