"""Accuracy against a ground-truth log: the paper's table (e_MAE, |e|max, σ_e, μ_e per axis) plus RMSE."""

from __future__ import annotations

import re
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from tracking.errors import InputError, check_text_file
from tracking.estimate import TOLERANCE_M
from tracking.outputs import atomic_path

AXES = ("dx", "dy", "dz")
SIGMAS = ("sdx", "sdy", "sdz")
TIME = "time"
CONE = "cone"
TRUTH_PREFIXES = ("cone_", "pair_", "camera_")  # the wide truth's numeric columns
WIDE_COLUMN = re.compile(r"^cone_(.+)_d[xyz]$")
EMPTY_CELLS = ("", "nan", "na", "n/a", "null", "none")  # an axis no camera gave (the tracker writes nan)
MAX_OFFSET_M = 1e6  # beyond any installation; keeps every square in the statistics finite
MAX_TIME_S = 1e11  # Unix time in s is 1.7e9; beyond this a time is a typo or another unit
MAX_SPAN_S = 86400.0  # a run of a day at most: the lag and availability grids of a longer one would not fit in memory
SHOWN_CHARS = 40  # of a bad cell, in its error
UNSAFE_FILE_CHARS = re.compile(r"[^A-Za-z0-9_.-]")
NO_VALUE = "–"  # a statistic of no samples, in the tables: never a bare nan
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
    """An offsets CSV as written by `topside track` (time, cone, dx, dy, dz, ...), sorted by time; a one-line
    InputError naming the file (and column) when it is not one. Empty dx/dy/dz (axes no camera gave) stay NaN."""
    path = Path(path)
    df = _read_csv(path, "offsets file", "an offsets CSV (time, cone, dx, dy, dz, cameras)")
    missing = [c for c in (TIME, CONE, *AXES) if c not in df.columns]
    if missing:
        raise InputError(path, "missing (expected columns time, cone, dx, dy, dz, cameras)", missing[0])
    _cone_names(path, df)
    _numeric_columns(path, df, [TIME], MAX_TIME_S, required=True)
    _numeric_columns(path, df, [*AXES, *(c for c in SIGMAS if c in df.columns)], MAX_OFFSET_M, required=False)
    return _by_time(path, df)


def read_truth(path: str | Path) -> pd.DataFrame:
    """A ground-truth log: wide (the simulator's truth.csv: time and cone_<C>_dx/dy/dz columns) or long (time, cone,
    dx, dy, dz: converted to wide), sorted by time; a one-line InputError naming the file (and column) otherwise."""
    path = Path(path)
    df = _read_csv(path, "truth file", "a truth CSV (time, cone_<C>_dx, cone_<C>_dy, cone_<C>_dz)")
    if TIME not in df.columns:
        raise InputError(path, "missing (expected a time column in s)", TIME)
    if not _wide_cones(df) and CONE in df.columns and all(a in df.columns for a in AXES):
        return _long_to_wide(path, df)
    cones = _wide_cones(df)
    if not cones:
        raise InputError(path, "no cone columns (expected cone_<C>_dx, cone_<C>_dy, cone_<C>_dz, or the long form "
                               "time, cone, dx, dy, dz)", "cone_<C>_dx")
    for cone in cones:
        for col in (f"cone_{cone}_{a}" for a in AXES):
            if col not in df.columns:
                raise InputError(path, f"missing (expected all of cone_{cone}_dx, _dy, _dz)", col)
    _numeric_columns(path, df, [TIME], MAX_TIME_S, required=True)
    _numeric_columns(path, df, [c for c in df.columns if c.startswith(TRUTH_PREFIXES)], MAX_OFFSET_M,
                     required=False)
    truth = _by_time(path, df)
    _unique_times(path, truth[TIME].to_numpy())
    return truth


