"""Property-based fuzzing of every reader of user files: rig, calibration, dictionary, offsets and truth CSVs.

Each test mutates a valid file (byte flips, truncation, line deletion and duplication, values replaced by NaN, inf,
-1, huge numbers, strings, keys deleted, types changed) and asserts the project's rule: the reader either loads it,
and then the result is sane (finite numbers, positive sizes), or raises InputError whose message is one line naming
the file. Any other exception fails the test with the shrunk file.

Deterministic by default (derandomize); TOPSIDE_FUZZ_EXAMPLES=2000 runs a deeper, random search.
"""

from __future__ import annotations

import copy
import math
import os
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.synthetic import PAPER_K, PAPER_SIZE, rig_dict
from tracking.camera import DISTORTION_SIZES, CameraModel, load_camera, save_camera
from tracking.detection import load_dictionary
from tracking.errors import InputError
from tracking.evaluate import AXES, check_overlap, evaluate_runs, read_offsets, read_truth
from tracking.rig import load_rig

DEEP_EXAMPLES = int(os.environ.get("TOPSIDE_FUZZ_EXAMPLES", "0"))  # > 0: a longer, random search
FUZZ = settings(max_examples=DEEP_EXAMPLES or 150, deadline=None, derandomize=not DEEP_EXAMPLES, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
MAX_MUTATIONS = 3
MAX_SLICE = 12  # bytes a value replacement overwrites at most
NUMBER = re.compile(rb"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")
BAD_TEXT = [b".nan", b"nan", b"NaN", b".inf", b"-.inf", b"inf", b"-inf", b"-1", b"0", b"1e308", b"-1e400", b"1e-320",
            b"99999999999999999999999", b"abc", b"", b" ", b"[]", b"{}", b"[1, 2]", b"true", b"yes", b"null", b"~",
            b"'x'", b'"', b"'", b"!!opencv-matrix", b"!!binary", b"\x00", b"\xff\xfe", b"\xc3", b"2001-02-30", b"&a",
            b"*a", b"0x10", b"1_0", b",", b",,", b"\n", b"\r\n", b": ", b"- ", b"#", b"%YAML:1.0", b"\t",
            b"\\\xc3\xa9"]  # a backslash before a multibyte character: OpenCV unescapes it into invalid UTF-8
BAD_VALUES: list[Any] = [math.nan, math.inf, -math.inf, -1, 0, -0.0, 1e308, -1e308, 10**30, 1e-320, "x", "", " ",
                         "nan", [], {}, None, True, False, [1, 2], [1, 2, 3, 4], {"a": 1}, "0", 0.5, "DICT_4X4_50"]


# --- valid files to start from ----------------------------------------------------------------------------------

def valid_rig() -> dict:
    """A rig using every field: cones, a marker with its own normal, pairs, a camera with and one without mount."""
    cams = [{"name": "stern-1", "calibration": "cam.yaml", "source": "stern-1.mp4", "time_offset": 0.25,
             "mount": "vessel"},
            {"name": "drone-1", "calibration": "cam.yaml", "source": 0}]
    rig = rig_dict(cams)
    rig["markers"].append({"id": 7, "body": "jacket", "cone": "A", "face": "odd", "center": [-11.0, -11.0, -1.0],
                           "normal": [0.6, 0.8, 0.0]})
    return rig


def valid_calibration(folder: Path) -> bytes:
    """A calibration as `topside calibrate` writes it (OpenCV FileStorage YAML, 8 coefficients)."""
    dist = np.array([-0.1, 0.05, 0.001, -0.001, 0.01, 0.0, 0.0, 0.0])
    path = folder / "seed-calibration.yaml"
    save_camera(path, CameraModel(PAPER_K, dist, *PAPER_SIZE, rms=0.21), extra={"nframes": 14})
    return path.read_bytes()


def valid_dictionary(folder: Path) -> bytes:
    """Six markers of DICT_4X4_50 as OpenCV's writeDictionary writes a custom dictionary."""
    source = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50)
    small = cv2.aruco.Dictionary(source.bytesList[:6], source.markerSize, source.maxCorrectionBits)
    path = folder / "seed-dictionary.yml"
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    small.writeDictionary(fs)
    fs.release()
    return path.read_bytes()


TIMES = np.round(np.arange(0.0, 3.0, 0.25), 3)


