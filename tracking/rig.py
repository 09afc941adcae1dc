"""Rig file: one YAML file that describes an installation to the tracker.

Frames (paper, Fig. 8): the jacket frame has x to port, y astern, z up, in metres. The topside
frame is the frame fixed to the topside that coincides with the jacket frame when the topside is
mated, so every offset is zero when mated.

A marker's frame is OpenCV's: origin at the marker centre, x to the right and y up as seen by
someone facing the marker, z out of the face towards that viewer. A marker on face ``astern``
looks astern (+y); its x axis then points to starboard (-x).

A marker's orientation in its body's frame is given in exactly one of three ways:

- ``face`` (a name from FACE_NORMALS) or ``face`` with ``normal: [x, y, z]`` (any label): marker z is the
  outward normal, marker y as near up as can be; optionally ``rotation_deg: 90``, the marker turned about its
  normal by that angle (any angle, degrees), counter-clockwise as seen by someone facing it (riggers mount
  markers turned: a marker whose printed top points to the left of someone facing it has rotation_deg: 90).
- ``R: [[r11, r12, r13], [r21, r22, r23], [r31, r32, r33]]``: the rotation R_body_marker, rows as written;
  its columns are the marker's x, y, z axes in the body's frame (orthonormal, right-handed, to 1e-3).
- ``quaternion: [w, x, y, z]``: the same rotation as a unit quaternion (Hamilton, scalar first; norm 1 to 1e-3).

With R or quaternion, ``face`` is still required: a label for pairs and reports; a label that names a face of
FACE_NORMALS must agree with the orientation's z axis within FACE_LABEL_TOLERANCE_DEG.

A camera may carry a surveyed position: ``position: [x, y, z]``, its optical centre in the jacket frame (m),
with ``position_sigma``, the survey's σ (m, per axis). The fusion filter takes it as a prior on the camera's
position when it first places the camera; a survey farther than its σ allows from where the camera's markers
place it is not applied, and is reported (tracking.estimator, `topside check`).
"""

from __future__ import annotations

import re
from functools import cache, cached_property, lru_cache
from pathlib import Path
from typing import Annotated, Any, Literal

import cv2
import numpy as np
import yaml
from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, ValidationError, field_validator, model_validator

from tracking.errors import InputError, one_line, read_yaml
from tracking.frame_times import FrameClock, read_frame_times
from tracking.geometry import nearest_rotation, quaternion_rotation, transform
from tracking.outputs import write_text

MAX_COORDINATE_M = 1e6  # an installation spans tens of metres; this bound only keeps every product finite
MAX_MARKER_SIZE_M = 100.0
MAX_TIME_OFFSET_S = 1e10  # beyond the Unix clock's 300 years: a clock offset past it is a typo
INTERNAL_FIELDS = ("path", "warnings")  # set by load_rig, never by the file
SIMPLE_KEY = re.compile(r"^[A-Za-z0-9_-]+$")  # a location part printed bare; anything else is quoted


def _number(value: Any) -> Any:
    """Refuses a YAML boolean (true, yes, on) where a number is expected; pydantic would read it as 1 or 0."""
    if isinstance(value, bool):
        raise ValueError(f"expected a number, got {str(value).lower()}")
    return value


Body = Literal["jacket", "topside"]
Mount = Literal["fixed", "vessel", "drone", "moving"]  # on the jacket or a platform; on the crane vessel (waves);
# flying; moving briskly against the jacket (a boom, a hand-held camera, or a jacket marker group carried by hand)
DEFAULT_MOUNT: Mount = "drone"  # the loosest motion prior: what a camera without `mount` gets
Coordinate = Annotated[float, BeforeValidator(_number), Field(ge=-MAX_COORDINATE_M, le=MAX_COORDINATE_M)]
Vec3 = Annotated[list[Coordinate], Field(min_length=3, max_length=3)]

