"""The filter's noise model: every σ, gate and time constant, and the process noise of the topside and the cameras.

One place for the numbers the estimator, the survey (tracking.survey) and the readiness check (tracking.check) share.
Evidence for each is in docs/method.md#the-filters-constants. Units: metres, radians, seconds, pixels.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field
from functools import lru_cache
from statistics import NormalDist

import numpy as np

from tracking.pose import BodyPose

STATE = 12  # per body: pose (6) and rates (6)
GATE_CHI2 = {3: 16.27, 6: 22.46}  # by degrees of freedom, 99.9 %
REINIT_AFTER_REJECTS = 15  # consecutive gated measurements before the filter reopens a covariance
CONTRIBUTION_WINDOW_S = 0.5  # a camera counts as contributing when it was accepted this recently
AMBIGUOUS_VARIANCE_GAIN = 25.0  # σ × 5 for poses IPPE could not settle: their error is bimodal, not Gaussian
MEASUREMENT_FLOOR_M = 0.01  # σ added to every measured position: biases corner noise does not explain (far markers'
# tilt, first-order rotation, timing); evidence in docs/method.md#the-filters-constants, as for the constants below
ROTATION_FLOOR_RAD = 1e-3  # σ added to every measured body rotation, for the same reasons
TILT_FLOOR_RAD = 0.75e-3  # the least σ of the topside's turn about an axis only its markers' orientation tells: the
# slow (1 s) orientation error left on the campaign's worst view, a steep telephoto drone's (0.73 mrad RMS)
TILT_BASELINE_SIDES = 5.0  # seen topside markers whose RMS distance from an axis is less than this many marker sides
# (5 m for 1 m markers: two cones 10 m apart, or one cone's faces) tell the topside's turn about it no better than
# TILT_FLOOR_RAD by their positions (a few mm over 5 m; a 40 mm marker at 1 m is a 1 m marker at 25 m): tilt_floor
REPORT_MAX_SIGMA_M = 0.05  # a cone whose offset σ exceeds this on any axis is reported as unknown (NaN): 3σ must fit
# in the 150 mm concentricity tolerance for a number to be worth showing
REPORT_WARMUP_S = 4.0  # for this long after the topside is placed, a cone is reported only when its σ is below
REPORT_WARMUP_SIGMA_SIDES = 0.025  # this many marker sides (25 mm for 1 m markers): the first seconds' camera poses
# are poorly known and not Gaussian, by as much as the scene is large (a 4 cm board at 1 m is a 1 m marker at 25 m)
SMOOTHER_SPAN_S = 30.0  # recorded runs are smoothed this much at a time, each time with SMOOTHER_LAG_S of the
SMOOTHER_LAG_S = 45.0  # future after it: memory holds both, not the whole run; a still camera gains from the far future
CORNER_NOISE_PX = 0.15  # σ of a corner coordinate from frame to frame (edge-fit corners in fog and rain: 0.1 px median)
VIEW = 8  # corner coordinates of a view (camera, marker): each has two bias states (VIEW_STATES)
CORNER_NOISE_SAMPLES = 30  # body fits whose median measures a camera's corner noise (CornerNoise): 2-5 s of frames
CORNER_NOISE_MIN_SAMPLES = 3  # fewer fits than this measure nothing: CORNER_NOISE_PX until then
VIEW_BIAS_PX = 0.08  # σ of the part of a corner's error that stays while its marker's image stays
VIEW_BIAS_RENEW_PX = 0.5  # that part renews as the marker's image moves: exp(-travel / this) of it stays from one
# frame of the view to the next (travel: the mean shift of its predicted corners, the filter's own corrections included)
VIEW_BIAS_TAU_S = 0.5  # ... but no faster than with this time constant, however far the image travels (a drone's
# marker cells and the stream's coding move with the marker, not the pixel grid)
VIEW_SHAPE_BIAS_PX = 0.04  # σ of the part of a corner's error that stays while its marker's image keeps its shape,
# wherever the image goes (the plate's edge and what lies beyond it, the code cells beside the border, the blur across
# a cell): over 796 views of 114 random installations a view's whole-run mean error is 0.016 px at the median and
# 0.045 px RMS (0.044 where the marker moves), up to 0.5 px where a plate's edge meets a dark leg
# (benchmarks/results/corner_persistence.md). It grows as a cell thins across (0.13 px RMS under 2.5 px, 0.03 from
# 4.5 px), but a filter given that much at a far camera's 2 px cells lost its depth (docs/method.md): one σ for all.
# Since the corners' blur-matched levels, 0.022 px RMS over 88 installations (0.020 moving); 0.025 px changed one cone
# of 106 (docs/accuracy.md), so it stays
VIEW_SHAPE_RENEW = 0.1  # that part renews as its image's shape changes: exp(-change / this) of it stays, change the
# growth of the image's departure from the shape it had at the last reset (when the departure reached this), over its
# size (a tenth: 10 % nearer, or turned 0.1 rad in the image); a shape that only trembles about one (a hovering drone)
# renews it once, one swinging by more (a camera rolling 3-5° in waves) at every swing (measurements.shape_kept)
VIEW_MISREAD_TAU_S = 2.0  # how long a view's corners are averaged to find its marker misread (measurements.misread):
# its image departing from every affine map of the square its pose predicts, where no pose error puts it
VIEW_MISREAD_STEP_S = 0.25  # ... where one frame stands for at most this long (a view back after a gap is one frame,
# not the gap: 6 fps webcams' frames are 0.17-0.21 s apart)
VIEW_MISREAD_MIN_S = 0.5  # ... and a view is judged once its frames weigh this long: a raindrop on its first frames
# is a share of the average, not all of it (judged after 2 s, a still camera's view with one
# corner 1 px off turned the camera and its cones 61 mm off before it was found; after 0.5 s, 39 mm; 28 after 0.2 s)
VIEW_MISREAD_MIN_WEIGHT = 1.0 - float(np.exp(-VIEW_MISREAD_MIN_S / VIEW_MISREAD_TAU_S))
VIEW_MISREAD_CHI2 = 13.82  # χ²(2 dof, 99.9 %) of what the view's bias prior allows there: beyond, it is misread (a
# shadow's edge, a plate's edge against a dark leg: over 964 views of the campaign that departure is 0.006 px RMS a
# coordinate at the median, 0.08 at the 99th percentile and 0.18-0.43 in six, one of them random-9011's stern camera,
# a corner 1.07 px off all run long)
VIEW_MISREAD_GAIN = 1.0  # ... and its shape bias's σ a coordinate widens to this many times the departure (one of four
# corners off by δ departs by δ/2: a variance of δ²/4 a coordinate over the four), for good
VIEW_STATES = 2 * VIEW  # bias states per view: the part that renews with travel, then the part that renews with shape

VIEW_PRIOR = np.array([VIEW_BIAS_PX**2] * VIEW + [VIEW_SHAPE_BIAS_PX**2] * VIEW)  # (VIEW_STATES,) their variances
VIEW_PRIOR.flags.writeable = False
CORNER_HUBER_CHI2 = 5.99  # 2 degrees of freedom, 95 %: beyond it a corner's variance grows with its residual (rain's
# heavy tail)
CAMERA_RATE_TAU_S = 0.5  # a camera's rates revert to zero with this time constant: a drone's jitter and a vessel's
# wave motion turn within a second or two
MOTION_LAG_S = 1.0  # lag of the second differences of jacket-marker image positions that measure a camera's motion
POSE_MOTION_LAG_S = 1.0 / 3.0  # lag of the second differences of a camera's fitted jacket rotation (PoseMotionLevel):
# a hand turning a board turns within a second, which a 1 s lag averages away (caliscope's webcams: 0.02-0.1 rad²/s³
# at 2 frames, 0.004-0.05 at 6; their jacket markers' images read 0.001-0.005)
POSE_MOTION_SNR = 3.0  # ... a level counted only where it is this many times what the fits' own noise reads
MOTION_SAMPLES = 60  # second differences (per marker and image axis) whose median gives the camera's motion level
MOTION_MIN_SAMPLES = 12  # until then the mount's motion prior is used as it stands
MOTION_UPDATE_EVERY = 5  # frames with new samples between two medians (the level changes over seconds)
MOTION_FLOOR = 1e-4  # the least share of its mount's process noise a camera keeps
MOTION_LEVEL_MAX = 10.0  # rad²/s³, the most a camera's measured level raises its process noise to (the brisk mount's):
# a mount is a prior, not a limit (caliscope's webcams declared `fixed` while the board turned before them: live
# 62-78 % within 2σ, up to 27 % beyond 3σ, |e|max 30 mm when the level could not exceed the mount; 84-95 %, 14 mm when
# it could)
MOUNT_MISMATCH = 100.0  # `check` names a camera whose level exceeds its mount's prior this many times
GAUSSIAN_MEDIAN_CHI2_1 = 0.4549  # median of a χ² variable with 1 degree of freedom: variance from a median of squares
JOLT_CHI2_2 = 9.21  # a camera whose jacket corners' median squared innovation exceeds χ²(2 dof, 99 %) moved beyond its
# prior since its last frame (a hand, a gust): it gets its mount's whole process noise back at once where its motion
# level had lowered it, so its own jacket corners take the move up, not the topside (real webcams filming a board
# turned by hand: post_optimization's live |e|max 7/31/26 -> 3/14/7 mm). It acts on every mount whose level adapts:
# procedure 1's stern (vessel) cameras jolt 35-86 times in 100 s of waves (docs/method.md: a camera jolted)
PLACEMENT_GAIN = 25.0  # σ × 5 on the pose that first places a camera: it only linearises; the same frame's corners,
# applied right after, carry its information (else counted twice)
CORNER_GATE_CHI2 = 26.12  # 8 degrees of freedom (a marker's four corners), 99.9 %
CORNER_ITERATIONS = 4  # at most this many linearisations of one corner update (an iterated EKF)
LINEARISATION_TOL_PX = 0.015  # ... iterated while the updated state's corners depart from the linearisation by more
# than a tenth of CORNER_NOISE_PX (a frame's corrections of millimetres depart by 1e-4 px; a camera's first metres, by
# pixels)
TOPSIDE_PLACEMENT_M = 1.0  # σ of the topside's position when a single view first places it
PLACEMENT_FIT_P = 0.99  # a view places a camera or the topside only if its pose fits its corners as well as
# CORNER_NOISE_PX would at this probability (χ² of the RMS over 8 N - 6 degrees of freedom, N markers)
SURVEY_GATE_CHI2 = GATE_CHI2[3]  # a camera's surveyed position (rig: position, position_sigma) is applied when its
# first view places it, unless it lies beyond this from that placement: then reported (survey_conflicts), not trusted



@dataclass(frozen=True)
class CameraMotion:
    """How a camera on one kind of mount may move: its pose's process noise and the prior of its rates."""

    mount: str
    angular_accel_psd: float  # rad²/s³, white-noise angular acceleration
    accel_psd: float  # m²/s³, white-noise acceleration
    prior_rate_radps: float
    prior_speed_mps: float
    adapts: bool = True  # its process noise follows the motion its images show (below); a hovering drone's
    # jitter is fast at every scale (its 1 s level understates its frame-to-frame motion), so it keeps its prior
    orbits: bool = False  # it may circle what it films (a board turned before a webcam): a turn about its markers
    # leaves their images still, so only its measured turns lower that part of its prior (process.orbit_psd); a vessel
    # rolls and sways, which moves the images


