"""Runs of the tracker over recorded videos: `track` one installation, `batch` many, `evaluate` offsets against a
truth, and the `demo` that simulates, tracks and evaluates one.

`track` and `batch` share one loop (RunLoop): the rig's videos cut into chunks and tracked by worker processes or Ray
tasks (tracking.parallel), each frame counted, shown on the progress bar and given to the sinks (a Rerun recording,
an MCAP archive), and the estimator's offsets written to the CSV and given to the sinks; a long run's fusion split
over time into segments fused by the same workers (tracking.split). `batch` with at least as many installations as
workers tracks and fuses each whole on one worker, as many at once as there are workers.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from tracking.cli.archive import ArchiveSettings, archive_sink
from tracking.cli.common import (
    EXIT_INTERRUPTED,
    Reporter,
    console,
    err_console,
    one_line,
    progress_bar,
    rig_inputs,
    warn_lines,
    warn_rig,
)
from tracking.cli.options import (
    CHUNK_FRAMES_DEFAULT,
    FUSION_SEGMENT_DEFAULT,
    ChunkOption,
    FusionSegmentOption,
    KeyOption,
    Mode,
    OnePassOption,
    OperatorOption,
    RayOption,
    RefineOption,
    VesselOption,
    VideoFormat,
    VideoOption,
    WorkersOption,
    finite,
)
from tracking.cli.track_summary import print_cones, print_track_outputs, print_track_summary, rig_findings, warn_cones
from tracking.cli.view import view
from tracking.cone_tally import ConeTallies
from tracking.detection import DEFAULT_REFINEMENT, Refinement
from tracking.errors import InputError
from tracking.outputs import Outputs, check_outputs

if TYPE_CHECKING:
    import pandas as pd

    from tracking.batch import Installation, Outcome
    from tracking.estimate import ConeEstimate
    from tracking.estimator import FilterReport, Measurement
    from tracking.evaluate import Evaluation
    from tracking.offsets_csv import OffsetsWriter
    from tracking.parallel import Runner, VideoPlan
    from tracking.pipeline import Sink, TrackStats
    from tracking.rig import Rig
    from tracking.split import SplitInfo

# tracking.estimator.ESTIMATORS' values: (rig, measurements, report)
Estimator = Callable[..., Iterable["ConeEstimate"]]

DEMO_SCENARIO = "config2-procedure5-weather"
DEMO_DURATION_S = 20.0


@dataclass
class RunLoop:
    """The loop `track` and `batch` share: the rig's planned chunks tracked by run (tracking.parallel.track_chunks),
    each frame counted in stats, advanced on the progress bar and given to the sinks; the estimator's offsets written
    to the offsets CSV and given to the sinks. roi: search each frame around the markers of the frames before it;
    warn: print each frame's warnings."""

    rig: Rig
    run: Runner
    refine: Refinement
    plans: list[VideoPlan]
    stats: TrackStats
    advance: Callable[[], None] = lambda: None
    sinks: list[Sink] = field(default_factory=list)
    roi: bool = False
    warn: bool = False
    writer: OffsetsWriter | None = None  # the offsets CSV's, once open
    tally: ConeTallies = field(default_factory=ConeTallies)  # what each cone showed, and why not

    @property
    def rows(self) -> int:
        """Offsets written so far (also after an interruption)."""
        return self.writer.rows if self.writer is not None else 0

    def measurements(self) -> Iterator[Measurement]:
        """The tracked frames' pair offsets and body observations, in capture-time order."""
        from tracking.parallel import track_chunks

        sinks = bool(self.sinks)  # the sinks record the frames' packets, images, detections and poses; the CSV alone
        for result in track_chunks(self.rig, self.run, self.refine, packets=sinks, keep_gray=sinks,  # needs none
                                   roi_tracking=self.roi, stats=self.stats, plans=self.plans, lean=not sinks):
            self.stats.add(result)
            self.advance()
            if self.warn:
                warn_lines(result.warnings)
            for sink in self.sinks:
                sink.on_frame(result)
            for m in result.measurements:
                self.tally.measured(m)
                yield m

    def write(self, csv: Path, estimator: Estimator, report: FilterReport | None = None) -> None:
        """The estimator's offsets into csv and the sinks. The sinks are closed after the CSV however the loop ends
        (an archive attaches the finished CSV); while an error propagates, a sink that fails to close does not hide
        it."""
        from tracking.offsets_csv import OffsetsWriter

        try:
            with OffsetsWriter(csv) as self.writer:
                for e in estimator(self.rig, self.measurements(), report=report):
                    for sink in self.sinks:
                        sink.on_estimate(e)
                    self.writer.write(e)
                    self.tally.add(e)
        finally:
            error = sys.exc_info()[1]
            failing = error is not None
            stopped = "" if error is None else "stopped by the operator" if isinstance(error, KeyboardInterrupt) \
                else f"stopped by an error: {one_line(error)}"
            for sink in self.sinks:
                try:
                    sink.close(stopped)
                except Exception:
                    if not failing:
                        raise