_D = float(np.sqrt(0.5))
FACE_NORMALS: dict[str, tuple[float, float, float]] = {
    "port": (1.0, 0.0, 0.0),
    "starboard": (-1.0, 0.0, 0.0),
    "astern": (0.0, 1.0, 0.0),
    "ahead": (0.0, -1.0, 0.0),
    "port-astern": (_D, _D, 0.0),
    "port-ahead": (_D, -_D, 0.0),
    "starboard-astern": (-_D, _D, 0.0),
    "starboard-ahead": (-_D, -_D, 0.0),
}
UP = np.array([0.0, 0.0, 1.0])
MATED_TOLERANCE_M = 0.005
# Defaults of the rig's optional drawing fields (a ~10,000 t topside on a four-legged jacket, as the simulator has it)
DEFAULT_LEG_DIAMETER_M = 2.0  # when no marker tells the leg's surface
DEFAULT_LEG_LENGTH_M = 20.0
DEFAULT_TOPSIDE_LEG_LENGTH_M = 8.0
DEFAULT_CONE_HEIGHT_M = 1.5
PLATE_STANDOFF_M = 0.1  # a marker's plate face stands this far proud of its leg's surface
ORTHONORMAL_TOLERANCE = 1e-3  # largest |RᵀR - I| entry of a typed R: rows of 4 decimals (0.7071) are within it
UNIT_TOLERANCE = 1e-3  # largest |norm - 1| of a typed quaternion, for the same reason
FACE_LABEL_TOLERANCE_DEG = 45.0  # an R or quaternion whose z is farther than this from its named face's normal is
# a mistyped face or orientation: neighbouring faces (port, port-ahead) are 45° apart, wrong ones 90° or more
MAX_ROTATION_DEG = 360.0  # a turn about the normal beyond one revolution is a typo
MAX_POSITION_SIGMA_M = 100.0  # a survey σ beyond this says nothing about a camera tens of metres away
MAX_MARKER_SIGMA_M = 1.0  # a marker's survey σ beyond this is not a survey (markers are placed to centimetres)
MAX_MARKER_SIGMA_DEG = 30.0  # nor a tilt σ beyond this
MAX_TIME_SIGMA_S = 3600.0  # a clock σ beyond an hour is no estimate


def normal_rotation(normal: np.ndarray) -> np.ndarray:
    """R_body_marker (3, 3) for a face with outward normal (3,): marker z = normal, marker y as near up as can be."""
    z = np.asarray(normal, dtype=float) / np.linalg.norm(normal)
    ref = UP if abs(z @ UP) < 0.95 else np.array([0.0, -1.0, 0.0])
    y = ref - (ref @ z) * z
    y /= np.linalg.norm(y)
    return np.column_stack([np.cross(y, z), y, z])


def face_rotation(face: str) -> np.ndarray:
    """R_body_marker (3, 3) of a marker on a named vertical face (port, astern, port-ahead, ...)."""
    return normal_rotation(np.array(FACE_NORMALS[face]))


def turned(R: np.ndarray, degrees: float) -> np.ndarray:
    """R_body_marker (3, 3) of a marker turned about its own z (its outward normal) by degrees, counter-clockwise as
    seen by someone facing it: R (3, 3) @ Rz(degrees)."""
    a = np.deg2rad(degrees)
    c, s = np.cos(a), np.sin(a)
    return np.asarray(R, dtype=float) @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def rotation_problem(R: np.ndarray) -> str | None:
    """Why a typed matrix (3, 3) is not a rotation to ORTHONORMAL_TOLERANCE, or None when it is one."""
    R = np.asarray(R, dtype=float)
    error = float(np.max(np.abs(R.T @ R - np.eye(3))))
    if error > ORTHONORMAL_TOLERANCE:
        return (f"not orthonormal (|RᵀR - I| reaches {error:.3g}, expected at most {ORTHONORMAL_TOLERANCE:g}; "
                "its columns are the marker's x, y, z axes in its body's frame)")
    if np.linalg.det(R) < 0:
        return "a reflection (determinant -1; expected the right-handed marker axes x, y, z as its columns)"
    return None


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)  # NaN or inf: an error, not a row


