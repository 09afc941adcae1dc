"""Built-in scenarios: the paper's procedures 1-7 (Tables I and II) in its two camera configurations.

Configuration 1 (Fig. 9): pairs on two perpendicular faces at 45 deg to the vessel on cones A and B,
four stern cameras (one per pair), and one drone on a pair of rear cone C. Configuration 2
(Fig. 10): pairs on cones A and D; A is filmed by a stern camera and a drone, D by two drones.
`config1-cone-a` keeps only cone A's pairs and their stern cameras (not in the paper).

`random-SEED` draws a whole installation from a seed (tracking.sim.installations).

Name suffixes: `-weather` adds the paper's fog 50 % and rain 30 %; `-clear` switches off fog, rain,
noise, shadows, light changes and motion blur (for exact tests); `-realities` gives every camera a clock off by up
to ±0.5 s and every marker a survey error of 20 mm and 1° (σ), which the rig does not know. Suffixes combine:
`config2-setdown-realities-weather`.
"""

from __future__ import annotations

import re
from collections.abc import Callable

import numpy as np

from tracking.errors import InputError
from tracking.rig import FACE_NORMALS
from tracking.sim.scenario import (
    CalibrationSpec,
    CameraSpec,
    MotionSpec,
    PairSpec,
    Scenario,
    SeaSpec,
    SurveyErrorSpec,
    WeatherSpec,
)
from tracking.sim.scene import Layout

STERN_CAMERA_Z = 2.0  # m, jacket frame: 27 m above the sea, on the stern crane pedestals
DRONE_DISTANCE = 15.0  # m from the middle of the watched pair's travel
DRONE_RISE = 1.0  # m above the middle of the pair's travel
DRONE_REACH = 8.0  # m: a drone frames the last this-many metres of a longer move (20 m do not fit)
DRONE_EXPOSURE = 1 / 200
DRONE_DROP_RATE = 0.002
PAPER_WEATHER = {"fog": 0.5, "rain": 0.3}
WAVE_HOLD = 90.0  # s, procedures 3 and 4
STORM_WIND_KNOTS = 20.0

PROCEDURES: dict[str, tuple[int, list[list[float]]]] = {
    "procedure1": (1, [[0, -20], [0, 0]]),
    "procedure2": (1, [[0, 0], [10, 0]]),
    "procedure3": (1, [[0, 0]]),
    "procedure4": (1, [[0, 0]]),
    "procedure5": (2, [[0, -5], [0, 0]]),
    "procedure6": (2, [[0, 0], [5, 0], [0, 0]]),
    "procedure7": (2, [[0, 0], [0, -3], [3, -3], [3, 0], [0, 0]]),
    "setdown": (0, [[0.5, -0.5, 2.0], [0, 0, 2.0], [0, 0, 0]]),
}

CONFIG1_PAIRS = [("A", "port-ahead"), ("A", "starboard-ahead"), ("B", "port-ahead"), ("B", "starboard-ahead"),
                 ("C", "starboard-astern")]
CONFIG1_STERN_X = {("A", "port-ahead"): 34.0, ("A", "starboard-ahead"): -10.0,
                   ("B", "port-ahead"): 10.0, ("B", "starboard-ahead"): -34.0}
STERN_FOLLOW = 0.4  # stern cameras sit this fraction of a port move further to port (procedure 2: 4 m)
CONFIG2_PAIRS = [("A", "ahead"), ("A", "port"), ("D", "port"), ("D", "astern")]


def pair_points(layout: Layout, cone: str, face: str, waypoints: list[list[float]], hover: float) -> np.ndarray:
    """(n, 3) jacket marker centre and topside marker centres at every waypoint, jacket frame."""
    pts = [layout.marker_center(cone, face, "jacket")]
    top = layout.marker_center(cone, face, "topside")
    for w in waypoints:
        pts.append(top + np.array([w[0], w[1], w[2] if len(w) == 3 else hover]))
    return np.array(pts)


def aim_point(layout: Layout, cone: str, face: str, waypoints: list[list[float]], hover: float,
              reach: float = np.inf) -> np.ndarray:
    """Middle of the box spanned by a pair over the procedure (offsets clipped to reach m): where its camera looks."""
    clipped = []
    for w in waypoints:
        xy = np.array(w[:2], float)
        n = np.linalg.norm(xy)
        clipped.append([*(xy * min(1.0, reach / n) if n > 0 else xy), *w[2:]])
    pts = pair_points(layout, cone, face, clipped, hover)
    return (pts.min(axis=0) + pts.max(axis=0)) / 2


