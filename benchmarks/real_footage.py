"""The tracker on real footage: ../shared/data/caliscope's two sessions (four webcams, a hand-held ChArUco board
printed white on black, MPEG-4 at 20-37 KB a frame, each frame's real capture time). The board's upper five markers
are the "topside", its lower five the "jacket" (benchmarks/real/build.py): the true offset is zero at every instant.

Per session: markers found per camera against plain OpenCV (ArucoDetector, inverted markers allowed, default
parameters) and the detections dropped as possibly mirrored; the fused and smoothed offsets' error against zero
(e_MAE, |e|max per axis, in mm and in % of the marker side; share within 2σ and beyond 3σ; availability: the share of
camera frames seeing both groups at whose capture time an offset is shown); a plain-OpenCV baseline on the same frames
(each marker's pose alone with IPPE, every jacket/topside pair's relative offset, no filter); and the fused offsets with
the containers' nominal presentation times instead of the times files. Results: benchmarks/results/real_footage.md.

Run: .venv/bin/python benchmarks/real_footage.py; with --sessions FOLDER... other caliscope sessions (its repository's
tests/sessions: 4_cam_recording, post_monocal, charuco_calibration_2_cam) into real_footage-caliscope.md. With
--each-camera, every camera tracked alone (a rig of that camera only: one view's depth, as a cone one camera sees),
its offsets' figures and why the rest of its frames were not shown, into real_footage-each-camera.md. With --pairs,
every stacked pair of the board alone (one jacket marker and the topside marker above it: one marker a body, as a
cone's pair offshore), all cameras fused, into real_footage-pairs.md.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from collections import Counter
from dataclasses import replace
from pathlib import Path

import av
import cv2
import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from tracking.estimator import ESTIMATORS
from tracking.geometry import rt_to_T
from tracking.outputs import write_text
from tracking.pipeline import TrackStats, track_rig
from tracking.rig import Rig, load_rig

REPO = Path(__file__).resolve().parents[1]
REAL = REPO / "benchmarks" / "real"
RESULTS = REPO / "benchmarks" / "results" / "real_footage.md"
SESSIONS = ("charuco_calibration", "post_optimization")
AXES = ("x", "y", "z")


def plain_opencv(rig: Rig) -> tuple[Counter, list[np.ndarray]]:
    """Per camera, rig markers plain OpenCV finds in the frames the times file lists; and every jacket/topside pair's
    offset error (3,) in the jacket frame (m) from each marker's own IPPE pose, as the paper's method has it without
    its filter."""
    from tracking.camera import load_camera
    from tracking.pose import marker_object_points

    params = cv2.aruco.DetectorParameters()
    params.detectInvertedMarker = rig.inverted
    detector = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, rig.dictionary)), params)
    markers, obj = rig.marker_by_id, marker_object_points(rig.marker_size)
    found: Counter = Counter()
    errors: list[np.ndarray] = []
    for entry in rig.cameras:
        camera = load_camera(rig.resolve(entry.calibration))
        clock = rig.clock(entry)
        with av.open(str(rig.resolve(entry.source))) as video:
            for k, frame in enumerate(video.decode(video=0)):
                if np.isnan(clock.capture(k, 0.0)):
                    continue  # the frames the tracker drops too (no time in the times file)
                corners, ids, _ = detector.detectMarkers(frame.to_ndarray(format="gray"))
                poses = {}
                for c, i in zip(corners, ids.ravel() if ids is not None else [], strict=True):
                    if int(i) not in markers:
                        continue
                    found[entry.name] += 1
                    ok, r, t = cv2.solvePnP(obj, c.reshape(4, 2), camera.K, camera.dist, flags=cv2.SOLVEPNP_IPPE_SQUARE)
                    if ok:
                        poses[int(i)] = rt_to_T(r.ravel(), t.ravel())
                for j, T_cj in poses.items():
                    for s, T_cs in poses.items():
                        if markers[j].body == "jacket" and markers[s].body == "topside":
                            T_js = np.linalg.inv(T_cj) @ T_cs  # topside marker in the jacket marker's frame
                            seen = markers[j].T_body_marker @ T_js  # ... in the jacket frame
                            errors.append(seen[:3, 3] - markers[s].T_body_marker[:3, 3])
    return found, errors


def both_groups_times(results: list) -> np.ndarray:
    """Capture times of the camera frames that show a jacket and a topside marker."""
    return np.array([r.time for r in results if r.observation is not None and r.observation.jacket is not None
                     and r.observation.topside is not None])


def scored(df: pd.DataFrame, seen: np.ndarray, side: float) -> dict:
    """An estimator's offsets against zero: per axis e_MAE and |e|max (mm, % of the side), within 2σ, beyond 3σ, over
    the samples that axis shows; availability (a sample showing any axis)."""
    shown = df.dropna(subset=["dx", "dy", "dz"], how="all")
    out: dict = {"availability": float(np.isin(np.round(seen, 6), np.round(shown["time"].to_numpy(), 6)).mean())
                 if len(seen) else float("nan")}
    for a in AXES:
        e, s = shown[f"d{a}"].to_numpy(), shown[f"sd{a}"].to_numpy()
        e, s = e[np.isfinite(e)], s[np.isfinite(e)]  # an axis withheld alone (its σ beyond the limit)
        out[a] = (np.mean(np.abs(e)) * 1e3, np.max(np.abs(e)) * 1e3, np.mean(np.abs(e) <= 2 * s),
                  np.mean(np.abs(e) > 3 * s)) if len(e) else (np.nan,) * 4
    out["side_mm"] = side * 1e3
    return out


def estimates(rig: Rig, results: list, mode: str) -> pd.DataFrame:
    """An estimator's offsets over tracked frames, as the offsets CSV has them."""
    rows = []
    for e in ESTIMATORS[mode](rig, (m for r in results for m in r.measurements)):
        sd = np.sqrt(np.diag(e.covariance)) if e.covariance is not None else np.full(3, np.nan)
        rows.append({"time": e.time, "dx": e.offset[0], "dy": e.offset[1], "dz": e.offset[2],
                     "sdx": sd[0], "sdy": sd[1], "sdz": sd[2], "withheld": e.withheld})
    return pd.DataFrame(rows, columns=["time", "dx", "dy", "dz", "sdx", "sdy", "sdz", "withheld"])


