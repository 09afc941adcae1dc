"""Scenario files: built-ins, `base:` overrides, and one-line errors naming the file and field."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from tracking.errors import InputError
from tracking.sim.builtins import builtin_names, builtin_scenario
from tracking.sim.motion import CranePath
from tracking.sim.scenario import dump_scenario, load_scenario


def test_every_builtin_validates_and_round_trips(tmp_path: Path) -> None:
    for name in builtin_names():
        sc = builtin_scenario(name)
        path = tmp_path / f"{name}.yaml"
        path.write_text(dump_scenario(sc))
        assert load_scenario(path) == sc


def test_weather_suffix_and_base_override(tmp_path: Path) -> None:
    assert load_scenario("config2-procedure5-weather").weather.fog == 0.5
    assert load_scenario("config2-procedure5-weather").weather.rain == 0.3
    path = tmp_path / "s.yaml"
    path.write_text("base: config2-procedure5\nseed: 7\nweather: {fog: 0.4}\n")
    sc = load_scenario(path)
    assert (sc.seed, sc.weather.fog, sc.weather.rain, sc.name) == (7, 0.4, 0.0, "config2-procedure5")


def test_procedures_follow_the_paper_tables() -> None:
    starts_ends = {1: ((0, -20), (0, 0)), 2: ((0, 0), (10, 0)), 5: ((0, -5), (0, 0)), 6: ((0, 0), (0, 0)),
                   7: ((0, 0), (0, 0))}
    for n, (start, end) in starts_ends.items():
        sc = load_scenario(f"config{1 if n < 5 else 2}-procedure{n}")
        path = CranePath.from_spec(sc.motion)
        assert tuple(path.points[0, :2]) == start and tuple(path.points[-1, :2]) == end
        assert path.points[0, 2] == sc.motion.hover
    down = CranePath.from_spec(load_scenario("config2-setdown").motion)
    assert down.at([down.length])[0] == pytest.approx([0, 0, 0])


@pytest.mark.parametrize(("text", "field"), [
    ("base: config2-procedure5\nweather: {fog: 1.5}\n", "weather.fog"),
    ("base: config2-procedure5\nmotion: {waypoints: [[0, 0]], speed: -1}\n", "motion.speed"),
    ("base: config2-procedure5\ncameras: [{name: c, kind: tripod, position: [0,0,0], look_at: [1,0,0]}]\n",
     "cameras[0].kind"),
    ("base: config2-procedure5\npairs: [{cone: E, face: port, jacket_id: 0, topside_id: 1}]\n", "pairs[0].cone"),
    ("base: config2-procedure5\ncameras: [{name: c, kind: drone, position: [0,0,0], look_at: [1,0,0], width: 641}]\n",
     "cameras[0].width"),
    ("base: nowhere\n", "base"),
    ("seed: [1\n", "line"),
])
def test_bad_value_names_file_and_field(tmp_path: Path, text: str, field: str) -> None:
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    with pytest.raises(InputError) as info:
        load_scenario(path)
    message = str(info.value)
    assert str(path) in message and field in message and "\n" not in message


def test_unknown_builtin_is_an_input_error() -> None:
    with pytest.raises(InputError, match="built-in"):
        load_scenario("config9-procedure1")


def test_cli_bad_scenario_one_line_exit_2(tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("base: config2-procedure5\nweather: {rain: 3}\n")
    proc = subprocess.run([sys.executable, "-m", "tracking.cli", "simulate", str(bad), "-o", str(tmp_path / "x")],
                          capture_output=True, text=True, cwd=Path(__file__).resolve().parents[2])
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert "bad.yaml" in lines[0] and "weather.rain" in lines[0]
    assert "Traceback" not in proc.stderr