def valid_offsets() -> bytes:
    """An offsets CSV as `topside track` writes it, with an axis no camera gave (nan)."""
    lines = ["time,cone,dx,dy,dz,cameras,sdx,sdy,sdz"]
    for t in TIMES:
        dy = "nan" if t == 1.0 else f"{-0.3 + 0.1 * t:.5f}"
        lines.append(f"{t + 0.01:.6f},A,{0.2 * t:.5f},{dy},{0.4:.5f},cam-ahead cam-port,0.01000,0.01000,0.01000")
        lines.append(f"{t + 0.02:.6f},D,{0.1 * t:.5f},{0.05:.5f},{0.3:.5f},cam-port,0.02000,0.02000,0.02000")
    return ("\n".join(lines) + "\n").encode()


def valid_truth_wide() -> bytes:
    """A truth log as the simulator writes it: time, cone_<C>_dx/dy/dz and a camera's pose."""
    lines = ["time,cone_A_dx,cone_A_dy,cone_A_dz,cone_D_dx,cone_D_dy,cone_D_dz,camera_c_x,camera_c_rz"]
    lines += [f"{t:.4f},{0.2 * t:.6f},{-0.3 + 0.1 * t:.6f},0.4,{0.1 * t:.6f},0.05,0.3,1.5,0.1" for t in TIMES]
    return ("\n".join(lines) + "\n").encode()


def valid_truth_long() -> bytes:
    """The same truth in the long form: time, cone, dx, dy, dz."""
    lines = ["time,cone,dx,dy,dz"]
    for t in TIMES:
        lines += [f"{t:.4f},A,{0.2 * t:.6f},{-0.3 + 0.1 * t:.6f},0.4", f"{t:.4f},D,{0.1 * t:.6f},0.05,0.3"]
    return ("\n".join(lines) + "\n").encode()


# --- mutations ----------------------------------------------------------------------------------------------------

def _flip(draw: st.DrawFn, data: bytes) -> bytes:
    i = draw(st.integers(0, max(len(data) - 1, 0)))
    return data[:i] + bytes([draw(st.integers(0, 255))]) + data[i + 1:]


def _truncate(draw: st.DrawFn, data: bytes) -> bytes:
    return data[:draw(st.integers(0, len(data)))]


def _lines(draw: st.DrawFn, data: bytes, op: str) -> bytes:
    lines = data.split(b"\n")
    i = draw(st.integers(0, len(lines) - 1))
    if op == "delete":
        del lines[i]
    elif op == "duplicate":
        lines.insert(i, lines[i])
    else:
        j = draw(st.integers(0, len(lines) - 1))
        lines[i], lines[j] = lines[j], lines[i]
    return b"\n".join(lines)


def _replace_number(draw: st.DrawFn, data: bytes) -> bytes:
    found = list(NUMBER.finditer(data))
    if not found:
        return data
    m = draw(st.sampled_from(found))
    new = draw(st.sampled_from(BAD_TEXT) | st.binary(max_size=6))
    return data[:m.start()] + new + data[m.end():]


def _replace_slice(draw: st.DrawFn, data: bytes) -> bytes:
    i = draw(st.integers(0, len(data)))
    j = min(len(data), i + draw(st.integers(0, MAX_SLICE)))
    return data[:i] + draw(st.sampled_from(BAD_TEXT)) + data[j:]


def _insert_text(draw: st.DrawFn, data: bytes) -> bytes:
    i = draw(st.integers(0, len(data)))
    return data[:i] + draw(st.text(max_size=8)).encode("utf-8", "surrogatepass") + data[i:]


MUTATIONS: dict[str, Callable[[st.DrawFn, bytes], bytes]] = {
    "flip": _flip,
    "truncate": _truncate,
    "delete line": lambda draw, data: _lines(draw, data, "delete"),
    "duplicate line": lambda draw, data: _lines(draw, data, "duplicate"),
    "swap lines": lambda draw, data: _lines(draw, data, "swap"),
    "replace number": _replace_number,
    "replace value": _replace_slice,
    "insert text": _insert_text,
}


@st.composite
def mutated(draw: st.DrawFn, original: bytes) -> bytes:
    """original after one to MAX_MUTATIONS random mutations."""
    data = original
    for _ in range(draw(st.integers(1, MAX_MUTATIONS))):
        data = MUTATIONS[draw(st.sampled_from(sorted(MUTATIONS)))](draw, data)
    return data


def _paths(node: Any, prefix: tuple = ()) -> list[tuple]:
    """Every path (keys and indices) into a nested structure of dicts and lists."""
    out = [prefix] if prefix else []
    items = node.items() if isinstance(node, dict) else enumerate(node) if isinstance(node, list) else []
    for key, child in items:
        out += _paths(child, (*prefix, key))
    return out