def without_stated_errors(rig: Rig, work: Path) -> Rig:
    """The rig with each calibration copied into work without its avg_reprojection_error (as a camera maker's or
    ROS's file comes): what a user whose calibrations state none gets."""
    from tracking.camera import load_camera, save_camera

    cameras = []
    for c in rig.cameras:
        copy = work / f"{c.name}.yaml"
        save_camera(copy, replace(load_camera(rig.resolve(c.calibration)), rms=None))
        cameras.append(c.model_copy(update={"calibration": str(copy)}))
    return rig.model_copy(update={"cameras": cameras})


def self_calibrated(rig: Rig, board_folder: Path, work: Path) -> tuple[Rig, list[str]]:
    """The rig with each camera calibrated from its own video of the session's board (board_folder's charuco.toml) as
    `topside import-caliscope` does for a camera without intrinsics, the calibrations written into work: what a user
    with only the footage gets; and a table row per camera (views, fit, stated error, coverage, f against the
    session's own). A camera no video of which calibrates it keeps the session's calibration."""
    from tracking.caliscope import calibrate_camera, session_board
    from tracking.camera import load_camera, save_camera

    board = session_board(board_folder)
    cameras, rows = [], []
    for c in rig.cameras:
        theirs = load_camera(rig.resolve(c.calibration))
        result, said = calibrate_camera(board_folder, rig.resolve(c.source), int(c.name.rpartition("_")[2]), board)
        if result is None:  # e.g. a camera that sees only the board's mirrored back
            rows.append(f"| {c.name} | — | — | the session's kept: {said} | — | — | {theirs.K[0, 0]:.1f} |")
            cameras.append(c)
            continue
        rows.append(f"| {c.name} | {len(result.per_view_rms)} | {result.rms:.3f} | {result.camera.rms:.2f} | "
                    f"{result.coverage:.0%} | {result.camera.K[0, 0]:.1f} | {theirs.K[0, 0]:.1f} |")
        copy = work / f"{c.name}.yaml"
        save_camera(copy, result.camera)
        cameras.append(c.model_copy(update={"calibration": str(copy)}))
    return rig.model_copy(update={"cameras": cameras}), rows


