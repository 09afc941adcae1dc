"""Scenario file: a pydantic-validated YAML that fixes everything a simulation renders, with a seed.

A scenario file either lists everything (the form `topside simulate` writes to DIR/scenario.yaml)
or names a built-in as `base:` and overrides some sections, e.g.::

    base: config2-procedure5
    seed: 7
    weather: {fog: 0.5, rain: 0.3}

or draws a whole installation from a seed (tracking.sim.installations) as `random: 17`, with overrides likewise.
"""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Annotated, Any, Literal

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from tracking.errors import InputError, read_yaml
from tracking.rig import FACE_NORMALS
from tracking.sim.scene import CONES, Layout

PAPER_K = (1258.27, 1259.0, 468.746, 296.561)  # fx, fy, cx, cy at 920 x 600 (paper eq. 22)
PAPER_SIZE = (920, 600)
DEFAULT_DIST = (-0.10, 0.06, 0.0, 0.0, 0.0)  # k1 k2 p1 p2 k3: mild barrel, ~12 px at the corners

Vec3 = Annotated[list[float], Field(min_length=3, max_length=3)]
FaceName = Literal[tuple(FACE_NORMALS)]  # type: ignore[valid-type]
ConeName = Literal[CONES]  # type: ignore[valid-type]


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class CameraSpec(_Model):
    """One camera: where it is, what it looks at, its intrinsics, clock and exposure."""

    name: str = Field(min_length=1, pattern=r"^[A-Za-z0-9_.-]+$")
    kind: Literal["stern", "fixed", "drone"]  # on the vessel (rides its motion), on a platform (still), flying
    position: Vec3  # jacket frame, m; stern cameras: with the vessel at rest
    look_at: Vec3  # jacket frame, m
    roll: float = 0.0  # degrees about the optical axis
    watch: str | None = None  # the pair it is placed for, "A/port-ahead" (documentation and checks)
    width: int = Field(PAPER_SIZE[0], ge=64, le=8192, multiple_of=2)
    height: int = Field(PAPER_SIZE[1], ge=64, le=8192, multiple_of=2)
    K: Annotated[list[float], Field(min_length=4, max_length=4)] = list(PAPER_K)  # fx, fy, cx, cy, px
    dist: Annotated[list[float], Field(min_length=4, max_length=8)] = list(DEFAULT_DIST)
    fps: float = Field(30.0, gt=0, le=240)
    exposure: float = Field(1 / 250, gt=0, le=0.1)  # s; motion blur integrates over it
    time_offset: float | None = Field(None, ge=0)  # s, common-clock time of PTS 0; None: drawn from seed
    drop_rate: float = Field(0.0, ge=0, le=0.5)  # probability that a frame is lost (drones)
    position_sigma: float | None = Field(None, gt=0, le=10)  # m: the rig states the camera's position as surveyed to
    # this σ (the survey's error drawn from the seed); None: no survey

    @field_validator("K")
    @classmethod
    def _positive_focal(cls, value: list[float]) -> list[float]:
        if value[0] <= 0 or value[1] <= 0:
            raise ValueError(f"focal lengths must be positive, got fx={value[0]}, fy={value[1]}")
        return value

    @field_validator("dist")
    @classmethod
    def _dist_size(cls, value: list[float]) -> list[float]:
        if len(value) not in (4, 5, 8):
            raise ValueError(f"expected 4, 5 or 8 distortion coefficients, got {len(value)}")
        return value

    @model_validator(mode="after")
    def _looks_somewhere(self) -> CameraSpec:
        if sum((a - b) ** 2 for a, b in zip(self.position, self.look_at, strict=True)) < 1e-6:
            raise ValueError("look_at: must differ from position")
        return self


class PairSpec(_Model):
    """A marker pair on one face of a cone's legs: jacket marker below, topside marker above."""

    cone: ConeName
    face: FaceName
    jacket_id: int = Field(ge=0)
    topside_id: int = Field(ge=0)
    jacket_tilt_deg: Vec3 = [0.0, 0.0, 0.0]  # the jacket marker mounted off its face's plumb pose by this rotation
    topside_tilt_deg: Vec3 = [0.0, 0.0, 0.0]  # vector (degrees, body frame, about its centre); surveyed: the rig has it


