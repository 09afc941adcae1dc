"""`topside simulate`: a scenario (a file, a built-in, or an installation drawn from a seed) rendered by the
simulator (tracking.sim): one video per camera, the rig, calibration files and the ground-truth log."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from tracking.cli.options import finite
from tracking.errors import InputError

MAX_CLOCK_ERROR_S = 10.0  # --clock-error beyond this is not a clock off, it is another recording


def simulate(
    scenario: Annotated[str | None, typer.Argument(
        help="Scenario YAML file or built-in name (e.g. config2-procedure5, random-17).")] = None,
    out: Annotated[Path | None, typer.Option("-o", "--out", help="Output folder for videos, rig, calibration, truth.")
                   ] = None,
    random: Annotated[int | None, typer.Option(
        "--random", help="Draw a whole installation from this seed (cameras, markers, lift, weather) instead of a "
                         "scenario: the same as the scenario random-SEED.", min=0)] = None,
    seed: Annotated[int | None, typer.Option(help="Random seed (default: the scenario's).", min=0)] = None,
    duration: Annotated[float | None, typer.Option(help="Cut the scenario to this many seconds.",
                                                   callback=finite(0.0))] = None,
    clock_error: Annotated[float | None, typer.Option(
        help="Every camera's clock off by a uniform draw within ±this many s; the rig keeps the nominal offsets.",
        callback=finite(0.0, low_open=False, high=MAX_CLOCK_ERROR_S))] = None,
    survey_error: Annotated[tuple[float, float] | None, typer.Option(
        help="Markers off their surveyed poses: σ of the centre (m) and of the tilt (°), e.g. 0.02 1; the rig keeps "
             "the nominal poses.")] = None,
) -> None:
    """Render a scenario: one video per camera, the rig, calibration files and the ground-truth log.

    Built-ins: config1-procedure1..4, config2-procedure5..7, config1-setdown, config2-setdown,
    config1-cone-a (markers at cone A only), calibration-shots;
    add -weather (fog 50 %, rain 30 %), -clear (no weather, no noise) or -realities (clocks off by up to
    ±0.5 s, markers 20 mm and 1° off their survey; truth_rig.yaml has the truth, for benchmarks only).
    random-SEED (or --random SEED) draws a whole installation from a seed.
    """
    from tracking.sim.command import run_simulate

    if (scenario is None) == (random is None):
        raise InputError("SCENARIO", "give a scenario or --random SEED (exactly one)")
    if out is None:
        raise InputError("--out", "missing (expected the folder to write the simulation into)")
    scenario = scenario if random is None else f"random-{random}"

    run_simulate(scenario, out, seed=seed, duration=duration, clock_error_s=clock_error, survey_error=survey_error)
