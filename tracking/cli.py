"""The `topside` command line: one subcommand per job, bad input as one line and exit status 2."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console

from tracking.errors import EXIT_BAD_INPUT, InputError

app = typer.Typer(
    name="topside",
    help="Watch an offshore topside being set down on its jacket, from cameras.",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    add_completion=False,
)
err_console = Console(stderr=True, highlight=False, soft_wrap=True)


@app.command()
def simulate(
    scenario: Annotated[str, typer.Argument(help="Scenario YAML file or built-in name (e.g. config2-procedure5).")],
    out: Annotated[Path, typer.Option("-o", "--out", help="Output folder for videos, rig, calibration, truth.")],
    seed: Annotated[int | None, typer.Option(help="Random seed (default: the scenario's).")] = None,
    duration: Annotated[float | None, typer.Option(help="Cut the scenario to this many seconds.")] = None,
) -> None:
    """Render a scenario: one video per camera, the rig, calibration files and the ground-truth log."""
    from tracking.sim.command import run_simulate

    run_simulate(scenario, out, seed=seed, duration=duration)


def main() -> None:
    """Console entry point: bad input becomes one line on stderr and exit status 2."""
    try:
        app()
    except InputError as exc:
        err_console.print(f"topside: error: {exc}", markup=False)
        sys.exit(EXIT_BAD_INPUT)


if __name__ == "__main__":
    main()