class SeaSpec(_Model):
    """Short-crested JONSWAP sea driving the vessel."""

    hs: float = Field(1.0, ge=0, le=6)  # significant wave height, m
    tp: float = Field(8.0, gt=2, le=25)  # peak period, s
    heading: float = 135.0  # wave direction relative to the bow, degrees, 180 = head seas
    spreading: float = Field(4.0, ge=0, le=50)  # cos^(2s) directional spreading exponent s
    gamma: float = Field(3.3, ge=1, le=7)  # peak enhancement


class MotionSpec(_Model):
    """The crane's path for the topside, its rigging, the sea and the wind."""

    waypoints: Annotated[list[Annotated[list[float], Field(min_length=2, max_length=3)]],
                         Field(min_length=1)]  # x, y [, z] offsets from mated, jacket frame, m
    hover: float = Field(2.0, ge=0, le=20)  # z offset when a waypoint gives none, m
    speed: float = Field(0.25, gt=0, le=2)  # crane speed, m/s
    lower_speed: float = Field(0.05, gt=0, le=1)  # vertical speed limit, m/s
    ramp_time: float = Field(10.0, ge=0, le=60)  # smooth acceleration / deceleration time, s
    dwell: float = Field(5.0, ge=0, le=600)  # still time at the start and after each move, s
    hold: float = Field(0.0, ge=0, le=21600)  # extra still time at the end, s
    pendulum_length: float = Field(50.0, gt=5, le=200)  # hook to centre of gravity, m
    pendulum_damping: float = Field(0.03, ge=0, le=1)  # fraction of critical
    initial_swing: float = Field(0.1, ge=0, le=5)  # m
    twist_amplitude: float = Field(0.1, ge=0, le=5)  # degrees, torsional oscillation of the rigging
    sea: SeaSpec | None = None
    wind_knots: float = Field(10.0, ge=0, le=60)


class WeatherSpec(_Model):
    """Atmosphere, light and imaging."""

    fog: float = Field(0.0, ge=0, le=0.95)  # contrast lost at 40 m (0.5 = half: visibility ~230 m)
    rain: float = Field(0.0, ge=0, le=1)  # rain intensity, 0..1 (0.3 = moderate rain)
    noise: float = Field(1.5, ge=0, le=30)  # sensor noise standard deviation, 8-bit levels
    light_variation: float = Field(0.1, ge=0, le=0.5)  # relative swing of daylight (clouds)
    shadows: float = Field(0.5, ge=0, le=1)  # strength of moving shadow lines across plates
    sun_azimuth: float = 290.0  # degrees from +x (port) toward +y (astern): 290 = ahead, a little to port
    sun_elevation: float = Field(35.0, ge=-5, le=90)  # degrees
    motion_blur: bool = True
    lens_blur: float = Field(0.0, ge=0, le=5)  # optical blur (lens, sensor), Gaussian σ in pixels; 0: ideal pixels
    crf: int = Field(22, ge=0, le=51)  # H.264 constant rate factor: 1.6-1.7 Mbit/s per 920×600 camera at 15 FPS
    preset: Literal["ultrafast", "superfast", "veryfast", "faster", "fast", "medium"] = "veryfast"


class CalibrationSpec(_Model):
    """Chessboard calibration shots (the paper's experiment 1)."""

    shots: int = Field(30, ge=5, le=200)
    inner_corners: Annotated[list[int], Field(min_length=2, max_length=2)] = [9, 6]
    square: float = Field(0.25, gt=0)  # m

    @field_validator("inner_corners")
    @classmethod
    def _board(cls, value: list[int]) -> list[int]:
        if min(value) < 2:
            raise ValueError(f"need at least 2 x 2 inner corners, got {value}")
        return value


class SurveyErrorSpec(_Model):
    """How far the markers truly sit from where the rig's survey puts them: the σ of a normal draw per marker."""

    position_m: float = Field(0.0, ge=0, le=1)  # σ per axis of a marker centre's displacement in its body frame, m
    tilt_deg: float = Field(0.0, ge=0, le=10)  # σ per axis of the rotation of its face (normal tilted, face turned),
    # degrees, about the body's axes