@dataclass(frozen=True)
class FilterTuning:
    """Process and prior noise of the filter."""

    accel_psd: float = 0.05  # m²/s³: white-noise acceleration of the translation (crane and waves)
    angular_accel_psd: float = 1e-6  # rad²/s³: a topside hanging from cranes yaws and rolls slowly
    prior_position_m: float = 20.0
    prior_rotation_rad: float = 0.05
    prior_speed_mps: float = 1.0
    prior_rate_radps: float = 0.01
    camera_motion: tuple[CameraMotion, ...] = (
        CameraMotion("fixed", 1e-8, 1e-6, 1e-4, 1e-3),  # bolted to the jacket or a platform
        CameraMotion("vessel", 1e-5, 0.1, 0.005, 0.3),  # on the crane vessel: metres and milliradians in waves
        CameraMotion("drone", 1e-3, 0.5, 0.05, 1.0,  # flying: 0.3 m/s and 0.01 rad/s, changing within seconds
                     adapts=False),
        CameraMotion("moving", 10.0, 5.0, 1.0, 1.0, orbits=True),  # brisk: turns of 1 rad/s and 1 m/s changing
        # within a second (a hand-held board 1 m from a webcam); a ceiling, which its motion level lowers
    )

    def motion(self, mount: str) -> CameraMotion:
        """The motion prior of a camera mount."""
        return next(m for m in self.camera_motion if m.mount == mount)



