"""The field engineer's commands and their tables: `calibrate` a camera, `detect` markers in an image or a video,
print the rig's `markers`, `check` a rig before the lift, `sync` the cameras' clocks and `survey` the markers from
footage."""

from __future__ import annotations

import math
from collections import Counter
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import cv2
import numpy as np
import typer
from rich.table import Table

from tracking.calibration import SUBPIX_WINDOW
from tracking.cli.common import console, err_console, progress_bar, rig_inputs, warn_lines, warn_rig
from tracking.cli.options import RefineOption, SheetFormat, finite
from tracking.detection import DEFAULT_REFINEMENT
from tracking.errors import InputError
from tracking.outputs import atomic_path, check_outputs

if TYPE_CHECKING:
    from collections.abc import Iterator

    from tracking.calibration import CalibrationResult
    from tracking.camera import CameraModel
    from tracking.check import CheckReport
    from tracking.clocks import CameraClock
    from tracking.detection import MarkerDetection
    from tracking.images import Frame
    from tracking.rig import Rig
    from tracking.survey import SurveyFit

MAX_SUBPIX_WINDOW = 50  # px: cornerSubPix's window beyond this spans several squares of any usable board
MAX_MARKER_SIZE_M = 100.0  # a marker edge beyond this is a typo (mm for m)
MAX_CHECK_SECONDS = 600.0  # a check reads this much of each camera at most: minutes are a recording, not a check
LEARNT_SHARE = 0.25  # a marker whose σ the footage cut by less than this share is reported as not told by it


def calibrate(
    images: Annotated[list[Path], typer.Argument(help="Photos or videos of the board, one camera, several views.")],
    board: Annotated[str, typer.Option(help="The board, as written above: chessboard:... or charuco:...")],
    out: Annotated[Path, typer.Option("-o", "--out", help="Camera file to write (OpenCV YAML).")],
    fix_aspect: Annotated[bool, typer.Option("--fix-aspect", help="Keep fx = fy (OpenCV's fixed aspect ratio).")
                          ] = False,
    rational: Annotated[bool, typer.Option("--rational", help="8-coefficient rational distortion model.")] = False,
    subpix_window: Annotated[int, typer.Option(help="Half-size of cornerSubPix's window, px (chessboard).",
                                               min=1, max=MAX_SUBPIX_WINDOW)] = SUBPIX_WINDOW,
    inverted: Annotated[bool, typer.Option("--inverted", help="ChArUco markers printed white on black.")] = False,
) -> None:
    """Calibrate one camera from photos or videos of a chessboard or ChArUco board.

    --board is chessboard:COLSxROWS:SQUARE (inner corners across and down, the square's side in m), e.g.
    chessboard:9x6:0.025; or charuco:COLSxROWS:SQUARE:MARKER:DICT (squares across and down, the square's and the
    marker's sides in m, the ArUco dictionary), e.g. charuco:7x5:0.04:0.03:DICT_5X5_100. A video gives up to 40
    views spread over the board's poses (the frames that show it)."""
    import tracking.calibration as calib
    from tracking.camera import save_camera

    spec = calib.parse_board(board)
    check_outputs({"--out": out}, images)
    with progress_bar() as progress:
        task = progress.add_task("finding the board", total=len(images), unit="files")
        result = calib.calibrate(images, spec, fix_aspect=fix_aspect, rational=rational,
                                 subpix_window=subpix_window, progress=lambda: progress.advance(task),
                                 inverted=inverted)
    _print_calibration(result, len(images), fix_aspect)
    save_camera(out, result.camera, extra={"nframes": len(result.per_view_rms), "flags": result.flags,
                                           "fit_reprojection_error": result.rms, "board_coverage": result.coverage})
    console.print(f"wrote {out}")