Number = Annotated[float, BeforeValidator(_number)]
MarkerSigmaM = Annotated[Number, Field(ge=0, le=MAX_MARKER_SIGMA_M)]
MarkerSigmaDeg = Annotated[Number, Field(ge=0, le=MAX_MARKER_SIGMA_DEG)]


def _one_or_three(high: float, unit: str) -> BeforeValidator:
    """Checks a σ given as one number or three before pydantic's union of the two does: its error would name the
    union's members by their validators' internals (function reprs, memory addresses); this one says what is
    expected."""

    def within(v: Any) -> bool:
        try:  # what pydantic reads as a number (a numeric string too), but not a YAML boolean
            return not isinstance(v, bool) and 0 <= float(v) <= high
        except (TypeError, ValueError):
            return False

    def check(value: Any) -> Any:
        items = value if isinstance(value, list) else [value]
        if len(items) != (3 if isinstance(value, list) else 1) or not all(within(v) for v in items):
            got = repr(value) if len(repr(value)) <= 60 else repr(value)[:57] + "..."
            raise ValueError(f"expected a σ from 0 to {high:g} {unit}, or three (one per body axis), got {got}")
        return value

    return BeforeValidator(check)


class SurveySigma(_Model):
    """How well markers' poses in their bodies' frames are known: 1σ of a centre (m) and of a rotation about each axis
    (degrees), body frame; one number for every axis or one per axis."""

    position_m: Annotated[MarkerSigmaM | Annotated[list[MarkerSigmaM], Field(min_length=3, max_length=3)],
                          _one_or_three(MAX_MARKER_SIGMA_M, "m")] = 0.0
    tilt_deg: Annotated[MarkerSigmaDeg | Annotated[list[MarkerSigmaDeg], Field(min_length=3, max_length=3)],
                        _one_or_three(MAX_MARKER_SIGMA_DEG, "degrees")] = 0.0

    @model_validator(mode="before")
    @classmethod
    def _a_mapping(cls, value: Any) -> Any:
        if not isinstance(value, dict | SurveySigma):
            got = repr(value) if len(repr(value)) <= 60 else repr(value)[:57] + "..."
            raise ValueError(f"expected a mapping with position_m (m) and tilt_deg (degrees), got {got}")
        return value

    def position(self) -> np.ndarray:
        """(3,) σ of the centre along the body's axes, m."""
        return np.broadcast_to(np.asarray(self.position_m, dtype=float), (3,)).copy()

    def tilt_rad(self) -> np.ndarray:
        """(3,) σ of the rotation about the body's axes, rad."""
        return np.radians(np.broadcast_to(np.asarray(self.tilt_deg, dtype=float), (3,)))


class SurveyCorrection(_Model):
    """What `topside survey` moved a marker by (a record; the tracker uses the marker's center and R): its centre
    (m) and its rotation vector (degrees), body frame."""

    position_m: Vec3
    rotation_deg: Vec3


