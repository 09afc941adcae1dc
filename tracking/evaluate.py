"""Accuracy against a ground-truth log: the paper's table (e_MAE, |e|max, σ_e, μ_e per axis) plus RMSE."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from tracking.errors import InputError

AXES = ("dx", "dy", "dz")
TOLERANCE_M = 0.15  # concentricity requirement, shaded on the error plots
LAG_GRID_HZ = 50.0
MAX_LAG_S = 1.5
MIN_MOTION_M = 0.05  # an axis must move at least this much (σ of the truth) for its lag to mean anything
MIN_PEAK_CONTRAST = 1e-3  # correlation must vary this much over the shifts for a lag to be defined
AVAILABILITY_GRID_HZ = 10.0
MAX_ESTIMATE_AGE_S = 0.5  # an estimate older than this no longer counts as available


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


def estimate_lag(times: np.ndarray, estimate: np.ndarray, truth_times: np.ndarray, truth: np.ndarray) -> float:
    """Delay of an estimate behind the truth, s, by cross-correlation on a uniform grid (NaN if flat)."""
    ok = np.isfinite(estimate)
    if ok.sum() < 10:
        return float("nan")
    grid = np.arange(times[ok][0], times[ok][-1], 1.0 / LAG_GRID_HZ)
    true = np.interp(grid, truth_times, truth)
    if grid.size < 10 or np.std(true) < MIN_MOTION_M:
        return float("nan")
    est = np.interp(grid, times[ok], estimate[ok])
    shifts = np.arange(-int(MAX_LAG_S * LAG_GRID_HZ), int(MAX_LAG_S * LAG_GRID_HZ) + 1)
    scores = []
    for k in shifts:  # estimate(t) against truth(t - k dt): positive k = the estimate lags
        a, b = (est[k:], true[: true.size - k]) if k >= 0 else (est[:k], true[-k:])
        scores.append(np.corrcoef(a - a.mean(), b - b.mean())[0, 1] if a.size > 10 else -np.inf)
    scores = np.array(scores)
    if np.ptp(scores[np.isfinite(scores)]) < MIN_PEAK_CONTRAST:
        return float("nan")  # no peak: a constant-speed ramp correlates with itself at every shift
    return float(shifts[int(np.argmax(scores))] / LAG_GRID_HZ)


def lag(offsets: pd.DataFrame, truth: pd.DataFrame) -> float:
    """Median lag over every cone and axis that moves, s."""
    lags = []
    for cone, rows in offsets.groupby("cone"):
        cols = [f"cone_{cone}_{a}" for a in AXES]
        if any(c not in truth.columns for c in cols):
            continue
        for axis, col in zip(AXES, cols, strict=True):
            lags.append(estimate_lag(rows["time"].to_numpy(), rows[axis].to_numpy(dtype=float),
                                     truth["time"].to_numpy(), truth[col].to_numpy()))
    lags = [v for v in lags if np.isfinite(v)]
    return float(np.median(lags)) if lags else float("nan")


def availability(offsets: pd.DataFrame, truth: pd.DataFrame) -> float:
    """Share of the run, over the cones estimated, with an estimate at most MAX_ESTIMATE_AGE_S old."""
    grid = np.arange(truth["time"].min(), truth["time"].max(), 1.0 / AVAILABILITY_GRID_HZ)
    shares = []
    for _, rows in offsets.groupby("cone"):
        valid = np.sort(rows.loc[rows[list(AXES)].notna().all(axis=1), "time"].to_numpy())
        if valid.size == 0:
            shares.append(0.0)
            continue
        idx = np.searchsorted(valid, grid, side="right") - 1
        age = np.where(idx >= 0, grid - valid[np.clip(idx, 0, None)], np.inf)
        shares.append(float(np.mean(age <= MAX_ESTIMATE_AGE_S)))
    return float(np.mean(shares)) if shares else 0.0


@dataclass(frozen=True)
class Evaluation:
    """The paper's table and the figures beyond it, for one group of runs."""

    name: str
    axes: dict[str, AxisStats]
    lag_s: float
    availability: float


def evaluate_runs(name: str, runs: list[tuple[pd.DataFrame, pd.DataFrame]]) -> Evaluation:
    """Pool the errors of several (offsets, truth) runs into one table; lag and availability averaged."""
    errs = pd.concat([errors(o, t) for o, t in runs], ignore_index=True)
    lags = [lag(o, t) for o, t in runs]
    lags = [v for v in lags if np.isfinite(v)]
    return Evaluation(name, summary(errs), float(np.mean(lags)) if lags else float("nan"),
                      float(np.mean([availability(o, t) for o, t in runs])))


def evaluation_markdown(ev: Evaluation) -> str:
    """One group's table, with lag and availability beneath it."""
    return (markdown_table(ev.axes, ev.name) +
            f"\n\nlag {ev.lag_s:.2f} s · availability {ev.availability:.1%}\n")


def cone_figure(rows: pd.DataFrame, truth: pd.DataFrame, cone: str, title: str):
    """Estimate, truth and error per axis over time for one cone: the paper's Fig. 12 (a matplotlib Figure)."""
    import matplotlib.pyplot as plt

    true = truth_at(truth, cone, rows["time"].to_numpy())
    fig, axs = plt.subplots(3, 2, figsize=(12, 8), sharex=True, gridspec_kw={"width_ratios": [2, 1]})
    for i, axis in enumerate(AXES):
        axs[i, 0].plot(truth["time"], truth[f"cone_{cone}_{axis}"], color="0.5", lw=1.5, label="simulation log")
        axs[i, 0].plot(rows["time"], rows[axis], lw=1.0, label="estimate")
        axs[i, 0].set_ylabel(f"{axis} [m]")
        axs[i, 1].plot(rows["time"], rows[axis].to_numpy() - true[:, i], lw=0.8)
        axs[i, 1].axhspan(-TOLERANCE_M, TOLERANCE_M, color="g", alpha=0.08)
        axs[i, 1].set_ylabel(f"error {axis} [m]")
    axs[0, 0].legend(loc="best")
    axs[-1, 0].set_xlabel("capture time [s]")
    axs[-1, 1].set_xlabel("capture time [s]")
    fig.suptitle(f"{title}: cone {cone}")
    fig.tight_layout()
    return fig


def plot_run(offsets: pd.DataFrame, truth: pd.DataFrame, out_dir: Path, name: str) -> list[Path]:
    """One Fig. 12 PNG per cone that the truth log knows."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    for cone, rows in offsets.groupby("cone"):
        if f"cone_{cone}_dx" not in truth.columns:
            continue
        fig = cone_figure(rows, truth, str(cone), name)
        path = out_dir / f"{name}_cone_{cone}.png"
        fig.savefig(path, dpi=80)
        plt.close(fig)
        written.append(path)
    return written
