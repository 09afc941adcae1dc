"""The `topside` command line: one subcommand per job, bad input as one line and exit status 2."""

from __future__ import annotations

import math
import signal
import sys
from collections import Counter
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import cv2
import numpy as np
import typer
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, SpinnerColumn, TextColumn, TimeElapsedColumn

from tracking.calibration import SUBPIX_WINDOW
from tracking.detection import DEFAULT_REFINEMENT, Refinement
from tracking.errors import EXIT_BAD_INPUT, InputError
from tracking.estimator import ESTIMATORS, FilterReport
from tracking.outputs import Outputs, atomic_path, check_outputs

if TYPE_CHECKING:
    import pandas as pd

    from tracking.check import CheckReport
    from tracking.pipeline import TrackStats
    from tracking.rig import Rig
    from viewer.archive import ArchiveSink

if TYPE_CHECKING:
    from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey

app = typer.Typer(
    name="topside",
    help="Watch an offshore topside being set down on its jacket, from cameras.",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    add_completion=False,
)
err_console = Console(stderr=True, highlight=False, soft_wrap=True, markup=False)  # file names are never markup
console = Console(highlight=False, soft_wrap=True, markup=False)


# Options shared by `track --mcap` and `export`.
KeyOption = Annotated[Path | None, typer.Option(help="ed25519 private key (PEM) to sign the archive.")]
VesselOption = Annotated[str, typer.Option(help="Crane vessel, for the archive's metadata.")]
OperatorOption = Annotated[str, typer.Option(help="Operator, for the archive's metadata.")]
VideoOption = Annotated[str, typer.Option(help="Frames that have no H.264 of their own (stills, raw sources): jpeg "
                                               "(CompressedImage) or h264 (re-encoded, CompressedVideo). The "
                                               "cameras' own H.264 always passes through.")]


def _archive_options(key: Path | None, video: str) -> Ed25519PrivateKey | None:
    """The signing key (read before any work starts) after checking the frame format."""
    from viewer.archive import VIDEO_FORMATS
    from viewer.manifest import load_private_key

    if video not in VIDEO_FORMATS:
        raise InputError("--video", f"{video!r} is not a frame format (expected {' or '.join(VIDEO_FORMATS)})")
    return load_private_key(key) if key is not None else None


EXIT_INTERRUPTED = 130  # the shell's code for a command ended by Ctrl-C

# Options shared by `track` and `batch`: where the chunks of the videos are tracked.
CHUNK_FRAMES_DEFAULT = 150  # tracking.parallel.CHUNK_FRAMES (not imported here: the CLI starts fast)
WorkersOption = Annotated[int | None, typer.Option(min=1, help="Worker processes that decode and detect (default: "
                                                             "every core; 1: in this process).")]
RayOption = Annotated[str | None, typer.Option(metavar="[ADDRESS]", help="Run the chunks as Ray tasks: on the "
                                               "cluster at ADDRESS (ray://HOST:10001 or auto), or, without ADDRESS, "
                                               "on a Ray started here with --workers CPUs. Needs topside[cluster].")]
ChunkOption = Annotated[int, typer.Option(min=1, help="A chunk of a video starts at the first keyframe this many "
                                                      "frames after the previous chunk's start.")]


def _finite(low: float, low_open: bool = True, high: float = math.inf, allow_inf: bool = False
            ) -> Callable[[float | None], float | None]:
    """A typer callback refusing NaN, infinities (unless allow_inf) and values outside (low, high] (or [low, high])."""

    def check(value: float | None) -> float | None:
        if value is None:
            return value
        inside = (value > low if low_open else value >= low) and value <= high
        if math.isnan(value) or (math.isinf(value) and not allow_inf) or not inside:
            bound = f"{'>' if low_open else '≥'} {low:g}" + (f" and ≤ {high:g}" if math.isfinite(high) else "")
            raise typer.BadParameter(f"{value} is not a finite number {bound}")
        return value

    return check


def rig_inputs(rig: Rig) -> list[Path]:
    """Every file a rig reads: itself, its calibration files and its video files (devices and streams are not files)."""
    from tracking.sources import SourceKind, source_kind

    files = [rig.path]
    for cam in rig.cameras:
        files.append(rig.resolve(cam.calibration))
        if source_kind(cam.source) == SourceKind.FILE:
            files.append(rig.resolve(cam.source))
    return files


def _warn_rig(rig: Rig) -> None:
    """The rig's warnings (defaults that cost accuracy), one line each on stderr."""
    for warning in getattr(rig, "warnings", ()):
        err_console.print(f"topside: warning: {warning}", markup=False)


def _warn_lines(lines: tuple[str, ...] | list[str]) -> None:
    """Warnings met while working (a calibration's size taken from the first frame), one line each on stderr."""
    for line in lines:
        err_console.print(f"topside: warning: {line}", markup=False)


def _measurements(the_rig, run, refine: Refinement, sinks: list, stats, plans, advance: Callable[[], None],
                  roi: bool = False, warn: bool = False):
    """The tracked frames' pair offsets and body observations in capture-time order (parallel.track_chunks), each
    frame counted in stats, advanced on the progress bar, passed to the sinks and, with warn, its warnings printed."""
    from tracking.parallel import track_chunks

    for result in track_chunks(the_rig, run, refine, packets=bool(sinks), keep_gray=bool(sinks), roi_tracking=roi,
                               stats=stats, plans=plans):
        stats.add(result)
        advance()
        if warn:
            _warn_lines(result.warnings)
        for sink in sinks:
            sink.on_frame(result)
        yield from result.offsets
        if result.observation is not None:
            yield result.observation


def _progress() -> Progress:
    return Progress(SpinnerColumn(), TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                    TimeElapsedColumn(), console=err_console, transient=True)


@app.command()
def calibrate(
    images: Annotated[list[Path], typer.Argument(help="Photos of the board, one camera, several views.")],
    board: Annotated[str, typer.Option(help="chessboard:COLSxROWS:SQUARE (inner corners, m) or "
                                            "charuco:COLSxROWS:SQUARE:MARKER:DICT (squares, m).")],
    out: Annotated[Path, typer.Option("-o", "--out", help="Camera file to write (OpenCV YAML).")],
    fix_aspect: Annotated[bool, typer.Option("--fix-aspect", help="Keep fx = fy (CALIB_FIX_ASPECT_RATIO).")] = False,
    rational: Annotated[bool, typer.Option("--rational", help="8-coefficient rational distortion model.")] = False,
    subpix_window: Annotated[int, typer.Option(help="Half-size of cornerSubPix's window, px (chessboard).",
                                               min=1, max=MAX_SUBPIX_WINDOW)] = SUBPIX_WINDOW,
) -> None:
    """Calibrate one camera from photos of a chessboard or ChArUco board."""
    from rich.table import Table

    import tracking.calibration as calib
    from tracking.camera import save_camera

    spec = calib.parse_board(board)
    check_outputs({"--out": out}, images)
    with _progress() as progress:
        task = progress.add_task("finding the board", total=len(images))
        result = calib.calibrate(images, spec, fix_aspect=fix_aspect, rational=rational,
                                 subpix_window=subpix_window, progress=lambda: progress.advance(task))
    table = Table(title="per-view reprojection error")
    table.add_column("view")
    table.add_column("RMS [px]", justify="right")
    for name, err in result.per_view_rms.items():
        table.add_row(name, f"{err:.4f}")
    console.print(table)
    K, d = result.camera.K, result.camera.dist
    std = dict(result.std_intrinsics)
    if fix_aspect and "fy" in std:  # OpenCV reports 0 for fx, which it derives from fy at the fixed aspect
        std["fx"] = std["fy"] * K[0, 0] / K[1, 1]
    console.print(f"views used: {len(result.per_view_rms)} of {len(images)}")
    console.print(f"total RMS reprojection error: {result.rms:.4f} px")
    values = {"fx": K[0, 0], "fy": K[1, 1], "cx": K[0, 2], "cy": K[1, 2]}
    values.update({n: d[i] for i, n in enumerate(calib.INTRINSIC_NAMES[4:4 + d.size])})
    for name, value in values.items():
        sigma = std.get(name)
        console.print(f"  {name:>3} = {value:12.6f}" + (f" ± {sigma:.6f}" if sigma is not None and sigma > 0 else
                                                         " (σ not estimated)"))
    if result.missed:
        console.print(f"no board found in {len(result.missed)}: {', '.join(result.missed)}", style="yellow")
    if result.coverage < calib.COVERAGE_WARN:
        console.print(f"warning: the board covered only {result.coverage:.0%} of the image "
                      "(corners and edges unseen); distortion is poorly determined there", style="yellow")
    save_camera(out, result.camera, extra={"nframes": len(result.per_view_rms), "flags": result.flags})
    console.print(f"wrote {out}")