class Marker(_Model):
    """One ArUco marker: its id, the body it is fixed to, its cone and face, its centre and orientation in the body
    frame (the module's docstring gives the three ways of writing the orientation)."""

    id: int = Field(ge=0)
    body: Body
    cone: str = Field(min_length=1)
    face: str = Field(min_length=1)  # a name from FACE_NORMALS, or any label when normal, R or quaternion is given
    center: Vec3
    normal: Vec3 | None = None  # outward face normal in the body frame; default: the named face's
    # turned about its normal by this much, degrees, counter-clockwise as seen facing it (0: y as near up as can be)
    rotation_deg: Annotated[Number | None, Field(ge=-MAX_ROTATION_DEG, le=MAX_ROTATION_DEG)] = None
    R: Annotated[list[Annotated[list[Number], Field(min_length=3, max_length=3)]] | None,
                 Field(min_length=3, max_length=3)] = None  # R_body_marker, rows: columns are marker x, y, z
    quaternion: Annotated[list[Number] | None, Field(min_length=4, max_length=4)] = None  # [w, x, y, z] of it
    reference: bool = False  # its body's datum: `topside survey` holds it where it is, the filter takes it as exact
    sigma: SurveySigma | None = None  # how well its pose is known (default: the rig's survey_sigma)
    correction: SurveyCorrection | None = None  # what `topside survey` moved it by (a record only)

    @model_validator(mode="after")
    def _face_known(self) -> Marker:
        full = [name for name in ("R", "quaternion") if getattr(self, name) is not None]
        if len(full) == 2:
            raise ValueError("quaternion: give R or quaternion, not both (exactly one way of giving the orientation)")
        if full:
            for name in ("normal", "rotation_deg"):
                if getattr(self, name) is not None:
                    raise ValueError(f"{name}: not with {full[0]} (exactly one way of giving the orientation: "
                                     f"face with normal and rotation_deg, or R, or quaternion)")
        if self.R is not None:
            problem = rotation_problem(np.array(self.R))
            if problem:
                raise ValueError(f"R: {problem}")
        if self.quaternion is not None:
            norm = float(np.linalg.norm(self.quaternion))
            if abs(norm - 1.0) > UNIT_TOLERANCE:
                raise ValueError(f"quaternion: norm {norm:.6g} is not 1 (expected a unit quaternion [w, x, y, z], "
                                 f"to {UNIT_TOLERANCE:g})")
        if not full and self.normal is None and self.face not in FACE_NORMALS:
            raise ValueError(f"face: unknown face {self.face!r} (expected one of {', '.join(FACE_NORMALS)}, "
                             "or give normal: [x, y, z], R or quaternion)")
        if self.normal is not None and np.linalg.norm(self.normal) < 1e-9:
            raise ValueError("normal: must not be zero")
        if full and self.face in FACE_NORMALS:
            z = self.R_body_marker[:, 2]
            angle = float(np.degrees(np.arccos(np.clip(z @ np.array(FACE_NORMALS[self.face]), -1.0, 1.0))))
            if angle > FACE_LABEL_TOLERANCE_DEG:
                raise ValueError(f"{full[0]}: its z axis (the outward normal) {np.round(z, 3).tolist()} is "
                                 f"{angle:.0f}° from face {self.face}'s normal (expected at most "
                                 f"{FACE_LABEL_TOLERANCE_DEG:.0f}°: a mistyped face or orientation)")
        return self

    @property
    def R_body_marker(self) -> np.ndarray:
        """(3, 3) orientation of the marker in its body's frame, from whichever way the rig gives it."""
        if self.R is not None:
            return nearest_rotation(np.array(self.R))
        if self.quaternion is not None:
            return quaternion_rotation(np.array(self.quaternion))
        R = normal_rotation(np.array(self.normal)) if self.normal else face_rotation(self.face)
        return turned(R, self.rotation_deg) if self.rotation_deg else R

    @cached_property
    def T_body_marker(self) -> np.ndarray:
        """(4, 4) pose of the marker in its body's frame; computed once (the model is frozen), read-only."""
        T = transform(self.R_body_marker, np.asarray(self.center, dtype=float))
        T.flags.writeable = False
        return T


class Pair(_Model):
    """A jacket marker and the topside marker above it, in one plane when mated."""

    cone: str
    face: str
    jacket: int
    topside: int
    mated: Vec3 | None = None  # topside marker centre minus jacket marker centre when mated, jacket frame, m