class Scenario(_Model):
    """Everything a simulation run renders; reproducible with its seed."""

    name: str = "scenario"
    description: str = ""
    seed: int = 0
    duration: float | None = Field(None, gt=0, le=21600)  # s; default: the procedure's own length
    truth_rate: float = Field(30.0, gt=0, le=1000)  # Hz of truth.csv
    dictionary: str = "DICT_6X6_250"
    marker_size: float = Field(1.0, gt=0)
    layout: Layout = Layout()
    pairs: list[PairSpec] = Field(default_factory=list)
    cameras: Annotated[list[CameraSpec], Field(min_length=1)]
    motion: MotionSpec = MotionSpec(waypoints=[[0.0, 0.0]])
    weather: WeatherSpec = WeatherSpec()
    calibration: CalibrationSpec | None = None  # set: render chessboard shots instead of a procedure
    clock_error_s: float = Field(0.0, ge=0, le=10)  # each camera's clock is off by a uniform draw within ±this, s:
    # the rig's time_offset is the nominal (wrong) one, the videos are captured at the true times
    survey_error: SurveyErrorSpec = SurveyErrorSpec()  # markers sit off their surveyed (rig) poses by this much

    @field_validator("dictionary")
    @classmethod
    def _known_dictionary(cls, value: str) -> str:
        import cv2

        if not value.startswith("DICT_") or not hasattr(cv2.aruco, value):
            raise ValueError(f"unknown ArUco dictionary {value!r} (expected e.g. DICT_6X6_250)")
        return value

    @model_validator(mode="after")
    def _consistent(self) -> Scenario:
        ids = [i for p in self.pairs for i in (p.jacket_id, p.topside_id)]
        dup = sorted({i for i in ids if ids.count(i) > 1})
        if dup:
            raise ValueError(f"pairs: marker id {dup[0]} is used twice")
        names = [c.name for c in self.cameras]
        dup_cam = sorted({n for n in names if names.count(n) > 1})
        if dup_cam:
            raise ValueError(f"cameras: duplicate camera name {dup_cam[0]!r}")
        if self.calibration is None and not self.pairs:
            raise ValueError("pairs: at least one marker pair is needed")
        return self


def deep_merge(base: dict[str, Any], override: dict[str, Any]) -> dict[str, Any]:
    """Mapping base with override's keys merged in (nested mappings merged, lists replaced)."""
    out = copy.deepcopy(base)
    for key, value in override.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = deep_merge(out[key], value)
        else:
            out[key] = value
    return out


def _format_location(loc: tuple) -> str:
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        elif str(part).startswith(("function-", "constrained-", "literal[")):
            continue
        else:
            out += f".{part}" if out else str(part)
    return out


def validate_scenario(data: Any, source: str | Path) -> Scenario:
    """Validate a scenario mapping; errors become InputError naming the source and field."""
    if not isinstance(data, dict):
        raise InputError(source, "expected a mapping with cameras, pairs, motion, weather (or base:)")
    try:
        return Scenario.model_validate(data)
    except ValidationError as exc:
        err = exc.errors()[0]
        msg = err["msg"].removeprefix("Value error, ")
        loc = _format_location(err["loc"])
        head, sep, rest = msg.partition(": ")
        if sep and " " not in head:
            loc, msg = ".".join(p for p in (loc, head) if p), rest
        if "input" in err and err["type"] not in ("missing",) and not isinstance(err["input"], dict | list):
            msg = f"{msg} (got {err['input']!r})"
        raise InputError(source, msg, loc or None) from None


def load_scenario(scenario: str | Path) -> Scenario:
    """A scenario from a YAML file (optionally with `base:`) or a built-in name."""
    from tracking.sim.builtins import builtin_names, builtin_scenario

    path = Path(scenario)
    if not path.is_file():
        name = str(scenario)
        if name in builtin_names() or builtin_scenario(name, missing_ok=True) is not None:
            return builtin_scenario(name)
        raise InputError(path, "no such file and no such built-in scenario "
                         f"(built-ins: {', '.join(builtin_names())})")
    data = read_yaml(path)
    if isinstance(data, dict) and "random" in data:
        from tracking.sim.installations import random_scenario

        seed = data.pop("random")
        if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
            raise InputError(path, f"expected a whole number ≥ 0, the installation's seed (got {seed!r})", "random")
        if "base" in data:
            raise InputError(path, "give random or base, not both", "random")
        data = deep_merge(random_scenario(seed).model_dump(mode="json"), data)
    elif isinstance(data, dict) and "base" in data:
        base_name = data.pop("base")
        base = builtin_scenario(str(base_name), missing_ok=True)
        if base is None:
            raise InputError(path, f"unknown built-in scenario {base_name!r} "
                             f"(built-ins: {', '.join(builtin_names())})", "base")
        data = deep_merge(base.model_dump(mode="json"), data)
    return validate_scenario(data, path)


def dump_scenario(scenario: Scenario) -> str:
    """The scenario as YAML, every field explicit."""
    return yaml.safe_dump(scenario.model_dump(mode="json"), sort_keys=False, default_flow_style=None)