def _read_csv(path: Path, what: str, expected: str) -> pd.DataFrame:
    """Every cell of a CSV file as a stripped string ('' when empty); one line naming the file when it is missing,
    unreadable, binary, not CSV, or has no rows."""
    check_text_file(path, what)
    try:
        with warnings.catch_warnings():  # rows longer than the header: pandas drops their last cells with a warning
            warnings.simplefilter("error", pd.errors.ParserWarning)
            df = pd.read_csv(path, dtype=str, keep_default_na=False, skipinitialspace=True, index_col=False)
    except pd.errors.EmptyDataError:
        raise InputError(path, f"is empty (expected {expected})") from None
    except pd.errors.ParserWarning:
        raise InputError(path, f"has rows with more cells than its header (expected {expected})") from None
    except (pd.errors.ParserError, UnicodeDecodeError, ValueError, OverflowError, MemoryError) as exc:
        reason = str(exc).strip().removeprefix("Error tokenizing data. ")
        raise InputError(path, f"not a CSV file ({reason}); expected {expected}") from None
    except OSError as exc:
        raise InputError(path, f"cannot be read ({exc.strerror or exc})") from None
    df.columns = [str(c).strip() for c in df.columns]
    twice = df.columns[df.columns.duplicated()]
    if len(twice):
        raise InputError(path, "appears twice in the header (expected each column once)", twice[0])
    if df.empty:
        raise InputError(path, f"has no rows (expected {expected})")
    return df.apply(lambda col: col.str.strip())


def _numeric_columns(path: Path, df: pd.DataFrame, columns: list[str], limit: float, required: bool) -> None:
    """Columns of text cells turned into float in place; one line naming the column and row (1 = first data row)
    for a cell that is not a number, is beyond ±limit or infinite, or (required) empty."""
    for col in columns:
        text = df[col]
        empty = text.str.lower().isin(EMPTY_CELLS).to_numpy()
        values = pd.to_numeric(text.where(~empty), errors="coerce").to_numpy(dtype=float)
        bad = np.flatnonzero(np.isnan(values) & ~empty)
        if bad.size:
            raise InputError(path, f"row {bad[0] + 1}: {text.iloc[bad[0]][:SHOWN_CHARS]!r} is not a number", col)
        if required and empty.any():
            raise InputError(path, f"row {np.argmax(empty) + 1}: empty or NaN (expected a number)", col)
        beyond = np.flatnonzero(np.abs(values) > limit)  # inf too; NaN compares False
        if beyond.size:
            raise InputError(path, f"row {beyond[0] + 1}: {text.iloc[beyond[0]][:SHOWN_CHARS]} is beyond ±{limit:g} "
                                   "(expected a finite number)", col)
        df[col] = values


def _cone_names(path: Path, df: pd.DataFrame) -> None:
    """One line naming the row of an empty cone name."""
    empty = (df[CONE] == "").to_numpy()
    if empty.any():
        raise InputError(path, f"row {np.argmax(empty) + 1}: empty (expected a cone name)", CONE)


def _by_time(path: Path, df: pd.DataFrame) -> pd.DataFrame:
    """Rows sorted by time (stable), the file's name in attrs["source"]; one line when the times span more than
    MAX_SPAN_S (the evaluation grids would not fit in memory)."""
    t = df[TIME].to_numpy()
    if t.max() - t.min() > MAX_SPAN_S:
        raise InputError(path, f"spans {t.min():g} to {t.max():g} s (expected at most {MAX_SPAN_S:g} s)", TIME)
    out = df.sort_values(TIME, kind="stable", ignore_index=True)
    out.attrs["source"] = str(path)
    return out


def _unique_times(path: Path, t: np.ndarray) -> None:
    """One line naming a time that appears twice in a (sorted) truth log: its value would be ambiguous."""
    twice = np.flatnonzero(np.diff(t) == 0)
    if twice.size:
        raise InputError(path, f"{t[twice[0]]:g} s appears twice (expected one row per time)", TIME)


def _wide_cones(df: pd.DataFrame) -> list[str]:
    """The cones a wide truth log names in cone_<C>_dx/dy/dz columns."""
    found = (WIDE_COLUMN.match(c) for c in df.columns)
    return sorted({m.group(1) for m in found if m})


def _long_to_wide(path: Path, df: pd.DataFrame) -> pd.DataFrame:
    """A long truth log (time, cone, dx, dy, dz) as the wide one: time and cone_<C>_dx/dy/dz; a cone's cells are
    NaN at the other cones' times (truth_at interpolates each cone over its own rows)."""
    _cone_names(path, df)
    _numeric_columns(path, df, [TIME], MAX_TIME_S, required=True)
    _numeric_columns(path, df, list(AXES), MAX_OFFSET_M, required=False)
    twice = df.duplicated([TIME, CONE]).to_numpy()
    if twice.any():
        i = int(np.argmax(twice))
        raise InputError(path, f"row {i + 1}: cone {df[CONE].iloc[i]} at {df[TIME].iloc[i]:g} s appears twice "
                               "(expected one row per time and cone)", TIME)
    wide = df.pivot(index=TIME, columns=CONE, values=list(AXES))
    columns = {f"cone_{cone}_{axis}": wide[(axis, cone)].to_numpy() for cone in sorted(df[CONE].unique())
               for axis in AXES}
    return _by_time(path, pd.DataFrame({TIME: wide.index.to_numpy(dtype=float), **columns}))


