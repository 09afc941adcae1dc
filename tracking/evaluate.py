"""Accuracy against a ground-truth log: the paper's table (e_MAE, |e|max, σ_e, μ_e per axis) plus RMSE."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from tracking.errors import InputError

AXES = ("dx", "dy", "dz")


@dataclass(frozen=True)
class AxisStats:
    """Error statistics of one axis, m."""

    mae: float
    max_abs: float
    std: float
    mean: float
    rmse: float
    n: int


def read_offsets(path: str | Path) -> pd.DataFrame:
    """An offsets CSV as written by `topside track`."""
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "offsets file not found")
    df = pd.read_csv(path)
    missing = [c for c in ("time", "cone", *AXES) if c not in df.columns]
    if missing:
        raise InputError(path, "missing (expected columns time, cone, dx, dy, dz, cameras)", missing[0])
    return df


def read_truth(path: str | Path) -> pd.DataFrame:
    """A ground-truth log (the simulator's truth.csv): time and cone_<C>_dx/dy/dz columns."""
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "truth file not found")
    df = pd.read_csv(path)
    if "time" not in df.columns:
        raise InputError(path, "missing (expected a time column in s)", "time")
    return df


def truth_at(truth: pd.DataFrame, cone: str, times: np.ndarray, kind: str = "cone") -> np.ndarray:
    """(N, 3) true offset of a cone (or kind='pair' columns) interpolated at the given times."""
    cols = [f"{kind}_{cone}_{a}" for a in AXES]
    if any(c not in truth.columns for c in cols):
        raise InputError("truth", f"no columns {', '.join(cols)} (expected the cone's true offset)", cols[0])
    t = truth["time"].to_numpy()
    return np.column_stack([np.interp(times, t, truth[c].to_numpy()) for c in cols])


def errors(offsets: pd.DataFrame, truth: pd.DataFrame) -> pd.DataFrame:
    """Per row of the offsets: time, cone, error per axis (estimate minus truth), cameras; grouped by cone."""
    parts = []
    t_lo, t_hi = truth["time"].min(), truth["time"].max()
    for cone, rows in offsets.groupby("cone", sort=True):
        rows = rows[(rows["time"] >= t_lo) & (rows["time"] <= t_hi)]
        true = truth_at(truth, str(cone), rows["time"].to_numpy())
        err = rows[list(AXES)].to_numpy() - true
        part = pd.DataFrame({"time": rows["time"].to_numpy(), "cone": cone,
                             **{f"e{a[1]}": err[:, i] for i, a in enumerate(AXES)}})
        if "cameras" in rows.columns:
            part["cameras"] = rows["cameras"].to_numpy()
        parts.append(part)
    return pd.concat(parts, ignore_index=True) if parts else pd.DataFrame(columns=["time", "cone", "ex", "ey", "ez"])


def axis_stats(err: np.ndarray) -> AxisStats:
    """Statistics of one axis' errors, NaNs (axes no camera gave) left out."""
    e = err[np.isfinite(err)]
    if e.size == 0:
        return AxisStats(*(np.nan,) * 5, n=0)
    return AxisStats(mae=float(np.mean(np.abs(e))), max_abs=float(np.max(np.abs(e))), std=float(np.std(e)),
                     mean=float(np.mean(e)), rmse=float(np.sqrt(np.mean(e**2))), n=int(e.size))


def summary(err: pd.DataFrame) -> dict[str, AxisStats]:
    """The paper's table over all cones: x, y, z -> statistics."""
    return {axis: axis_stats(err[f"e{axis}"].to_numpy(dtype=float)) for axis in ("x", "y", "z")}


def markdown_table(stats: dict[str, AxisStats], title: str = "") -> str:
    """The paper's table layout as markdown, in metres."""
    lines = [f"**{title}**", ""] if title else []
    lines += ["| axis | e_MAE [m] | abs(e)max [m] | σ_e [m] | μ_e [m] | RMSE [m] | n |",
              "| --- | ---: | ---: | ---: | ---: | ---: | ---: |"]
    for axis, s in stats.items():
        lines.append(f"| {axis} | {s.mae:.3f} | {s.max_abs:.3f} | {s.std:.3f} | {s.mean:.3f} | {s.rmse:.3f} | {s.n} |")
    return "\n".join(lines)
