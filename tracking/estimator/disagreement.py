"""How much the cameras that see a cone disagree beyond their noise: a floor under the cone's σ.

The filter weighs each camera's frames as if the part of their errors it does not model as persistent (the views'
biases) averaged away over time. A camera's model error does not (a calibration that maps one part of the picture
a few tenths of a pixel off, a board that is not flat): real webcams' own offsets keep means 1-2 mm apart for a
whole session where one frame's σ is 1-2 mm (caliscope's 4_cam_recording), and the filter's σ then shrank to a
tenth of its error. Different cameras' model errors differ, so they show as cameras whose offsets disagree, which
the filter's σ alone does not say.

Each camera frame that shows a pair (both its markers) and whose two fits IPPE settled gives its own offset at the
pair's cone, from its T_jacket_topside, linear in the pose as the filter's offsets are (point_offset_matrix); its
residual r (3,) against the filter's before the frame (kept where the filter used the frame's topside corners), and
its σ² from the fits' covariances and the filter's own. Per camera and cone, a mean and variance of r weighted by
the residuals' precision (1 / σ²: a frame of a far or grazing view, or one while the filter still settles, counts
little) and by age (time constant DISAGREEMENT_TAU_S), and its effective number of frames n. Over the cameras of a
cone with DISAGREEMENT_MIN_FRAMES or more, seen within DISAGREEMENT_WINDOW_S, that carry DISAGREEMENT_MIN_SHARE of
its estimate or more (w_c: their frames over their residuals' scatter, so a poor view's own error is not taken for
the others'), the random-effects estimate of the variance of their persistent errors, per axis: B = var_c(mean_c) -
mean_c(var_c / n_c), where it is significant (var_c(mean_c) beyond the noise term's DISAGREEMENT_P quantile), else
0. The estimate holds each camera's error in its share w_c, so its error's variance is B Σ w_c²: a cone's reported
variance is at least that. Cameras that agree, or a cone one camera sees, add nothing. A cone that a camera new to
it sees is not shown until that camera is compared, for DISAGREEMENT_WAIT_S at most (the first frames of two webcams
put the board's halves 5-10σ apart before anything said they disagree; a third joining later pulled them 5σ off).

A camera alone, or cameras not yet compared, show no disagreement, yet each carries its calibration's error: the RMS
reprojection error the calibration states, or an assumed one where it states none (model_px, CameraModel.model_px).
Each frame's offsets also carry the covariance that error gives them at each cone (_lens_at): across the camera's
line of sight, where it shifts the markers' images, and along it, where it scales them (a marker's depth is read from
its image's size: Z / S times looser). Across, weighted as the residuals are, a cone's variance is at least Σ share² of
its cameras' (their residuals' weights aged to now). Along, where no two cameras are compared (their disagreement
then measures what their lenses leave), each camera's through its weight in the estimate by information, W_c =
(Σ Λ)⁻¹ Λ_c (its frames' offset covariance from its fits, inverted, aged as the residuals): a camera alone gives all
of its depth error, a second camera at an angle carries the first one's depth by its own cross-sight. Or the
disagreement's floor where that is more.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from statistics import NormalDist

import numpy as np

from tracking.estimator.noise import chi2_quantile
from tracking.estimator.state import STATE
from tracking.geometry import inverse, rotation_jacobian_of, rotvec, skew
from tracking.offsets import BodyObservation
from tracking.pose import Choice

DISAGREEMENT_TAU_S = 5.0  # s: a camera's model error stays while its view of the markers does (seconds at least);
# shorter than a lift's phases, so a camera whose view changed is judged on its new view
DISAGREEMENT_MIN_FRAMES = 2.5  # frames weighed by age (three recent ones) before a camera's noise is told from its
# bias: half a second of 6 fps webcams
DISAGREEMENT_MIN_SHARE = 0.1  # a camera whose frames carry less of a cone's estimate is not compared: its own bias
# moves the estimate little, and a view that much poorer disagrees by its own error (a far stern camera 70 mm off where
# the near one carrying 98 % of the estimate agrees with it)
DISAGREEMENT_WINDOW_S = 2.0  # a camera counts for a cone while its last frame of it is this recent
DISAGREEMENT_WAIT_S = 0.5  # a cone waits this long at most for a camera new to it to be compared (a camera whose fits
# are ambiguous, or that shows the cone for a frame or two, must not hide it for long)
LENS_SHARE = float(np.sqrt(2.0))  # (no unit) × a calibration's RMS reprojection error × depth / f: how far a
# camera's own offset at a cone is off an axis across its line of sight, for as long as its markers stay in that part
# of the picture (no number of its frames averages it away). Each marker's image is taken as missed by model_px an
# axis (the RMS read as each axis's σ, as the corners' noise reads it: measurements._corner_covariance), its two
# markers' misses apart: √2. OpenCV's RMS is the 2-D miss's length, so that reading is √2 conservative; read per axis
# (model_px / √2, LENS_SHARE 1), caliscope's post_monocal kept 9.7 % of its Δy errors beyond 3σ in its first seconds.
# Along the line of sight the same miss scales a marker's image of side S by √2 model_px over its f S / Z pixels: its
# depth off by Z / S times as much (caliscope's 4_cam_recording, cam_0 alone at 16 sides: Δy 2.5 mm off for seconds
# at σ 0.6 mm, 54 % of its errors beyond 3σ, when nothing took its depth to be off; about 3 mm with it)
INFO_FLOOR_M = 1e-6  # σ added to a frame's offset covariance before it is inverted into information (a fit's
# covariance is positive definite; this keeps a degenerate one finite)
DISAGREEMENT_P = 0.95  # the cameras' means must scatter beyond what their noise gives at this probability (χ² over
# cameras - 1 degrees of freedom) before their spread counts: unbiased cameras must not widen σ by chance


@dataclass
class _Moments:
    """Exponentially weighted moments of one camera's residuals at one cone."""

    time: float
    count: float = 0.0  # its frames, each weighed by age alone
    known: bool = False  # it once had DISAGREEMENT_MIN_FRAMES: back after a gap, its noise is known
    w: float = 0.0  # Σ weights
    w2: float = 0.0  # Σ weights²
    s1: np.ndarray = field(default_factory=lambda: np.zeros(3))  # Σ w r
    s2: np.ndarray = field(default_factory=lambda: np.zeros(3))  # Σ w r²
    s_across: np.ndarray = field(default_factory=lambda: np.zeros(3))  # Σ w diag(L): its calibration's error across
    s_along: np.ndarray = field(default_factory=lambda: np.zeros((3, 3)))  # Σ w L: ... and along its line of sight, m²
    info: np.ndarray = field(default_factory=lambda: np.zeros((3, 3)))  # Σ Λ: its frames' information at the cone
    w_lens: float = 0.0  # Σ weights of the frames its lens terms hold (the residuals' and the placing frame's)

    def add(self, time: float, r: np.ndarray, weight: float, lens: tuple[np.ndarray, np.ndarray],
            info: np.ndarray, counted: bool = True) -> None:
        """A frame's residual r (3,) of weight 1 / σ², its lens terms (across (3,), along (3, 3)) and information; not
        counted: its lens terms alone (the frame that placed the topside, its residual against itself)."""
        k = self.aged(time)
        c = 1.0 if counted else 0.0
        self.count = k * self.count + c
        self.known = self.known or self.count >= DISAGREEMENT_MIN_FRAMES
        self.w, self.w2 = k * self.w + c * weight, k * k * self.w2 + c * weight * weight
        self.s1, self.s2 = k * self.s1 + c * weight * r, k * self.s2 + c * weight * r * r
        self.w_lens = k * self.w_lens + weight
        self.s_across = k * self.s_across + weight * lens[0]
        self.s_along = k * self.s_along + weight * lens[1]
        self.info = k * self.info + info
        self.time = time

    @property
    def frames(self) -> float:
        """Effective number of frames, (Σw)² / Σw²."""
        return self.w * self.w / self.w2 if self.w2 else 0.0

    @property
    def mean(self) -> np.ndarray:
        return self.s1 / self.w

    @property
    def across(self) -> np.ndarray:
        """(3,) variance its calibration's error gives its offset at the cone across its line of sight, m² (weighted
        as its residuals)."""
        return self.s_across / self.w_lens

    @property
    def along(self) -> np.ndarray:
        """(3, 3) covariance the same error gives it along its line of sight, m²."""
        return self.s_along / self.w_lens

    def aged(self, time: float) -> float:
        """How much of its sums still counts at a time (DISAGREEMENT_TAU_S since its last frame)."""
        return float(np.exp(-max(0.0, time - self.time) / DISAGREEMENT_TAU_S))

    @property
    def scatter(self) -> np.ndarray:
        """(3,) variance of one frame's residual about the mean."""
        return np.maximum(self.s2 / self.w - self.mean**2, 0.0)

    @property
    def noise(self) -> np.ndarray:
        """(3,) variance of the mean from the residuals' scatter."""
        return self.scatter / max(self.frames - 1.0, 1.0)