def session(rig_path: Path, unstated: bool = False, board_folder: Path | None = None) -> dict:
    """Every figure of one session (unstated: its calibrations' stated errors removed; board_folder: its cameras
    calibrated from their own videos of that folder's board instead)."""
    with tempfile.TemporaryDirectory(prefix="calibrations-") as work:
        rig, rows = load_rig(rig_path), []
        if board_folder is not None:
            rig, rows = self_calibrated(rig, board_folder, Path(work))
        return {**figures(without_stated_errors(rig, Path(work)) if unstated else rig), "calibrations": rows}


def figures(rig: Rig) -> dict:
    """Every figure of one session's rig."""
    stats = TrackStats()
    results = list(track_rig(rig, stats=stats))
    for r in results:
        stats.add(r)
    nominal = rig.model_copy(update={"cameras": [c.model_copy(update={"times": None}) for c in rig.cameras]})
    nominal_results = list(track_rig(nominal))
    found, baseline = plain_opencv(rig)
    seen = both_groups_times(results)
    return {"rig": rig, "stats": stats, "opencv": found, "baseline": np.array(baseline),
            "fused": scored(estimates(rig, results, "fused"), seen, rig.marker_size),
            "smoothed": scored(estimates(rig, results, "smoothed"), seen, rig.marker_size),
            "nominal": scored(estimates(nominal, nominal_results, "fused"), both_groups_times(nominal_results),
                              rig.marker_size)}


def alone(label: str, rig: Rig) -> list[str]:
    """A table row per mode of one rig tracked: frames showing both groups, shown, per axis e_MAE / |e|max (mm) and
    within 2σ / beyond 3σ, and why the rest were withheld."""
    results = list(track_rig(rig))
    seen = both_groups_times(results)
    if not len(seen):
        return [f"| {label} | — | 0 | — | — | — | — | — | — | — | no frame shows both groups |"]
    rows = []
    for mode in ("fused", "smoothed"):
        df = estimates(rig, results, mode)
        r = scored(df, seen, rig.marker_size)
        held = df[df[["dx", "dy", "dz"]].isna().all(axis=1) & np.isin(np.round(df["time"], 6), np.round(seen, 6))]
        why = ", ".join(f"{reason} ×{n}" for reason, n in Counter(held["withheld"]).most_common())
        axes = " | ".join(f"{r[a][0]:.2f} / {r[a][1]:.1f}" for a in AXES)
        cover = " | ".join(f"{r[a][2]:.0%} / {r[a][3]:.1%}" for a in AXES)
        rows.append(f"| {label} | {mode} | {len(seen)} | {r['availability']:.0%} | {axes} | {cover} | {why or '—'} |")
    return rows


TABLE_HEAD = ("frames with both groups | shown | x e_MAE / abs(e)max [mm] | y | z | x within 2σ / beyond 3σ | y | z | "
              "withheld (of those frames) |", "| --- | --- | ---: | ---: | --- | --- | --- | --- | --- | --- | --- |")


def each_camera_markdown(name: str, rig: Rig) -> str:
    """One session's table of its cameras tracked alone."""
    return "\n".join([f"## {name}", "", f"Offset error against zero (marker side {rig.marker_size * 1e3:.1f} mm), each "
                      "camera alone:", "", f"| camera | mode | {TABLE_HEAD[0]}", TABLE_HEAD[1],
                      *(row for camera in rig.cameras
                        for row in alone(camera.name, rig.model_copy(update={"cameras": [camera]})))])