class CameraEntry(_Model):
    """A camera: its calibration file, its video source, its clock offset and how it is mounted."""

    name: str = Field(min_length=1, pattern=r"^[A-Za-z0-9_.-]+$")
    calibration: str = Field(min_length=1)
    source: str = Field(min_length=1)  # a device index (0), a stream URL or a video file
    # s, added to the video's timestamps to give capture time on the common clock
    time_offset: Annotated[float, BeforeValidator(_number), Field(ge=-MAX_TIME_OFFSET_S, le=MAX_TIME_OFFSET_S)] = 0.0
    mount: Mount = DEFAULT_MOUNT  # how much the camera may move: the fusion filter's motion prior for its pose
    position: Vec3 | None = None  # surveyed optical centre, jacket frame, m: a prior on the camera's position
    # σ of that survey per axis, m (required with position)
    position_sigma: Annotated[Number | None, Field(gt=0, le=MAX_POSITION_SIGMA_M)] = None
    # σ of time_offset against the other cameras' clocks, s (`topside sync` writes it; unset: unknown, taken as exact)
    time_offset_sigma: Annotated[Number | None, Field(ge=0, le=MAX_TIME_SIGMA_S)] = None
    times: str | None = Field(default=None, min_length=1)  # CSV of each frame's capture time (tracking.frame_times):
    # used instead of the video's presentation times; time_offset is still added

    @model_validator(mode="after")
    def _survey_complete(self) -> CameraEntry:
        if self.position is not None and self.position_sigma is None:
            raise ValueError("position_sigma: missing (expected the survey's σ in m with position)")
        if self.position is None and self.position_sigma is not None:
            raise ValueError("position: missing (expected the surveyed [x, y, z] in the jacket frame with "
                             "position_sigma)")
        return self

    @model_validator(mode="after")
    def _times_of_a_file(self) -> CameraEntry:
        if self.times is not None and (self.source.isdigit() or "://" in self.source):
            raise ValueError("times: a times file goes with a video file (expected no times for a device or stream)")
        return self

    @field_validator("source", mode="before")
    @classmethod
    def _device_index(cls, value: Any) -> Any:
        """A device index written as a YAML integer (source: 0) is the string "0"."""
        if isinstance(value, int) and not isinstance(value, bool):
            if value < 0:
                raise ValueError(f"device index {value} is negative (expected 0, 1, ..., a stream URL or a file)")
            return str(value)
        return value


