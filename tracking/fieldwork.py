"""What `topside sync` and `topside survey` share: the footage's measurements and the rig they write (their tables are
the command line's: tracking/cli/fieldwork.py)."""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

from tracking.detection import DEFAULT_REFINEMENT, Refinement
from tracking.errors import InputError
from tracking.offsets import BodyObservation, PairOffset
from tracking.rig import Rig, save_rig
from tracking.sources import SourceKind, source_kind


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