MAX_SUBPIX_WINDOW = 50  # px: cornerSubPix's window beyond this spans several squares of any usable board
MAX_MARKER_SIZE_M = 100.0  # a marker edge beyond this is a typo (mm for m)


@app.command()
def detect(
    source: Annotated[Path, typer.Argument(help="An image or a video.")],
    dictionary: Annotated[str | None, typer.Option(help="DICT_6X6_250 (default) or a dictionary YAML.")] = None,
    rig: Annotated[Path | None, typer.Option(help="Rig file: its dictionary, marker size and ids.")] = None,
    camera: Annotated[Path | None, typer.Option(help="Camera file: also estimate every marker's pose.")] = None,
    marker_size: Annotated[float | None, typer.Option(help="Marker edge in m (default: the rig's, or 1.0).",
                                                      callback=_finite(0.0, high=MAX_MARKER_SIZE_M))] = None,
    refine: Annotated[Refinement, typer.Option(help="Corner refinement.")] = DEFAULT_REFINEMENT,
    as_json: Annotated[bool, typer.Option("--json", help="One JSON object per frame.")] = False,
) -> None:
    """Print the markers found in every frame: ids, corners (TL TR BR BL) and, given a camera, poses."""
    import json

    from tracking.camera import load_camera
    from tracking.detection import MarkerDetector
    from tracking.images import frames, is_image
    from tracking.pose import estimate_pose
    from tracking.rig import load_rig

    the_rig = load_rig(rig) if rig else None
    if the_rig is not None:
        _warn_rig(the_rig)
    if dictionary and the_rig and dictionary != the_rig.dictionary:
        raise InputError("--dictionary", f"{dictionary} differs from the rig's {the_rig.dictionary}")
    cam = load_camera(camera) if camera else None
    detector = MarkerDetector(dictionary or (the_rig.dictionary if the_rig else "DICT_6X6_250"), refine, cam)
    size = marker_size or (the_rig.marker_size if the_rig else 1.0)
    known = the_rig.marker_by_id if the_rig else None
    unknown: Counter[int] = Counter()
    n_frames = 0
    for frame in frames(source):
        n_frames += 1
        det = detector.detect(frame.gray)
        if cam is not None and not cam.sized:  # a calibration without a size: the first frame's
            cam, warning = cam.sized_from(frame.gray.shape[1], frame.gray.shape[0], camera, source)
            _warn_lines([warning])
        if cam is not None and (frame.gray.shape[1], frame.gray.shape[0]) != cam.image_size:
            raise InputError(camera, f"is for {cam.width}x{cam.height} but {source} is "
                             f"{frame.gray.shape[1]}x{frame.gray.shape[0]}", "image_width/image_height")
        markers = []
        for m in det.markers:
            if known is not None and m.id not in known:
                unknown[m.id] += 1
                if is_image(source):
                    raise InputError(source, f"marker id {m.id} is not in the rig {rig}", "id")
                continue
            entry: dict = {"id": m.id, "corners": np.round(m.corners, 3).tolist()}
            if cam is not None:
                pose = estimate_pose(m, cam, size)
                entry["pose"] = {
                    "tvec": np.round(pose.T_camera_marker[:3, 3], 4).tolist(),
                    "rvec": np.round(cv2.Rodrigues(pose.T_camera_marker[:3, :3])[0].reshape(3), 5).tolist(),
                    "reprojection_error": round(pose.reprojection_error, 4),
                    "alternative_error": round(pose.solutions[1].reprojection_error, 4),
                    "choice": str(pose.choice),
                }
            markers.append(entry)
        if as_json:
            print(json.dumps({"frame": frame.index, "time": round(frame.time, 6), "markers": markers}))
            continue
        console.print(f"frame {frame.index}  t={frame.time:.3f}s  {len(markers)} markers")
        for e in markers:
            corners = " ".join(f"({x:.2f},{y:.2f})" for x, y in e["corners"])
            console.print(f"  id {e['id']:>4}  {corners}")
            if "pose" in e:
                p = e["pose"]
                console.print(f"         t={p['tvec']} m  r={p['rvec']}  reproj {p['reprojection_error']:.3f}px "
                              f"(other {p['alternative_error']:.3f}px, {p['choice']})")
    if unknown:
        summary = ", ".join(f"id {i}: {n}" for i, n in sorted(unknown.items()))
        err_console.print(f"{n_frames} frames; markers not in the rig ignored: {summary}")




@app.command()
def track(
    rig: Annotated[Path, typer.Option(help="Rig file of the installation.")],
    out: Annotated[Path, typer.Option("-o", "--out", help="Offsets CSV to write.")] = Path("offsets.csv"),
    mode: Annotated[str, typer.Option(help="fused: live rigid-body Kalman filter of all cameras; smoothed: the "
                                           "same, then smoothed (RTS) by the next 45 s at least; paper: the paper's "
                                           "method; raw: every camera's pair offset.")] = "fused",
    refine: Annotated[Refinement, typer.Option(help="Corner refinement.")] = DEFAULT_REFINEMENT,
    rrd: Annotated[Path | None, typer.Option(help="Also record everything to this Rerun file (.rrd).")] = None,
    truth: Annotated[Path | None, typer.Option(help="Ground-truth log to overlay in the recording.")] = None,
    rejected: Annotated[bool, typer.Option("--rejected", help="Record rejected marker candidates too.")] = False,
    mcap: Annotated[Path | None, typer.Option(help="Also write an MCAP audit archive (opens in Foxglove, Rerun).")
                    ] = None,
    key: KeyOption = None,
    vessel: VesselOption = "",
    operator: OperatorOption = "",
    video: VideoOption = "jpeg",
    workers: WorkersOption = None,
    ray: RayOption = None,
    chunk_frames: ChunkOption = CHUNK_FRAMES_DEFAULT,
    roi: Annotated[bool, typer.Option("--roi", help="Search each frame around the markers of the frames before it "
                                                    "(the live path's detector, afresh at every chunk): about 2.4x "
                                                    "less CPU per frame; on the demo 0.8 % fewer markers, e_MAE 1 mm "
                                                    "larger in x and y.")] = False,
) -> None:
    """Track the rig's videos and write the offset at each cone per timestamp (CSV), optionally a recording.

    Each camera's video is cut into chunks at keyframes, tracked in worker processes (--workers) or Ray tasks
    (--ray) and fused here in capture-time order: the output is the same whatever runs the chunks."""
    from tracking.evaluate import read_truth
    from tracking.parallel import plan_rig, runner
    from tracking.pipeline import TrackStats
    from tracking.report import OffsetsWriter
    from tracking.rig import load_rig

    if mode not in ESTIMATORS:
        raise InputError("--mode", f"{mode!r} is not a mode (expected {', '.join(ESTIMATORS)})")
    estimator = ESTIMATORS[mode]
    the_rig = load_rig(rig)
    _warn_rig(the_rig)
    check_outputs({"--out": out, "--rrd": rrd, "--mcap": mcap}, [*rig_inputs(the_rig), truth, key])
    truth_df = read_truth(truth) if truth else None
    private = _archive_options(key, video) if mcap is not None else None  # read before any work starts
    options = {"mode": mode, "refine": refine.value, **({"roi": "on"} if roi else {})}
    stats = TrackStats()
    plans = plan_rig(the_rig, chunk_frames=chunk_frames)
    total = sum(p.frames for p in plans) or None
    outputs = Outputs(keep_on_interrupt=True)
    writer: OffsetsWriter | None = None
    report = FilterReport()
    run = runner(workers, ray)
    try:
        with outputs, _progress() as progress:
            csv_partial = outputs.claim(out)
            sinks = []  # the CLI composes tracker and viewer; tracking/ never imports viewer
            if rrd is not None:
                from viewer.session import Recorder

                sinks.append(Recorder(the_rig, outputs.claim(rrd), truth_df, show_rejected=rejected,
                                      options=options))
            if mcap is not None:
                sinks.append(_archive_sink(the_rig, outputs.claim(mcap), options, truth_df, private, csv_partial,
                                           vessel, operator, video))
            task = progress.add_task(f"tracking {len(the_rig.cameras)} cameras", total=total)

            measurements = _measurements(the_rig, run, refine, sinks, stats, plans, lambda: progress.advance(task),
                                         roi=roi, warn=True)
            try:
                with OffsetsWriter(csv_partial) as writer:
                    for e in estimator(the_rig, measurements, report=report):
                        for sink in sinks:
                            sink.on_estimate(e)
                        writer.write(e)
            finally:
                _close_sinks(sinks)
    except KeyboardInterrupt:
        kept = ", ".join(map(str, outputs.kept)) or "nothing"
        err_console.print(f"stopped after {writer.rows if writer else 0} rows; what was written is kept in {kept}",
                          markup=False)
        raise typer.Exit(EXIT_INTERRUPTED) from None
    finally:
        run.close()
    _print_track_summary(the_rig, rig, mode, stats)
    console.print(f"wrote {writer.rows if writer else 0} rows to {out}")
    if rrd is not None:
        console.print(f"wrote {rrd} (open it with: topside view {rrd})")
    if mcap is not None:
        console.print(f"wrote {mcap} (check it with: topside verify {mcap})")
    if mode in ("fused", "smoothed"):
        _rig_findings(rig, report)