@st.composite
def mutated_structure(draw: st.DrawFn, original: dict) -> dict:
    """original with one to MAX_MUTATIONS fields deleted, duplicated, or given a bad value or another type."""
    data = copy.deepcopy(original)
    for _ in range(draw(st.integers(1, MAX_MUTATIONS))):
        paths = _paths(data)
        if not paths:
            break
        path = draw(st.sampled_from(paths))
        parent = data
        for key in path[:-1]:
            parent = parent[key]
        key = path[-1]
        op = draw(st.sampled_from(["delete", "value", "duplicate"]))
        if op == "delete":
            del parent[key]
        elif op == "duplicate" and isinstance(parent, list):
            parent.insert(key, copy.deepcopy(parent[key]))
        else:
            parent[key] = copy.deepcopy(draw(st.sampled_from(BAD_VALUES)))  # a later mutation must not edit it
    return data


# --- the property -------------------------------------------------------------------------------------------------

def load_or_refuse(reader: Callable[[Path], Any], path: Path, *others: Path) -> Any | None:
    """reader(path), or None when it refuses with a one-line InputError naming the file (or one of others, for a
    check of several files); any other exception (a traceback for the user) propagates and fails the test."""
    try:
        return reader(path)
    except InputError as exc:
        text = str(exc)
        assert len(text.splitlines()) == 1, text
        assert any(str(p) in text for p in (path, *others)), text
        return None


def _finite_numbers(node: Any) -> list[float]:
    """Every number in a nested dump (a model_dump)."""
    if isinstance(node, bool):
        return []
    if isinstance(node, int | float):
        return [float(node)]
    if isinstance(node, dict):
        return [v for child in node.values() for v in _finite_numbers(child)]
    if isinstance(node, list | tuple):
        return [v for child in node for v in _finite_numbers(child)]
    return []


def check_rig(path: Path) -> None:
    """A rig that loads has finite numbers, a positive marker size, usable poses and one-line warnings."""
    rig = load_or_refuse(load_rig, path)
    if rig is None:
        return
    assert all(math.isfinite(v) for v in _finite_numbers(rig.model_dump()))
    assert rig.marker_size > 0
    for m in rig.markers:
        assert np.isfinite(m.T_body_marker).all()
    for pair in rig.all_pairs():
        assert np.isfinite(rig.T_W_S_mated(pair)).all()
    for line in rig.warnings:
        assert len(line.splitlines()) == 1 and str(path) in line


def check_camera(path: Path) -> None:
    """A calibration that loads has a finite 3x3 K with positive focal lengths, a finite distortion vector of an
    OpenCV size, a positive image size or none (sized by the first frame) and a finite RMS >= 0 if any."""
    cam = load_or_refuse(load_camera, path)
    if cam is None:
        return
    assert cam.K.shape == (3, 3) and np.isfinite(cam.K).all() and cam.K[0, 0] > 0 and cam.K[1, 1] > 0
    assert cam.dist.ndim == 1 and cam.dist.size in DISTORTION_SIZES and np.isfinite(cam.dist).all()
    assert (cam.width is None and cam.height is None) or (cam.width > 0 and cam.height > 0)  # None: sized by a frame
    assert cam.rms is None or (math.isfinite(cam.rms) and cam.rms >= 0)


def check_dictionary(path: Path) -> None:
    """A dictionary that loads has markers of a sensible size and can draw its first marker."""
    d = load_or_refuse(lambda p: load_dictionary(str(p)), path)
    if d is None:
        return
    assert d.bytesList.shape[0] > 0 and d.markerSize >= 2
    assert d.generateImageMarker(0, 4 * (d.markerSize + 2)).shape == (4 * (d.markerSize + 2),) * 2


def check_offsets(path: Path) -> Any:
    """Offsets that load have finite, sorted times, named cones and finite-or-empty axes."""
    df = load_or_refuse(read_offsets, path)
    if df is None:
        return None
    t = df["time"].to_numpy(dtype=float)
    assert np.isfinite(t).all() and (np.diff(t) >= 0).all()
    assert (df["cone"].astype(str) != "").all()
    assert not np.isinf(df[list(AXES)].to_numpy(dtype=float)).any()
    return df


def check_truth(path: Path) -> Any:
    """Truth that loads has finite, strictly increasing times and finite-or-empty cone columns, at least one cone."""
    df = load_or_refuse(read_truth, path)
    if df is None:
        return None
    t = df["time"].to_numpy(dtype=float)
    assert np.isfinite(t).all() and (np.diff(t) > 0).all()
    cones = [c for c in df.columns if c.startswith("cone_")]
    assert cones and not np.isinf(df[cones].to_numpy(dtype=float)).any()
    return df