@dataclass(frozen=True)
class Residuals:
    """One camera frame's view of the cones: those its two fits show (indices), and its residual (3,), weight (1 /
    σ²), the variance its calibration's error gives there (across its line of sight (3,), along it (3, 3)) and its own
    offset's information (3, 3, the inverse of its fits' covariance there), at each where the filter had an
    estimate."""

    camera: str
    time: float
    seen: list[int]
    residuals: list[tuple[int, np.ndarray, float, tuple[np.ndarray, np.ndarray], np.ndarray]]
    counted: bool = True  # False: its lens terms alone count (the frame that placed the topside: its own state)


@dataclass
class Disagreement:
    """The cameras' residuals at each cone (names and H: the cones in the filter's order, FilterState.cone_rows;
    pairs: per cone the (jacket, topside) marker ids whose view shows it)."""

    names: list[str]
    H: np.ndarray  # (C, 3, 12) the cones' offsets from the topside's state (point_offset_matrix)
    pairs: dict[str, list[tuple[int, int]]]
    moments: dict[tuple[str, str], _Moments] = field(default_factory=dict)  # (camera, cone) ->
    first_seen: dict[tuple[str, str], float] = field(default_factory=dict)  # (camera, cone) -> of its first
    by_cone: dict[int, dict[str, float]] = field(default_factory=dict)  # cone index -> camera -> its last view
    versions: dict[int, int] = field(default_factory=dict)  # cone index -> residuals kept so far
    _cache: dict[int, tuple] = field(default_factory=dict)  # cone index -> ((cameras, version), its floor (3,))
    points: np.ndarray = field(init=False)  # (C, 3) the cones' points in the jacket frame (H's [:, 3:6] = -[r]×)
    lensed: bool = False  # a camera's calibration error (model_px) is above 0: until then no cone has a lens floor
    side: float = 0.0  # the markers' side, m (rig.marker_size): their depth is read from their images' size; 0: the
    # lens error taken across the line of sight alone

    def __post_init__(self) -> None:
        self.points = -np.stack([self.H[:, 2, 4], self.H[:, 0, 5], self.H[:, 1, 3]], axis=1)

    def residuals(self, o: BodyObservation, x: np.ndarray | None, P: np.ndarray | None = None,
                  counted: bool = True) -> Residuals:
        """A camera frame's own offset at each cone whose pair it shows, against the state x's (n,) with covariance P
        before the frame (None: the topside not placed yet, the view only noted); kept by record. A frame whose fit
        IPPE could not settle gives nothing (its pose may be the wrong one of two). Not counted: against the state
        the frame itself placed, which only its lens terms hold anything of."""
        if o.jacket is None or o.topside is None or Choice.AMBIGUOUS in (o.jacket.choice, o.topside.choice):
            return Residuals(o.camera, o.time, [], [])
        seen = [k for k, cone in enumerate(self.names) if any(j in o.jacket.marker_ids and t in o.topside.marker_ids
                                                              for j, t in self.pairs.get(cone, ()))]
        if not seen or x is None or P is None:
            return Residuals(o.camera, o.time, seen, [])
        return Residuals(o.camera, o.time, seen, self._posed(o, seen, x, P), counted)

    def _posed(self, o: BodyObservation, seen: list[int], x: np.ndarray, P: np.ndarray
               ) -> list[tuple[int, np.ndarray, float, tuple[np.ndarray, np.ndarray], np.ndarray]]:
        """Residuals at the cones from the frame's T_jacket_topside (its two fits), linear in the pose as the
        filter's offsets are (point_offset_matrix), with their σ² from the fits' covariances (first order), the
        covariance the camera's calibration error gives there (_lens_at) and the frame's information there."""
        assert o.jacket is not None and o.topside is not None
        T = inverse(o.jacket.T_camera_body) @ o.topside.T_camera_body
        own = np.zeros(STATE)
        own[:3], own[3:6] = T[:3, 3], rotvec(T[:3, :3])
        G = relative_pose_jacobian(o.jacket.T_camera_body, o.topside.T_camera_body)  # (6, 12)
        cov = G[:, :6] @ o.jacket.covariance @ G[:, :6].T + G[:, 6:] @ o.topside.covariance @ G[:, 6:].T
        H = self.H[seen]  # (S, 3, 12)
        C = np.einsum("sij,jk,slk->sil", H[:, :, :6], cov, H[:, :, :6])  # (S, 3, 3) the fits' covariance at each cone
        fits = np.trace(C, axis1=1, axis2=2)  # their σ²
        filtered = np.einsum("sij,jk,sik->s", H, P[:STATE, :STATE], H)  # and the filter's own
        across, along = _lens_at(o, self.points[seen], self.side)  # (S, 3) and (S, 3, 3)
        self.lensed = self.lensed or o.model_px > 0.0
        residuals = H @ (own - x[:STATE])
        return [(k, residuals[i], 1.0 / v, (across[i], along[i]), np.linalg.inv(C[i] + INFO_FLOOR_M**2 * np.eye(3)))
                for i, (k, v) in enumerate(zip(seen, fits + filtered, strict=True))
                if np.isfinite(v) and v > 1e-18 and np.isfinite(residuals[i]).all() and np.isfinite(C[i]).all()]
        # a NaN would stay for good

    def record(self, r: Residuals) -> None:
        """Keep a frame's residuals: the filter used its topside corners (a view it refused makes no estimate)."""
        for k in r.seen:
            key = (r.camera, self.names[k])
            self.by_cone.setdefault(k, {})[r.camera] = r.time
            self.first_seen.setdefault(key, r.time)
        for k, residual, weight, lens, info in r.residuals:
            key = (r.camera, self.names[k])
            if key not in self.moments:
                self.moments[key] = _Moments(r.time)
            self.moments[key].add(r.time, residual, weight, lens, info, r.counted)
            self.versions[k] = self.versions.get(k, 0) + 1

    def floors(self, time: float) -> tuple[np.ndarray, np.ndarray]:
        """(C, 3) variance, m², each cone's σ² is at least for its cameras' disagreement at a time, or for their
        calibrations' error where that is more (_lens); and (C,) whether a cone waits for a camera new to it to be
        compared (DISAGREEMENT_WAIT_S at most)."""
        out, pending = np.zeros((len(self.names), 3)), np.zeros(len(self.names), dtype=bool)
        for k, cameras in self.by_cone.items():
            recent = self._recent(k, time)
            cone = self.names[k]
            ms = {c: self.moments.get((c, cone)) for c in recent}
            if len(recent) >= 2:
                pending[k] = any((m is None or not m.known) and time - self.first_seen[(c, cone)] <=
                                 DISAGREEMENT_WAIT_S for c, m in ms.items())  # a camera new to it, its noise unknown
            disagreement, kept = self._compare(k, ms)
            if self.lensed:  # every camera that made the estimate, not only recent ones: its error stays; along the
                # line of sight assumed only where no two cameras are compared (their disagreement measures it)
                held = [m for c in cameras if (m := self.moments.get((c, cone))) is not None and m.w_lens > 0.0]
                out[k] = _lens(held, time, along=kept < 2)
            out[k] = np.maximum(out[k], disagreement)
        return out, pending

    def _recent(self, k: int, time: float) -> list[str]:
        """The cameras whose last view of cone k is within DISAGREEMENT_WINDOW_S of a time."""
        return [c for c, t in self.by_cone.get(k, {}).items() if time - t <= DISAGREEMENT_WINDOW_S]

    def _compare(self, k: int, ms: dict[str, _Moments | None]) -> tuple[np.ndarray, int]:
        """(3,) the disagreement floor of cone k's recent cameras (ms: camera -> its moments there) and how many
        cameras it compared (those with frames enough that carry DISAGREEMENT_MIN_SHARE of the estimate), cached
        while their moments stay."""
        compared = {c: m for c, m in ms.items() if m is not None and m.count >= DISAGREEMENT_MIN_FRAMES}
        if len(compared) < 2:
            return np.zeros(3), 0
        key = (tuple(compared), self.versions.get(k, 0))
        if self._cache.get(k, (None,))[0] != key:  # the moments changed since: compare again
            self._cache[k] = (key, _compared(list(compared.values())))
        return self._cache[k][1]