def _print_calibration(result: CalibrationResult, n_images: int, fix_aspect: bool) -> None:
    """Each view's reprojection error, the intrinsics with their σ, the photos without a board, a poor coverage."""
    import tracking.calibration as calib

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
    frames = result.video_frames
    photos = len(result.per_view_rms) - frames
    console.print(f"views used: {len(result.per_view_rms)} ({photos} photo{'s' * (photos != 1)}, {frames} video "
                  f"frame{'s' * (frames != 1)}) from {n_images} file{'s' * (n_images != 1)}")
    console.print(f"total RMS reprojection error: {result.rms:.4f} px")
    values = {"fx": K[0, 0], "fy": K[1, 1], "cx": K[0, 2], "cy": K[1, 2]}
    values.update({n: d[i] for i, n in enumerate(calib.INTRINSIC_NAMES[4:4 + d.size])})
    for name, value in values.items():
        sigma = std.get(name)
        console.print(f"  {name:>3} = {value:12.6f}" + (f" ± {sigma:.6f}" if sigma is not None and sigma > 0 else
                                                         " (σ not estimated)"))
    if result.missed:
        console.print(f"no board found in {len(result.missed)}: {', '.join(result.missed)}", style="yellow")
    if result.far_off:
        by_rms = sorted(result.far_off.items(), key=lambda item: -item[1])[:5]
        worst = ", ".join(f"{name} {rms:.2f} px" for name, rms in by_rms)
        n = len(result.far_off)
        done = ("left out, the camera fitted again without them" if result.refitted else
                "kept: without them too few distinct poses would remain (film more of the board)")
        warn_lines([f"{n} video frame{'s' * (n > 1)} far off the other views (blurred or misread), {done}: {worst}"])
    for photo, first in result.repeated.items():
        warn_lines([f"{photo}: the board where {first} has it (the same pose: the view adds nothing)"])
    if result.coverage < calib.COVERAGE_WARN:
        console.print(f"warning: the board covered only {result.coverage:.0%} of the image "
                      "(corners and edges unseen); distortion is poorly determined there", style="yellow")
    if result.camera.rms is not None and result.camera.rms > result.rms:
        console.print(f"the file states the lens model's error as {result.camera.rms:.2f} px, not the fit's "
                      f"{result.rms:.2f}: a fit to part of the picture does not vouch for the rest, and the tracker's "
                      "σ rests on it (fill the picture with the board for a smaller one)", style="yellow")


def detect(
    source: Annotated[str, typer.Argument(help="An image, a video, a camera's device index (0) or a stream URL "
                                               "(rtsp://, http://).")],
    dictionary: Annotated[str | None, typer.Option(help="DICT_6X6_250 (default) or a dictionary YAML.")] = None,
    rig: Annotated[Path | None, typer.Option(help="Rig file: its dictionary, marker size and ids.")] = None,
    camera: Annotated[Path | None, typer.Option(help="Camera file: also estimate every marker's pose.")] = None,
    marker_size: Annotated[float | None, typer.Option(help="Marker edge in m (default: the rig's, or 1.0).",
                                                      callback=finite(0.0, high=MAX_MARKER_SIZE_M))] = None,
    refine: RefineOption = DEFAULT_REFINEMENT,
    as_json: Annotated[bool, typer.Option("--json", help="One JSON object per frame.")] = False,
    inverted: Annotated[bool, typer.Option("--inverted", help="Markers printed white on black (a rig says so "
                                                              "itself: inverted: true).")] = False,
    max_frames: Annotated[int | None, typer.Option("--frames", min=1, help="Stop after this many frames (default: "
                                                                           "all of a file; a camera or stream "
                                                                           "until Ctrl-C).")] = None,
) -> None:
    """Print the markers found in every frame: ids, corners (TL TR BR BL) and, given a camera, poses.

    A camera can be tried before the rig exists: `topside detect 0 --frames 30` (a device) or `topside detect
    rtsp://10.0.0.5/stream1` shows the ids it sees and, with --camera, how far they are."""
    import itertools

    from tracking.camera import load_camera
    from tracking.detection import MarkerDetector
    from tracking.rig import load_rig

    the_rig = load_rig(rig) if rig else None
    if dictionary and the_rig and dictionary != the_rig.dictionary:
        raise InputError("--dictionary", f"{dictionary} differs from the rig's {the_rig.dictionary}")
    cam = load_camera(camera) if camera else None
    if the_rig is not None:
        warn_rig(the_rig)  # once the inputs are accepted: bad input stays the one line on stderr
    detector = MarkerDetector(dictionary or (the_rig.dictionary if the_rig else "DICT_6X6_250"), refine, cam,
                              inverted=inverted or bool(the_rig and the_rig.inverted))
    size = marker_size or (the_rig.marker_size if the_rig else 1.0)
    unknown: Counter[int] = Counter()  # ids not in the rig: detections
    n_frames = 0
    for frame in itertools.islice(_source_frames(source), max_frames):
        n_frames += 1
        det = detector.detect(frame.gray)
        cam = _sized_camera(cam, frame, camera, source)
        _print_detections(frame, _marker_entries(det.markers, cam, size, the_rig, rig, source, unknown), as_json)
    if unknown:
        summary = ", ".join(f"id {i}: {n}" for i, n in sorted(unknown.items()))
        err_console.print(f"{n_frames} frames; markers not in the rig ignored: {summary}")