def truth_sources(offsets: pd.DataFrame, truth: pd.DataFrame) -> tuple[str, str]:
    """The files an offsets table and a truth log were read from (attrs["source"]), or generic names."""
    return offsets.attrs.get("source", "offsets"), truth.attrs.get("source", "truth")


def truth_span(truth: pd.DataFrame, cone: str) -> tuple[float, float] | None:
    """(first, last) time at which the truth gives all of a cone's axes, None when it never does."""
    cols = [f"cone_{cone}_{a}" for a in AXES]
    if any(c not in truth.columns for c in cols):
        return None
    known = np.isfinite(truth[cols].to_numpy(dtype=float)).all(axis=1)
    t = truth[TIME].to_numpy(dtype=float)[known]
    return (float(t.min()), float(t.max())) if t.size else None


def check_overlap(offsets_path: str | Path, offsets: pd.DataFrame, truth_path: str | Path, truth: pd.DataFrame
                  ) -> None:
    """A one-line InputError naming both files when the offsets and the truth share no cone, no time span, or no
    estimate within it (there would be nothing to evaluate: a table of NaN), or when the truth lacks a cone the
    offsets estimate (errors() would stop there)."""
    estimated = sorted({str(c) for c in offsets[CONE]})
    spans = {cone: truth_span(truth, cone) for cone in estimated}
    shared = [cone for cone, span in spans.items() if span is not None]
    known = ", ".join(_wide_cones(truth)) or "none"
    if not shared:
        raise InputError(offsets_path, f"shares no cone with {truth_path} (offsets: {', '.join(estimated)}; truth: "
                                       f"{known}); expected the truth of the same run", CONE)
    absent = [cone for cone in estimated if any(f"cone_{cone}_{a}" not in truth.columns for a in AXES)]
    if absent:  # errors() would stop at it: say so before anything is computed
        raise InputError(offsets_path, f"cone {absent[0]!r} is not in {truth_path} (it gives {known}; expected the "
                                       "truth of every cone estimated)", CONE)
    cones = offsets[CONE].astype(str).to_numpy()
    t = offsets[TIME].to_numpy(dtype=float)
    inside = np.zeros(len(offsets), dtype=bool)
    for cone in shared:
        lo, hi = spans[cone]
        inside |= (cones == cone) & (t >= lo) & (t <= hi)
    if not inside.any():
        lo, hi = min(s[0] for s in spans.values() if s), max(s[1] for s in spans.values() if s)
        raise InputError(offsets_path, f"times {t.min():g} to {t.max():g} s do not overlap {truth_path} ({lo:g} to "
                                       f"{hi:g} s); expected the same run on the same clock", TIME)
    if not np.isfinite(offsets[list(AXES)].to_numpy(dtype=float)[inside]).any():
        raise InputError(offsets_path, f"has no estimate (dx, dy, dz all empty) within {truth_path}'s time span",
                         "dx")


def truth_at(truth: pd.DataFrame, cone: str, times: np.ndarray, kind: str = "cone") -> np.ndarray:
    """(N, 3) true offset of a cone (or kind='pair' columns) interpolated at the given times, each axis over the rows
    that give it (held beyond them)."""
    cols = [f"{kind}_{cone}_{a}" for a in AXES]
    if any(c not in truth.columns for c in cols):
        raise InputError(truth.attrs.get("source", "truth"),
                         f"no columns {', '.join(cols)} (expected the cone's true offset)", cols[0])
    t = truth["time"].to_numpy(dtype=float)
    out = []
    for c in cols:
        v = truth[c].to_numpy(dtype=float)
        ok = np.isfinite(v) & np.isfinite(t)
        order = np.argsort(t[ok], kind="stable")  # np.interp needs increasing times
        out.append(np.interp(times, t[ok][order], v[ok][order]) if ok.any() else np.full(len(times), np.nan))
    return np.column_stack(out) if out else np.zeros((len(times), 0))


