"""The Kalman filter of one installation: the topside and every camera, measured by their markers' corners.

Each camera frame is applied at its capture time (cameras need no synchronisation): the state predicted to it
(tracking.estimator.process), the camera placed at its first jacket view and the topside at its first view through a
placed camera (tracking.estimator.placement), then the frame's jacket corners refine the camera and its topside corners,
through the camera just refined, the topside (tracking.estimator.measurements). Pair offsets are accepted too. The
offset at every cone follows from the topside pose, including cones no camera sees (cone_estimates); a cone whose σ
says it cannot be known, or whose offset only a rig error explains, is withheld with the reason.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from tracking.estimate import (
    WITHHELD_BELOW,
    WITHHELD_CLOCKS,
    WITHHELD_COMPARING,
    WITHHELD_SCALE,
    WITHHELD_SIGMA,
    WITHHELD_WARMING,
    ConeEstimate,
)
from tracking.estimator.disagreement import Disagreement
from tracking.estimator.measurements import Measurement, corner_update, jolted, nearest, pair_rows, renew
from tracking.estimator.noise import (
    AMBIGUOUS_VARIANCE_GAIN,
    CAMERA_RATE_TAU_S,
    CONTRIBUTION_WINDOW_S,
    GATE_CHI2,
    MEASUREMENT_FLOOR_M,
    MOTION_FLOOR,
    MOTION_LEVEL_MAX,
    REINIT_AFTER_REJECTS,
    REPORT_MAX_SIGMA_M,
    REPORT_WARMUP_S,
    REPORT_WARMUP_SIGMA_SIDES,
    STATE,
    block_noises,
    camera_psds,
    fits_its_corners,
    lens_px,
    prior_covariance,
    topside_psds,
)
from tracking.estimator.placement import camera_covariance, place_camera, place_topside
from tracking.estimator.process import Transition, orbit_psd, rate_decay
from tracking.estimator.state import CameraPoses, CameraState, FilterState
from tracking.geometry import inverse, numeric_jacobian, pose_params, pose_residual, rotation
from tracking.offsets import BodyObservation
from tracking.pose import BodyPose, Choice
from tracking.scale import ScaleEvidence, below_cones, survey_sample


class TopsideFilter(FilterState):
    """The Kalman filter of one installation: the topside and every camera of the rig."""

    def __post_init__(self) -> None:
        super().__post_init__()
        pairs: dict[str, list[tuple[int, int]]] = {}
        for pair in self.rig.all_pairs():
            pairs.setdefault(pair.cone, []).append((pair.jacket, pair.topside))
        self.disagreement = Disagreement(*self.cone_rows, pairs, side=self.rig.marker_size)  # the cameras' disagreement

    def predict(self, time: float, frame: Sequence[Measurement] = ()) -> Transition:
        """Move the state to a capture time and renew the corner biases of the views a frame's body observations will
        measure, by how far their markers' images moved; returns the transition used."""
        dt = 0.0 if self.time is None else max(0.0, time - self.time)
        blocks = 1 + len(self.cameras)
        a_cam, b_cam = rate_decay(dt, CAMERA_RATE_TAU_S)  # the topside keeps its speed, cameras' rates revert
        a, b = np.full((blocks, 6), a_cam), np.full((blocks, 6), b_cam)
        a[0], b[0] = 1.0, dt
        psds = np.zeros((blocks, 6, 6))  # a camera not placed: none
        psds[0] = np.diag(topside_psds(self.tuning))
        for k, cam in enumerate(self.cameras.values()):
            if cam.T_jacket_camera is not None:
                psds[1 + k] = self._camera_psd(cam)
        noise = block_noises(dt, psds)
        bodies = Transition(a, b, noise, np.ones(self.size - self.body_size), self.renewal)
        self.x = bodies.apply(self.x[:, None])[:, 0]
        self.P = bodies.covariance(self.P)
        self.fold_cameras()
        self.time = time if self.time is None else max(self.time, time)
        observations = [o for o in frame if isinstance(o, BodyObservation)]
        keep = renew(self, observations)
        self._jolts(observations, noise, dt)
        return Transition(a, b, noise, keep, self.renewal)

    def _camera_psd(self, cam: CameraState) -> np.ndarray:
        """(6, 6) a placed camera's acceleration psd: its mount's scaled by its motion level, and on a mount that
        orbits, where the level is only its images' (no turn of it measured) and it saw one jacket marker alone, its
        mount's whole prior along an orbit about that marker, which leaves its image where it was (a board turned
        before a webcam seen one marker a body, its fits ambiguous: the images' level lowered all of its noise, its
        pose swung away while the topside took the move, 141 mm off at σ 22 mm)."""
        psd = np.diag(camera_psds(self.tuning, cam.mount, cam.motion_scale))
        motion = self.tuning.motion(cam.mount)
        if motion.orbits and cam.motion_scale < 1.0 and cam.turned is None and cam.centre is not None and \
                cam.T_jacket_camera is not None:
            psd = psd + orbit_psd(cam.T_jacket_camera, cam.centre, (1.0 - cam.motion_scale) * motion.angular_accel_psd)
        return psd

    def _jolts(self, observations: list[BodyObservation], noise: np.ndarray, dt: float) -> None:
        """A camera whose jacket corners in this frame say it moved beyond its prior (measurements.jolted) gets its
        mount's whole process noise back at once, where its motion level had lowered it (the level's median takes
        seconds to rise): added to its predicted covariance and to noise (B, 12, 12), which the smoother replays."""
        for o in observations:
            cam = self.cameras.get(o.camera)
            if cam is None or cam.T_jacket_camera is None or cam.motion_scale >= 1.0:
                continue
            if jolted(self, cam, {i: z for i, z in o.corners.items() if i in self.jacket_corners}, o.K, o.time):
                k = cam.index // STATE
                extra = block_noises(dt, np.diag(camera_psds(self.tuning, cam.mount, 1.0 - cam.motion_scale))[None])[0]
                b = slice(cam.index, cam.index + STATE)  # (added to what it had: an orbit's noise beyond the prior
                self.P[b, b] += extra  # stays)
                noise[k] += extra
                cam.motion_scale = 1.0  # until its motion level next says otherwise
                self.jolts += 1

    def update(self, m: Measurement) -> bool:
        """Apply one measurement; False when (its topside part) was gated out or could not be used."""
        if isinstance(m, BodyObservation):
            return self.observe(m)
        if not self.last_accepted and m.choice == Choice.AMBIGUOUS:
            return False  # never start from a pose IPPE could not settle: nothing could gate it
        H = pair_rows(self, m)
        gain = AMBIGUOUS_VARIANCE_GAIN if m.choice == Choice.AMBIGUOUS else 1.0
        candidates = [(o - H @ self.x, c) for o, c in ((m.offset, m.covariance), *m.alternatives)]
        d2, y, R = nearest(self.P, candidates, H, gain, MEASUREMENT_FLOOR_M**2 * np.eye(3))
        if not np.isfinite(d2) or d2 > GATE_CHI2[3]:
            self._topside_rejected()
            return False
        self.apply(H, y, R)
        self.consecutive_rejects = 0
        self.last_accepted[m.camera] = m.time
        self.pair_seen[m.cone] = m.time
        self.topside_seen[m.topside_id] = m.time
        if self.placed_at is None:
            self.placed_at = m.time
        return True

    def _topside_rejected(self) -> None:
        self.rejected += 1
        self.consecutive_rejects += 1
        if self.consecutive_rejects >= REINIT_AFTER_REJECTS:  # lost: reopen, keep the state
            self.P[:STATE, :STATE] += prior_covariance(self.tuning)
            self.consecutive_rejects = 0

    def observe(self, o: BodyObservation) -> bool:
        """Apply one camera frame's marker corners; False when no topside corner of it was used.

        The corners are measured directly: each marker's four corners (8 pixel coordinates) against
        their projection through the camera's and the topside's poses in the state. The IPPE
        ambiguity of a lone marker never arises; poses only place a camera or the topside at first sight.
        """
        cam = self.cameras.get(o.camera)
        if cam is None:
            return False
        self._measure_scale(o)
        cam.corner_noise.add(o.jacket)
        cam.model_px = o.model_px
        cam.corner_noise.add(o.topside)
        placed = self.topside_placed
        lensed = replace(o, model_px=lens_px(o.model_px, cam.corner_noise))  # its lens floor's view of the frame
        residuals = self.disagreement.residuals(lensed, *((self.x, self.P) if placed else (None, None)))
        if cam.T_jacket_camera is None:
            if o.jacket is None:
                cam.waiting = "no jacket marker of the rig in its view (a camera is placed by the jacket's markers)"
                return False
            if not place_camera(self, cam, o):
                return False
        if not self.topside_placed and (o.topside is None or not place_topside(self, cam, o.topside)):
            o = replace(o, topside=None, corners={i: c for i, c in o.corners.items() if i in self.jacket_corners})
        if not placed and self.topside_placed:  # placed by this frame: its calibration's error holds from it on
            residuals = self.disagreement.residuals(lensed, self.x, self.P, counted=False)
        jacket = {i: z for i, z in o.corners.items() if i in self.jacket_corners}
        self._measure_motion(cam, o.time, jacket, o.K, o.jacket)
        topside = {i: z for i, z in o.corners.items() if i in self.topside_corners and self.topside_placed}
        renew(self, [o])  # when predict was not given the frame
        used_jacket = corner_update(self, cam, jacket, o.K, False, o.time)  # the camera first, then the topside
        if not used_jacket and o.jacket is not None and self._jumped(cam, o.jacket):  # moved beyond its prior:
            cam.T_jacket_camera = None  # placed again at this view, not refused frame after frame until lost
            self.reset_camera(cam)
            self.replacements += 1
            if place_camera(self, cam, o):
                used_jacket = corner_update(self, cam, jacket, o.K, False, o.time)
        used_topside = corner_update(self, cam, topside, o.K, True, o.time)  # through the camera just refined
        if o.jacket is not None:
            self._camera_refused(cam, used_jacket)
        if o.topside is not None and self.topside_placed and not used_topside:
            self.consecutive_rejects += 1
            if self.consecutive_rejects >= REINIT_AFTER_REJECTS:  # lost: place it again at its next view
                self.topside_placed = False
                self.consecutive_rejects = 0
        if used_topside:
            self.consecutive_rejects = 0
            self.last_accepted[o.camera] = o.time
            self.disagreement.record(residuals)
            if used_jacket:
                self._measured_pairs(o.time, jacket, topside)
        return used_topside

    def _jumped(self, cam: CameraState, view: BodyPose) -> bool:
        """Whether a placed camera moved beyond what its state allows: the pose its jacket view alone gives (two
        markers or more, unique, fitting its corners) lies outside the state's camera covariance plus its own (χ² over
        6 at GATE_CHI2). A rain-struck corner, which refuses the corners, leaves the view's own fit (outliers removed)
        where the state has the camera; a camera knocked or carried off does not. A lone far marker's pose is not
        trusted to say so: its covariance misses the biases of a view far off its normal."""
        if len(view.marker_ids) < 2 or view.choice != Choice.UNIQUE or \
                not fits_its_corners(view, cam.corner_noise.sigma_px):
            return False
        d = pose_residual(inverse(view.T_camera_body), self.camera_pose(cam))
        b = slice(cam.index, cam.index + 6)
        S = self.P[b, b] + camera_covariance(view.T_camera_body, view.covariance)
        return float(d @ np.linalg.solve(S, d)) > GATE_CHI2[6]

    def _camera_refused(self, cam: CameraState, used: bool) -> None:
        """Count a camera's jacket views refused in a row; at REINIT_AFTER_REJECTS it is lost, placed again later."""
        cam.consecutive_rejects = 0 if used else cam.consecutive_rejects + 1
        if cam.consecutive_rejects >= REINIT_AFTER_REJECTS:
            cam.T_jacket_camera = None
            cam.waiting = f"lost: its jacket corners were refused {REINIT_AFTER_REJECTS} frames in a row"
            self.reset_camera(cam)

    def _measure_motion(self, cam: CameraState, time: float, jacket: dict[int, np.ndarray], K: np.ndarray,
                        fit: BodyPose | None) -> None:
        """A frame's jacket corners and jacket fit into the camera's motion levels; its process noise scaled to the
        larger of them (its images' motion, its turns where measured). On a mount that orbits, a lone marker's fit
        gives turns too (a level of its own): a camera orbiting its one jacket marker keeps that marker's image still,
        and the image's level alone lowered its noise while its pose swung where one marker's corners barely tell
        (caliscope's webcams with one marker a body: poses 90 mm off at σ 10 mm, offsets 26 % beyond 3σ). Elsewhere a
        lone far marker's covariance misses its view's biases, which would read as turns (as in _jumped)."""
        prior = self.tuning.motion(cam.mount)
        if not prior.adapts or not jacket:
            return
        cam.motion.add(time, jacket, float(K[0, 0] + K[1, 1]) / 2)
        cam.centre = self.centres[next(iter(jacket))] if len(jacket) == 1 else None  # (several markers' corners
        # tell an orbit about them: their images turn against each other)
        if fit is not None and fit.choice == Choice.UNIQUE:  # (an ambiguous fit's turn may be the other option's)
            turns = cam.turns if len(fit.marker_ids) >= 2 else cam.lone_turns if prior.orbits else None
            if turns is not None:
                turns.add(time, fit.T_camera_body[:3, :3], float(np.trace(fit.covariance[:3, :3])) / 3)
        if cam.level is not None:  # the mount is a prior: what the camera's images show decides, up to the brisk
            cam.motion_scale = float(np.clip(cam.level / prior.angular_accel_psd, MOTION_FLOOR,
                                             max(1.0, MOTION_LEVEL_MAX / prior.angular_accel_psd)))

    def _measure_scale(self, o: BodyObservation) -> None:
        """A frame's evidence of the markers' size: two markers of one body in it, and a surveyed camera's distance to
        its jacket marker (the same for both IPPE options)."""
        for sample in o.scale:
            self.scale.add(sample, o.time)
        if o.camera not in self.surveys or o.jacket is None:
            return
        position, sigma = self.surveys[o.camera]
        T, cov = o.jacket.T_camera_body, o.jacket.covariance
        for i in o.jacket.marker_ids:
            c = self.centres[i]

            def distance(p: np.ndarray, c: np.ndarray = c) -> np.ndarray:
                return np.array([np.linalg.norm(rotation(p[:3]) @ c + p[3:])])

            p0 = pose_params(T)
            J = numeric_jacobian(distance, p0)
            surveyed = survey_sample(o.camera, i, float(distance(p0)[0]), float(np.sqrt(J @ cov @ J.T)[0, 0]),
                                   float(np.linalg.norm(position - c)), sigma, self.rig.marker_size)
            if surveyed is not None:
                self.scale.add(surveyed, o.time)

    def clock_bound(self, cameras: tuple[str, ...]) -> float:
        """σ, s, of the time an estimate resting on these cameras (all when none) is the topside's: the largest of their
        clocks' (rig: time_offset_sigma), a bound whatever their weights and signs (a share by weight is not honest:
        docs/method.md#clocks-and-the-marker-survey-sync-survey)."""
        return max((self.clock_sigma.get(c, 0.0) for c in cameras or self.clock_sigma), default=0.0)

    def contributing(self) -> tuple[str, ...]:
        """Cameras accepted within CONTRIBUTION_WINDOW_S of the current time."""
        now = self.time if self.time is not None else -np.inf
        return tuple(sorted(c for c, t in self.last_accepted.items() if now - t <= CONTRIBUTION_WINDOW_S))

    def measured(self) -> frozenset[str]:
        """The cones whose pair a camera's frame measured (both its markers used) within CONTRIBUTION_WINDOW_S of the
        current time: their offsets are measured there; the others' come through the rigid topside."""
        now = self.time if self.time is not None else -np.inf
        return frozenset(cone for cone, t in self.pair_seen.items() if now - t <= CONTRIBUTION_WINDOW_S)

    def _measured_pairs(self, time: float, jacket: Iterable[int], topside: Iterable[int]) -> None:
        """Note the pairs both of whose markers a frame showed, its jacket and topside corners both used."""
        seen = {*jacket, *topside}
        for cone, j, t in self.pair_ids:
            if j in seen and t in seen:
                self.pair_seen[cone] = time

    def seen_topside(self) -> frozenset[int]:
        """The topside markers measured within CONTRIBUTION_WINDOW_S of the last one measured: those the topside's pose
        rests on now, or did before a gap (its turn is no better known for it)."""
        last = max(self.topside_seen.values(), default=0.0)
        return frozenset(i for i, t in self.topside_seen.items() if last - t <= CONTRIBUTION_WINDOW_S)

    def warming(self) -> bool:
        """Whether the filter is within REPORT_WARMUP_S of the topside's (last) placement."""
        return self.placed_at is None or self.time is None or self.time - self.placed_at < REPORT_WARMUP_S

    def cone_estimates(self, x: np.ndarray | None = None, P: np.ndarray | None = None,
                       time: float | None = None, cameras: tuple[str, ...] | None = None,
                       warming: bool | None = None, floors: tuple[np.ndarray, np.ndarray] | None = None,
                       measured: frozenset[str] | None = None,
                       seen: frozenset[int] | None = None) -> list[ConeEstimate]:
        """Offset and covariance at every cone from a state (default: the current one), its variance per axis at least
        its cameras' disagreement (floors: (C, 3) variances and (C,) cones whose cameras are not yet compared,
        default: the current ones, tracking.estimator.disagreement), withholding cones whose σ exceeds
        REPORT_MAX_SIGMA_M, or REPORT_WARMUP_SIGMA_SIDES of a marker side while warming (default: whether the filter
        is now; after the warm-up, at a cone whose pair a camera measures (measured, default: now), only its axes
        beyond the limit), or whose cameras are not yet compared; from the current state, with the placed cameras'
        poses (a past state's are relative to nominals since moved). A past state without its floors gets none. The
        topside's turn about the axes the seen topside markers (seen, default: seen_topside) do not tell by their
        positions is held to σ ≥ TILT_FLOOR_RAD (FilterState.tilt_floor)."""
        poses = None if x is not None else CameraPoses(
            {name: (cam.T_jacket_camera, cam.index) for name, cam in self.cameras.items()
             if cam.T_jacket_camera is not None}, self.x[:self.body_size].copy())
        if floors is None:  # the current disagreement belongs to the current state alone
            floors = self.disagreement.floors(self.time or 0.0) if x is None else \
                (np.zeros((len(self.cone_rows[0]), 3)), np.zeros(len(self.cone_rows[0]), dtype=bool))
        x = self.x if x is None else x
        P = self.P if P is None else P
        time = (self.time if time is None else time) or 0.0
        added, pending = floors
        cameras = self.contributing() if cameras is None else cameras
        warming = self.warming() if warming is None else warming
        measured = self.measured() if measured is None else measured
        seen = self.seen_topside() if seen is None else seen
        limit = min(REPORT_MAX_SIGMA_M, REPORT_WARMUP_SIGMA_SIDES * self.rig.marker_size) if warming \
            else REPORT_MAX_SIGMA_M
        clock = self.clock_bound(cameras)
        out = []
        names, H = self.cone_rows
        covs = timeds = H @ P[:STATE, :STATE] @ H.transpose(0, 2, 1)  # (C, 3, 3)
        tilt = self.tilt_floor(seen, P[3:6, 3:6])
        if tilt is not None:  # first: the cameras' spread below is a floor on all of the σ
            covs = timeds = covs + tilt
        if added.any():  # σ at least the cameras' spread (the filter's own σ may hold it already)
            covs = timeds = covs + np.fmax(added - np.diagonal(covs, axis1=1, axis2=2), 0.0)[:, :, None] * np.eye(3)
        if clock:  # the estimate is the topside's at a time its cameras' clocks hold to σ: its motion over it
            speeds = H[:, :, :6] @ x[6:STATE]
            covs = covs + clock**2 * (speeds[:, :, None] * speeds[:, None, :]
                                      + H[:, :, :6] @ P[6:STATE, 6:STATE] @ H[:, :, :6].transpose(0, 2, 1))
        offsets = H @ x[:STATE]
        sds = np.sqrt(np.diagonal(covs, axis1=1, axis2=2)).tolist()  # (C, 3) σ per axis, and with exact clocks
        timed_sds = sds if timeds is covs else np.sqrt(np.diagonal(timeds, axis1=1, axis2=2)).tolist()
        mismatch = self.scale.mismatch  # every offset scaled: once a time, not once a cone
        for k, (cone, offset, cov, sd, timed_sd) in enumerate(zip(names, offsets, covs, sds, timed_sds, strict=True)):
            withheld = self._withheld(float(offset[2]), sd, timed_sd, limit, mismatch, bool(pending[k]), warming)
            if withheld in (WITHHELD_SIGMA, WITHHELD_CLOCKS) and cone in measured and not warming:  # its axes
                offset = np.where(np.array(sd) > limit, np.nan, offset)  # within the limit stay: one camera sees
                # height, not depth. Not at a cone no pair measures (its axes all lean on the topside's turn over tens
            elif withheld:  # of metres, where an error no σ holds grows), nor in the warm-up (its poses are not
                offset = np.full(3, np.nan)  # Gaussian): there, whole (docs/accuracy.md)
            out.append(ConeEstimate(time, cone, offset, cameras, cov, poses, withheld))
        return out

    def _withheld(self, dz: float, sd: list[float], timed_sd: list[float], limit: float, mismatch: bool,
                  comparing: bool = False, warming: bool = False) -> str:
        """Why a cone's offset of Δz dz and σ per axis sd (3,) is not shown (empty: it is): a rig error (mismatch: the
        markers are not the size the rig states), σ beyond limit (the clocks' fault when its σ with exact clocks,
        timed_sd, would have been shown; the warm-up's when warming and it is within REPORT_MAX_SIGMA_M), or a camera
        new to it not yet compared with the others (comparing)."""
        if mismatch:  # every offset scaled
            return WITHHELD_SCALE
        if below_cones(dz, sd[2]):  # no set-down can be there
            self.below = (self.below[0] + 1, min(self.below[1], dz))
            return WITHHELD_BELOW
        hard = REPORT_MAX_SIGMA_M if warming else limit  # what the cameras and clocks are judged by; the warm-up's
        if max(sd) > hard:  # tighter limit only says the filter is new
            return WITHHELD_CLOCKS if max(timed_sd) <= hard else WITHHELD_SIGMA
        if max(sd) > limit:
            return WITHHELD_WARMING
        return WITHHELD_COMPARING if comparing else ""


