"""What `track` prints after a run: a table per camera and per cone, what it wrote, and the rig's findings (a rig
error as one error line, cameras never placed, a scale nothing fixed, cones never shown)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from tracking.cli.common import console, err_console
from tracking.cli.options import Mode
from tracking.errors import InputError

if TYPE_CHECKING:
    from tracking.cli.run import Fusion
    from tracking.cone_tally import ConeTallies
    from tracking.estimator import FilterReport
    from tracking.pipeline import TrackStats
    from tracking.rig import Rig


def print_track_summary(rig: Rig, rig_path: Path, mode: Mode, stats: TrackStats, fusion: Fusion) -> None:
    """The run's table per camera, how it was fused, and what it ignored."""
    from rich.table import Table

    from tracking.split import LEAD_IN_S

    table = Table(title=f"tracked {rig_path} ({mode} mode)")
    for col in ("camera", "frames", "markers", "pair offsets", "ambiguous"):
        table.add_column(col, justify="right" if col != "camera" else "left")
    for cam in rig.cameras:
        n = cam.name
        table.add_row(n, str(stats.frames[n]), str(stats.markers[n]), str(stats.pair_offsets[n]),
                      str(stats.ambiguous[n]))
    console.print(table)
    if fusion.info.segments > 1:
        console.print(f"fused in {fusion.info.segments} segments of {fusion.segment_s:g} s over time, each from "
                      f"{LEAD_IN_S:g} s before its start (--one-pass-fusion: in one pass)")
    if stats.unknown_ids:
        summary = ", ".join(f"id {i}: {n}" for i, n in sorted(stats.unknown_ids.items()))
        console.print(f"markers not in the rig (ignored): {summary}", style="yellow")
    if stats.mirrored:
        summary = ", ".join(f"{cam} id {i}: {n}" for (cam, i), n in sorted(stats.mirrored.items()))
        console.print(f"markers that may be seen mirrored (from behind, or reflected) and that no other marker of "
                      f"their body confirmed (dropped): {summary}", style="yellow")
    for line in stats.warnings([c.name for c in rig.cameras]):  # videos cut short, timestamps back or jumping
        err_console.print(f"topside: warning: {line}", style="yellow")


def print_cones(tally: ConeTallies) -> None:
    """Per cone: the share of its estimates shown, the first, why the others were withheld, the least σ it reached and
    the cameras that measured its pair."""
    from rich.table import Table

    if not tally.cones:
        return
    table = Table(title="cones")
    for col in ("cone", "shown", "first shown", "withheld", "least σ", "pair measured by (frames)"):
        table.add_column(col, justify="right" if col in ("shown", "first shown") else "left")
    for row in tally.rows():
        table.add_row(*row)
    console.print(table)


def warn_cones(tally: ConeTallies) -> None:
    """A warning line for each cone never shown, saying why (after the rig's findings: a rig error says it instead)."""
    for cone in tally.cones.values():
        if why := cone.why_never():
            err_console.print(f"topside: warning: {why}", markup=False)


def print_track_outputs(rows: int, out: Path, rrd: Path | None, mcap: Path | None) -> None:
    """What the run wrote, and the command that opens or checks each."""
    console.print(f"wrote {rows} rows to {out}")
    if rrd is not None:
        console.print(f"wrote {rrd} (open it with: topside view {rrd})")
    if mcap is not None:
        console.print(f"wrote {mcap} (check it with: topside verify {mcap})")


def rig_findings(rig_path: Path, report: FilterReport, stats: TrackStats | None = None) -> None:
    """After a fused run: a rig error it found (the markers' size, the topside through its cones), which withheld the
    offsets, is one error line and exit status 2; else a warning each for the cameras never placed (with why: where
    the filter had none of its frames, the markers it dropped as seen mirrored), a scale nothing fixed and each view it
    found misread."""
    if report.scale.mismatch:
        raise InputError(rig_path, report.scale.message() + "; the offsets were withheld", "marker_size")
    if report.below[0]:
        raise InputError(rig_path, f"{report.below[0]} offsets put the topside up to {-report.below[1]:.2f} m below "
                                   "its cone tips, where no set-down can be (withheld): marker_size, a marker's centre "
                                   "or a pair's mated offset is wrong", "marker_size")
    for name, why in report.unplaced.items():
        why = stats.never_placed(name, why) if stats is not None else why
        err_console.print(f"topside: warning: {name}: never placed, so none of its frames was used: {why}",
                          markup=False)
    if not report.scale.fixed:
        err_console.print(f"topside: warning: {rig_path}: marker_size: {report.scale.message()}", markup=False)
    from tracking.estimator.filter import misread_warning

    for (camera, marker), px in sorted(report.misread.items()):
        err_console.print(f"topside: warning: {misread_warning(camera, marker, px)}", markup=False)