def errors(offsets: pd.DataFrame, truth: pd.DataFrame) -> pd.DataFrame:
    """Per row of the offsets within the truth's span for its cone: time, cone, error per axis (estimate minus
    truth), cameras; grouped by cone."""
    parts = []
    for cone, rows in offsets.groupby("cone", sort=True):
        if any(f"cone_{cone}_{a}" not in truth.columns for a in AXES):
            offsets_source, truth_source = truth_sources(offsets, truth)
            raise InputError(offsets_source, f"cone {str(cone)!r} is not in {truth_source} (it gives "
                                             f"{', '.join(_wide_cones(truth)) or 'no cone'}; expected the truth of "
                                             "every cone estimated)", CONE)
        span = truth_span(truth, str(cone))
        if span is None:
            continue  # the truth never gives this cone: nothing to compare (check_overlap names it if none is left)
        rows = rows[(rows["time"] >= span[0]) & (rows["time"] <= span[1])]
        true = truth_at(truth, str(cone), rows["time"].to_numpy(dtype=float))
        err = rows[list(AXES)].to_numpy(dtype=float) - true
        part = pd.DataFrame({"time": rows["time"].to_numpy(), "cone": cone,
                             **{f"e{a[1]}": err[:, i] for i, a in enumerate(AXES)}})
        if "cameras" in rows.columns:
            part["cameras"] = rows["cameras"].to_numpy()
        parts.append(part)
    parts = [p for p in parts if len(p)]
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
        cells = [f"{v:.3f}" if s.n else NO_VALUE for v in (s.mae, s.max_abs, s.std, s.mean, s.rmse)]
        lines.append(f"| {axis} | {' | '.join(cells)} | {s.n} |")
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
        defined = a.size > 10 and np.ptp(a) > 0 and np.ptp(b) > 0  # a flat stretch has no correlation (0 / 0)
        scores.append(np.corrcoef(a - a.mean(), b - b.mean())[0, 1] if defined else -np.inf)
    scores = np.array(scores)
    finite = scores[np.isfinite(scores)]
    if finite.size == 0 or np.ptp(finite) < MIN_PEAK_CONTRAST:
        return float("nan")  # no peak: a constant-speed ramp correlates with itself at every shift
    return float(shifts[int(np.argmax(scores))] / LAG_GRID_HZ)


def lag(offsets: pd.DataFrame, truth: pd.DataFrame) -> float:
    """Median lag over every cone and axis that moves, s."""
    lags = []
    t_truth = truth["time"].to_numpy(dtype=float)
    for cone, rows in offsets.groupby("cone"):
        cols = [f"cone_{cone}_{a}" for a in AXES]
        if any(c not in truth.columns for c in cols):
            continue
        rows = rows.sort_values("time", kind="stable")  # the cross-correlation interpolates over time
        for axis, col in zip(AXES, cols, strict=True):
            true = truth[col].to_numpy(dtype=float)
            known = np.isfinite(true)  # a long truth log gives each cone at its own times only
            if known.sum() < 2:
                continue
            order = np.argsort(t_truth[known], kind="stable")
            lags.append(estimate_lag(rows["time"].to_numpy(dtype=float), rows[axis].to_numpy(dtype=float),
                                     t_truth[known][order], true[known][order]))
    lags = [v for v in lags if np.isfinite(v)]
    return float(np.median(lags)) if lags else float("nan")


def availability(offsets: pd.DataFrame, truth: pd.DataFrame) -> float:
    """Share of the run, over the cones estimated, with an estimate at most MAX_ESTIMATE_AGE_S old."""
    t0, t1 = truth["time"].min(), truth["time"].max()
    grid = np.arange(t0, t1, 1.0 / AVAILABILITY_GRID_HZ) if t1 > t0 else np.array([t0], dtype=float)
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
    if not np.isfinite(errs[["ex", "ey", "ez"]].to_numpy(dtype=float)).any():
        sources = "; ".join(" and ".join(truth_sources(o, t)) for o, t in runs)
        raise InputError(sources or name, "no estimate within the truth's time span at a cone the truth gives: "
                                          "nothing to evaluate (expected offsets and truth of the same run)")
    lags = [lag(o, t) for o, t in runs]
    lags = [v for v in lags if np.isfinite(v)]
    return Evaluation(name, summary(errs), float(np.mean(lags)) if lags else float("nan"),
                      float(np.mean([availability(o, t) for o, t in runs])))