def lens_sigmas(d: Disagreement, cone: str, time: float) -> dict[str, np.ndarray]:
    """Per camera that has shown a cone's pair, the σ (3,) its calibration's error gives the cone's estimate at
    a time, m: its own (_lens_at, as its frames weighed it) through its weight in the estimate (_lens_parts), along
    its line of sight too where no two cameras are compared (as Disagreement.floors)."""
    k = d.names.index(cone)
    _, kept = d._compare(k, {c: d.moments.get((c, cone)) for c in d._recent(k, time)})
    ms = {c: m for (c, name), m in d.moments.items() if name == cone and m.w_lens > 0.0}
    parts = _lens_parts(list(ms.values()), time, along=kept < 2)
    return {c: np.sqrt(part) for c, part in zip(ms, parts, strict=True)}


def relative_pose_jacobian(T_camera_jacket: np.ndarray, T_camera_topside: np.ndarray) -> np.ndarray:
    """(6, 12) first-order change of T_jacket_topside = T_camera_jacket⁻¹ T_camera_topside, as its translation and a
    rotation vector turning it in the jacket frame, with the two poses' (rvec, tvec) each (the fits' covariances'
    parameters): δt = Rⱼᵀ (δt_t - δt_j) + Rⱼᵀ [t_t - t_j]× φⱼ, ψ = Rⱼᵀ (φ_t - φⱼ), φ = L(rvec) δrvec the turn in the
    camera (L from OpenCV's Rodrigues Jacobian)."""
    R_j = T_camera_jacket[:3, :3]
    L_j, L_t = _turn(rotvec(R_j)), _turn(rotvec(T_camera_topside[:3, :3]))
    G = np.zeros((6, 12))
    G[:3, 0:3] = R_j.T @ skew(T_camera_topside[:3, 3] - T_camera_jacket[:3, 3]) @ L_j
    G[:3, 3:6], G[:3, 9:12] = -R_j.T, R_j.T
    G[3:, 0:3], G[3:, 6:9] = -R_j.T @ L_j, R_j.T @ L_t
    return G


