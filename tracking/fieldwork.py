"""What `topside sync` and `topside survey` share: the footage's measurements and the rig they write (their tables are
the command line's: tracking/cli/fieldwork.py).

A rig file is a record (who surveyed what, and when, in its comments), so the rig they write is the rig file they
read, edited: its text read with ruamel.yaml's round trip, and only what the new rig changes (a camera's clock, a
marker's pose, σ and correction, a pair's mated offset, paths relative to the new folder) set in it, in the layout
and style it has; comments, key order, flow lists and every untouched number stay as written."""

from __future__ import annotations

import io
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

from tracking.detection import DEFAULT_REFINEMENT, Refinement
from tracking.errors import InputError
from tracking.offsets import BodyObservation, PairOffset
from tracking.outputs import write_text
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


def write_rig(rig: Rig, out: Path, source: Rig | None = None) -> None:
    """Write a rig atomically at out, its paths relative to out's folder: source's file edited where rig differs
    from source (comments and layout kept), or, without a source file, the rig as save_rig writes it."""
    rig = rig_for(rig, out)
    if source is None or source.path is None or not Path(source.path).is_file():
        save_rig(out, rig)
        return
    document = _round_trip().load(Path(source.path).read_text())
    _edit(document, _dump(source), _dump(rig))
    text = io.StringIO()
    _round_trip().dump(document, text)
    write_text(out, text.getvalue())


def _round_trip() -> Any:
    """ruamel.yaml's round-trip reader and writer, widths as a person writes (no line folding)."""
    from ruamel.yaml import YAML

    yaml = YAML()  # round trip: comments, order, flow style and scalars' text kept
    yaml.width = 4096
    yaml.preserve_quotes = True
    return yaml


def _dump(rig: Rig) -> dict:
    """A rig as plain data, as save_rig writes it."""
    return rig.model_dump(mode="json", exclude_none=True)


def _edit(node: Any, old: Any, new: Any) -> None:
    """Set in node (a mapping or sequence of the document) what new changes from old, node's style kept."""
    keys = new.keys() if isinstance(new, dict) else range(len(new))
    for key in keys:
        before = old.get(key) if isinstance(old, dict) else old[key]
        after = new[key]
        if _same(before, after):
            continue
        here = node.get(key) if isinstance(node, dict) else node[key]
        nested = isinstance(after, dict) and isinstance(before, dict) and isinstance(here, dict)
        listed = isinstance(after, list) and isinstance(before, list) and isinstance(here, list) \
            and len(after) == len(before) == len(here)
        if nested or listed:
            _edit(here, before, after)
        else:
            node[key] = _styled(after)
    if isinstance(new, dict):
        for key in [k for k in old if k not in new and k in node]:
            del node[key]


def _same(a: Any, b: Any) -> bool:
    """Equal as data (1 and 1.0 alike)."""
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, bool) or isinstance(b, bool):
        return a is b
    if isinstance(a, int | float) and isinstance(b, int | float):
        return float(a) == float(b)
    return bool(a == b)


def _styled(value: Any) -> Any:
    """A new value as save_rig would lay it out: lists of numbers or strings in flow style, mappings in block."""
    from ruamel.yaml.comments import CommentedMap, CommentedSeq

    if isinstance(value, dict):
        return CommentedMap((k, _styled(v)) for k, v in value.items())
    if isinstance(value, list):
        seq = CommentedSeq(_styled(v) for v in value)
        if not any(isinstance(v, dict | list) for v in value):
            seq.fa.set_flow_style()
        return seq
    return value