def _rig_findings(rig_path: Path, report: FilterReport) -> None:
    """After a fused run: a rig error it found (the markers' size, the topside through its cones), which withheld the
    offsets, is one error line and exit status 2; else a warning each for the cameras never placed (with why) and a
    scale nothing fixed."""
    if report.scale.mismatch:
        raise InputError(rig_path, report.scale.message() + "; the offsets were withheld", "marker_size")
    if report.below[0]:
        raise InputError(rig_path, f"{report.below[0]} offsets put the topside up to {-report.below[1]:.2f} m below "
                                   "its cone tips, where no set-down can be (withheld): marker_size, a marker's centre "
                                   "or a pair's mated offset is wrong", "marker_size")
    for name, why in report.unplaced.items():
        err_console.print(f"topside: warning: {name}: never placed, so none of its frames was used: {why}",
                          markup=False)
    if not report.scale.fixed:
        err_console.print(f"topside: warning: {rig_path}: marker_size: {report.scale.message()}", markup=False)


def _close_sinks(sinks: list) -> None:
    """Close every sink; while an error propagates, a sink that fails to close does not hide it."""
    failing = sys.exc_info()[1] is not None
    for sink in sinks:
        try:
            sink.close()
        except Exception:
            if not failing:
                raise


def _print_track_summary(rig: Rig, rig_path: Path, mode: str, stats: TrackStats) -> None:
    """The run's table per camera, and what it ignored."""
    from rich.table import Table

    table = Table(title=f"tracked {rig_path} ({mode} mode)")
    for col in ("camera", "frames", "markers", "pair offsets", "ambiguous"):
        table.add_column(col, justify="right" if col != "camera" else "left")
    for cam in rig.cameras:
        n = cam.name
        table.add_row(n, str(stats.frames[n]), str(stats.markers[n]), str(stats.pair_offsets[n]),
                      str(stats.ambiguous[n]))
    console.print(table)
    if stats.unknown_ids:
        summary = ", ".join(f"id {i}: {n}" for i, n in sorted(stats.unknown_ids.items()))
        console.print(f"markers not in the rig (ignored): {summary}", style="yellow")
    for line in stats.warnings([c.name for c in rig.cameras]):  # videos cut short, timestamps back or jumping
        err_console.print(f"topside: warning: {line}", style="yellow")


def _archive_sink(rig: Rig, path: Path, options: dict[str, str], truth_df: pd.DataFrame | None,
                  private: Ed25519PrivateKey | None, offsets_csv: Path | None, vessel: str, operator: str, video: str
                  ) -> ArchiveSink:
    """The MCAP archive writer for `track --mcap`."""
    from viewer.archive import ArchiveSink

    return ArchiveSink(rig, path, options, {"vessel": vessel, "operator": operator}, truth_df, private, offsets_csv,
                       video=video)


@app.command()
def batch(
    manifest: Annotated[Path, typer.Argument(help="YAML manifest: a list of installations, one per line: {rig: R, "
                                                  "out: FOLDER, truth: T (optional)}.")],
    workers: WorkersOption = None,
    ray: RayOption = None,
    refine: Annotated[Refinement, typer.Option(help="Corner refinement.")] = DEFAULT_REFINEMENT,
    chunk_frames: ChunkOption = CHUNK_FRAMES_DEFAULT,
) -> None:
    """Re-analyse many installations: each one's offsets.csv (run.rrd with rrd: true, accuracy.md with a truth) in
    its out folder, one progress bar over all, then a table: frames, video and wall time, accuracy, failures.

    One that fails does not stop the others. Exit status: 0 when all succeeded, 1 when any failed, 2 for a bad
    manifest."""
    import time

    from rich import box
    from rich.table import Table

    from tracking.batch import load_manifest
    from tracking.parallel import plan_rig, runner
    from tracking.rig import load_rig

    installations = load_manifest(manifest)
    prepared: list = []
    for inst in installations:  # every rig read and every video's keyframes found before any work
        try:
            the_rig = load_rig(inst.rig)
            prepared.append((inst, the_rig, plan_rig(the_rig, chunk_frames=chunk_frames), ""))
        except InputError as exc:
            prepared.append((inst, None, [], _one_line(exc)))
    run = runner(workers, ray)
    outcomes = []
    started = time.perf_counter()
    try:
        with _progress() as progress:
            total = sum(p.frames for *_, plans, _ in prepared for p in plans) or None
            task = progress.add_task(f"{len(installations)} installations on {run.workers} workers", total=total)
            for inst, the_rig, plans, error in prepared:
                progress.update(task, description=f"{inst.label} ({len(outcomes) + 1}/{len(installations)})")
                outcomes.append(_batch_one(inst, the_rig, plans, error, run, refine, progress, task))
    finally:
        run.close()
    table = Table(title=f"{manifest}: {sum(o.ok for o in outcomes)} of {len(outcomes)} installations re-analysed in "
                        f"{time.perf_counter() - started:.0f} s (errors against the truth in mm)", box=box.SIMPLE_HEAD,
                  pad_edge=False, collapse_padding=True)
    for col in ("installation", "frames", "video s", "wall s", "fps", "e_MAE x/y/z", "max mm", "result"):
        table.add_column(col, justify="left" if col in ("installation", "result") else "right")
    for o in outcomes:
        mae = "/".join(f"{v:.1f}" for v in o.mae_mm) if o.mae_mm else "—"
        table.add_row(o.name, str(o.frames), f"{o.video_s:.1f}", f"{o.wall_s:.1f}",
                      f"{o.frames / o.wall_s:.0f}" if o.wall_s > 0 and o.frames else "—", mae,
                      f"{o.max_mm:.0f}" if o.max_mm is not None else "—", "ok" if o.ok else "FAILED")
    console.print(table)
    for o in outcomes:
        if not o.ok:
            err_console.print(f"topside: {o.name} failed: {o.error}", markup=False)
    if not all(o.ok for o in outcomes):
        raise typer.Exit(1)