def misread_warning(camera: str, marker: int, departure_px: float) -> str:
    """A misread view's line: its camera, its marker and how far off one corner reads (twice the departure: one corner
    of four off by δ departs δ/2)."""
    return (f"{camera}: marker {marker}'s corners depart from a square's image by {departure_px:.2f} px all along "
            f"(one corner about {2 * departure_px:.1f} px off: a shadow's or a plate's edge across it, dirt, a bent "
            "plate, the lens model off there?); the filter trusts that view less")


@dataclass
class FilterReport:
    """What a run of the filter found besides its estimates, taken when the run ends: the cameras it never placed and
    why (each camera's CameraState.waiting), the markers' size against the rig's (tracking.scale), and the offsets it
    withheld for putting the topside through its cones, and the views whose corners it found misread."""

    unplaced: dict[str, str] = field(default_factory=dict)
    scale: ScaleEvidence = field(default_factory=ScaleEvidence)
    below: tuple[int, float] = (0, 0.0)  # estimates withheld as the topside through its cones, and the deepest Δz, m
    misread: dict[tuple[str, int], float] = field(default_factory=dict)  # (camera, marker) -> the departure, px, of
    # each view found misread (measurements.misread)

    def take(self, kf: TopsideFilter) -> None:
        """The findings of a filter at the end of its run."""
        self.unplaced = {name: cam.waiting for name, cam in kf.cameras.items() if cam.placed_at is None}
        self.scale = kf.scale
        self.below = kf.below
        self.misread = {key: v.misread_px for key, v in kf.views.items() if v.misread_px > 0.0}