def block_noises(dt: float, psds: np.ndarray) -> np.ndarray:
    """(B, 12, 12) white-noise-acceleration process noise of B bodies, their pose's acceleration psds (B, 6, 6)."""
    q = np.asarray(psds, dtype=float)
    Q = np.zeros((len(q), STATE, STATE))
    Q[:, :6, :6] = q * dt**3 / 3
    Q[:, :6, 6:] = Q[:, 6:, :6] = q * dt**2 / 2
    Q[:, 6:, 6:] = q * dt
    return Q


def topside_psds(tuning: FilterTuning) -> list[float]:
    """(6,) the topside's acceleration psds per pose axis (translation first)."""
    return [tuning.accel_psd] * 3 + [tuning.angular_accel_psd] * 3


def camera_psds(tuning: FilterTuning, mount: str, scale: float = 1.0) -> list[float]:
    """(6,) a camera's acceleration psds on a mount (rotation first, then position), scaled by the share of the
    mount's motion the camera shows (1: all of it)."""
    m = tuning.motion(mount)
    return [scale * m.angular_accel_psd] * 3 + [scale * m.accel_psd] * 3


def prior_covariance(tuning: FilterTuning) -> np.ndarray:
    """(12, 12) initial covariance of the topside: anywhere near, barely rotated."""
    sd = [tuning.prior_position_m] * 3 + [tuning.prior_rotation_rad] * 3 + \
         [tuning.prior_speed_mps] * 3 + [tuning.prior_rate_radps] * 3
    return np.diag(np.square(sd))