def _batch_one(inst, the_rig, plans, error: str, run, refine: Refinement, progress: Progress, task):
    """One installation of a batch: its outputs, or its one-line failure (the frames it did not track are counted
    off the progress bar)."""
    import time

    from tracking.batch import ACCURACY_NAME, OFFSETS_NAME, RRD_NAME, Outcome
    from tracking.evaluate import evaluate_runs, evaluation_markdown, read_offsets, read_truth
    from tracking.outputs import write_text
    from tracking.pipeline import TrackStats
    from tracking.report import OffsetsWriter

    outcome = Outcome(inst.label, error=error)
    planned = sum(p.frames for p in plans)
    fresh = not inst.out.exists()  # a folder made here and left empty by a failure is removed
    stats = TrackStats()
    t0 = time.perf_counter()
    try:
        if error:
            return outcome
        csv, rrd = inst.out / OFFSETS_NAME, (inst.out / RRD_NAME) if inst.rrd else None
        accuracy = inst.out / ACCURACY_NAME if inst.truth is not None else None
        check_outputs({"out": csv, "rrd": rrd, "accuracy": accuracy}, [*rig_inputs(the_rig), inst.truth])
        truth_df = read_truth(inst.truth) if inst.truth is not None else None
        with Outputs() as outputs:
            sinks = []
            if rrd is not None:
                from viewer.session import Recorder

                sinks.append(Recorder(the_rig, outputs.claim(rrd), truth_df, options={"mode": inst.mode,
                                                                                      "refine": refine.value}))

            measurements = _measurements(the_rig, run, refine, sinks, stats, plans, lambda: progress.advance(task))
            try:
                with OffsetsWriter(outputs.claim(csv)) as writer:
                    for e in ESTIMATORS[inst.mode](the_rig, measurements):
                        for sink in sinks:
                            sink.on_estimate(e)
                        writer.write(e)
            finally:
                _close_sinks(sinks)
        outcome.rows = writer.rows
        if truth_df is not None and accuracy is not None:
            ev = evaluate_runs(inst.label, [(read_offsets(csv), truth_df)])
            axes = list(ev.axes.values())
            outcome.mae_mm = tuple(1000 * a.mae for a in axes[:3])
            outcome.max_mm = 1000 * max(a.max_abs for a in axes[:3])
            write_text(accuracy, evaluation_markdown(ev))
    except InputError as exc:
        outcome.error = _one_line(exc)
    except Exception as exc:  # not bad input: a bug or the environment; named in one line, the others go on
        outcome.error = _one_line(f"{type(exc).__name__}: {exc}")
    finally:
        outcome.frames = sum(stats.frames.values())
        outcome.video_s = max(((v.last_s or 0.0) - (v.first_s or 0.0) for v in stats.videos.values()), default=0.0)
        outcome.wall_s = time.perf_counter() - t0
        progress.advance(task, max(planned - outcome.frames, 0))
        if outcome.error and fresh and inst.out.is_dir() and not any(inst.out.iterdir()):
            inst.out.rmdir()
    return outcome


@app.command()
def export(
    recording: Annotated[Path, typer.Argument(help="A recording (.rrd) written by `topside track --rrd`.")],
    mcap: Annotated[Path, typer.Option(help="MCAP archive to write.")],
    offsets: Annotated[Path | None, typer.Option(help="Offsets CSV of the same run, to attach.")] = None,
    key: KeyOption = None,
    vessel: VesselOption = "",
    operator: OperatorOption = "",
    video: VideoOption = "jpeg",
) -> None:
    """Write the MCAP audit archive of a recording: the same content `track --mcap` writes."""
    from viewer.export import export_recording

    check_outputs({"--mcap": mcap}, [recording, offsets, key])
    private = _archive_options(key, video)
    if offsets is not None and not offsets.is_file():
        raise InputError(offsets, "offsets CSV not found", "--offsets")
    with atomic_path(mcap) as partial:
        n = export_recording(recording, partial, {"vessel": vessel, "operator": operator}, private,
                             offsets.read_bytes() if offsets else None, video)
    console.print(f"wrote {mcap}: {n} messages (check it with: topside verify {mcap})")


MAX_FINDINGS = 50  # printed by `verify`; the rest are counted


@app.command()
def verify(
    archive: Annotated[Path, typer.Argument(help="An MCAP archive written by topside.")],
    key: Annotated[Path | None, typer.Option(help="ed25519 public key (PEM) the archive must be signed with.")
                   ] = None,
    recover: Annotated[bool, typer.Option("--recover", help="Rebuild a valid file from a damaged or killed "
                                                            "writer's, then check that.")] = False,
    out: Annotated[Path | None, typer.Option("-o", "--out", help="Where --recover writes (default: "
                                                                 "NAME.recovered.mcap).")] = None,
) -> None:
    """Check an archive: CRCs, indexes, every channel non-empty, the manifest's SHA-256 digests, the signature."""
    from viewer.audit import is_intact
    from viewer.audit import recover as recover_file
    from viewer.audit import verify as verify_file
    from viewer.manifest import load_public_key, time_text

    public = load_public_key(key) if key is not None else None
    if recover:
        target = out or archive.with_name(f"{archive.stem}.recovered.mcap")
        check_outputs({"--out": target}, [archive, key])
        if is_intact(archive):
            console.print(f"{archive} is intact (a finished writer's summary, indexes and manifest all check): "
                          "nothing to recover, nothing written", markup=False, soft_wrap=True)
        else:
            with atomic_path(target) as partial:
                r = recover_file(archive, partial)
            console.print(f"recovered {r.messages} messages in {r.chunks} chunks up to "
                          f"{time_text(r.last_ns) if r.last_ns is not None else '-'}; {r.chunks_damaged} damaged "
                          f"chunks and {r.bytes_dropped} trailing bytes dropped", soft_wrap=True)
            if r.manifest_was_missing:
                console.print("the manifest was missing (the writer did not close); the recovered file carries its "
                              "own, marked 'recovered'", style="yellow")
            console.print(f"wrote {target}")
            archive = target
    report = verify_file(archive, public)
    for note in report.notes:
        console.print(f"note: {note}", markup=False, soft_wrap=True)
    for err in report.errors[:MAX_FINDINGS]:
        console.print(f"FAIL: {err}", markup=False, soft_wrap=True)
    if len(report.errors) > MAX_FINDINGS:
        console.print(f"FAIL: ... and {len(report.errors) - MAX_FINDINGS} more", soft_wrap=True)
    sig = {"valid": "signature valid", "invalid": "signature INVALID", "absent": "not signed",
           "unchecked": "signed (not checked: no --key)"}[report.signature]
    state = "OK" if report.ok else f"{len(report.errors)} problems"
    console.print(f"{archive}: {state}; {report.messages} messages on {report.channels} channels; {sig}; "
                  f"{report.size / 1e6:.1f} MB checked at {report.mb_per_s:.0f} MB/s", markup=False, soft_wrap=True)
    if not report.ok:
        raise typer.Exit(1)