class Rig(_Model):
    """An installation as the tracker sees it."""

    name: str = "installation"
    dictionary: str = "DICT_6X6_250"
    inverted: bool = False  # the markers are printed white on black
    marker_size: Annotated[float, BeforeValidator(_number), Field(gt=0, le=MAX_MARKER_SIZE_M)]  # black square, m
    cones: dict[str, Vec3] = Field(default_factory=dict)  # cone tip on the jacket, jacket frame, m
    markers: list[Marker]
    pairs: list[Pair] = Field(default_factory=list)
    cameras: list[CameraEntry] = Field(default_factory=list)
    # Drawing only (the viewer's 3-D installation; the tracker never reads them), m. Unset: the leg diameter from
    # the markers (their plates sit PLATE_STANDOFF_M proud of the leg), the lengths and the cone height below.
    leg_diameter: Annotated[float | None, BeforeValidator(_number), Field(gt=0, le=MAX_MARKER_SIZE_M)] = None
    leg_length: Annotated[float | None, BeforeValidator(_number), Field(gt=0, le=MAX_COORDINATE_M)] = None  # jacket
    # leg drawn below its cone (default DEFAULT_LEG_LENGTH_M)
    topside_leg_length: Annotated[float | None, BeforeValidator(_number), Field(gt=0, le=MAX_COORDINATE_M)] = None
    # topside leg from its bottom (at the cone tip when mated) to the deck (default DEFAULT_TOPSIDE_LEG_LENGTH_M)
    cone_height: Annotated[float | None, BeforeValidator(_number), Field(gt=0, le=MAX_MARKER_SIZE_M)] = None
    # stabbing cone from its base on the leg top to its tip (default DEFAULT_CONE_HEIGHT_M)
    survey_sigma: SurveySigma | None = None  # how well the survey placed every marker without a sigma of its own; the
    # fusion filter widens its σ by it (unset: the markers are taken as exact)
    survey_tolerance: SurveySigma | None = None  # a marker `topside survey` moves farther than this is flagged
    path: Path = Field(default=Path("rig.yaml"), exclude=True)  # the file it was read from
    warnings: tuple[str, ...] = Field(default=(), exclude=True)  # one line each, set by load_rig, for the CLI to print

    @property
    def base_dir(self) -> Path:
        """Folder that relative paths in the rig are resolved against."""
        return self.path.parent

    @field_validator("dictionary")
    @classmethod
    def _known_dictionary(cls, value: str) -> str:
        if not hasattr(cv2.aruco, value) or not value.startswith("DICT_"):
            raise ValueError(f"unknown ArUco dictionary {value!r} (expected e.g. DICT_6X6_250)")
        return value

    @model_validator(mode="after")
    def _consistent(self) -> Rig:
        ids = [m.id for m in self.markers]
        dup = sorted({i for i in ids if ids.count(i) > 1})
        if dup:
            raise ValueError(f"duplicate marker id {dup[0]} (each id may appear once)")
        count = dictionary_size(self.dictionary)
        for i, m in enumerate(self.markers):
            if m.id >= count:
                raise ValueError(f"markers[{i}].id: {m.id} is not in {self.dictionary} (expected 0 to {count - 1})")
        by_id = {m.id: m for m in self.markers}
        names = [c.name for c in self.cameras]
        dup_cam = sorted({n for n in names if names.count(n) > 1})
        if dup_cam:
            raise ValueError(f"duplicate camera name {dup_cam[0]!r}")
        for i, pair in enumerate(self.pairs):
            for role in ("jacket", "topside"):
                mid = getattr(pair, role)
                if mid not in by_id:
                    raise ValueError(f"pairs[{i}].{role}: marker id {mid} is not in markers")
                if by_id[mid].body != role:
                    raise ValueError(f"pairs[{i}].{role}: marker {mid} is on the {by_id[mid].body}")
            if pair.mated is not None:
                derived = self._derived_mated(pair)
                if np.max(np.abs(np.array(pair.mated) - derived)) > MATED_TOLERANCE_M:
                    raise ValueError(
                        f"pairs[{i}].mated: {pair.mated} disagrees with the marker centres "
                        f"({derived.round(3).tolist()})")
        return self

    def _derived_mated(self, pair: Pair) -> np.ndarray:
        by_id = self.marker_by_id
        return np.array(by_id[pair.topside].center) - np.array(by_id[pair.jacket].center)

    def marker_sigma(self, marker: Marker) -> SurveySigma | None:
        """How well a marker's pose is known: its own sigma, else none for a reference, else the rig's survey_sigma."""
        if marker.sigma is not None:
            return marker.sigma
        return None if marker.reference else self.survey_sigma

    @property
    def code_cells(self) -> int:
        """Cells along a marker's side: its code and the black border."""
        return dictionary_cells(self.dictionary)

    @property
    def marker_by_id(self) -> dict[int, Marker]:
        """Markers keyed by id."""
        return {m.id: m for m in self.markers}

    def paired_cones(self) -> list[str]:
        """The cones with marker pairs, sorted (the others' offsets come through the rigid topside)."""
        return sorted({p.cone for p in self.all_pairs()})

    def all_cones(self) -> list[str]:
        """Every cone, sorted: its pairs' cones and the cones whose tips are surveyed (a cone without markers)."""
        return sorted({*self.paired_cones(), *self.cones})

    def all_pairs(self) -> list[Pair]:
        """The listed pairs, or, if none are listed, every jacket/topside marker on the same cone and face."""
        if self.pairs:
            return list(self.pairs)
        found = []
        for j in (m for m in self.markers if m.body == "jacket"):
            for s in (m for m in self.markers if m.body == "topside"):
                if s.cone == j.cone and s.face == j.face:
                    found.append(Pair(cone=j.cone, face=j.face, jacket=j.id, topside=s.id))
        return found

    def T_W_S_mated(self, pair: Pair) -> np.ndarray:
        """(4, 4) nominal pose of the topside marker S in the jacket marker W's frame when mated."""
        by_id = self.marker_by_id
        T = np.linalg.inv(by_id[pair.jacket].T_body_marker) @ by_id[pair.topside].T_body_marker
        if pair.mated is not None:
            R_jacket_W = by_id[pair.jacket].T_body_marker[:3, :3]
            T[:3, 3] = R_jacket_W.T @ np.array(pair.mated)
        return T

    def clock(self, entry: CameraEntry) -> FrameClock:
        """A camera's clock: its time_offset, and the capture times of its times file when it names one."""
        return FrameClock(entry.time_offset, _frame_times(self.resolve(entry.times)) if entry.times else None)

    def resolve(self, relative: str) -> Path:
        """A path from the rig file, relative to the rig file's folder."""
        p = Path(relative)
        return p if p.is_absolute() else self.base_dir / p