def evaluation_markdown(ev: Evaluation) -> str:
    """One group's table, with lag and availability beneath it."""
    lag_text = f"{ev.lag_s:.2f} s" if np.isfinite(ev.lag_s) else f"{NO_VALUE} (no axis moves enough to tell)"
    return markdown_table(ev.axes, ev.name) + f"\n\nlag {lag_text} · availability {ev.availability:.1%}\n"


AXIS_LABELS = {"dx": "Δx (to port)", "dy": "Δy (astern)", "dz": "Δz (up)"}
TRUTH_COLOR, ESTIMATE_COLOR, SIGMA_COLOR, BAND_COLOR = "0.45", "tab:blue", "tab:blue", "tab:green"
ERROR_SPAN_TOLERANCES = 1.3  # an error panel spans at least this many tolerances each way (a wide σ is cut off)


def cone_figure(rows: pd.DataFrame, truth: pd.DataFrame, cone: str, title: str):
    """Estimate, truth and error per axis over time for one cone: the paper's Fig. 12 (a matplotlib Figure). Errors
    with the ±150 mm tolerance band and, where the offsets CSV has σ, the estimate's ±2σ band; units in every label;
    one legend below the plots, covering none of them."""
    import matplotlib.pyplot as plt
    from matplotlib.patches import Patch

    time = rows["time"].to_numpy()
    true = truth_at(truth, cone, time)
    fig, axs = plt.subplots(3, 2, figsize=(12, 8.5), sharex=True, gridspec_kw={"width_ratios": [2, 1]})
    for i, (axis, sd) in enumerate(zip(AXES, SIGMAS, strict=True)):
        label = AXIS_LABELS[axis]
        axs[i, 0].plot(truth["time"], truth[f"cone_{cone}_{axis}"], color=TRUTH_COLOR, lw=1.5)
        axs[i, 0].plot(time, rows[axis], color=ESTIMATE_COLOR, lw=1.0)
        axs[i, 0].set_ylabel(f"{label} [m]")
        err = axs[i, 1]
        err.axhspan(-TOLERANCE_M, TOLERANCE_M, color=BAND_COLOR, alpha=0.12, lw=0)
        e = rows[axis].to_numpy(dtype=float) - true[:, i]
        if sd in rows.columns and rows[sd].notna().any():  # σ only where there is an estimate to go with it
            two = np.where(np.isfinite(e), 2 * rows[sd].to_numpy(dtype=float), np.nan)
            err.fill_between(time, -two, two, color=SIGMA_COLOR, alpha=0.18, lw=0)
        err.plot(time, e, color=ESTIMATE_COLOR, lw=0.8)
        err.axhline(0.0, color=TRUTH_COLOR, lw=0.6)
        worst = np.nanmax(np.abs(e)) if np.isfinite(e).any() else 0.0
        lim = max(ERROR_SPAN_TOLERANCES * TOLERANCE_M, 1.2 * worst)  # the tolerance and every error in view
        err.set_ylim(-lim, lim)
        err.set_ylabel(f"error {label} [m]")
    axs[0, 0].set_title("estimate and truth [m]")
    axs[0, 1].set_title("error: estimate − truth [m]")
    axs[-1, 0].set_xlabel("capture time [s]")
    axs[-1, 1].set_xlabel("capture time [s]")
    handles = [plt.Line2D([], [], color=TRUTH_COLOR, lw=1.5), plt.Line2D([], [], color=ESTIMATE_COLOR, lw=1.0),
               Patch(color=BAND_COLOR, alpha=0.12), Patch(color=SIGMA_COLOR, alpha=0.18)]
    labels = ["truth (simulation log)", "estimate", f"±{TOLERANCE_M * 1000:.0f} mm tolerance",
              "±2σ of the estimate"]
    fig.legend(handles, labels, loc="lower center", ncol=4, frameon=False)
    fig.suptitle(f"{title}: cone {cone}")
    fig.tight_layout(rect=(0, 0.04, 1, 1))
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
        path = out_dir / f"{name}_cone_{UNSAFE_FILE_CHARS.sub('_', str(cone))}.png"  # a cone name is the file's text
        with atomic_path(path) as partial:  # complete under its name, or not at all
            fig.savefig(partial, dpi=80, format="png")
        plt.close(fig)
        written.append(path)
    return written