@app.command()
def view(
    recording: Annotated[Path, typer.Argument(help="A Rerun recording (.rrd), or a segmented one (its .rrd name "
                                                   "or its .segments.csv).")],
    start: Annotated[float | None, typer.Option("--from", help="Open from this capture time, s.")] = None,
    end: Annotated[float | None, typer.Option("--to", help="Open up to this capture time, s.")] = None,
    web: Annotated[bool, typer.Option("--web", help="Serve the web viewer instead of opening the native one.")] = False,
    bind: Annotated[str, typer.Option(help="Address (or host name) of this machine the viewer's servers listen on.")
                    ] = "127.0.0.1",
    web_port: Annotated[int, typer.Option(help="Port of the web viewer's page (with --web).", min=1, max=65535)
                        ] = 9090,
    grpc_port: Annotated[int | None, typer.Option(help="Port of the viewer's gRPC server (default: 9876 with --web, "
                                                       "a free one for the native viewer).", min=1, max=65535)] = None,
) -> None:
    """Open a recording in Rerun's viewer (native, or web with --web); --from/--to open a window of it.

    With --web, prints the URL to open; Ctrl-C (or SIGTERM) stops the server and removes its temporary files.
    """
    from viewer.playback import view_recording

    if start is not None and end is not None and end <= start:
        raise InputError("--to", f"{end} is not after --from {start}")
    view_recording(recording, start, end, web=web, bind=bind, grpc_port=grpc_port, web_port=web_port)


LIVE_SEGMENT_MIN = 1.0  # a minute a file: quick to open, and `topside view --from --to` picks the window
LIVE_ESTIMATE_PERIOD_S = 1 / 30  # the recording keeps a cone's estimates at up to 30 Hz (the CSV keeps all)


@app.command()
def live(
    rig: Annotated[Path, typer.Option(help="Rig file; each camera's source is a device index, a stream URL "
                                           "(rtsp://, http://) or a video file replayed at its frame rate.")],
    rrd: Annotated[Path | None, typer.Option(help="Recording to write, in segments <stem>-NNN.rrd (default: "
                                                  "recordings/live-<date>-<time>.rrd).")] = None,
    out: Annotated[Path | None, typer.Option("-o", "--out", help="Offsets CSV, written as they are measured "
                                                                 "(default: beside the recording).")] = None,
    spawn: Annotated[bool, typer.Option("--spawn", help="Stream to a native viewer.")] = False,
    web: Annotated[bool, typer.Option("--web", help="Serve the web viewer (a tablet on the stern).")] = False,
    bind: Annotated[str, typer.Option(help="Address (or host name) of this machine the viewer's servers listen on "
                                           "(--web, --spawn).")] = "127.0.0.1",
    stale: Annotated[float, typer.Option(help="Seconds after which a cone shows NO DATA.",
                                         callback=_finite(0.0))] = 0.5,
    segment_minutes: Annotated[float, typer.Option(help="Minutes of capture time per recording file.",
                                                   callback=_finite(0.0))] = LIVE_SEGMENT_MIN,
    speed: Annotated[float, typer.Option(help="Replay speed of video files (1: real time; inf: flat out).",
                                         callback=_finite(0.0, allow_inf=True))] = 1.0,
    duration: Annotated[float | None, typer.Option(help="Stop after this many seconds of capture time.",
                                                   callback=_finite(0.0))] = None,
    layout: Annotated[str, typer.Option(help="Layout stored in the recording: superintendent or analysis.")
                      ] = "superintendent",
    viewer_scope: Annotated[str, typer.Option(help="What the viewer (--web, --spawn) of the superintendent's layout "
                                                   "gets: superintendent (what it shows) or all (everything "
                                                   "recorded).")] = "superintendent",
    web_port: Annotated[int, typer.Option(help="Port of the web viewer's page (with --web).", min=1, max=65535)
                        ] = 9090,
    grpc_port: Annotated[int, typer.Option(help="Port of the viewer's gRPC server (--web, --spawn).", min=1,
                                           max=65535)] = 9876,
    foxglove: Annotated[bool, typer.Option("--foxglove", help="Stream the archive's channels to Foxglove (a "
                                                              "WebSocket server, ws://<bind>:<port>).")] = False,
    port: Annotated[int, typer.Option("--port", help="Port of the Foxglove WebSocket server (with --foxglove).",
                                      min=1, max=65535)] = 8765,
) -> None:
    """Track every camera live, fuse them, record, and stream to the superintendent's view (and Foxglove)."""
    import time

    from tracking.live import LiveTracker
    from tracking.report import OffsetsWriter
    from tracking.rig import load_rig
    from viewer.playback import (
        check_port_free,
        resolve_bind,
        start_live_viewer,
        stop_viewer,
        url_host,
        warn_if_exposed,
        web_viewer_url,
    )
    from viewer.session import VIEWER_SCOPES, Recorder

    if spawn and web:
        raise InputError("--spawn/--web", "choose one viewer")
    if layout not in ("superintendent", "analysis"):
        raise InputError("--layout", f"{layout!r} is not a layout (expected superintendent or analysis)")
    if viewer_scope not in VIEWER_SCOPES:
        raise InputError("--viewer-scope", f"{viewer_scope!r} is not a scope (expected {' or '.join(VIEWER_SCOPES)})")
    the_rig = load_rig(rig)
    _warn_rig(the_rig)
    rrd = rrd or Path("recordings") / f"live-{time.strftime('%Y%m%d-%H%M%S')}.rrd"
    out = out or rrd.with_name(f"{rrd.stem}-offsets.csv")
    check_outputs({"--out": out, "--rrd": rrd}, rig_inputs(the_rig))
    for path, option in ((out, "--out"), (rrd.with_name(f"{rrd.stem}.segments.csv"), "--rrd"),
                         (rrd.with_name(f"{rrd.stem}-000.rrd"), "--rrd")):
        if path.exists():
            raise InputError(path, "exists (an earlier session's record; a live session never overwrites one): "
                                   "expected another name", option)
    fox_address = resolve_bind(bind) if foxglove else None
    if fox_address is not None:
        check_port_free(fox_address, port, "--port")
    if spawn or web:
        check_port_free(resolve_bind(bind), grpc_port, "--grpc-port")
    if web:
        check_port_free(resolve_bind(bind), web_port, "--web-port")
    viewer_url, viewer_process = (start_live_viewer(web, bind, grpc_port, web_port) if (spawn or web)
                                  else (None, None))
    if web:
        console.print(f"web viewer: {web_viewer_url(resolve_bind(bind), grpc_port, web_port)}")
    fox = None
    outputs = Outputs()  # every end (done, Ctrl-C, SIGTERM, a failure) keeps what was recorded, under its name
    writer: OffsetsWriter | None = None
    recorder: Recorder | None = None

    def estimates(tracker: LiveTracker):
        start = None  # capture time of the first frame
        for update in tracker.updates():
            recorder.on_update(update)
            for event in update.events:
                err_console.print(f"{event.camera}: {event.state}" + (f" ({event.detail})" if event.detail else ""))
            yield from update.estimates
            for result in update.results:
                _warn_lines(result.warnings)
            if update.results:
                start = update.results[0].time if start is None else start
                if duration is not None and update.results[-1].time - start >= duration:
                    return

    try:
        if fox_address is not None:
            from viewer.foxglove_live import FoxgloveStream

            if not (spawn or web):  # the viewers warn for themselves
                warn_if_exposed(fox_address)
            fox = FoxgloveStream(the_rig, fox_address, port)
            console.print(f"foxglove: ws://{url_host(fox_address)}:{fox.port}", markup=False)
        recorder = Recorder(the_rig, rrd, viewer=viewer_url, segment_s=segment_minutes * 60, stale_s=stale,
                            layout=layout, estimate_period_s=LIVE_ESTIMATE_PERIOD_S, viewer_scope=viewer_scope,
                            forward=[fox] if fox is not None else [])
        with OffsetsWriter(outputs.claim(out)) as writer:
            console.print(f"recording to {rrd.with_name(rrd.stem + '-*.rrd')} and {writer.path} (renamed {out.name} "
                          "when the session ends)", markup=False, soft_wrap=True)
            with LiveTracker(the_rig, speed=speed) as tracker:
                console.print(f"live: {len(tracker.names)} cameras; Ctrl-C stops and keeps everything recorded")
                for e in estimates(tracker):
                    writer.write(e)
    except KeyboardInterrupt:
        err_console.print("stopped")
    finally:
        try:
            if recorder is not None:
                recorder.close()
        finally:
            outputs.commit()  # what was measured is the record of the lift, however the session ended
            if viewer_process is not None:  # the viewers the tool starts end with it
                stop_viewer(viewer_process)
            if fox is not None:
                fox.close()
    console.print(f"wrote {writer.rows if writer else 0} rows to {out}; recording {rrd.with_name(rrd.stem + '-*.rrd')}")


