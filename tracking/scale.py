"""What fixes an installation's scale, and whether its markers look the size the rig says.

Every distance a camera measures from one marker scales with the rig's marker_size: a marker k times larger than
stated puts the camera k times farther away, the topside marker of its pair too, and the offset from its mated
position becomes k (mated + offset) - mated. Every view of one marker, every pair and every rigid topside stay
consistent with that; no number of such views can tell. Two things can:

- a camera that sees two markers of one body at once: the rig gives their separation in metres, the camera measures
  it in marker sizes (their IPPE translations);
- a camera whose position is surveyed: the rig gives its distance to a jacket marker, the camera measures it.

Each such frame gives a sample of r = true size / stated size (ScaleSample); ScaleEvidence pools them (frames closer
than EVIDENCE_TAU_S count in part: a view's corner errors last that long) and says whether the markers agree with
their stated size, are off by a factor (a rig error: marker_size is the black square's side), or whether nothing
fixed the scale (then a wrong marker_size would scale every offset unseen).

A topside cannot stand below its cones: an offset whose Δz lies more than BELOW_CONES_M + 3σ under zero is a rig
error (a marker size, a marker's height, a mated offset), never a number to show (below_cones).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

EVIDENCE_TAU_S = 0.5  # s: a view's corner errors stay about this long (estimator.noise.VIEW_BIAS_TAU_S)
MIN_SEPARATION_SIDES = 1.0  # markers closer than this many marker sides give little evidence of scale
MAX_OFF_NORMAL_DEG = 60.0  # a marker seen further off its normal measures its distance poorly and with a bias the
# corner noise does not explain (evidence in docs/method.md#fusion-the-default, the markers' size)
SAMPLE_FLOOR = 0.01  # relative σ of one frame's sample, at least (corner biases the pose covariance leaves out)
MARKER_SURVEY_SIDES = 0.02  # a marker centre's survey in the rig is good to about this share of a marker's side (20 mm
# for 1 m markers, check.RIG_SURVEY_SIGMA_M; a print's layout holds a board's markers at least as well)
SCALE_FLOOR = 0.003  # relative σ of the pooled size, at least: corner biases common to a camera's markers
MISMATCH_SIGMAS = 5.0  # the pooled size is off when it is this many σ from 1 ...
MIN_MISMATCH = 0.03  # ... and off by this share at least (a print or survey, not a typo, below it)
BELOW_CONES_M = 0.05  # a landed topside sits at most this far below its cone tips (bearings, shims)


@dataclass(frozen=True)
class ScaleSample:
    """One frame's measure of the markers' true size over their stated size."""

    ratio: float  # r = true / stated: the rig's distance over the measured one
    sigma: float  # σ of log r
    camera: str
    what: str  # "markers 3 and 5" or "its surveyed position"
    rig_m: float  # the distance as the rig has it, m
    seen_m: float  # as the camera measured it with the stated size, m


def off_normal_deg(T_camera_marker: np.ndarray) -> float:
    """Angle (degrees) between a marker's normal and its line of sight, from its pose (4, 4) in the camera."""
    t = T_camera_marker[:3, 3]
    cos = float(-T_camera_marker[:3, 2] @ t) / max(float(np.linalg.norm(t)), 1e-9)
    return float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))


def separation_sample(camera: str, ids: tuple[int, int], T_i: np.ndarray, T_j: np.ndarray, cov_i: np.ndarray,
                      cov_j: np.ndarray, rig_separation: float, marker_size: float = 1.0) -> ScaleSample | None:
    """From two markers of one body in one frame: their poses in the camera (4, 4) with their translations'
    covariances (3, 3), and their separation in the rig (m), markers of marker_size (m); None when they are too close,
    or one is seen too far off its normal, to tell."""
    seen = T_i[:3, 3] - T_j[:3, 3]
    d = float(np.linalg.norm(seen))
    off = max(off_normal_deg(T_i), off_normal_deg(T_j))
    if rig_separation < MIN_SEPARATION_SIDES * marker_size or d <= 0 or off > MAX_OFF_NORMAL_DEG:
        return None
    u = seen / d
    rel = np.sqrt(float(u @ (cov_i + cov_j) @ u)) / d
    sigma = float(np.hypot(max(rel, SAMPLE_FLOOR), np.sqrt(2.0) * MARKER_SURVEY_SIDES * marker_size / rig_separation))
    return ScaleSample(rig_separation / d, sigma, camera, f"markers {ids[0]} and {ids[1]}", rig_separation, d)