def _drone(name: str, layout: Layout, cone: str, face: str, motion: MotionSpec) -> CameraSpec:
    aim = aim_point(layout, cone, face, motion.waypoints, motion.hover, DRONE_REACH)
    n = np.array(FACE_NORMALS[face])
    pos = aim + DRONE_DISTANCE * n + np.array([0, 0, DRONE_RISE])
    return CameraSpec(name=name, kind="drone", position=pos.round(3).tolist(), look_at=aim.round(3).tolist(),
                      watch=f"{cone}/{face}", exposure=DRONE_EXPOSURE, drop_rate=DRONE_DROP_RATE)


def _stern(name: str, layout: Layout, cone: str, face: str, x: float, motion: MotionSpec) -> CameraSpec:
    aim = aim_point(layout, cone, face, motion.waypoints, motion.hover)
    return CameraSpec(name=name, kind="stern", position=[x, layout.stern_y, STERN_CAMERA_Z],
                      look_at=aim.round(3).tolist(), watch=f"{cone}/{face}")


def configuration(number: int, motion: MotionSpec, layout: Layout) -> tuple[list[PairSpec], list[CameraSpec]]:
    """Pairs and cameras of the paper's configuration 1 or 2."""
    if number == 1:
        pairs = [PairSpec(cone=c, face=f, jacket_id=2 * i, topside_id=2 * i + 1)
                 for i, (c, f) in enumerate(CONFIG1_PAIRS)]
        shift = STERN_FOLLOW * max(w[0] for w in motion.waypoints)
        cams = [_stern(f"stern{i + 1}", layout, c, f, CONFIG1_STERN_X[(c, f)] + shift, motion)
                for i, (c, f) in enumerate(CONFIG1_PAIRS[:4])]
        cams.append(_drone("drone_C", layout, "C", "starboard-astern", motion))
        return pairs, cams
    pairs = [PairSpec(cone=c, face=f, jacket_id=2 * i, topside_id=2 * i + 1) for i, (c, f) in enumerate(CONFIG2_PAIRS)]
    a_x = float(layout.marker_center("A", "ahead", "jacket")[0])
    cams = [_stern("stern_A", layout, "A", "ahead", a_x, motion),
            _drone("drone_A", layout, "A", "port", motion),
            _drone("drone_D1", layout, "D", "port", motion),
            _drone("drone_D2", layout, "D", "astern", motion)]
    return pairs, cams


def procedure_scenario(config: int, procedure: str) -> Scenario:
    """Configuration 1 or 2 running one of the paper's procedures (or the set-down)."""
    _, waypoints = PROCEDURES[procedure]
    number = int(procedure.removeprefix("procedure")) if procedure.startswith("procedure") else 0
    layout = Layout()
    motion_kw: dict = {"waypoints": waypoints}
    weather = WeatherSpec()
    if procedure in ("procedure3", "procedure4"):
        motion_kw.update(sea=SeaSpec(), hold=WAVE_HOLD, wind_knots=STORM_WIND_KNOTS)
        weather = WeatherSpec(**PAPER_WEATHER)
    motion = MotionSpec(**motion_kw)
    pairs, cams = configuration(config, motion, layout)
    desc = {
        "procedure1": "Start 20 m ahead, move 20 m astern to the final position (paper Table I).",
        "procedure2": "Start above the jacket, move 10 m to port (paper Table I).",
        "procedure3": "Hold above the jacket in a JONSWAP sea (1 m, 8 s, 135 deg, s=4), fog 50 %, rain 30 %.",
        "procedure4": "As procedure 3 with another wave realisation (paper Table I).",
        "procedure5": "Start 5 m ahead, move 5 m astern to the final position (paper Table II).",
        "procedure6": "Start above, 5 m to port, 5 m back to starboard (paper Table II).",
        "procedure7": "Start above, 3 m ahead, 3 m port, 3 m astern, 3 m starboard (paper Table II).",
        "setdown": "Align from 0.7 m off and lower 2 m onto the cones (not in the paper).",
    }[procedure]
    seed = {"procedure4": 44}.get(procedure, number or 8 + config)
    return Scenario(name=f"config{config}-{procedure}", description=desc, seed=seed, layout=layout,
                    pairs=pairs, cameras=cams, motion=motion, weather=weather)