@app.command()
def sync(
    rig: Annotated[Path, typer.Option(help="Rig file whose cameras' clocks to measure.")],
    out: Annotated[Path, typer.Option("-o", "--out", help="Rig file to write, with the measured time_offsets.")],
    reference: Annotated[str | None, typer.Option(help="Camera whose clock the others are set to (default: the one "
                                                       "that times the topside's motion best).")] = None,
    refine: Annotated[Refinement, typer.Option(help="Corner refinement.")] = DEFAULT_REFINEMENT,
) -> None:
    """Measure every camera's clock offset against the others from the topside's motion they all see; write the rig
    with the measured time_offsets and their σ.

    A camera whose offset the footage cannot tell (a still topside, a far view) keeps the rig's offset and is named.
    Exit status: 0 when every clock is measured; 1 when one is not (the rig is still written); 2 for bad input.
    """
    import time

    from tracking.clocks import synced_rig, synchronise
    from tracking.fieldwork import clock_lines, clock_table, footage_measurements, write_rig
    from tracking.rig import load_rig

    the_rig = load_rig(rig)
    _warn_rig(the_rig)
    check_outputs({"--out": out}, rig_inputs(the_rig))
    if reference is not None and reference not in {c.name for c in the_rig.cameras}:
        raise InputError(reference, f"is not a camera of {rig} (expected one of "
                                    f"{', '.join(c.name for c in the_rig.cameras)})", "--reference")
    t0 = time.perf_counter()
    with _progress() as progress:
        progress.add_task(f"measuring {len(the_rig.cameras)} cameras", total=None)
        offsets, _, seconds = footage_measurements(the_rig, refine, observations=False)
        t1 = time.perf_counter()
        clocks = synchronise(the_rig, offsets, reference)
    console.print(clock_table(clocks))
    for line in clock_lines(clocks):
        console.print(line, markup=False)
    write_rig(synced_rig(the_rig, clocks), out)
    console.print(f"wrote {out} · {seconds / 60:.1f} camera-minutes: measured in {t1 - t0:.0f} s, fitted in "
                  f"{time.perf_counter() - t1:.1f} s", markup=False)
    if not all(c.known for c in clocks):
        raise typer.Exit(1)


@app.command()
def survey(
    rig: Annotated[Path, typer.Option(help="Rig file whose markers to survey (its clocks measured: topside sync).")],
    out: Annotated[Path, typer.Option("-o", "--out", help="Rig file to write, with the markers' corrected poses.")],
    start: Annotated[float | None, typer.Option("--from", help="From this capture time, s (the bodies still or "
                                                               "moving rigidly: before the lift).")] = None,
    end: Annotated[float | None, typer.Option("--to", help="To this capture time, s.")] = None,
    refine: Annotated[Refinement, typer.Option(help="Corner refinement.")] = DEFAULT_REFINEMENT,
) -> None:
    """Refine every marker's pose on its body from the footage (a bundle adjustment of all cameras' frames and the
    markers' corners, each marker's survey σ as its prior, a marker named reference held); write the rig with each
    correction and its σ, and flag markers moved beyond the rig's survey_tolerance.

    Exit status: 0 when no marker is flagged; 1 when one is (the rig is still written); 2 for bad input.
    """
    import time

    from tracking.fieldwork import footage_measurements, survey_lines, survey_table, write_rig
    from tracking.rig import load_rig
    from tracking.survey import survey_markers, surveyed_rig

    the_rig = load_rig(rig)
    _warn_rig(the_rig)
    check_outputs({"--out": out}, rig_inputs(the_rig))
    if start is not None and end is not None and end <= start:
        raise InputError("--to", f"{end:g} s is not after --from {start:g} s (expected a stretch of footage)")
    t0 = time.perf_counter()
    with _progress() as progress:
        progress.add_task(f"measuring {len(the_rig.cameras)} cameras", total=None)
        offsets, observations, seconds = footage_measurements(the_rig, refine, start, end)
        t1 = time.perf_counter()
        fit = survey_markers(the_rig, [*offsets, *observations])
    console.print(survey_table(the_rig, fit))
    console.print("where: J jacket, T topside; survey's σ kept: the footage cut its σ by less than a quarter (it "
                  "cannot tell where that marker sits)", markup=False)
    for line in survey_lines(the_rig, fit):
        console.print(line, markup=False)
    write_rig(surveyed_rig(the_rig, fit), out)
    console.print(f"wrote {out} · {seconds / 60:.1f} camera-minutes: measured in {t1 - t0:.0f} s, fitted in "
                  f"{time.perf_counter() - t1:.1f} s ({fit.iterations} iterations)", markup=False)
    if any(s.flagged for s in fit.markers):
        raise typer.Exit(1)


@app.command()
def simulate(
    scenario: Annotated[str | None, typer.Argument(
        help="Scenario YAML file or built-in name (e.g. config2-procedure5, random-17).")] = None,
    out: Annotated[Path | None, typer.Option("-o", "--out", help="Output folder for videos, rig, calibration, truth.")
                   ] = None,
    random: Annotated[int | None, typer.Option(
        "--random", help="Draw a whole installation from this seed (cameras, markers, lift, weather) instead of a "
                         "scenario: the same as the scenario random-SEED.", min=0)] = None,
    seed: Annotated[int | None, typer.Option(help="Random seed (default: the scenario's).", min=0)] = None,
    duration: Annotated[float | None, typer.Option(help="Cut the scenario to this many seconds.",
                                                   callback=_finite(0.0))] = None,
    clock_error: Annotated[float | None, typer.Option(
        help="Every camera's clock off by a uniform draw within ±this many s; the rig keeps the nominal offsets.",
        callback=_finite(0.0, low_open=False, high=10.0))] = None,
    survey_error: Annotated[tuple[float, float] | None, typer.Option(
        help="Markers off their surveyed poses: σ of the centre (m) and of the tilt (°), e.g. 0.02 1; the rig keeps "
             "the nominal poses.")] = None,
) -> None:
    """Render a scenario: one video per camera, the rig, calibration files and the ground-truth log.

    Built-ins: config1-procedure1..4, config2-procedure5..7, config1-setdown, config2-setdown,
    config1-cone-a (markers at cone A only), calibration-shots;
    add -weather (fog 50 %, rain 30 %), -clear (no weather, no noise) or -realities (clocks off by up to
    ±0.5 s, markers 20 mm and 1° off their survey; truth_rig.yaml has the truth, for benchmarks only).
    random-SEED (or --random SEED) draws a whole installation from a seed.
    """
    from tracking.sim.command import run_simulate

    if (scenario is None) == (random is None):
        raise InputError("SCENARIO", "give a scenario or --random SEED (exactly one)")
    if out is None:
        raise InputError("--out", "missing (expected the folder to write the simulation into)")
    scenario = scenario if random is None else f"random-{random}"

    run_simulate(scenario, out, seed=seed, duration=duration, clock_error_s=clock_error, survey_error=survey_error)