def survey_sample(camera: str, marker: int, seen_distance: float, seen_sigma: float, rig_distance: float,
                  survey_sigma: float, marker_size: float = 1.0) -> ScaleSample | None:
    """From a surveyed camera's distance to a jacket marker: measured (with its σ, m) and from the rig."""
    if seen_distance <= 0 or rig_distance <= 0:
        return None
    sigma = float(np.hypot(max(seen_sigma / seen_distance, SAMPLE_FLOOR),
                           np.hypot(survey_sigma, MARKER_SURVEY_SIDES * marker_size) / rig_distance))
    return ScaleSample(rig_distance / seen_distance, sigma, camera, f"its surveyed position (marker {marker})",
                       rig_distance, seen_distance)


@dataclass
class ScaleEvidence:
    """The pooled samples of a run (see the module)."""

    information: float = 0.0  # Σ w / σ² of log r
    weighted: float = 0.0  # Σ w log r / σ²
    samples: int = 0
    last: dict[tuple[str, str], float] = field(default_factory=dict)  # (camera, what) -> time of its last sample
    example: ScaleSample | None = None  # the most informative sample (for the message)

    def add(self, sample: ScaleSample, time: float) -> None:
        """One frame's sample at a capture time."""
        key = (sample.camera, sample.what)
        before = self.last.get(key)
        weight = 1.0 if before is None else min(1.0, max(0.0, time - before) / EVIDENCE_TAU_S)
        self.last[key] = time
        self.information += weight / sample.sigma**2
        self.weighted += weight * np.log(sample.ratio) / sample.sigma**2
        self.samples += 1
        if self.example is None or sample.sigma < self.example.sigma:
            self.example = sample

    @property
    def fixed(self) -> bool:
        """Whether anything measured the scale."""
        return self.samples > 0

    @property
    def ratio(self) -> float:
        """Pooled true size over stated size (1 without samples)."""
        return float(np.exp(self.weighted / self.information)) if self.information else 1.0

    @property
    def sigma(self) -> float:
        """σ of the pooled ratio's log."""
        return max(1.0 / np.sqrt(self.information), SCALE_FLOOR) if self.information else np.inf

    @property
    def mismatch(self) -> bool:
        """Whether the markers are off their stated size (a rig error)."""
        off = abs(np.log(self.ratio))
        return self.fixed and off > max(MISMATCH_SIGMAS * self.sigma, np.log1p(MIN_MISMATCH))

    def message(self) -> str:
        """One line: what the markers look like against marker_size, and what shows it."""
        if not self.fixed:
            return ("nothing fixes the scale: no camera is surveyed and none sees two markers of one body within "
                    f"{MAX_OFF_NORMAL_DEG:.0f}° of their normals, so a wrong "
                    "marker_size (the black square's side) would scale every offset unseen")
        e = self.example
        assert e is not None
        detail = (f"{e.camera} sees {e.what} {e.seen_m:.2f} m apart where the rig has {e.rig_m:.2f} m"
                  if e.what.startswith("markers") else
                  f"{e.camera} measures {e.seen_m:.2f} m to {e.what.removeprefix('its surveyed position ')[1:-1]} "
                  f"where its surveyed position gives {e.rig_m:.2f} m")
        return (f"the markers look {self.ratio:.2f}× their stated size ({detail}): marker_size is the black square's "
                "side")


def below_cones(dz: float, sigma_z: float) -> bool:
    """Whether an offset's Δz (m, with its σ) puts the topside through its cones: no set-down can be there."""
    return dz + 3.0 * sigma_z < -BELOW_CONES_M