@lru_cache(maxsize=256)
def chi2_quantile(dof: int, p: float) -> float:
    """χ² quantile at p over dof degrees of freedom (Wilson-Hilferty, within 1 % from 2 degrees of freedom up)."""
    z = NormalDist().inv_cdf(p)
    return dof * (1.0 - 2.0 / (9 * dof) + z * np.sqrt(2.0 / (9 * dof))) ** 3


def fits_its_corners(pose: BodyPose, sigma_px: float = CORNER_NOISE_PX) -> bool:
    """Whether a pose's reprojection RMS is what corner noise of sigma_px leaves at PLACEMENT_FIT_P over the corners
    its fit kept."""
    points = 8 * len(pose.marker_ids) - 2 * pose.outliers  # coordinates of the corners the fit kept
    return pose.reprojection_error**2 * points <= chi2_quantile(points - 6, PLACEMENT_FIT_P) * sigma_px**2


@dataclass
class CornerNoise:
    """A camera's corner noise, measured from the residuals of its body-pose fits (views of two markers or more): a
    fit's RMS² × its corner coordinates over the median χ² of its degrees of freedom estimates σ²; the camera's σ is
    the median of the last CORNER_NOISE_SAMPLES (robust to a frame a raindrop struck), never below CORNER_NOISE_PX.
    A real camera's compression, rolling shutter and calibration leave more than a render does, and a gate or a weight
    at CORNER_NOISE_PX would refuse or over-trust them (docs/method.md#real-cameras-prints-mirrors-and-motion)."""

    samples: deque = field(default_factory=lambda: deque(maxlen=CORNER_NOISE_SAMPLES))  # σ² estimates, px²

    def add(self, pose: BodyPose | None) -> None:
        """One body-pose fit's residuals (a lone marker's fit, 2 degrees of freedom, tells too little)."""
        if pose is None or len(pose.marker_ids) < 2:
            return
        points = 8 * len(pose.marker_ids) - 2 * pose.outliers
        self.samples.append(pose.reprojection_error**2 * points / chi2_quantile(points - 6, 0.5))

    @property
    def sigma_px(self) -> float:
        """The camera's corner σ, px."""
        fits = self.fits_px
        return CORNER_NOISE_PX if fits is None else max(CORNER_NOISE_PX, fits)

    @property
    def fits_px(self) -> float | None:
        """What its fits leave a corner, px, unfloored: the 2-D RMS (as a calibration states its error, OpenCV's RMS
        a point's miss), √2 its σ a coordinate; None before CORNER_NOISE_MIN_SAMPLES fits."""
        if len(self.samples) < CORNER_NOISE_MIN_SAMPLES:
            return None
        return float(np.sqrt(np.median(self.samples)))


def lens_px(stated: float, noise: CornerNoise) -> float:
    """A camera's model error for its lens floor (tracking.estimator.disagreement), px: what its calibration states
    (CameraModel.model_px), or what its own fits of the markers leave where that is more, the lens, the print and the
    corners together (caliscope's cam_0 states 0.19 px and its fits leave 0.36-0.42: alone, its Δz held 87 % of its
    errors within 2σ, 100 % so). A calibration stating none (0 px, an exact one's: a render's) stays at none: its fits
    leave corner noise, which its frames average, not a model error; one stating any error is a real lens's, whose
    fits leave its model error and its corners' together, taken as lasting (conservative)."""
    fits = noise.fits_px
    return max(stated, fits) if stated > 0.0 and fits is not None else stated
