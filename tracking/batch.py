"""`topside batch`: many installations re-analysed in one run, from a manifest.

The manifest is YAML: a list of installations (or a mapping with one key, `installations`, holding it), one per
line in flow style::

    installations:
      - {rig: site-a/rig.yaml, out: results/site-a, truth: site-a/truth.csv}
      - {rig: site-b/rig.yaml, out: results/site-b, mode: smoothed, report: true}

Paths are relative to the manifest's folder. Each installation writes `offsets.csv` into its `out` folder (and
`run.rrd` with `rrd: true`, `run.rrd` and its `report.html` with `report: true`, `accuracy.md` when a truth is
given). One that fails is reported with its one-line reason and the others go on.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

from tracking.errors import InputError, read_yaml
from tracking.rig import _format_location

MODES = ("fused", "smoothed", "paper", "raw")  # tracking.estimator.ESTIMATORS' keys (not imported: heavy)
OFFSETS_NAME = "offsets.csv"
RRD_NAME = "run.rrd"
ACCURACY_NAME = "accuracy.md"
REPORT_NAME = "report.html"
FIELDS = "rig, out, and optionally truth, name, mode, rrd, report"


class Installation(BaseModel):
    """One installation to re-analyse: its rig, where its results go, and optionally its truth."""

    model_config = ConfigDict(extra="forbid")

    rig: Path
    out: Path  # a folder: offsets.csv, run.rrd, report.html, accuracy.md
    truth: Path | None = None  # a truth log (the simulator's truth.csv, or time, cone, dx, dy, dz) to score against
    name: str = ""  # for the summary (default: the rig file's folder)
    mode: str = "fused"
    rrd: bool = False  # also write run.rrd
    report: bool = False  # also write run.rrd and the lift's report.html from it (`topside report`'s page)

    @field_validator("mode")
    @classmethod
    def _mode(cls, value: str) -> str:
        if value not in MODES:
            raise ValueError(f"{value!r} is not a mode (expected {', '.join(MODES)})")
        return value

    @property
    def label(self) -> str:
        return self.name or self.rig.parent.name or str(self.rig)


class Manifest(BaseModel):
    """The installations of one batch."""

    model_config = ConfigDict(extra="forbid")

    installations: list[Installation] = Field(min_length=1)


def load_manifest(path: str | Path) -> list[Installation]:
    """A manifest's installations, paths resolved against its folder; a one-line InputError naming the file and the
    field (installations[2].rig) otherwise."""
    path = Path(path)
    data: Any = read_yaml(path, "manifest")
    if isinstance(data, list):
        data = {"installations": data}
    if not isinstance(data, dict):
        raise InputError(path, f"expected a list of installations ({FIELDS})")
    try:
        manifest = Manifest.model_validate(data)
    except ValidationError as exc:
        err = exc.errors()[0]
        msg = err["msg"].removeprefix("Value error, ")
        if err["type"] == "missing":
            msg = "missing (expected rig and out for every installation)"
        elif err["type"] == "extra_forbidden":
            msg = f"not a field (expected {FIELDS})"
        raise InputError(path, msg, _format_location(err["loc"]) or None) from None
    base = path.parent
    out = [i.model_copy(update={"rig": base / i.rig, "out": base / i.out,
                                "truth": base / i.truth if i.truth is not None else None})
           for i in manifest.installations]
    folders: dict[Path, int] = {}
    for k, inst in enumerate(out):
        key = inst.out.resolve()
        if key in folders:
            raise InputError(path, f"{inst.out} is also installations[{folders[key]}]'s out (expected a folder of its "
                                   "own)", f"installations[{k}].out")
        folders[key] = k
        if inst.out.exists() and not inst.out.is_dir():
            raise InputError(path, f"{inst.out} is a file (expected a folder)", f"installations[{k}].out")
    return _distinct_names(path, out, [i.out for i in manifest.installations])


def _distinct_names(path: Path, installations: list[Installation], written: list[Path]) -> list[Installation]:
    """Every installation named apart: the summary table and the failure lines name installations by their label. A
    name given twice is a one-line InputError naming the manifest, the field and the name; an installation without a
    name whose rig's folder names another too is labelled by its out folder as the manifest writes it (written)."""
    names: dict[str, int] = {}
    for k, inst in enumerate(installations):
        if inst.name in names:
            raise InputError(path, f"{inst.name!r} is also installations[{names[inst.name]}]'s name (expected a name "
                                   "of its own: the summary tells installations apart by it)",
                             f"installations[{k}].name")
        if inst.name:
            names[inst.name] = k
    labels = Counter(inst.label for inst in installations)
    return [inst if inst.name or labels[inst.label] == 1 else inst.model_copy(update={"name": str(out)})
            for inst, out in zip(installations, written, strict=True)]


@dataclass
class Outcome:
    """What one installation gave: its frames and wall time, its accuracy against the truth, or why it failed."""

    name: str
    frames: int = 0
    video_s: float = 0.0  # seconds of video, the longest camera's
    wall_s: float = 0.0
    rows: int = 0
    mae_mm: tuple[float, float, float] | None = None  # e_MAE x, y, z against the truth, mm
    max_mm: float | None = None  # the largest |error| of any axis, mm
    error: str = ""  # one line: why it failed ('' when it did not)
    verdict: str = ""  # the report's verdict, with report: true

    @property
    def ok(self) -> bool:
        return not self.error