@dataclass(frozen=True)
class Fusion:
    """How a run fuses: in one pass on the command's process, or split over time into segments of segment_s fused by
    the runner (tracking.split; the modes without a filter always in one pass)."""

    one_pass: bool = False
    segment_s: float = FUSION_SEGMENT_DEFAULT
    info: SplitInfo = field(default_factory=lambda: _split_info())  # what the split did, once run

    def estimator(self, mode: str, run: Runner, poses: bool) -> Estimator:
        """The estimator of `mode` as this fusion runs it: (rig, measurements, report=None) -> estimates.
        poses: keep the cameras' poses in the estimates (the sinks show them)."""
        from tracking.estimator import ESTIMATORS
        from tracking.split import SPLIT_MODES, split_estimates

        if self.one_pass or mode not in SPLIT_MODES:
            return ESTIMATORS[mode]

        def split(rig: Rig, measurements: Iterable[Measurement], report: FilterReport | None = None
                  ) -> Iterable[ConeEstimate]:
            return split_estimates(rig, measurements, mode, run, self.segment_s, poses=poses, report=report,
                                   info=self.info)

        return split


def _split_info() -> SplitInfo:
    from tracking.split import SplitInfo

    return SplitInfo()


def recorder(rig: Rig, path: Path, truth_df: pd.DataFrame | None, options: dict[str, str],
             show_rejected: bool = False) -> Sink:
    """The Rerun recording of a run (the command line composes tracker and viewer; tracking/ never imports viewer)."""
    from viewer.session import Recorder

    return Recorder(rig, path, truth_df, show_rejected=show_rejected, options=options)


ModeOption = Annotated[Mode, typer.Option(help="fused: live rigid-body Kalman filter of all cameras; smoothed: the "
                                               "same, then smoothed (RTS) by the next 45 s at least; paper: the "
                                               "paper's method; raw: every camera's pair offset.")]
RoiOption = Annotated[bool, typer.Option("--roi", help="Search each frame around the markers of the frames before it "
                                                       "(the live path's detector, afresh at every chunk): about 2.4x "
                                                       "less CPU per frame; on the demo 0.8 % fewer markers, e_MAE 1 "
                                                       "mm larger in x and y.")]