def check_evaluation(offsets_path: Path, truth_path: Path) -> None:
    """Offsets and truth that both load either give a table with numbers or a one-line error naming a file."""
    offsets, truth = check_offsets(offsets_path), check_truth(truth_path)
    if offsets is None or truth is None:
        return

    def evaluate(_: Path) -> Any:
        check_overlap(offsets_path, offsets, truth_path, truth)
        return evaluate_runs("fuzz", [(offsets, truth)])

    ev = load_or_refuse(evaluate, offsets_path, truth_path)
    if ev is None:
        return
    assert any(s.n > 0 and math.isfinite(s.mae) for s in ev.axes.values())
    for s in ev.axes.values():
        assert s.n == 0 or all(math.isfinite(v) for v in (s.mae, s.max_abs, s.std, s.mean, s.rmse))
    assert 0.0 <= ev.availability <= 1.0


# --- the tests ----------------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A folder the examples overwrite (module-scoped: hypothesis runs many examples per test call)."""
    return tmp_path_factory.mktemp("fuzz")


RIG_TEXT = yaml.safe_dump(valid_rig(), sort_keys=False).encode()


@FUZZ
@given(data=mutated(RIG_TEXT))
def test_rig_bytes(folder: Path, data: bytes) -> None:
    path = folder / "rig.yaml"
    path.write_bytes(data)
    check_rig(path)


@FUZZ
@given(rig=mutated_structure(valid_rig()))
def test_rig_fields(folder: Path, rig: dict) -> None:
    path = folder / "rig.yaml"
    path.write_text(yaml.safe_dump(rig, sort_keys=False))
    check_rig(path)


@pytest.fixture(scope="module")
def opencv_seeds(folder: Path) -> dict[str, bytes]:
    """The valid calibration and dictionary files, written once by OpenCV."""
    return {"calibration": valid_calibration(folder), "dictionary": valid_dictionary(folder)}


@FUZZ
@given(data=st.data())
def test_calibration(folder: Path, opencv_seeds: dict[str, bytes], data: st.DataObject) -> None:
    path = folder / "cam.yaml"
    path.write_bytes(data.draw(mutated(opencv_seeds["calibration"])))
    check_camera(path)


@FUZZ
@given(data=st.data())
def test_dictionary(folder: Path, opencv_seeds: dict[str, bytes], data: st.DataObject) -> None:
    path = folder / "dict.yml"
    path.write_bytes(data.draw(mutated(opencv_seeds["dictionary"])))
    check_dictionary(path)


@FUZZ
@given(data=mutated(valid_offsets()))
def test_offsets(folder: Path, data: bytes) -> None:
    path = folder / "offsets.csv"
    path.write_bytes(data)
    check_evaluation(path, _write(folder / "truth-ok.csv", valid_truth_wide()))


@FUZZ
@given(data=mutated(valid_truth_wide()))
def test_truth_wide(folder: Path, data: bytes) -> None:
    path = folder / "truth.csv"
    path.write_bytes(data)
    check_evaluation(_write(folder / "offsets-ok.csv", valid_offsets()), path)


@FUZZ
@given(data=mutated(valid_truth_long()))
def test_truth_long(folder: Path, data: bytes) -> None:
    path = folder / "truth.csv"
    path.write_bytes(data)
    check_evaluation(_write(folder / "offsets-ok.csv", valid_offsets()), path)


def _write(path: Path, data: bytes) -> Path:
    path.write_bytes(data)
    return path


def test_the_seeds_are_valid(folder: Path) -> None:
    """The unmutated files load: the fuzzing starts from valid input."""
    rig = folder / "seed-rig.yaml"
    rig.write_bytes(RIG_TEXT)
    assert load_rig(rig).cameras[1].source == "0"
    valid_calibration(folder)
    assert load_camera(folder / "seed-calibration.yaml").dist.size == 8
    valid_dictionary(folder)
    assert load_dictionary(str(folder / "seed-dictionary.yml")).bytesList.shape[0] == 6
    offsets = read_offsets(_write(folder / "o.csv", valid_offsets()))
    wide = read_truth(_write(folder / "w.csv", valid_truth_wide()))
    long = read_truth(_write(folder / "l.csv", valid_truth_long()))
    for truth in (wide, long):
        ev = evaluate_runs("seed", [(offsets, truth)])
        assert ev.axes["x"].n == 2 * (len(TIMES) - 1)  # the last rows come after the truth ends