@app.command()
def evaluate(
    runs: Annotated[list[Path], typer.Argument(help="OFFSETS.csv TRUTH.csv, repeated: runs pooled into one table.")],
    name: Annotated[str, typer.Option(help="Name of the group of runs (e.g. 'procedures 5, 6, 7').")] = "",
    markdown: Annotated[Path | None, typer.Option(help="Also write the table as markdown.")] = None,
    plots: Annotated[Path | None, typer.Option(help="Folder for estimate/truth/error plots per cone.")] = None,
) -> None:
    """The paper's accuracy table (e_MAE, |e|max, σ_e, μ_e per axis), RMSE, lag and availability against truth."""
    from rich.table import Table

    from tracking.evaluate import (
        NO_VALUE,
        check_overlap,
        evaluate_runs,
        evaluation_markdown,
        plot_run,
        read_offsets,
        read_truth,
    )
    from tracking.outputs import write_text

    if len(runs) % 2:
        raise InputError(runs[-1], "has no truth file after it (expected OFFSETS.csv TRUTH.csv pairs)")
    check_outputs({"--markdown": markdown}, runs)
    if plots is not None and plots.exists() and not plots.is_dir():
        raise InputError(plots, "is a file (expected a folder for the plots)", "--plots")
    pairs = [(read_offsets(runs[i]), read_truth(runs[i + 1])) for i in range(0, len(runs), 2)]
    for i, (off, tru) in enumerate(pairs):
        check_overlap(runs[2 * i], off, runs[2 * i + 1], tru)
    label = name or ", ".join(str(runs[i].name) for i in range(0, len(runs), 2))
    ev = evaluate_runs(label, pairs)
    table = Table(title=f"{label} against the truth (m)")
    for col in ("axis", "e_MAE", "|e|max", "σ_e", "μ_e", "RMSE", "n"):
        table.add_column(col, justify="right")
    for axis, s in ev.axes.items():
        cells = [f"{v:.3f}" if s.n else NO_VALUE for v in (s.mae, s.max_abs, s.std, s.mean, s.rmse)]
        table.add_row(axis, *cells, str(s.n))
    console.print(table)
    lag_text = f"{ev.lag_s:.2f} s" if math.isfinite(ev.lag_s) else f"{NO_VALUE} (no axis moves enough to tell)"
    console.print(f"lag {lag_text} (cross-correlation) · availability {ev.availability:.1%} "
                  f"(share of time with an estimate at most 0.5 s old)")
    if markdown:
        write_text(markdown, evaluation_markdown(ev))
    if plots:
        for i, (off, tru) in enumerate(pairs):
            for path in plot_run(off, tru, plots, runs[2 * i].stem):
                console.print(f"wrote {path}")


MAX_CHECK_SECONDS = 600.0  # a check reads this much of each camera at most: minutes are a recording, not a check


@app.command()
def check(
    rig: Annotated[Path, typer.Option(help="Rig file of the installation.")],
    seconds: Annotated[float, typer.Option(help="Seconds of each camera to read.",
                                           callback=_finite(0.0, high=MAX_CHECK_SECONDS))] = 5.0,
    rrd: Annotated[Path | None, typer.Option(help="Also write a Rerun recording of the installation as understood: "
                                                  "markers, cones, every camera placed by its markers with its "
                                                  "first frame.")] = None,
    refine: Annotated[Refinement, typer.Option(help="Corner refinement.")] = DEFAULT_REFINEMENT,
) -> None:
    """Check a rig on a few seconds of every camera before the lift: what each camera sees, its clock, each cone's
    predicted σ and verdict (ready, weak, blind), and every marker that disagrees with the rig.

    Exit status: 0 when every cone is ready and nothing disagrees; 1 when a cone is weak or blind, a marker disagrees
    with the rig, a camera sees no rig marker, its clock is off its rate or its survey is refuted, or an unknown id is
    seen while a rig marker is not; 2 for bad input.
    """
    from tracking.check import check_rig
    from tracking.rig import load_rig

    the_rig = load_rig(rig)
    _warn_rig(the_rig)
    check_outputs({"--rrd": rrd}, rig_inputs(the_rig))
    with _progress() as progress:
        progress.add_task(f"reading {seconds:g} s of {len(the_rig.cameras)} cameras", total=None)
        report = check_rig(the_rig, seconds, refine)
    _warn_lines(report.warnings)
    _print_check(report)
    if rrd is not None:
        with atomic_path(rrd) as partial:
            _check_recording(report, partial)
        console.print(f"wrote {rrd} (open it with: topside view {rrd})")
    if not report.ready:
        raise typer.Exit(1)


def _print_check(report: CheckReport) -> None:
    """The check's tables (cameras, markers seen, disagreements, cones), a line per finding, and its verdict."""
    from rich.table import Table

    rig = report.rig
    console.print(f"checked {rig.path} ({rig.name}): {len(rig.markers)} markers, {len(report.cones)} cones, "
                  f"{len(rig.cameras)} cameras, {report.seconds:g} s of each")
    for line in report.rig_errors():  # first: everything after may follow from it
        console.print(f"rig error: {line}", markup=False)
    cams = Table(title="cameras")
    for col in ("camera", "frames", "fps stated", "fps kept", "dropped", "irregular", "markers", "survey [m]"):
        cams.add_column(col, justify="left" if col in ("camera", "markers") else "right")
    for c in report.cameras:
        k = c.clock
        survey = "–" if c.survey_m is None else f"{c.survey_m:.2f}" + (" refused" if c.survey_conflict else "")
        cams.add_row(c.camera, str(k.frames), f"{k.declared_fps:.3f}",
                     f"{k.measured_fps:.3f}" if np.isfinite(k.measured_fps) else "–", str(k.dropped),
                     str(k.irregular), " ".join(str(s.marker) for s in c.sights) or "none", survey)
    console.print(cams)
    for c in report.cameras:
        for line in c.problems:
            console.print(line)
    markers = Table(title="markers seen (medians over the frames that show them)")
    for col in ("camera", "marker", "where", "seen", "distance [m]", "off normal [°]", "px/cell", "reproj. [px]"):
        markers.add_column(col, justify="left" if col in ("camera", "where") else "right")
    by_id = rig.marker_by_id
    for c in report.cameras:
        for s in c.sights:
            m = by_id[s.marker]
            markers.add_row(c.camera, str(s.marker), f"{m.body[0].upper()} {m.cone}/{m.face}", f"{s.share:.0%}",
                            f"{s.distance_m:.1f}", f"{s.angle_deg:.0f}", f"{s.cell_px:.1f}", f"{s.reprojection_px:.2f}")
    console.print(markers)
    console.print("where: J jacket, T topside; px/cell: pixels per code cell along the marker's shortest side")
    if report.unseen_markers:
        console.print(f"markers of the rig no camera sees: {', '.join(map(str, report.unseen_markers))}")
    for i, cameras in report.unknown_ids.items():
        console.print(f"id {i} is not in the rig, seen by {', '.join(cameras)}")
    if report.disagreements:
        table = Table(title="markers that disagree with the rig")
        for col in ("camera", "markers", "frames", "residual [m]", "σ [m]", "normal [°]", "turn [°]"):
            table.add_column(col, justify="left" if col in ("camera", "markers") else "right")
        for d in report.disagreements:
            table.add_row(d.camera, ", ".join(map(str, d.markers)), str(d.frames), f"{d.offset_m:.2f}",
                          f"{d.sigma_m:.2f}", f"{d.normal_deg:.0f}", f"{d.turn_deg:+.0f}")
        console.print(table)
        for d in report.disagreements:
            console.print(f"disagrees: {d.camera}: {d.reason}")
    cones = Table(title="cones (σ from the fusion filter after these seconds)")
    for col in ("cone", "σx [mm]", "σy [mm]", "σz [mm]", "cameras", "verdict"):
        cones.add_column(col, justify="right" if col.startswith("σ") else "left")
    for c in report.cones:
        sigma = [f"{v * 1000:.0f}" if np.isfinite(v) else "–" for v in c.sigma_m]
        cones.add_row(c.cone, *sigma, ", ".join(c.cameras) or "none", c.verdict)
    console.print(cones)
    for c in report.cones:
        console.print(f"cone {c.cone}: {c.verdict}: {c.reason}")
    problems = report.problems()
    if not problems:
        console.print("READY: every cone is ready and every marker agrees with the rig")
        return
    verdicts = Counter(c.verdict for c in report.cones if c.verdict != "ready")
    parts = [f"{n} cone{'' if n == 1 else 's'} {v}" for v, n in sorted(verdicts.items())]
    if report.disagreeing_markers:
        parts.append(f"markers {', '.join(map(str, report.disagreeing_markers))} disagree with the rig")
    others = len(problems) - sum(verdicts.values()) - len(report.disagreements)
    if others:
        parts.append(f"{others} other finding{'' if others == 1 else 's'} above")
    console.print(f"NOT READY: {'; '.join(parts)}")
    for line in _check_next_steps(report):
        console.print(f"next: {line}")


