"""Where the fused filter's largest errors come from, on the accuracy benchmark's cached runs.

For every run (benchmarks/accuracy.py must have cached its renders and detections): the largest fused
error, when it happens (and the largest after the first 3 s of estimates), the filter's own σ there,
and the same filter given the simulator's true camera poses at every frame (a diagnosis only: the filter
never reads the truth). Then the filter on two altered copies of the detected corners, which separate the
size of the corner errors from their order in time: the same errors (detected minus true, truth_frames.csv)
shuffled in time within each camera and marker, and the true corners plus white Gaussian noise of the
errors' robust σ. Then how honest the filter's σ is (the share of errors beyond 2σ and 3σ: 4.6 % and 0.3 % for a
Gaussian), and, at the largest error, what one frame of each camera alone measures along that axis at that cone
(the σ from its own jacket and topside corners, with the topside and that camera free): a camera that sees one far
jacket marker barely fixes its swing about it, and the swing moves a topside marker at another depth sideways.
Results: benchmarks/results/fusion_diagnosis.md.

Run: .venv/bin/python benchmarks/fusion_diagnosis.py [--only config2-procedure5 ...]
"""

from __future__ import annotations

import argparse
import pickle
import sys
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))
from accuracy import CACHE, RESULTS, RUNS, WEATHER, detections_cache, measure, with_mounts

from tracking.estimator import TopsideFilter, filter_frame, frames, point_offset_matrix
from tracking.estimator.measurements import corner_jacobian
from tracking.estimator.noise import CORNER_NOISE_PX, STATE
from tracking.estimator.process import Transition
from tracking.evaluate import truth_at
from tracking.offsets import BodyObservation
from tracking.rig import load_rig
from tracking.sim.transforms import pose_to_T
from viewer.recording import TRUTH_POSE_AXES

OUT = RESULTS.parent / "fusion_diagnosis.md"
STARTUP_S = 3.0
SEED = 0
MAD_TO_SIGMA = 1.4826  # σ of a Gaussian from its median absolute deviation
ONE_FRAME_PRIOR = (1.0,) * 3 + (0.05,) * 3 + (1.0,) * 6  # m, rad: topside t, ω (the filter's rotation prior),
# then the camera's rotation and position: free
Detections = list[tuple[str, float, dict[int, np.ndarray]]]


class TrueCameras(TopsideFilter):
    """The filter with every camera's pose set to the truth at each step (its block decoupled, exact)."""

    truth: pd.DataFrame

    def predict(self, time: float, frame=()) -> Transition:
        F = super().predict(time, frame)
        assert self.x is not None and self.P is not None and self.time is not None
        t = self.truth["time"].to_numpy()
        for name, cam in self.cameras.items():
            cam.T_jacket_camera = pose_to_T(np.array([np.interp(self.time, t, self.truth[f"camera_{name}_{a}"])
                                                      for a in TRUTH_POSE_AXES]))
            b = slice(cam.index, cam.index + STATE)
            self.x[b] = 0.0
            self.P[b, :] = 0.0
            self.P[:, b] = 0.0
            self.P[b, b] = 1e-12 * np.eye(STATE)
        return F


def true_corners(scene: Path, min_unoccluded: float = 0.0) -> dict[tuple[str, float, int], np.ndarray]:
    """(camera, capture time rounded to ms, marker) -> the simulator's (4, 2) corners, distorted pixels, of the
    markers with more than min_unoccluded of their area in sight."""
    tf = pd.read_csv(scene / "truth_frames.csv").dropna(subset=["marker_id"])
    tf = tf[tf["unoccluded"] > min_unoccluded] if min_unoccluded > 0 else tf
    corners = tf[[f"c{i}{a}" for i in range(4) for a in "xy"]].to_numpy().reshape(-1, 4, 2)
    keys = zip(tf["camera"], tf["capture_time"].round(3), tf["marker_id"].astype(int), strict=True)
    return dict(zip(keys, corners, strict=True))


def altered(detections: Detections, truth: dict[tuple[str, float, int], np.ndarray], how: str) -> Detections:
    """The detections with their corner errors shuffled in time per camera and marker ("shuffled"), or
    replaced by white Gaussian noise of the errors' robust σ ("white")."""
    rng = np.random.default_rng(SEED)
    err = {(c, round(t, 3), i): np.asarray(z, float).reshape(4, 2) - truth[(c, round(t, 3), i)]
           for c, t, found in detections for i, z in found.items()}
    if how == "shuffled":
        series: dict[tuple[str, int], list] = {}
        for c, t, i in err:
            series.setdefault((c, i), []).append((c, t, i))
        new = {}
        for keys in series.values():
            for k, j in zip(keys, rng.permutation(len(keys)), strict=True):
                new[k] = err[keys[j]]
    else:
        e = np.stack(list(err.values())).reshape(-1)
        sigma = MAD_TO_SIGMA * float(np.median(np.abs(e - np.median(e))))
        new = {k: rng.normal(0.0, sigma, (4, 2)) for k in err}
    return [(c, t, {i: (truth[(c, round(t, 3), i)] + new[(c, round(t, 3), i)]).astype(np.float32)
                    for i in found}) for c, t, found in detections]


def errors(kf: TopsideFilter, measurements: list, truth: pd.DataFrame, monitored: list[str]) -> pd.DataFrame:
    """Per reported estimate at a monitored cone: time, cone, error (m) and σ per axis."""
    rows = []
    for group in frames(measurements):
        for e in filter_frame(kf, group):
            if e.cone in monitored and np.isfinite(e.offset).all():
                err = e.offset - truth_at(truth, e.cone, np.array([e.time]))[0]
                rows.append((e.time, e.cone, *err, *np.sqrt(np.diag(e.covariance))))
    return pd.DataFrame(rows, columns=["time", "cone", "ex", "ey", "ez", "sx", "sy", "sz"])