@cache
def dictionary_cells(name: str) -> int:
    """Cells along a side of a predefined ArUco dictionary's markers (DICT_6X6_250: 8), its black border's two
    included."""
    return int(cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, name)).markerSize) + 2


def dictionary_size(name: str) -> int:
    """How many markers a predefined ArUco dictionary (DICT_6X6_250) holds."""
    return int(cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, name)).bytesList.shape[0])


def _format_location(loc: tuple) -> str:
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        elif SIMPLE_KEY.match(str(part)):
            out += f".{part}" if out else str(part)
        else:  # a key from the file (a cone's name) that would read as punctuation or break the line
            out += f"[{str(part)!r}]"
    return out


WARN_CLOCK_SIGMA_S = 0.02  # a clock σ beyond this is warned of: at WARN_SPEED_MPS it is 5 mm the σ does not hold
WARN_SPEED_MPS = 0.25  # the crane's lowering speed, for the warning's figure
WARN_SURVEY_M = 0.005  # a survey σ beyond 5 mm or 0.2° is warned of: benchmarks/results/realities.md found the
WARN_SURVEY_DEG = 0.2  # offsets' σ missing survey errors of 20 mm and 1° (35-78 % of errors within 2σ)


def rig_warnings(path: Path, rig: Rig) -> tuple[str, ...]:
    """One line per default the file leaves to the tracker that changes its numbers (a camera without `mount`, cones
    without a tip) and per uncertainty that widens the offsets' σ (clocks, marker surveys)."""
    out = [f"{path}: cameras[{i}].mount: not given; {cam.name} is treated as a {DEFAULT_MOUNT} (the loosest motion "
           "prior: a still camera reads worse; give fixed or vessel)"
           for i, cam in enumerate(rig.cameras) if "mount" not in cam.model_fields_set]
    paired = rig.paired_cones()
    tipless = [cone for cone in paired if cone not in rig.cones]
    if tipless and not rig.cones:
        out.append(f"{path}: cones: not given; each cone's offset is reported at its topside marker's centre, "
                   "not at the cone tip")
    elif tipless:
        out.append(f"{path}: cones: no tip for {', '.join(tipless)}; reported at the topside marker's centre, "
                   "not at the cone tip")
    out += _markers_off_cones(path, rig, paired)
    loose = [c for c in rig.cameras if (c.time_offset_sigma or 0.0) > WARN_CLOCK_SIGMA_S]
    if loose:
        worst = max(c.time_offset_sigma or 0.0 for c in loose)
        out.append(f"{path}: cameras[].time_offset_sigma: {', '.join(c.name for c in loose)} state clocks known to "
                   f"±{worst:.2g} s; the offsets' σ grows by the topside's motion over that time (at {WARN_SPEED_MPS} "
                   f"m/s, {worst * WARN_SPEED_MPS * 1000:.0f} mm), so moving cones may be withheld: measure them with "
                   "topside sync")
    sigmas = [s for s in (rig.marker_sigma(m) for m in rig.markers) if s is not None]
    position = max((float(s.position().max()) for s in sigmas), default=0.0)
    tilt = max((float(np.degrees(s.tilt_rad().max())) for s in sigmas), default=0.0)
    if position > WARN_SURVEY_M or tilt > WARN_SURVEY_DEG:
        out.append(f"{path}: survey_sigma: markers known to {position * 1000:.0f} mm and {tilt:.2g}° (1σ); the "
                   "offsets' σ grows by what such errors do at each cone (a marker's tilt turns the topside's pose), "
                   "and cones may be withheld: refine them with topside survey, or survey the markers better")
    return tuple(out)