def track(
    rig: Annotated[Path, typer.Option(help="Rig file of the installation.")],
    out: Annotated[Path, typer.Option("-o", "--out", help="Offsets CSV to write.")] = Path("offsets.csv"),
    mode: ModeOption = Mode.FUSED,
    refine: RefineOption = DEFAULT_REFINEMENT,
    rrd: Annotated[Path | None, typer.Option(help="Also record everything to this Rerun file (.rrd).")] = None,
    truth: Annotated[Path | None, typer.Option(help="Ground-truth log to overlay in the recording.")] = None,
    rejected: Annotated[bool, typer.Option("--rejected", help="Record rejected marker candidates too.")] = False,
    mcap: Annotated[Path | None, typer.Option(help="Also write an MCAP audit archive (opens in Foxglove, Rerun).")
                    ] = None,
    key: KeyOption = None,
    vessel: VesselOption = "",
    operator: OperatorOption = "",
    video: VideoOption = VideoFormat.JPEG,
    workers: WorkersOption = None,
    ray: RayOption = None,
    chunk_frames: ChunkOption = CHUNK_FRAMES_DEFAULT,
    roi: RoiOption = False,
    one_pass_fusion: OnePassOption = False,
    fusion_segment: FusionSegmentOption = FUSION_SEGMENT_DEFAULT,
) -> None:
    """Track the rig's videos and write the offset at each cone per timestamp (CSV), optionally a recording.

    Each camera's video is cut into chunks at keyframes, tracked in worker processes (--workers) or Ray tasks
    (--ray) and fused in capture-time order, a run longer than --fusion-segment in segments over time by the same
    workers (--one-pass-fusion: in one pass here). The output is the same whatever runs the chunks and segments."""
    from tracking.rig import load_rig

    the_rig = load_rig(rig)  # bad input first: the tracker's own imports cost a second
    check_outputs({"--out": out, "--rrd": rrd, "--mcap": mcap}, [*rig_inputs(the_rig), truth, key])
    truth_df = optional_truth(truth)
    archive = ArchiveSettings.for_track(mcap, key, vessel, operator, video)  # before any work
    from tracking.estimator import FilterReport
    from tracking.parallel import runner
    from tracking.pipeline import TrackStats

    options = {"mode": mode.value, "refine": refine.value, **({"roi": "on"} if roi else {})}
    report, fusion, outputs = FilterReport(), Fusion(one_pass_fusion, fusion_segment), Outputs(keep_on_interrupt=True)
    loop = RunLoop(the_rig, runner(workers, ray), refine, [], TrackStats(), roi=roi, warn=True)
    try:
        with outputs, progress_bar() as progress:
            _plan(loop, progress, chunk_frames)
            csv = outputs.claim(out)
            if rrd is not None:
                loop.sinks.append(recorder(the_rig, outputs.claim(rrd), truth_df, options, show_rejected=rejected))
            if archive is not None:
                loop.sinks.append(archive_sink(the_rig, outputs.claim(mcap), options, truth_df, archive, csv))
            loop.write(csv, fusion.estimator(mode.value, loop.run, poses=bool(loop.sinks)), report)
    except KeyboardInterrupt:
        kept = ", ".join(map(str, outputs.kept)) or "nothing"
        err_console.print(f"stopped after {loop.rows} rows; what was written is kept in {kept}", markup=False)
        raise typer.Exit(EXIT_INTERRUPTED) from None
    finally:
        loop.run.close()
    print_track_summary(the_rig, rig, mode, loop.stats, fusion)
    print_cones(loop.tally)
    print_track_outputs(loop.rows, out, rrd, mcap)
    if mode in (Mode.FUSED, Mode.SMOOTHED):
        rig_findings(rig, report, loop.stats)
    warn_cones(loop.tally)


def optional_truth(path: Path | None) -> pd.DataFrame | None:
    """The truth CSV, when one is given (pandas is imported only then: 0.5 s at a command's start)."""
    if not path:
        return None
    from tracking.evaluate import read_truth

    return read_truth(path)


def _plan(loop: RunLoop, progress: Reporter, chunk_frames: int) -> None:
    """The rig's videos cut into chunks (their keyframes found) under a progress task, then the rig's warnings (once
    every input is read: bad input stays the one line on stderr); the task then counts the frames tracked."""
    from tracking.parallel import plan_rig

    cameras = len(loop.rig.cameras)
    task = progress.add_task(f"finding the keyframes of {cameras} videos", total=None)
    loop.plans = plan_rig(loop.rig, chunk_frames=chunk_frames)
    warn_rig(loop.rig)
    progress.update(task, description=f"tracking {cameras} cameras", total=sum(p.frames for p in loop.plans) or None,
                    unit="frames")
    loop.advance = lambda: progress.advance(task)


@dataclass
class Prepared:
    """One installation of a batch as read before any work: its rig and plans, or the one-line reason it cannot run."""

    inst: Installation
    rig: Rig | None
    plans: list[VideoPlan]
    error: str = ""