def consistency(df: pd.DataFrame) -> str:
    """Share of errors (every axis) beyond 2σ and 3σ of the filter's own σ, %."""
    z = np.abs(df[["ex", "ey", "ez"]].to_numpy() / df[["sx", "sy", "sz"]].to_numpy())
    return f"{100 * (z > 2).mean():.1f} / {100 * (z > 3).mean():.2f}"


def one_frame_sigmas(rig, measurements: list, df: pd.DataFrame) -> str:
    """At the largest error: σ (mm) of that cone's offset along that axis from one frame of each camera alone, its
    last frame before then (its jacket and topside corners; the topside and the camera free, linearised at the
    filter's state there)."""
    e = df[["ex", "ey", "ez"]].abs().to_numpy()
    i, axis = np.unravel_index(np.argmax(e), e.shape)
    when, cone = df.iloc[i].time, df.iloc[i].cone
    kf = TopsideFilter(rig)
    last: dict[str, BodyObservation] = {}
    for group in frames(measurements):
        if group[0].time > when:
            break
        filter_frame(kf, group)
        last.update({m.camera: m for m in group if isinstance(m, BodyObservation)})
    c = point_offset_matrix(kf.cones[cone])[axis, :6]
    out = []
    for name, o in sorted(last.items()):
        cam = kf.cameras[name]
        if cam.T_jacket_camera is None or not kf.topside_placed:
            continue
        columns = [*range(6), *range(cam.index, cam.index + 6)]
        H = np.vstack([corner_jacobian(kf, cam.T_jacket_camera, cam.index, marker, kf.x, o.K, columns)[1]
                       for marker in o.corners])
        info = H.T @ H / CORNER_NOISE_PX**2 + np.diag(1.0 / np.square(ONE_FRAME_PRIOR))
        cov = np.linalg.inv(info)[:6, :6]
        out.append(f"{name} {np.sqrt(c @ cov @ c) * 1e3:.0f}")
    return ", ".join(out) or "—"


def worst(df: pd.DataFrame) -> str:
    """The largest error: mm, axis, cone, time, and |e|/σ there."""
    if df.empty:
        return "—"
    e = df[["ex", "ey", "ez"]].abs().to_numpy()
    i, k = np.unravel_index(np.argmax(e), e.shape)
    r = df.iloc[i]
    sd = r[["sx", "sy", "sz"]].to_numpy()[k]
    return f"{e[i, k] * 1e3:.0f} ({'xyz'[k]}, {r.cone}, {r.time:.1f} s, {e[i, k] / sd:.1f}σ)"


def main() -> None:
    """Diagnose every cached run and write the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", nargs="*", default=None)
    args = parser.parse_args()
    lines = ["# Where the fused filter's largest errors come from", "",
             "Fused (live) filter on the accuracy benchmark's runs (fog 50 %, rain 30 %, 15 FPS). Largest error "
             f"over the run and after the first {STARTUP_S:g} s of estimates, mm (axis, cone, capture time, and "
             "the error over the filter's own σ there); σ_e per axis; and the same filter given the simulator's "
             "true camera poses (diagnosis only). Then the filter on the detected corner errors shuffled in time (per "
             "camera and marker: same errors, no order) and on the true corners plus white noise of the errors' robust "
             "σ. Last, the share of errors beyond 2σ / 3σ of the filter's own σ (a Gaussian: 4.6 / 0.27 %), and at "
             "the largest error, the σ along its axis at its cone from one frame of each camera alone (its last frame "
             "before then; its own jacket and topside corners, the topside and that camera free).", "",
             "| run | largest | after the start | σ_e x/y/z [mm] | true cameras: largest | true cameras: σ_e | "
             "errors shuffled: largest | white noise: largest | beyond 2σ / 3σ [%] | one frame per camera at the "
             "largest: σ [mm] |",
             "| --- | --- | --- | ---: | --- | ---: | --- | --- | ---: | --- |"]
    for name in RUNS:
        if args.only is not None and name not in args.only:
            continue
        scene = CACHE / f"{name}{WEATHER}-15fps"
        cache = detections_cache(scene)
        if not cache.is_file():
            continue
        rig = with_mounts(load_rig(scene / "rig.yaml"), name)
        detections = pickle.loads(cache.read_bytes())
        measurements = measure(rig, detections)
        truth = pd.read_csv(scene / "truth.csv")
        monitored = rig.paired_cones()
        fused = errors(TopsideFilter(rig), measurements, truth, monitored)
        oracle = TrueCameras(rig)
        oracle.truth = truth
        exact = errors(oracle, measurements, truth, monitored)
        corners = true_corners(scene)
        shuffled, white = (errors(TopsideFilter(rig), measure(rig, altered(detections, corners, how)), truth,
                                  monitored) for how in ("shuffled", "white"))
        late = fused[fused["time"] > fused["time"].min() + STARTUP_S]

        def sd(df: pd.DataFrame) -> str:
            return "/".join(f"{df[c].std() * 1e3:.1f}" for c in ("ex", "ey", "ez"))

        lines.append(f"| {name} | {worst(fused)} | {worst(late)} | {sd(fused)} | {worst(exact)} | {sd(exact)} | "
                     f"{worst(shuffled)} | {worst(white)} | {consistency(fused)} | "
                     f"{one_frame_sigmas(rig, measurements, fused)} |")
        print(lines[-1], flush=True)
    OUT.write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
