"""What `topside sync` and `topside survey` share: the footage's measurements, the rig they write, their tables."""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

import numpy as np
from rich.table import Table

from tracking.clocks import CameraClock
from tracking.detection import DEFAULT_REFINEMENT, Refinement
from tracking.errors import InputError
from tracking.offsets import BodyObservation, PairOffset
from tracking.rig import Rig, save_rig
from tracking.sources import SourceKind, source_kind
from tracking.survey import SurveyFit, untimed_cameras

LEARNT_SHARE = 0.25  # a marker whose σ the footage cut by less than this share is reported as not told by it


def footage_measurements(rig: Rig, refinement: Refinement = DEFAULT_REFINEMENT, start: float | None = None,
                         end: float | None = None, observations: bool = True,
                         on_frame: Callable[[float], None] | None = None
                         ) -> tuple[list[PairOffset], list[BodyObservation], float]:
    """Every camera's pair offsets and body observations (with observations) between start and end (capture times on
    the rig's clocks, s), as `topside track` measures them; and the seconds of footage read per camera, summed."""
    from tracking.pipeline import track_rig

    offsets: list[PairOffset] = []
    seen: list[BodyObservation] = []
    spans: dict[str, list[float]] = {}
    for r in track_rig(rig, refinement):
        if on_frame is not None:
            on_frame(r.time)
        if start is not None and r.time < start:
            continue
        if end is not None and r.time > end:
            break  # merged in capture-time order: every later frame is later still
        span = spans.setdefault(r.camera, [r.time, r.time])
        span[1] = r.time
        offsets += r.offsets
        if observations and r.observation is not None:
            seen.append(r.observation)
    if not offsets and not seen:
        window = "" if start is None and end is None else f" between {start or 0:g} s and {end if end else 'the end'}"
        raise InputError(rig.path, f"no camera saw a rig marker{window} (expected footage showing the markers)")
    return offsets, seen, sum(b - a for a, b in spans.values())


def rig_for(rig: Rig, out: Path) -> Rig:
    """The rig with its cameras' file paths made relative to out's folder (a rig written elsewhere still finds its
    calibrations and videos)."""
    here = rig.path.parent.resolve() if rig.path else Path.cwd()
    there = Path(out).parent.resolve()
    if here == there:
        return rig

    def moved(relative: str) -> str:
        if source_kind(relative) != SourceKind.FILE or Path(relative).is_absolute():
            return relative
        return os.path.relpath(rig.resolve(relative).resolve(), there)

    cameras = [c.model_copy(update={"calibration": moved(c.calibration), "source": moved(c.source)})
               for c in rig.cameras]
    return rig.model_copy(update={"cameras": cameras})


def write_rig(rig: Rig, out: Path) -> None:
    """Write a rig atomically at out, its paths relative to out's folder."""
    save_rig(out, rig_for(rig, out))


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