def _source_frames(source: str) -> Iterator[Frame]:
    """The frames of what `detect` was given: a device index, a stream URL (kept as written: a Path would make
    rtsp://host rtsp:/host), or an image or video file; live frames on the wall clock."""
    from tracking.images import frames
    from tracking.sources import SourceKind, device_frames, source_kind, stream_frames

    kind = source_kind(source)
    if kind == SourceKind.DEVICE:
        return device_frames(int(source), 0.0, encode=False)
    if kind == SourceKind.STREAM:
        return stream_frames(source, 0.0)
    return frames(Path(source))


def _sized_camera(cam: CameraModel | None, frame: Frame, camera: Path | None, source: str) -> CameraModel | None:
    """The camera model for this frame: a calibration without a size takes the first frame's (with a warning); one
    for another size is bad input."""
    if cam is None:
        return None
    width, height = frame.gray.shape[1], frame.gray.shape[0]
    if not cam.sized:
        cam, warning = cam.sized_from(width, height, camera, source)
        warn_lines([warning])
    if (width, height) != cam.image_size:
        raise InputError(camera, f"is for {cam.width}x{cam.height} but {source} is {width}x{height}",
                         "image_width/image_height")
    return cam


def _marker_entries(markers: list[MarkerDetection], cam: CameraModel | None, size: float, rig: Rig | None,
                    rig_path: Path | None, source: str, unknown: Counter[int]) -> list[dict]:
    """A frame's markers as printed: id, corners (4, 2) and, with a camera, the pose. With a rig, an id it does not
    list is counted in unknown and left out (in a single image, it is bad input)."""
    from tracking.images import is_image

    known = rig.marker_by_id if rig is not None else None
    entries = []
    for m in markers:
        if known is not None and m.id not in known:
            unknown[m.id] += 1
            if is_image(source):
                raise InputError(source, f"marker id {m.id} is not in the rig {rig_path}", "id")
            continue
        entry: dict = {"id": m.id, "corners": np.round(m.corners, 3).tolist()}
        if cam is not None:
            entry["pose"] = _pose_entry(m, cam, size)
        entries.append(entry)
    return entries


def _pose_entry(marker: MarkerDetection, cam: CameraModel, size: float) -> dict:
    """A marker's pose in the camera: t (m) and r (rotation vector), both solutions' reprojection errors (px)."""
    from tracking.pose import estimate_pose

    pose = estimate_pose(marker, cam, size)
    return {
        "tvec": np.round(pose.T_camera_marker[:3, 3], 4).tolist(),
        "rvec": np.round(cv2.Rodrigues(pose.T_camera_marker[:3, :3])[0].reshape(3), 5).tolist(),
        "reprojection_error": round(pose.reprojection_error, 4),
        "alternative_error": round(pose.solutions[1].reprojection_error, 4),
        "choice": str(pose.choice),
    }


def _print_detections(frame: Frame, markers: list[dict], as_json: bool) -> None:
    """One frame's markers: a JSON object, or a line per frame and per marker (and its pose)."""
    import json

    if as_json:
        print(json.dumps({"frame": frame.index, "time": round(frame.time, 6), "markers": markers}))
        return
    console.print(f"frame {frame.index}  t={frame.time:.3f}s  {len(markers)} markers")
    for e in markers:
        corners = " ".join(f"({x:.2f},{y:.2f})" for x, y in e["corners"])
        console.print(f"  id {e['id']:>4}  {corners}")
        if "pose" in e:
            p = e["pose"]
            console.print(f"         t={p['tvec']} m  r={p['rvec']}  reproj {p['reprojection_error']:.3f}px "
                          f"(other {p['alternative_error']:.3f}px, {p['choice']})")