def batch(
    manifest: Annotated[Path, typer.Argument(help="YAML manifest: a list of installations, one per line: {rig: R, "
                                                  "out: FOLDER, truth: T (optional)}.")],
    workers: WorkersOption = None,
    ray: RayOption = None,
    refine: RefineOption = DEFAULT_REFINEMENT,
    chunk_frames: ChunkOption = CHUNK_FRAMES_DEFAULT,
    one_pass_fusion: OnePassOption = False,
    fusion_segment: FusionSegmentOption = FUSION_SEGMENT_DEFAULT,
) -> None:
    """Re-analyse many installations: each one's offsets.csv (run.rrd with rrd: true, run.rrd and the lift's
    report.html with report: true, accuracy.md with a truth) in
    its out folder, one progress bar over all, then a table: frames, video and wall time, accuracy, failures.

    With at least as many installations as workers, each is tracked and fused whole by one worker, as many at once as
    there are workers; with fewer, one after another, each over every worker. The outputs are the same either way.
    One that fails does not stop the others. Exit status: 0 when all succeeded, 1 when any failed, 2 for a bad
    manifest."""
    import time

    from tracking.batch import load_manifest
    from tracking.parallel import runner

    installations = load_manifest(manifest)
    run = runner(workers, ray)
    fusion = Fusion(one_pass_fusion, fusion_segment)
    at_once = 1 < run.workers <= len(installations)
    outcomes: list[Outcome] = []
    started = time.perf_counter()
    try:
        with progress_bar() as progress:
            task = progress.add_task(f"finding the keyframes of {len(installations)} installations", total=None)
            prepared = [_prepare(inst, chunk_frames) for inst in installations]  # every rig and keyframe, first
            how = "at once" if at_once else "one after another"
            progress.update(task, description=f"{len(installations)} installations on {run.workers} workers ({how})",
                            total=sum(p.frames for one in prepared for p in one.plans) or None, unit="frames")

            def advance(frames: int = 1) -> None:
                progress.advance(task, frames)

            if at_once:
                outcomes = _batch_at_once(prepared, run, refine, fusion, advance)
            for one in prepared if not at_once else ():
                progress.update(task, description=f"{one.inst.label} ({len(outcomes) + 1}/{len(installations)})")
                outcomes.append(_batch_one(one, run, refine, fusion, advance))
    finally:
        run.close()
    _print_batch(manifest, outcomes, time.perf_counter() - started,
                 f"{min(run.workers, len(prepared))} at once, each on one worker" if at_once else
                 f"one after another, each on {run.workers} worker{'s' if run.workers > 1 else ''}")
    if not all(o.ok for o in outcomes):
        raise typer.Exit(1)


@dataclass(frozen=True)
class InstallationTask:
    """One installation of a batch for one worker to track and fuse whole (picklable: by value, paths every node
    sees)."""

    one: Prepared
    refine: Refinement
    fusion: Fusion


def installation_task(task: InstallationTask) -> Outcome:
    """A worker's installation: tracked in place (its chunks one after another, its segments too), its outputs
    written, its Outcome returned."""
    from tracking.parallel import InPlace

    return _batch_one(task.one, InPlace(), task.refine, task.fusion, lambda frames=1: None)


def _batch_at_once(prepared: list[Prepared], run: Runner, refine: Refinement, fusion: Fusion,
                   advance: Callable[..., None]) -> list[Outcome]:
    """Every installation as one task of the runner, their Outcomes in the manifest's order (a worker that died names
    its installation's failure in one line)."""
    from tracking.batch import Outcome

    handles = [run.call(installation_task, InstallationTask(one, refine, fusion)) for one in prepared]
    outcomes = []
    for one, handle in zip(prepared, handles, strict=True):
        try:
            outcome = run.wait(handle)
        except Exception as exc:  # the worker itself failed (killed, out of memory): this installation only
            outcome = Outcome(one.inst.label, error=one_line(f"{type(exc).__name__}: {exc}"))
        advance(sum(p.frames for p in one.plans))
        outcomes.append(outcome)
    return outcomes


def _prepare(inst: Installation, chunk_frames: int) -> Prepared:
    """An installation's rig read and every video's keyframes found, or why not."""
    from tracking.parallel import plan_rig
    from tracking.rig import load_rig

    try:
        the_rig = load_rig(inst.rig)
        return Prepared(inst, the_rig, plan_rig(the_rig, chunk_frames=chunk_frames))
    except InputError as exc:
        return Prepared(inst, None, [], one_line(exc))


