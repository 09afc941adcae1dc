"""Accuracy measures on synthetic series with known errors, delays and gaps."""

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from tracking.errors import InputError
from tracking.evaluate import (
    availability,
    check_overlap,
    errors,
    evaluate_runs,
    evaluation_markdown,
    lag,
    read_offsets,
    read_truth,
    summary,
)

T = np.arange(0.0, 30.0, 1 / 30)


def truth() -> pd.DataFrame:
    s_curve = 5 * (1 - np.cos(np.pi * T / T[-1])) / 2  # crane move: accelerates, then brakes
    return pd.DataFrame({"time": T, "cone_A_dx": 0.5 * np.sin(0.4 * T), "cone_A_dy": -5 + s_curve,
                         "cone_A_dz": np.full(T.size, 2.0)})


def offsets(delay: float = 0.0, bias: float = 0.0, keep: np.ndarray | None = None) -> pd.DataFrame:
    t = T[::2]
    tr = truth()
    rows = pd.DataFrame({"time": t, "cone": "A", **{a: np.interp(t - delay, T, tr[f"cone_A_{a}"]) for a in
                                                     ("dx", "dy", "dz")}})
    rows["dx"] += bias
    return rows if keep is None else rows[keep]


def test_paper_table_of_a_known_bias() -> None:
    stats = summary(errors(offsets(bias=0.02), truth()))
    assert stats["x"].mean == pytest.approx(0.02, abs=1e-9)
    assert stats["x"].mae == pytest.approx(0.02, abs=1e-9)
    assert stats["x"].std == pytest.approx(0.0, abs=1e-9)
    assert stats["y"].max_abs == pytest.approx(0.0, abs=1e-9)


@pytest.mark.parametrize("delay", [0.0, 0.3, 0.7])
def test_lag_by_cross_correlation(delay: float) -> None:
    assert lag(offsets(delay=delay), truth()) == pytest.approx(delay, abs=0.021)


def test_constant_speed_ramp_has_no_lag() -> None:
    from tracking.evaluate import estimate_lag

    assert np.isnan(estimate_lag(T, 0.2 * T, T, 0.2 * T))


def test_availability_counts_gaps() -> None:
    t = T[::2]
    keep = ~((t > 10) & (t < 20))  # ten seconds without an estimate
    share = availability(offsets(keep=keep), truth())
    assert share == pytest.approx(1 - (10 - 0.5) / 30, abs=0.02)  # estimates count for 0.5 s after they come


def test_nan_estimates_are_unavailable() -> None:
    rows = offsets()
    rows.loc[rows["time"] > 15, ["dx", "dy", "dz"]] = np.nan
    assert availability(rows, truth()) == pytest.approx(0.5 + 0.5 / 30, abs=0.02)


def test_runs_pool_into_one_group() -> None:
    ev = evaluate_runs("two runs", [(offsets(bias=0.01), truth()), (offsets(bias=0.03), truth())])
    assert ev.axes["x"].mean == pytest.approx(0.02, abs=1e-9)
    assert ev.axes["x"].n == 2 * len(offsets())
    assert ev.availability == pytest.approx(1.0, abs=0.01)


# --- reading the files: long-form truth, and every bad file one line naming it ------------------------------------

def _csv(tmp_path: Path, name: str, text: str | bytes) -> Path:
    path = tmp_path / name
    path.write_bytes(text.encode() if isinstance(text, str) else text)
    return path


def _wide_text() -> str:
    return truth().to_csv(index=False)


def _long_text(cones: tuple[str, ...] = ("A",)) -> str:
    tr = truth()
    rows = [pd.DataFrame({"time": tr["time"], "cone": c, **{a: tr[f"cone_A_{a}"] for a in ("dx", "dy", "dz")}})
            for c in cones]
    return pd.concat(rows).sample(frac=1.0, random_state=0).to_csv(index=False)  # any row order


def test_long_truth_is_converted_to_wide(tmp_path: Path) -> None:
    wide = read_truth(_csv(tmp_path, "wide.csv", _wide_text()))
    long = read_truth(_csv(tmp_path, "long.csv", _long_text(("A", "B"))))
    assert list(long.columns) == ["time", *(f"cone_{c}_{a}" for c in "AB" for a in ("dx", "dy", "dz"))]
    np.testing.assert_allclose(long[["time", "cone_A_dx", "cone_A_dy", "cone_A_dz"]].to_numpy(),
                               wide[["time", "cone_A_dx", "cone_A_dy", "cone_A_dz"]].to_numpy())
    a = summary(errors(offsets(bias=0.02), wide))
    b = summary(errors(offsets(bias=0.02), long))
    assert a == b