def markers(
    rig: Annotated[Path, typer.Option(help="Rig file whose markers to print.")],
    out: Annotated[Path, typer.Option("-o", "--out", help="Folder for the sheets (made if missing).")],
    fmt: Annotated[SheetFormat, typer.Option("--format", help="pdf (every cell a rectangle: sharp at any size) or "
                                                              "png (at --dpi).")] = SheetFormat.PDF,
    dpi: Annotated[float, typer.Option(help="Resolution of PNG sheets, dots per inch.",
                                       callback=finite(0.0, high=2400.0))] = 150.0,
) -> None:
    """Write a printable sheet per marker of the rig, at print scale: the black square of marker_size as cv2.aruco
    draws it, a white quiet zone around it, and a label with the marker's id, body, cone and face. Print at 100 %
    (no fitting to the paper): the square then measures marker_size."""
    import tracking.marker_sheets as ms
    from tracking.rig import load_rig

    the_rig = load_rig(rig)
    if out.exists() and not out.is_dir():
        raise InputError(out, "is a file (expected a folder for the sheets)", "--out")
    pages = [ms.sheet(the_rig, m) for m in the_rig.markers]
    paths = [out / ms.sheet_name(page.marker, fmt.value) for page in pages]
    check_outputs({f"--out ({p.name})": p for p in paths}, [the_rig.path])
    if fmt == SheetFormat.PNG and pages and (biggest := max(ms.png_pixels(p, dpi) for p in pages)) > ms.MAX_PNG_PIXELS:
        raise InputError("--dpi", f"{dpi:g} dpi makes a page of {biggest / 1e6:.0f} Mpx (expected at most "
                                  f"{ms.MAX_PNG_PIXELS / 1e6:.0f}: a lower --dpi, or --format pdf)")
    warn_rig(the_rig)
    out.mkdir(parents=True, exist_ok=True)
    table = Table(title=f"marker sheets of {rig} ({the_rig.dictionary}, black square {the_rig.marker_size * 1000:.0f} "
                        "mm)")
    for col in ("marker", "body", "cone", "face", "page [mm]", "file"):
        table.add_column(col, justify="right" if col in ("marker", "page [mm]") else "left")
    for page, path in zip(pages, paths, strict=True):
        ms.write_sheet(page, path, fmt.value, dpi)
        width, height = page.page_m
        table.add_row(str(page.marker.id), page.marker.body, page.marker.cone, page.marker.face,
                      f"{width * 1000:.0f} × {height * 1000:.0f}", str(path))
    console.print(table)
    console.print(f"wrote {len(pages)} sheets to {out}: print each at 100 % (actual size)", markup=False)