def _batch_one(one: Prepared, run: Runner, refine: Refinement, fusion: Fusion, advance: Callable[..., None]
               ) -> Outcome:
    """One installation of a batch: its outputs, or its one-line failure (the frames it did not track are counted
    off the progress bar)."""
    import time

    from tracking.batch import Outcome
    from tracking.pipeline import TrackStats

    inst = one.inst
    outcome = Outcome(inst.label, error=one.error)
    fresh = not inst.out.exists()  # a folder made here and left empty by a failure is removed
    loop = RunLoop(one.rig, run, refine, one.plans, TrackStats(), advance=advance)
    t0 = time.perf_counter()
    try:
        if not one.error:
            _track_installation(inst, loop, outcome, fusion)
    except InputError as exc:
        outcome.error = one_line(exc)
    except Exception as exc:  # not bad input: a bug or the environment; named in one line, the others go on
        outcome.error = one_line(f"{type(exc).__name__}: {exc}")
    finally:
        outcome.frames = sum(loop.stats.frames.values())
        outcome.video_s = max(((v.last_s or 0.0) - (v.first_s or 0.0) for v in loop.stats.videos.values()),
                              default=0.0)
        outcome.wall_s = time.perf_counter() - t0
        advance(max(sum(p.frames for p in one.plans) - outcome.frames, 0))
        if outcome.error and fresh and inst.out.is_dir() and not any(inst.out.iterdir()):
            inst.out.rmdir()
    return outcome


def _track_installation(inst: Installation, loop: RunLoop, outcome: Outcome, fusion: Fusion) -> None:
    """One installation's offsets.csv (and run.rrd), its report.html and verdict with report: true, then, with a truth,
    its accuracy.md and errors in outcome."""
    from tracking.batch import ACCURACY_NAME, OFFSETS_NAME, REPORT_NAME, RRD_NAME
    from tracking.evaluate import evaluate_runs, evaluation_markdown, read_offsets
    from tracking.outputs import write_bytes, write_text

    csv, rrd = inst.out / OFFSETS_NAME, (inst.out / RRD_NAME) if inst.rrd or inst.report else None
    accuracy = inst.out / ACCURACY_NAME if inst.truth is not None else None
    report = inst.out / REPORT_NAME if inst.report else None
    check_outputs({"out": csv, "rrd": rrd, "accuracy": accuracy, "report": report},
                  [*rig_inputs(loop.rig), inst.truth])
    truth_df = optional_truth(inst.truth)
    with Outputs() as outputs:
        if rrd is not None:
            loop.sinks.append(recorder(loop.rig, outputs.claim(rrd), truth_df,
                                       {"mode": inst.mode, "refine": loop.refine.value}))
        loop.write(outputs.claim(csv), fusion.estimator(inst.mode, loop.run, poses=bool(loop.sinks)))
    outcome.rows = loop.rows
    if report is not None and rrd is not None:  # the lift's page, from its recording as `topside report` reads it
        from viewer.installation_record import read_record
        from viewer.report import write_report

        outcome.verdict = write_report(read_record(rrd), report, write_text, None, write_bytes).verdict
    if truth_df is not None and accuracy is not None:
        ev = evaluate_runs(inst.label, [(read_offsets(csv), truth_df)])
        axes = list(ev.axes.values())
        outcome.mae_mm = tuple(1000 * a.mae for a in axes[:3])
        outcome.max_mm = 1000 * max(a.max_abs for a in axes[:3])
        write_text(accuracy, evaluation_markdown(ev))