def _check_next_steps(report: CheckReport) -> list[str]:
    """What to run after a check that found clocks or markers off (issue 22's sync and survey)."""
    from tracking.rig import WARN_CLOCK_SIGMA_S

    rig = report.rig
    out = []
    if any(c.clock.problems for c in report.cameras) or any(
            (c.time_offset_sigma or 0.0) > WARN_CLOCK_SIGMA_S for c in rig.cameras):
        out.append(f"measure the cameras' clock offsets from footage: topside sync --rig {rig.path} -o synced.yaml")
    if report.disagreements:
        out.append("correct the rig where a marker was entered wrongly (id, face, centre); for centimetres and "
                   f"degrees, refine the markers from footage before the lift: topside survey --rig {rig.path} "
                   "-o surveyed.yaml")
    return out


def _check_recording(report: CheckReport, path: Path) -> None:
    """The installation as the check understood it, as a Rerun recording: the rig's markers and cones, the topside
    where the filter has it, every camera placed by its own markers with its first frame and the markers it sees
    (red: named by a disagreement), and the findings."""
    import rerun as rr

    from viewer.installation import log_installation
    from viewer.recording import APP_ID, log_frustum, log_image, log_marker_frames, log_rig, set_capture_time

    rec = rr.RecordingStream(APP_ID)
    rec.save(str(path))
    log_rig(rec, report.rig)
    log_installation(rec, report.rig)
    if report.T_jacket_topside is not None:
        T = report.T_jacket_topside
        rr.log("world/topside", rr.Transform3D(translation=T[:3, 3], mat3x3=T[:3, :3]), static=True, recording=rec)
    wrong = set(report.disagreeing_markers)
    for c in report.cameras:
        if c.T_jacket_camera is None or c.model is None:
            continue
        base = f"world/cameras/{c.camera}"
        T = c.T_jacket_camera
        rr.log(base, rr.Transform3D(translation=T[:3, 3], mat3x3=T[:3, :3]), static=True, recording=rec)
        log_frustum(rec, base, c.model)
        if c.T_jacket_markers:
            log_marker_frames(rec, f"world/estimated/{c.camera}", report.rig.marker_size, c.T_jacket_markers,
                              [(230, 40, 40) if i in wrong else (40, 200, 80) for i in c.T_jacket_markers])
        if c.first_frame is not None and c.first_frame.gray is not None:
            set_capture_time(rec, c.first_frame.time)
            log_image(rec, f"{base}/image", c.first_frame)
    lines = ["# topside check", "", *(f"- {line}" for line in report.problems() or ["READY"]), "", "| cone | verdict |",
             "|---|---|", *(f"| {c.cone} | {c.verdict}: {c.reason} |" for c in report.cones)]
    rr.log("check", rr.TextDocument("\n".join(lines), media_type=rr.MediaType.MARKDOWN), static=True, recording=rec)
    rec.flush(timeout_sec=1e38)
    rec.disconnect()


DEMO_SCENARIO = "config2-procedure5-weather"
DEMO_DURATION_S = 20.0


@app.command()
def demo(
    out: Annotated[Path, typer.Option("-o", "--out", help="Folder for the demo's files.")] = Path("recordings"),
    duration: Annotated[float, typer.Option(help="Seconds of the scenario to simulate.",
                                            callback=_finite(0.0))] = DEMO_DURATION_S,
    no_viewer: Annotated[bool, typer.Option("--no-viewer", help="Do not open the viewer at the end.")] = False,
) -> None:
    """Simulate configuration 2, procedure 5 in fog and rain, track it (fused), record it, print its accuracy."""
    from tracking.sim.command import run_simulate
    from viewer.playback import has_display

    scene = out / "demo"
    console.rule(f"1/3 simulate {DEMO_SCENARIO} ({duration:.0f} s)")
    run_simulate(DEMO_SCENARIO, scene, seed=None, duration=duration)
    console.rule("2/3 track (all cameras fused) and record")
    rrd = out / "demo.rrd"
    csv = out / "demo-offsets.csv"
    track(rig=scene / "rig.yaml", out=csv, mode="fused", refine=DEFAULT_REFINEMENT, rrd=rrd,
          truth=scene / "truth.csv", rejected=False)
    console.rule("3/3 accuracy against the simulator's truth")
    evaluate(runs=[csv, scene / "truth.csv"], name="demo", markdown=out / "demo-accuracy.md", plots=None)
    if not no_viewer and has_display():
        view(recording=rrd, start=None, end=None, web=False, bind="127.0.0.1")
    else:
        console.print(f"open the recording with:  .venv/bin/topside view {rrd}   (or --web for a browser)")


def _interrupt(signum: int, frame: object) -> None:
    """SIGTERM ends a command as Ctrl-C does: outputs are completed or removed, recordings kept, children stopped."""
    raise KeyboardInterrupt


def _one_line(text: str) -> str:
    """A message on one line."""
    return " ".join(str(text).split())


def _ray_address_optional(args: list[str]) -> list[str]:
    """`--ray` given without an address (last, or before another option) means a Ray started here: "local"."""
    out = list(args)
    for i in range(len(out) - 1, -1, -1):
        if out[i] == "--ray" and (i + 1 == len(out) or out[i + 1].startswith("-")):
            out.insert(i + 1, "local")
    return out


def main() -> None:
    """Console entry point: bad input (files, options, usage) becomes one line on stderr and exit status 2."""
    if len(sys.argv) <= 1:  # no command: the help, as typer prints it
        app()
        return
    signal.signal(signal.SIGTERM, _interrupt)
    sys.argv[1:] = _ray_address_optional(sys.argv[1:])
    try:
        code = app(standalone_mode=False)
    except InputError as exc:
        err_console.print(f"topside: error: {_one_line(exc)}", markup=False)
        sys.exit(EXIT_BAD_INPUT)
    except typer.TyperException as exc:  # typer's usage errors: a missing option, a value of the wrong type
        message = exc.format_message() if hasattr(exc, "format_message") else str(exc)
        ctx = getattr(exc, "ctx", None)
        hint = f" (see: {ctx.command_path} --help)" if ctx is not None else ""
        err_console.print(f"topside: error: {_one_line(message)}{hint}", markup=False)
        sys.exit(getattr(exc, "exit_code", EXIT_BAD_INPUT))
    except (typer.Abort, KeyboardInterrupt):
        err_console.print("topside: stopped", markup=False)
        sys.exit(EXIT_INTERRUPTED)
    except OSError as exc:  # the disk filled, a folder vanished: the environment, named in one line
        where = f"{exc.filename}: " if exc.filename else ""
        err_console.print(f"topside: error: {where}{exc.strerror or exc}", markup=False)
        sys.exit(EXIT_BAD_INPUT)
    sys.exit(code if isinstance(code, int) else 0)


if __name__ == "__main__":
    main()