def test_long_truth_with_cones_at_their_own_times(tmp_path: Path) -> None:
    lines = ["time,cone,dx,dy,dz", "0.0,A,0,0,0", "1.0,B,5,5,5", "2.0,A,2,2,2", "3.0,B,7,7,7"]
    long = read_truth(_csv(tmp_path, "long.csv", "\n".join(lines)))
    assert np.isnan(long["cone_A_dx"].to_numpy()).sum() == 2  # A is not given at B's times
    rows = pd.DataFrame({"time": [1.0, 2.0], "cone": ["A", "B"], "dx": [1.0, 6.0], "dy": [1.0, 6.0],
                         "dz": [1.0, 6.0]})
    err = errors(rows, long)
    np.testing.assert_allclose(err[["ex", "ey", "ez"]].to_numpy(), 0.0)  # each cone over its own rows


def test_offsets_and_truth_are_sorted_by_time(tmp_path: Path) -> None:
    text = "time,cone,dx,dy,dz\n2.0,A,1,1,1\n1.0,A,0,0,0\n"
    assert read_offsets(_csv(tmp_path, "o.csv", text))["time"].tolist() == [1.0, 2.0]
    tr = read_truth(_csv(tmp_path, "t.csv", "time,cone_A_dx,cone_A_dy,cone_A_dz\n2,1,1,1\n1,0,0,0\n"))
    assert tr["time"].tolist() == [1.0, 2.0] and tr.attrs["source"] == str(tmp_path / "t.csv")


BAD_CSV = [
    (b"", None, "is empty"),
    (b"\x00\x01\x02\x03", None, "is binary, not text"),
    (b"time,cone\n\xff\xfe,A\n", None, "is binary, not text"),
    (b"time,cone,dx,dy,dz\n", None, "has no rows"),
    (b'time,cone,dx,dy,dz\n"1,A,0,0,0\n', None, "not a CSV file"),
    (b"time,cone,dx,dy,dz\n1,A,0,0,0,9,9\n", None, "has rows with more cells than its header"),
    (b"time,cone,dx,dy,dz\n1,A,0,0,0\n2,A,0,0,0,9\n", None, "not a CSV file (C error: Expected 5 fields in line 3"),
    (b"time,cone,dx,dy,dz\n1,A,0,0,0\nsoon,A,0,0,0\n", "time", "row 2: 'soon' is not a number"),
    (b"time,cone,dx,dy,dz\n1,A,0,0,0\nnan,A,0,0,0\n", "time", "row 2: empty or NaN"),
    (b"time,cone,dx,dy,dz\n1,A,0,0,0\ninf,A,0,0,0\n", "time", "row 2: inf is beyond"),
    (b"time,cone,dx,dy,dz\n1,A,0,0,0\n2,A,0,0,-inf\n", "dz", "row 2: -inf is beyond ±1e+06"),
    (b"time,cone,dx,dy,dz\n1,A,0,0,0\n2,A,0,1e400,0\n", "dy", "row 2: 1e400 is beyond"),
    (b"time,cone,dx,dy,dz\n1,A,0,0,0\n2,A,0x1,0,0\n", "dx", "row 2: '0x1' is not a number"),
    (b"time,cone,dx,dy,dz\n0,A,0,0,0\n100000,A,0,0,0\n", "time", "spans 0 to 100000 s (expected at most 86400 s)"),
    (b"time,cone,dx,dy,dz,dx \n1,A,0,0,0,1\n", "dx", "appears twice in the header"),
]


@pytest.mark.parametrize(("content", "column", "message"), BAD_CSV)
def test_bad_offsets_file_is_one_line(tmp_path: Path, content: bytes, column: str | None, message: str) -> None:
    path = _csv(tmp_path, "offsets.csv", content)
    with pytest.raises(InputError) as info:
        read_offsets(path)
    _assert_one_line(info.value, path, column, message)