def _print_batch(manifest: Path, outcomes: list[Outcome], seconds: float, how: str) -> None:
    """The batch's table, one row per installation, how they ran, and a line per failure on stderr."""
    from rich import box
    from rich.table import Table

    table = Table(title=f"{manifest}: {sum(o.ok for o in outcomes)} of {len(outcomes)} installations re-analysed in "
                        f"{seconds:.0f} s (errors against the truth in mm)", box=box.SIMPLE_HEAD,
                  pad_edge=False, collapse_padding=True)
    for col in ("installation", "frames", "video s", "wall s", "fps", "e_MAE x/y/z", "max mm", "result"):
        table.add_column(col, justify="left" if col in ("installation", "result") else "right")
    for o in outcomes:
        mae = "/".join(f"{v:.1f}" for v in o.mae_mm) if o.mae_mm else "—"
        table.add_row(o.name, str(o.frames), f"{o.video_s:.1f}", f"{o.wall_s:.1f}",
                      f"{o.frames / o.wall_s:.0f}" if o.wall_s > 0 and o.frames else "—", mae,
                      f"{o.max_mm:.0f}" if o.max_mm is not None else "—", "ok" if o.ok else "FAILED")
    console.print(table)
    console.print(f"installations tracked {how}")
    for o in outcomes:
        if o.verdict:
            console.print(f"{o.name}: {o.verdict}", markup=False, soft_wrap=True)
    for o in outcomes:
        if not o.ok:
            err_console.print(f"topside: {o.name} failed: {o.error}", markup=False)


def evaluate(
    runs: Annotated[list[Path], typer.Argument(help="OFFSETS.csv TRUTH.csv, repeated: runs pooled into one table.")],
    name: Annotated[str, typer.Option(help="Name of the group of runs (e.g. 'procedures 5, 6, 7').")] = "",
    markdown: Annotated[Path | None, typer.Option(help="Also write the table as markdown.")] = None,
    plots: Annotated[Path | None, typer.Option(help="Folder for estimate/truth/error plots per cone.")] = None,
) -> None:
    """The paper's accuracy table (e_MAE, |e|max, σ_e, μ_e per axis), RMSE, lag and availability against truth."""
    from tracking.evaluate import check_overlap, evaluate_runs, evaluation_markdown, plot_run, read_offsets, read_truth
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
    _print_evaluation(label, ev)
    if markdown:
        write_text(markdown, evaluation_markdown(ev))
    if plots:
        for i, (off, tru) in enumerate(pairs):
            for path in plot_run(off, tru, plots, runs[2 * i].stem):
                console.print(f"wrote {path}")


def _print_evaluation(label: str, ev: Evaluation) -> None:
    """The accuracy table per axis (m), then the lag and the availability."""
    from rich.table import Table

    from tracking.evaluate import NO_VALUE

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


def demo(
    out: Annotated[Path, typer.Option("-o", "--out", help="Folder for the demo's files.")] = Path("recordings"),
    duration: Annotated[float, typer.Option(help="Seconds of the scenario to simulate.",
                                            callback=finite(0.0))] = DEMO_DURATION_S,
    no_viewer: Annotated[bool, typer.Option("--no-viewer", help="Do not open the viewer at the end.")] = False,
) -> None:
    """Simulate configuration 2, procedure 5 in fog and rain, track it (fused), record it, print its accuracy."""
    from tracking.sim.command import run_simulate
    from viewer.playback import has_display

    scene = out / "demo"
    _rule(f"1/3 simulate {DEMO_SCENARIO} ({duration:.0f} s)")
    run_simulate(DEMO_SCENARIO, scene, seed=None, duration=duration)
    _rule("2/3 track (all cameras fused) and record")
    rrd = out / "demo.rrd"
    csv = out / "demo-offsets.csv"
    track(rig=scene / "rig.yaml", out=csv, mode=Mode.FUSED, refine=DEFAULT_REFINEMENT, rrd=rrd,
          truth=scene / "truth.csv", rejected=False)
    _rule("3/3 accuracy against the simulator's truth")
    evaluate(runs=[csv, scene / "truth.csv"], name="demo", markdown=out / "demo-accuracy.md", plots=None)
    if not no_viewer and has_display():
        view(recording=rrd, start=None, end=None, web=False, bind="127.0.0.1")
    else:
        console.print(f"open the recording with:  .venv/bin/topside view {rrd}   (or --web for a browser)")


RULE_WIDTH = 100  # columns of the demo's step rules at most (a log's console is far wider: common.LOG_WIDTH)


def _rule(title: str) -> None:
    """A step's rule across the terminal, or RULE_WIDTH columns in a log."""
    from rich.rule import Rule

    console.print(Rule(title), width=min(console.width, RULE_WIDTH))
