"""The `topside` command line: one subcommand per job, bad input as one line and exit status 2.

The command line is the one place that composes everything: the tracker (tracking/), the viewers and archives
(viewer/) and the simulator (tracking/sim/); nothing imports it (the contracts in pyproject.toml, checked by
lint-imports). Its commands live by group:

    fieldwork.py   calibrate, detect, markers, check, sync, survey (and their tables)
    caliscope.py   import-caliscope
    run.py         track, batch, evaluate, demo (track and batch share one run loop)
    archive.py     export, verify
    report.py      report
    live.py        live
    view.py        view
    sim.py         simulate
    options.py     the options several commands share, the finite-number callback, the choices (StrEnums)
    common.py      the consoles, warning lines, progress bar, the one-line rule
"""

from __future__ import annotations

import faulthandler
import signal
import sys
from typing import Annotated

import typer

from tracking.cli import archive, caliscope, fieldwork, live, report, run, sim, view
from tracking.cli.common import EXIT_INTERRUPTED, err_console, one_line
from tracking.errors import EXIT_BAD_INPUT, InputError

app = typer.Typer(
    name="topside",
    help="Watch an offshore topside being set down on its jacket, from cameras.",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,  # plain help (click): paragraphs re-wrapped to the terminal, nothing read as markup
    add_completion=False,
)
VERSIONS_OF = ("opencv-contrib-python-headless", "rerun-sdk", "numpy")  # what decides the numbers, beside topside's


def version_line() -> str:
    """topside's version and those of Python and the packages that decide its numbers, on one line."""
    from importlib.metadata import PackageNotFoundError, version

    def of(package: str) -> str:
        try:
            return version(package)
        except PackageNotFoundError:
            return "not installed"

    others = ", ".join(f"{name.removesuffix('-contrib-python-headless')} {of(name)}" for name in VERSIONS_OF)
    return f"topside {of('topside')} (Python {sys.version.split()[0]}, {others})"


def _show_version(value: bool) -> None:
    if value:
        print(version_line())
        raise typer.Exit()


@app.callback()
def _options(version: Annotated[bool, typer.Option("--version", help="Print the version and exit.",
                                                   callback=_show_version, is_eager=True)] = False) -> None:
    """Watch an offshore topside being set down on its jacket, from cameras."""


for command in (fieldwork.calibrate, fieldwork.detect, fieldwork.markers, run.track, run.batch, archive.export,
                archive.verify, report.report, view.view, live.live, fieldwork.sync, fieldwork.survey, sim.simulate,
                run.evaluate, fieldwork.check, caliscope.import_caliscope, run.demo):
    app.command()(command)  # in this order in `topside --help`


def _interrupt(signum: int, frame: object) -> None:
    """SIGTERM ends a command as Ctrl-C does: outputs are completed or removed, recordings kept, children stopped."""
    raise KeyboardInterrupt


def _ray_address_optional(args: list[str]) -> list[str]:
    """`--ray` given without an address (last, or before another option) means a Ray started here: "local"."""
    out = list(args)
    for i in range(len(out) - 1, -1, -1):
        if out[i] == "--ray" and (i + 1 == len(out) or out[i + 1].startswith("-")):
            out.insert(i + 1, "local")
    return out


def main() -> None:
    """Console entry point: bad input (files, options, usage) becomes one line on stderr and exit status 2."""
    if len(sys.argv) <= 1:  # no command: the help, as typer prints it
        app()
        return
    signal.signal(signal.SIGTERM, _interrupt)
    if hasattr(signal, "SIGUSR1"):  # `kill -USR1 <pid>`: every thread's stack on stderr, the command runs on
        try:
            faulthandler.register(signal.SIGUSR1, all_threads=True)
        except (AttributeError, ValueError, OSError):  # a stderr that is no file (None, captured in memory)
            pass
    sys.argv[1:] = _ray_address_optional(sys.argv[1:])
    try:
        code = app(standalone_mode=False)
    except InputError as exc:
        err_console.print(f"topside: error: {one_line(exc)}", markup=False)
        sys.exit(EXIT_BAD_INPUT)
    except typer.TyperException as exc:  # typer's usage errors: a missing option, a value of the wrong type
        message = exc.format_message() if hasattr(exc, "format_message") else str(exc)
        ctx = getattr(exc, "ctx", None)
        hint = f" (see: {ctx.command_path} --help)" if ctx is not None else ""
        err_console.print(f"topside: error: {one_line(message)}{hint}", markup=False)
        sys.exit(getattr(exc, "exit_code", EXIT_BAD_INPUT))
    except (typer.Abort, KeyboardInterrupt):
        err_console.print("topside: stopped", markup=False)
        sys.exit(EXIT_INTERRUPTED)
    except OSError as exc:  # the disk filled, a folder vanished: the environment, named in one line
        where = f"{exc.filename}: " if exc.filename else ""
        err_console.print(f"topside: error: {where}{exc.strerror or exc}", markup=False)
        sys.exit(EXIT_BAD_INPUT)
    sys.exit(code if isinstance(code, int) else 0)