def _turn(rvec: np.ndarray) -> np.ndarray:
    """(3, 3) L: the turn φ (3,) in the parent frame that a change δrvec of a rotation vector makes, φ = L δrvec."""
    R, dR = rotation_jacobian_of(rvec)
    turns = dR @ R.T  # (3, 3, 3): [φ_k]× per rotation-vector component
    return np.stack([turns[:, 2, 1], turns[:, 0, 2], turns[:, 1, 0]])  # rows: φ's axes; columns: δrvec's


def _lens_at(o: BodyObservation, points: np.ndarray, side: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """The variance, jacket frame, m², of a frame's own offsets at cones at points (S, 3) (jacket frame) that its
    camera's calibration error gives, at each one's depth Z along the unit line of sight l: across the line of sight
    the diagonal (S, 3) of s² (I - l lᵀ), s = LENS_SHARE × model_px × Z / f, and along it (s Z / side)² l lᵀ (S, 3, 3)
    for markers of that side (side 0: none; nothing at 0 px, an exact calibration's)."""
    assert o.jacket is not None
    f = float(o.K[0, 0])
    if not (o.model_px > 0.0 and np.isfinite(o.model_px) and f > 0.0):
        return np.zeros((len(points), 3)), np.zeros((len(points), 3, 3))
    T = o.jacket.T_camera_body  # T_camera_jacket
    p = points @ T[:3, :3].T + T[:3, 3]  # (S, 3) the cones in the camera
    depth = np.maximum(p[:, 2], 0.0)
    sight = p / np.maximum(np.linalg.norm(p, axis=1, keepdims=True), 1e-9) @ T[:3, :3]  # (S, 3) in the jacket frame
    s2 = (LENS_SHARE * o.model_px * depth / f) ** 2
    along = s2 * (depth / side) ** 2 if side > 0.0 else np.zeros_like(s2)
    return s2[:, None] * (1.0 - sight**2), along[:, None, None] * sight[:, :, None] * sight[:, None, :]


def _shares(ms: list[_Moments], time: float) -> np.ndarray:
    """(M,) each camera's share of a cone's estimate at a time: its residuals' weight, aged to then."""
    w = np.array([m.w_lens * m.aged(time) for m in ms])
    return w / w.sum() if w.sum() > 0.0 else np.zeros(len(ms))


def _lens_parts(ms: list[_Moments], time: float, along: bool = True) -> list[np.ndarray]:
    """(3,) per camera: the variance its calibration's error gives a cone's estimate at a time, m². Across its line
    of sight, its own in its share of the estimate (_shares), squared; along it (where along), W L Wᵀ's diagonal with
    its weight W = (Σ Λ)⁻¹ Λ_c by the cameras' information there (aged to then): a marker's size reads its depth Z / S
    times looser than its image's place, so another camera's cross-sight, not its share, carries that axis."""
    if not ms:
        return []
    across = [share**2 * m.across for share, m in zip(_shares(ms, time), ms, strict=True)]
    if not along:
        return across
    info = [m.info * m.aged(time) for m in ms]
    weights = np.linalg.pinv(np.sum(info, axis=0)) @ np.stack(info)  # (M, 3, 3) W_c
    return [a + np.diagonal(W @ m.along @ W.T) for a, W, m in zip(across, weights, ms, strict=True)]


def _lens(ms: list[_Moments], time: float, along: bool = True) -> np.ndarray:
    """(3,) variance of a cone's estimate's error its cameras' calibrations give at a time, m²: the sum of their
    parts (_lens_parts); a camera alone gives all of its own."""
    if not ms:
        return np.zeros(3)
    return np.sum(_lens_parts(ms, time, along), axis=0)


def _compared(ms: list[_Moments]) -> tuple[np.ndarray, int]:
    """(3,) variance of the estimate's error the persistent disagreement of cameras with frames enough gives, m², and
    how many of them carry enough of the estimate to be compared."""
    if len(ms) < 2:
        return np.zeros(3), 0
    precision = np.array([m.frames / max(float(m.scatter.sum()), 1e-12) for m in ms])
    keep = precision >= DISAGREEMENT_MIN_SHARE * precision.sum()  # the cameras that make the estimate
    ms, precision = [m for m, kept in zip(ms, keep, strict=True) if kept], precision[keep]
    if len(ms) < 2:
        return np.zeros(3), len(ms)
    means = np.array([m.mean for m in ms])
    between = means.var(axis=0, ddof=1)
    noise = np.mean([m.noise for m in ms], axis=0)
    dof = len(ms) - 1
    significant = chi2_quantile(dof, DISAGREEMENT_P) / dof if dof > 1 else \
        NormalDist().inv_cdf((1.0 + DISAGREEMENT_P) / 2.0) ** 2  # one degree of freedom: a squared normal
    shares = precision / precision.sum()  # each camera's share of the estimate
    return np.where(between > significant * noise, between - noise, 0.0) * float(shares @ shares), len(ms)