@pytest.mark.parametrize(("content", "column", "message"), [
    *BAD_CSV,
    (b"t,cone_A_dx\n1,2\n", "time", "missing (expected a time column in s)"),
    (b"time,dx\n1,2\n", "cone_<C>_dx", "no cone columns"),
    (b"time,cone_A_dx,cone_A_dy\n1,2,3\n", "cone_A_dz", "missing (expected all of cone_A_dx, _dy, _dz)"),
    (b"time,cone_A_dx,cone_A_dy,cone_A_dz\n1,0,0,0\n1,1,1,1\n", "time", "1 s appears twice"),
    (b"time,cone_A_dx,cone_A_dy,cone_A_dz,camera_c_x\n1,0,0,0,far\n", "camera_c_x", "row 1: 'far' is not a number"),
    (b"time,cone,dx,dy,dz\n1,A,0,0,0\n1,A,1,1,1\n", "time", "row 2: cone A at 1 s appears twice"),
    (b"time,cone,dx,dy,dz\n1,,0,0,0\n", "cone", "row 1: empty (expected a cone name)"),
])
def test_bad_truth_file_is_one_line(tmp_path: Path, content: bytes, column: str | None, message: str) -> None:
    path = _csv(tmp_path, "truth.csv", content)
    with pytest.raises(InputError) as info:
        read_truth(path)
    _assert_one_line(info.value, path, column, message)


def _assert_one_line(error: InputError, path: Path, column: str | None, message: str) -> None:
    text = str(error)
    assert len(text.splitlines()) == 1, text
    assert text.startswith(f"{path}: {column}: " if column else f"{path}: "), text
    assert message in text, text


def test_missing_file_and_folder(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="offsets file not found"):
        read_offsets(tmp_path / "nope.csv")
    with pytest.raises(InputError, match="is a folder"):
        read_truth(tmp_path)


# --- offsets and truth that do not overlap: an error naming both files, never a table of NaN ----------------------

def _files(tmp_path: Path, offsets_text: str, truth_text: str) -> tuple[Path, pd.DataFrame, Path, pd.DataFrame]:
    o, t = _csv(tmp_path, "offsets.csv", offsets_text), _csv(tmp_path, "truth.csv", truth_text)
    return o, read_offsets(o), t, read_truth(t)


def test_check_overlap_passes_on_a_run_and_its_truth(tmp_path: Path) -> None:
    o, off, t, tr = _files(tmp_path, offsets().to_csv(index=False), _wide_text())
    assert check_overlap(o, off, t, tr) is None


@pytest.mark.parametrize(("change", "column", "message"), [
    (lambda df: df.assign(cone="B"), "cone", "shares no cone with {truth} (offsets: B; truth: A)"),
    (lambda df: df.assign(time=df["time"] + 100.0), "time", "times 100 to 129.933 s do not overlap {truth} (0 to"),
    (lambda df: df.assign(dx=np.nan, dy=np.nan, dz=np.nan), "dx", "has no estimate (dx, dy, dz all empty) within"),
])
def test_check_overlap_names_both_files(tmp_path: Path, change, column: str, message: str) -> None:
    o, off, t, tr = _files(tmp_path, change(offsets()).to_csv(index=False), _wide_text())
    with pytest.raises(InputError) as info:
        check_overlap(o, off, t, tr)
    _assert_one_line(info.value, o, column, message.format(truth=t))


def test_evaluate_runs_refuses_nothing_to_evaluate(tmp_path: Path) -> None:
    o, off, t, tr = _files(tmp_path, offsets().assign(time=lambda d: d["time"] + 100.0).to_csv(index=False),
                           _wide_text())
    with pytest.raises(InputError) as info:
        evaluate_runs("late", [(off, tr)])
    assert str(o) in str(info.value) and str(t) in str(info.value)
    assert "nothing to evaluate" in str(info.value) and len(str(info.value).splitlines()) == 1


def test_a_cone_the_truth_lacks_names_both_files(tmp_path: Path) -> None:
    rows = pd.concat([offsets(), offsets().assign(cone="C")])
    o, off, t, tr = _files(tmp_path, rows.to_csv(index=False), _wide_text())
    for check in (lambda: check_overlap(o, off, t, tr), lambda: errors(off, tr)):
        with pytest.raises(InputError) as info:
            check()
        _assert_one_line(info.value, o, "cone", f"cone 'C' is not in {t} (it gives A;")


def test_an_axis_without_samples_is_a_dash_not_nan() -> None:
    rows = offsets()
    rows["dy"] = np.nan  # an axis no camera gave
    ev = evaluate_runs("one axis missing", [(rows, truth())])
    assert ev.axes["y"].n == 0 and ev.axes["x"].n > 0
    text = evaluation_markdown(ev)
    assert "nan" not in text.lower()
    assert "| y | – | – | – | – | – | 0 |" in text


def test_flat_estimate_has_no_lag() -> None:
    from tracking.evaluate import estimate_lag

    # a constant estimate correlates with nothing (0 / 0): no lag, not a crash
    assert np.isnan(estimate_lag(T, np.full(T.size, 0.3), T, np.sin(T)))