def check(
    rig: Annotated[Path, typer.Option(help="Rig file of the installation.")],
    seconds: Annotated[float, typer.Option(help="Seconds of each camera to read.",
                                           callback=finite(0.0, high=MAX_CHECK_SECONDS))] = 5.0,
    rrd: Annotated[Path | None, typer.Option(help="Also write a Rerun recording of the installation as understood: "
                                                  "markers, cones, every camera placed by its markers with its "
                                                  "first frame.")] = None,
    refine: RefineOption = DEFAULT_REFINEMENT,
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
    check_outputs({"--rrd": rrd}, rig_inputs(the_rig))
    warn_rig(the_rig)
    with progress_bar() as progress:
        task = progress.add_task(f"reading {seconds:g} s of {len(the_rig.cameras)} cameras", total=None, unit="frames")
        report = check_rig(the_rig, seconds, refine, on_frame=lambda: progress.advance(task))
    warn_lines(report.warnings)
    _print_check(report)
    if rrd is not None:
        from viewer.check_recording import record_check

        with atomic_path(rrd) as partial:
            record_check(report, partial)
        console.print(f"wrote {rrd} (open it with: topside view {rrd})")
    if not report.ready:
        raise typer.Exit(1)


def _print_check(report: CheckReport) -> None:
    """The check's tables (cameras, markers seen, disagreements, cones), a line per finding, and its verdict."""
    rig = report.rig
    console.print(f"checked {rig.path} ({rig.name}): {len(rig.markers)} markers, {len(report.cones)} cones, "
                  f"{len(rig.cameras)} cameras, {report.seconds:g} s of each")
    for line in report.rig_errors():  # first: everything after may follow from it
        console.print(f"rig error: {line}", markup=False)
    console.print(_cameras_table(report))
    for c in report.cameras:
        for line in c.problems:
            console.print(line)
    console.print(_markers_table(report))
    console.print("where: J jacket, T topside; px/cell: pixels per code cell along the marker's shortest side")
    if report.unseen_markers:
        console.print(f"markers of the rig no camera sees: {', '.join(map(str, report.unseen_markers))}")
    for i, cameras in report.unknown_ids.items():
        console.print(f"id {i} is not in the rig, seen by {', '.join(cameras)}")
    if report.disagreements:
        console.print(_disagreements_table(report))
        for d in report.disagreements:
            console.print(f"disagrees: {d.camera}: {d.reason}")
    console.print(_cones_table(report))
    for c in report.cones:
        console.print(f"cone {c.cone}: {c.verdict}: {c.reason}")
    _print_check_verdict(report)


def _cameras_table(report: CheckReport) -> Table:
    """Per camera: its clock (frames, rates, dropped and irregular intervals), the markers it sees, its survey."""
    table = Table(title="cameras")
    for col in ("camera", "frames", "fps stated", "fps kept", "dropped", "irregular", "markers", "survey [m]"):
        table.add_column(col, justify="left" if col in ("camera", "markers") else "right")
    for c in report.cameras:
        k = c.clock
        survey_m = "–" if c.survey_m is None else f"{c.survey_m:.2f}" + (" refused" if c.survey_conflict else "")
        table.add_row(c.camera, str(k.frames), f"{k.declared_fps:.3f}",
                      f"{k.measured_fps:.3f}" if np.isfinite(k.measured_fps) else "–", str(k.dropped),
                      str(k.irregular), " ".join(str(s.marker) for s in c.sights) or "none", survey_m)
    return table


def _markers_table(report: CheckReport) -> Table:
    """Per camera and marker seen: where it is, how often, how far, how oblique, how large and how well it fits."""
    table = Table(title="markers seen (medians over the frames that show them)")
    for col in ("camera", "marker", "where", "seen", "distance [m]", "off normal [°]", "px/cell", "reproj. [px]"):
        table.add_column(col, justify="left" if col in ("camera", "where") else "right")
    by_id = report.rig.marker_by_id
    for c in report.cameras:
        for s in c.sights:
            m = by_id[s.marker]
            table.add_row(c.camera, str(s.marker), f"{m.body[0].upper()} {m.cone}/{m.face}", f"{s.share:.0%}",
                          f"{s.distance_m:.1f}", f"{s.angle_deg:.0f}", f"{s.cell_px:.1f}", f"{s.reprojection_px:.2f}")
    return table


def _disagreements_table(report: CheckReport) -> Table:
    """Per disagreement: the camera, the markers it names, and how far off the rig they are."""
    table = Table(title="markers that disagree with the rig")
    for col in ("camera", "markers", "frames", "residual [m]", "σ [m]", "normal [°]", "turn [°]"):
        table.add_column(col, justify="left" if col in ("camera", "markers") else "right")
    for d in report.disagreements:
        table.add_row(d.camera, ", ".join(map(str, d.markers)), str(d.frames), f"{d.offset_m:.2f}",
                      f"{d.sigma_m:.2f}", f"{d.normal_deg:.0f}", f"{d.turn_deg:+.0f}")
    return table


def _cones_table(report: CheckReport) -> Table:
    """Per cone: σ per axis (mm, – when unknown), the cameras that see it, its verdict."""
    table = Table(title="cones (σ from the fusion filter after these seconds)")
    for col in ("cone", "σx [mm]", "σy [mm]", "σz [mm]", "cameras", "verdict"):
        table.add_column(col, justify="right" if col.startswith("σ") else "left")
    for c in report.cones:
        sigma = [f"{v * 1000:.0f}" if np.isfinite(v) else "–" for v in c.sigma_m]
        table.add_row(c.cone, *sigma, ", ".join(c.cameras) or "none", c.verdict)
    return table


def _print_check_verdict(report: CheckReport) -> None:
    """READY, or NOT READY with what is not (cones by verdict, markers that disagree, other findings) and what to run
    next."""
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


def sync(
    rig: Annotated[Path, typer.Option(help="Rig file whose cameras' clocks to measure.")],
    out: Annotated[Path, typer.Option("-o", "--out", help="Rig file to write, with the measured time_offsets.")],
    reference: Annotated[str | None, typer.Option(help="Camera whose clock the others are set to (default: the one "
                                                       "that times the topside's motion best).")] = None,
    refine: RefineOption = DEFAULT_REFINEMENT,
) -> None:
    """Measure every camera's clock offset against the others from the topside's motion they all see; write the rig
    with the measured time_offsets and their σ.

    A camera whose offset the footage cannot tell (a still topside, a far view) keeps the rig's offset and is named.
    Exit status: 0 when every clock is measured; 1 when one is not (the rig is still written); 2 for bad input.
    """
    import time

    from tracking.clocks import synced_rig, synchronise
    from tracking.fieldwork import footage_measurements, write_rig
    from tracking.rig import load_rig

    the_rig = load_rig(rig)
    check_outputs({"--out": out}, rig_inputs(the_rig))
    if reference is not None and reference not in {c.name for c in the_rig.cameras}:
        raise InputError(reference, f"is not a camera of {rig} (expected one of "
                                    f"{', '.join(c.name for c in the_rig.cameras)})", "--reference")
    warn_rig(the_rig)
    t0 = time.perf_counter()
    with progress_bar() as progress:
        task = progress.add_task(f"measuring {len(the_rig.cameras)} cameras", total=None, unit="frames")
        offsets, _, seconds = footage_measurements(the_rig, refine, observations=False,
                                                   on_frame=lambda _: progress.advance(task))
        t1 = time.perf_counter()
        clocks = synchronise(the_rig, offsets, reference)
    console.print(clock_table(clocks))
    for line in clock_lines(clocks):
        console.print(line, markup=False)
    write_rig(synced_rig(the_rig, clocks), out, the_rig)
    console.print(f"wrote {out} · {seconds / 60:.1f} camera-minutes: measured in {t1 - t0:.0f} s, fitted in "
                  f"{time.perf_counter() - t1:.1f} s", markup=False)
    if not all(c.known for c in clocks):
        raise typer.Exit(1)


def clock_table(clocks: list[CameraClock]) -> Table:
    """`topside sync`'s table: each camera's offset in the rig, as measured, the change and its σ."""
    table = Table(title="camera clocks (time_offset, s, against the reference's clock)")
    for col in ("camera", "frames", "rig [s]", "measured [s]", "change [ms]", "σ [ms]", "note"):
        table.add_column(col, justify="left" if col in ("camera", "note") else "right")
    for c in clocks:
        known = c.known and c.sigma is not None
        table.add_row(c.camera, str(c.frames), f"{c.rig_offset:+.3f}", f"{c.offset:+.4f}" if known else "–",
                      f"{c.change * 1e3:+.1f}" if known else "–", f"{c.sigma * 1e3:.1f}" if known else "–",
                      "reference" if c.reference else "" if known else "NOT MEASURED")
    return table


def clock_lines(clocks: list[CameraClock]) -> list[str]:
    """One line per camera whose offset the footage could not tell (left as the rig has it)."""
    return [f"{c.camera}: clock not measured: {c.note}; its time_offset is left at {c.rig_offset:+.3f} s"
            for c in clocks if not c.known]


def survey(
    rig: Annotated[Path, typer.Option(help="Rig file whose markers to survey (its clocks measured: topside sync).")],
    out: Annotated[Path, typer.Option("-o", "--out", help="Rig file to write, with the markers' corrected poses.")],
    start: Annotated[float | None, typer.Option("--from", help="From this capture time, s (the bodies still or "
                                                               "moving rigidly: before the lift).",
                                                callback=finite(-math.inf))] = None,
    end: Annotated[float | None, typer.Option("--to", help="To this capture time, s.", callback=finite(-math.inf))
                   ] = None,
    refine: RefineOption = DEFAULT_REFINEMENT,
) -> None:
    """Refine every marker's pose on its body from the footage (a bundle adjustment of all cameras' frames and the
    markers' corners, each marker's survey σ as its prior, a marker named reference held); write the rig with each
    correction and its σ, and flag markers moved beyond the rig's survey_tolerance.

    Exit status: 0 when no marker is flagged; 1 when one is (the rig is still written); 2 for bad input.
    """
    import time

    from tracking.fieldwork import footage_measurements, write_rig
    from tracking.rig import load_rig
    from tracking.survey import survey_markers, surveyable, surveyed_rig

    the_rig = load_rig(rig)
    check_outputs({"--out": out}, rig_inputs(the_rig))
    if start is not None and end is not None and end <= start:
        raise InputError("--to", f"{end:g} s is not after --from {start:g} s (expected a stretch of footage)")
    surveyable(the_rig)  # a rig with nothing to survey is refused before any footage is read
    warn_rig(the_rig)
    t0 = time.perf_counter()
    with progress_bar() as progress:
        task = progress.add_task(f"measuring {len(the_rig.cameras)} cameras", total=None, unit="frames")
        offsets, observations, seconds = footage_measurements(the_rig, refine, start, end,
                                                              on_frame=lambda _: progress.advance(task))
        t1 = time.perf_counter()
        fit = survey_markers(the_rig, [*offsets, *observations])
    console.print(survey_table(the_rig, fit))
    console.print("where: J jacket, T topside; survey's σ kept: the footage cut its σ by less than a quarter (it "
                  "cannot tell where that marker sits)", markup=False)
    for line in survey_lines(the_rig, fit):
        console.print(line, markup=False)
    write_rig(surveyed_rig(the_rig, fit), out, the_rig)
    console.print(f"wrote {out} · {seconds / 60:.1f} camera-minutes: measured in {t1 - t0:.0f} s, fitted in "
                  f"{time.perf_counter() - t1:.1f} s ({fit.iterations} iterations)", markup=False)
    if any(s.flagged for s in fit.markers):
        raise typer.Exit(1)


def survey_table(rig: Rig, fit: SurveyFit) -> Table:
    """`topside survey`'s table: each marker's correction and σ as the rig written takes it (largest over the body's
    axes; every axis is in the rig), what the footage taught, flags."""
    table = Table(title=f"marker poses ({fit.frames} camera frames, {fit.corners} corners, RMS {fit.rms_px:.2f} px)")
    for col in ("marker", "where", "views", "moved [mm]", "σ [mm]", "turned [°]", "σ [°]", "note"):
        table.add_column(col, justify="left" if col in ("where", "note") else "right")
    by_id = rig.marker_by_id
    for s in fit.markers:
        m = by_id[s.id]
        note = "reference" if s.reference else "FLAGGED" if s.flagged else \
            "survey's σ kept" if s.learnt < LEARNT_SHARE else ""
        table.add_row(str(s.id), f"{m.body[0].upper()} {m.cone}/{m.face}", str(s.views),
                      f"{np.linalg.norm(s.position_m) * 1e3:.1f}", f"{np.max(s.held_m) * 1e3:.1f}",
                      f"{np.degrees(np.linalg.norm(s.rotation_rad)):.2f}", f"{np.degrees(np.max(s.held_rad)):.2f}",
                      note)
    return table


def survey_lines(rig: Rig, fit: SurveyFit) -> list[str]:
    """One line per flagged marker, and one if the clocks look unsynchronised."""
    from tracking.survey import untimed_cameras

    lines = [f"marker {s.id}: moved {np.linalg.norm(s.position_m) * 1e3:.0f} mm and "
             f"{np.degrees(np.linalg.norm(s.rotation_rad)):.2f}° from the rig, beyond the survey's tolerance: check "
             "its mounting and its entry in the rig" for s in fit.markers if s.flagged]
    untimed = sorted(untimed_cameras(rig))
    if untimed:
        lines.append(f"{', '.join(untimed)}: clock not measured (topside sync): its views of the topside are left out, "
                     "its jacket markers kept")
    if len(rig.cameras) > 1 and all(c.time_offset_sigma is None for c in rig.cameras):
        lines.append("the rig's clocks are not measured (no time_offset_sigma): a moving topside seen on clocks that "
                     "disagree moves the markers; run topside sync first")
    return lines