def stacked_pairs(rig: Rig) -> list[tuple[int, int]]:
    """(jacket, topside) ids of the board's stacked pairs: each jacket marker with the nearest topside marker above it
    in its column (centres within half a marker side across), as a cone's pair stands offshore."""
    tops = [m for m in rig.markers if m.body == "topside"]
    pairs = []
    for j in (m for m in rig.markers if m.body == "jacket"):
        above = [t for t in tops if abs(t.center[0] - j.center[0]) < rig.marker_size / 2 and t.center[2] > j.center[2]]
        if above:
            pairs.append((j.id, min(above, key=lambda t: t.center[2] - j.center[2]).id))
    return pairs


def pairs_markdown(name: str, rig: Rig) -> str:
    """One session's table of its stacked pairs, each tracked alone by every camera: one marker a body, as offshore."""
    rows, markers = [], rig.marker_by_id
    for jacket, topside in stacked_pairs(rig):
        gap = np.linalg.norm(np.subtract(markers[topside].center, markers[jacket].center)) / rig.marker_size
        pair = rig.model_copy(update={"markers": [markers[jacket], markers[topside]]})
        rows += alone(f"{jacket} / {topside} ({gap:.1f} sides apart)", pair)
    return "\n".join([f"## {name}", "", f"Offset error against zero (marker side {rig.marker_size * 1e3:.1f} mm), each "
                      "stacked pair alone (jacket / topside marker), every camera fused:", "",
                      f"| pair | mode | {TABLE_HEAD[0]}", TABLE_HEAD[1], *rows])


def markdown(name: str, s: dict) -> str:
    """One session's tables."""
    rig, stats = s["rig"], s["stats"]
    lines = [f"## {name}", "",
             "| camera | frames | rig markers (ours) | rig markers (plain OpenCV) | dropped as mirrored |",
             "| --- | ---: | ---: | ---: | ---: |"]
    for c in rig.cameras:
        mirrored = sum(n for (cam, _), n in stats.mirrored.items() if cam == c.name)
        lines.append(f"| {c.name} | {stats.frames[c.name]} | {stats.markers[c.name]} | {s['opencv'][c.name]} | "
                     f"{mirrored} |")
    if s.get("calibrations"):
        lines += ["", "| camera | views | fit RMS [px] | stated [px] | board over | f [px] | f, the session's [px] |",
                  "| --- | ---: | ---: | ---: | ---: | ---: | ---: |", *s["calibrations"]]
    side = s["fused"]["side_mm"]
    lines += ["", f"Offset error against zero (marker side {side:.1f} mm):", "",
              "| method | axis | e_MAE [mm] | abs(e)max [mm] | e_MAE [% side] | abs(e)max [% side] | within 2σ | "
              "beyond 3σ | availability |", "| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"]
    b = s["baseline"]
    for k, a in enumerate(AXES):
        mae, mx = np.mean(np.abs(b[:, k])) * 1e3, np.max(np.abs(b[:, k])) * 1e3
        lines.append(f"| plain OpenCV (IPPE per marker, no filter; {len(b)} pair offsets) | {a} | {mae:.2f} | "
                     f"{mx:.1f} | {100 * mae / side:.1f} | {100 * mx / side:.0f} | — | — | — |")
    for label, key in (("fused", "fused"), ("smoothed", "smoothed"), ("fused, nominal times", "nominal")):
        r = s[key]
        for a in AXES:
            mae, mx, w2, b3 = r[a]
            lines.append(f"| {label} | {a} | {mae:.2f} | {mx:.1f} | {100 * mae / side:.1f} | {100 * mx / side:.0f} | "
                         f"{w2:.0%} | {b3:.1%} | {r['availability']:.0%} |")
    return "\n".join(lines)