def one_cone_scenario() -> Scenario:
    """Configuration 1's procedure 2 with markers at cone A only (its two faces towards the vessel) and the two stern
    cameras watching them: every other cone's offset rests on the topside's rotation from markers 1.6 m apart."""
    base = procedure_scenario(1, "procedure2")
    pairs = [p for p in base.pairs if p.cone == "A"]
    cams = [c for c in base.cameras if c.watch in {f"A/{p.face}" for p in pairs}]
    return base.model_copy(update={"name": "config1-cone-a", "pairs": pairs, "cameras": cams,
                                   "description": "Procedure 2 with markers at cone A only, two stern cameras."})


def calibration_scenario() -> Scenario:
    """Thirty chessboard shots with the paper's camera (experiment 1)."""
    cam = CameraSpec(name="camera", kind="drone", position=[0, -10, 0], look_at=[0, 0, 0])
    return Scenario(name="calibration-shots", description="Chessboard shots for calibration (paper exp. 1).",
                    seed=1, cameras=[cam], calibration=CalibrationSpec(),
                    weather=WeatherSpec(noise=1.0, shadows=0.0, light_variation=0.0, motion_blur=False))


BUILTINS: dict[str, Callable[[], Scenario]] = {
    **{f"config1-procedure{i}": (lambda i=i: procedure_scenario(1, f"procedure{i}")) for i in range(1, 5)},
    **{f"config2-procedure{i}": (lambda i=i: procedure_scenario(2, f"procedure{i}")) for i in range(5, 8)},
    "config1-setdown": lambda: procedure_scenario(1, "setdown"),
    "config2-setdown": lambda: procedure_scenario(2, "setdown"),
    "config1-cone-a": one_cone_scenario,
    "calibration-shots": calibration_scenario,
}  # and with -realities (below): config2-setdown-realities, config1-procedure1-realities, config2-procedure5-realities
CLEAR_WEATHER = {"fog": 0.0, "rain": 0.0, "noise": 0.0, "shadows": 0.0, "light_variation": 0.0,
                 "motion_blur": False}
REALITIES_CLOCK_S = 0.5  # a drone's video clock can be off by tenths of a second from the stern cameras'
REALITIES_SURVEY = {"position_m": 0.02, "tilt_deg": 1.0}  # riggers' mounting and its survey: 1-2 cm, a degree


RANDOM_NAME = re.compile(r"random-\d{1,9}")  # random-SEED: an installation drawn from the seed (sim.installations)


def builtin_names() -> list[str]:
    """Names of the built-in scenarios (each also with -weather, -clear and -realities)."""
    return list(BUILTINS)


def _realities(base: Scenario) -> Scenario:
    return base.model_copy(update={"clock_error_s": REALITIES_CLOCK_S,
                                   "survey_error": SurveyErrorSpec(**REALITIES_SURVEY)})


SUFFIXES: dict[str, Callable[[Scenario], Scenario]] = {
    "-weather": lambda base: base.model_copy(update={"weather": base.weather.model_copy(update=PAPER_WEATHER)}),
    "-clear": lambda base: base.model_copy(update={"weather": base.weather.model_copy(update=CLEAR_WEATHER)}),
    "-realities": _realities,
}


def builtin_scenario(name: str, missing_ok: bool = False) -> Scenario | None:
    """A built-in scenario by name, with optional -weather, -clear or -realities suffixes (in any order)."""
    if name in BUILTINS:
        return BUILTINS[name]()
    if RANDOM_NAME.fullmatch(name):
        from tracking.sim.installations import random_scenario

        return random_scenario(int(name.removeprefix("random-")))
    for suffix, change in SUFFIXES.items():
        if name.endswith(suffix):
            base = builtin_scenario(name.removesuffix(suffix), missing_ok=True)
            if base is not None:
                return change(base).model_copy(update={"name": name})
    if missing_ok:
        return None
    raise InputError(name, f"unknown built-in scenario (expected one of {', '.join(BUILTINS)})")