def _markers_off_cones(path: Path, rig: Rig, paired: list[str]) -> list[str]:
    """When `cones` is given, a line per marker whose cone is neither in it nor a pair's (a pair's cone without a tip
    has its own warning): what the tracker does with it, which is not to report an offset at that cone."""
    if not rig.cones:
        return []
    out = []
    pairs = rig.all_pairs()
    for i, m in enumerate(rig.markers):
        if m.cone in rig.cones or m.cone in paired:
            continue
        its = sorted({p.cone for p in pairs if m.id in (p.jacket, p.topside)})
        does = (f"marker {m.id} is tracked for cone {', '.join(its)}, as pairs says" if its else
                f"marker {m.id} is in no pair, so it gives no offset")
        out.append(one_line(f"{path}: markers[{i}].cone: {m.cone} is not in cones, and no pair is on it; {does}"))
    return out


def load_rig(path: str | Path) -> Rig:
    """Read and validate a rig file; errors name the file and the field."""
    path = Path(path)
    data = read_yaml(path, "rig file")  # names a missing, folder, empty, binary or non-YAML file
    if not isinstance(data, dict):
        raise InputError(path, "expected a mapping with dictionary, marker_size, markers, cameras")
    for key in INTERNAL_FIELDS:
        if key in data:
            raise InputError(path, "not a rig field (expected name, dictionary, marker_size, cones, markers, pairs, "
                                   "cameras)", key)
    try:
        rig = Rig.model_validate(data)
    except ValidationError as exc:
        raise rig_error(path, exc) from None
    rig = rig.model_copy(update={"path": path, "warnings": rig_warnings(path, rig)})
    for entry in rig.cameras:  # a times file that cannot be read is named now, before any work
        rig.clock(entry)
    return rig


def rig_error(source: str | Path, exc: ValidationError) -> InputError:
    """A rig's first validation error as one line naming its field (markers[2].center[1])."""
    err = exc.errors()[0]
    msg = err["msg"].removeprefix("Value error, ")
    loc = _format_location(err["loc"])
    head, sep, rest = msg.partition(": ")
    if sep and " " not in head:  # a cross-field check names its own field: "pairs[0].topside: ..."
        loc, msg = ".".join(p for p in (loc, head) if p), rest
    if err["type"] == "literal_error":
        msg = f"got {err['input']!r}; {msg[0].lower()}{msg[1:]}"
    return InputError(source, msg, loc or None)


@lru_cache(maxsize=32)
def _frame_times(path: Path) -> np.ndarray:
    """A times file's capture times by frame number, read once per process (read-only)."""
    times = read_frame_times(path)
    times.flags.writeable = False
    return times


def save_rig(path: str | Path, rig: Rig) -> None:
    """Write a rig file atomically (the simulator and tests use it; people write theirs by hand)."""
    data = rig.model_dump(mode="json", exclude_none=True)
    write_text(Path(path), yaml.safe_dump(data, sort_keys=False, default_flow_style=None))