VARIANTS = {  # flag -> (its help, what the file says of it); the default tracks the rig as given, fused and smoothed
    "unstated": ("track with the calibrations' stated RMS errors removed",
                 "Calibrations read without their stated RMS error (`--unstated`), as a camera maker's or ROS's file "
                 "comes: each taken as `UNSTATED_RMS_PX` (tracking/camera.py)."),
    "self-calibrated": ("track with each camera calibrated by `topside calibrate` from its own video of the session's "
                        "board",
                        "Every camera calibrated from its own video of the session's board (`--self-calibrated`), as "
                        "`topside calibrate` and `import-caliscope` do, not by caliscope's calibrations: what a user "
                        "with only the footage gets. A calibration whose board covered under 60 % of the picture "
                        "states the lens model's error as at least 0.5 px, whatever its fit (tracking/calibration.py, "
                        "COVERAGE_WARN): each session's table says each camera's."),
    "each-camera": ("track every camera alone",
                    "Every camera tracked alone (`--each-camera`): a rig of that camera only, as a cone one camera "
                    "sees, whose depth rests on the markers' size and shape in one view. Shown: the share of the "
                    "camera's frames showing both groups at whose capture time an offset is shown."),
    "pairs": ("track every stacked pair of the board alone, one marker a body as offshore",
              "Every stacked pair of the board tracked alone (`--pairs`): a rig of one jacket marker and the topside "
              "marker above it, as a cone's pair stands offshore, seen by every camera. Each camera's pose then rests "
              "on one marker a frame, whose turn its corners barely tell. Shown: the share of the frames showing both "
              "markers at whose capture time an offset is shown."),
}


def session_markdown(name: str, rig_path: Path, variant: str | None, board: Path) -> str:
    """One session's tables in a variant (None: the rig as given; board: the folder of its board, its cameras'
    videos for --self-calibrated)."""
    if variant == "each-camera":
        return each_camera_markdown(name, load_rig(rig_path))
    if variant == "pairs":
        return pairs_markdown(name, load_rig(rig_path))
    return markdown(name, session(rig_path, variant == "unstated", board if variant == "self-calibrated" else None))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sessions", type=Path, nargs="*", default=None,
                        help="other caliscope session folders, imported as `topside import-caliscope` does")
    parser.add_argument("--out", type=Path, default=None, help=f"markdown to write (default {RESULTS.name}, or "
                                                               "real_footage-caliscope.md with --sessions)")
    variants = parser.add_mutually_exclusive_group()
    for flag, (text, _) in VARIANTS.items():
        variants.add_argument(f"--{flag}", action="store_true", help=f"{text} (files suffixed -{flag})")
    args = parser.parse_args()
    variant = next((flag for flag in VARIANTS if getattr(args, flag.replace("-", "_"))), None)
    suffix = f"-{variant}" if variant else ""
    if args.sessions is None:
        parts = ["# Real footage: four webcams and a hand-held board", "",
                 f"Generated by `benchmarks/real_footage.py{suffix.replace('-', ' --', 1)}` "
                 "from ../shared/data/caliscope (benchmarks/real/build.py "
                 "writes the rigs). The true offset is zero at every instant: the board is rigid.", ""]
        for name in SESSIONS:
            board = REPO.parent / "shared" / "data" / "caliscope" / name
            parts += [session_markdown(name, REAL / name / "rig.yaml", variant, board), ""]
        out = args.out or RESULTS.with_name(f"{RESULTS.stem}{suffix}.md")
    else:
        from tracking.caliscope import read_session, write_session

        parts = ["# Real footage: caliscope sessions beyond ../shared/data", "",
                 f"Generated by `benchmarks/real_footage.py{suffix.replace('-', ' --', 1)} --sessions " +
                 " ".join(f.name for f in args.sessions) + "` (caliscope's tests/sessions, imported as "
                 "`topside import-caliscope` does). The true offset is zero at every instant: the board is rigid.", ""]
        with tempfile.TemporaryDirectory() as work:
            for folder in args.sessions:
                rig_path = write_session(read_session(folder), Path(work) / folder.name)
                parts += [session_markdown(folder.name, rig_path, variant, folder), ""]
        out = args.out or RESULTS.with_name(f"real_footage-caliscope{suffix}.md")
    if variant:
        parts.insert(2, VARIANTS[variant][1] + "\n")
    text = "\n".join(parts)
    print(text)
    write_text(out, text)


if __name__ == "__main__":
    main()
