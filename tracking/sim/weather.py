"""Weather and imaging: fog, rain, daylight changes, shadow lines, motion blur, sensor noise.

- fog: `fog` is the contrast lost at FOG_REFERENCE_M (40 m, the far stern-camera distance);
  transmission exp(-beta d) with beta = -ln(1 - fog) / 40 m, so fog 0.5 is a visibility of ~230 m.
- rain: streaks (length from the fall speed during the exposure, slanted by the wind) over the
  image, plus extinction RAIN_EXTINCTION * rain per metre.
- light: daylight level 1 + light_variation * (slow sum of sines: clouds); Lambert shading with
  ambient AMBIENT and sun DIFFUSE.
- shadow lines: each plate gets a straight shadow edge (a beam's shadow) that sweeps slowly across
  it; the shaded side loses `shadows` of its direct sunlight, with a PENUMBRA_M soft edge.
- motion blur: a line kernel along the image motion during the exposure (capture time = mid-exposure).
- noise: Gaussian, `noise` 8-bit levels standard deviation, per channel.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from tracking.sim.scenario import WeatherSpec

FOG_REFERENCE_M = 40.0
RAIN_EXTINCTION = 0.004  # 1/m at rain = 1
RAIN_STREAKS_PER_MPX = 900  # streaks per megapixel at rain = 1
FOG_ALBEDO = np.array([0.80, 0.79, 0.77])  # BGR, bright grey haze
AMBIENT = 0.45
DIFFUSE = 0.55
PENUMBRA_M = 0.04
SHADOW_MIN_PERIOD = 40.0  # s
SHADOW_MAX_PERIOD = 120.0
CLOUD_PERIODS = (23.0, 61.0, 149.0)  # s
BLUR_THRESHOLD_PX = 0.3


def extinction(weather: WeatherSpec) -> float:
    """Extinction coefficient beta (1/m) of fog and rain."""
    fog = -np.log(1 - weather.fog) / FOG_REFERENCE_M if weather.fog > 0 else 0.0
    return fog + RAIN_EXTINCTION * weather.rain


def sun_vector(weather: WeatherSpec) -> np.ndarray:
    """Unit vector toward the sun, jacket frame."""
    az, el = np.radians(weather.sun_azimuth), np.radians(weather.sun_elevation)
    return np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])


@dataclass(frozen=True)
class ShadowLine:
    """A straight shadow edge on a plate: shaded where X cos(a) + Y sin(a) > offset(t)."""

    angle: float
    amplitude: float  # m
    period: float  # s
    phase: float

    def offset(self, t: float) -> float:
        """Edge position (m from the plate centre) at time t."""
        return self.amplitude * np.sin(2 * np.pi * t / self.period + self.phase)


class Light:
    """Daylight level over time and the shadow lines on each plate."""

    def __init__(self, weather: WeatherSpec, seed: int, plate_keys: list[str]) -> None:
        rng = np.random.default_rng([seed, 5])
        self.weather = weather
        self.sun = sun_vector(weather)
        self.cloud_phase = rng.uniform(0, 2 * np.pi, len(CLOUD_PERIODS))
        self.shadows = {
            key: ShadowLine(angle=rng.uniform(0, 2 * np.pi), amplitude=rng.uniform(0.6, 1.2),
                            period=rng.uniform(SHADOW_MIN_PERIOD, SHADOW_MAX_PERIOD), phase=rng.uniform(0, 2 * np.pi))
            for key in plate_keys
        }

    def level(self, t: float) -> float:
        """Daylight multiplier at time t."""
        if self.weather.light_variation == 0:
            return 1.0
        s = sum(np.sin(2 * np.pi * t / p + ph) for p, ph in zip(CLOUD_PERIODS, self.cloud_phase, strict=True))
        return float(1.0 + self.weather.light_variation * s / len(CLOUD_PERIODS) * 1.5)


def rain_streaks(img: np.ndarray, rain: float, rng: np.random.Generator, exposure: float, fy: float,
                 wind_slant: float) -> np.ndarray:
    """Image with bright semi-transparent rain streaks drawn over it."""
    h, w = img.shape[:2]
    n = int(RAIN_STREAKS_PER_MPX * rain * w * h / 1e6)
    if n == 0:
        return img
    layer = np.zeros((h, w), np.uint8)
    x = rng.uniform(0, w, n)
    y = rng.uniform(0, h, n)
    dist = rng.uniform(1.0, 8.0, n)  # m from the lens
    length = np.clip(9.0 * exposure * fy / dist * 4, 4, 60)  # 9 m/s fall, streak lengthened by optics
    dx = np.sin(wind_slant) * length
    dy = np.cos(wind_slant) * length
    value = rng.integers(40, 110, n)
    thick = np.where(dist < 2.5, 2, 1)
    for i in range(n):
        cv2.line(layer, (int(x[i]), int(y[i])), (int(x[i] + dx[i]), int(y[i] + dy[i])), int(value[i]),
                 int(thick[i]), cv2.LINE_AA)
    return cv2.add(img, cv2.cvtColor(layer, cv2.COLOR_GRAY2BGR))


def motion_blur(img: np.ndarray, dx: float, dy: float) -> np.ndarray:
    """Image blurred along (dx, dy) px (the motion during the exposure), unchanged below a third of a pixel."""
    length = float(np.hypot(dx, dy))
    if length < BLUR_THRESHOLD_PX:
        return img
    size = int(np.ceil(length)) * 2 + 3
    sub = 8
    k = np.zeros((size * sub, size * sub), np.float32)
    c = (size * sub - 1) / 2
    cv2.line(k, (round((c - dx * sub / 2) * 16), round((c - dy * sub / 2) * 16)),
             (round((c + dx * sub / 2) * 16), round((c + dy * sub / 2) * 16)), 1.0, sub, cv2.LINE_AA, shift=4)
    k = cv2.resize(k, (size, size), interpolation=cv2.INTER_AREA)
    k /= k.sum()
    return cv2.filter2D(img, -1, k, borderType=cv2.BORDER_REFLECT)


class NoiseBank:
    """Pre-drawn Gaussian sensor noise; each frame takes a seeded random window of a random plane."""

    PLANES = 6
    PAD = 64

    def __init__(self, shape: tuple[int, int, int], sigma: float, seed: int) -> None:
        self.sigma = sigma
        self.shape = shape
        if sigma > 0:
            rng = np.random.default_rng([seed, 11])
            h, w, c = shape
            self.planes = [np.round(rng.standard_normal((h + self.PAD, w + self.PAD, c), np.float32) * sigma)
                           .astype(np.int16) for _ in range(self.PLANES)]

    def add(self, img: np.ndarray, seed: int) -> np.ndarray:
        """Image with a reproducible noise window added (saturating)."""
        if self.sigma <= 0:
            return img
        rng = np.random.default_rng([seed, 13])
        k, dy, dx = rng.integers(0, self.PLANES), rng.integers(0, self.PAD), rng.integers(0, self.PAD)
        h, w = img.shape[:2]
        return cv2.add(img, self.planes[k][dy:dy + h, dx:dx + w], dtype=cv2.CV_8U)
