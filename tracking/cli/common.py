"""What every command of the command line shares: the two consoles (results on stdout; warnings, errors and the
progress bar on stderr), the warning lines, the progress bar, the one-line rule for messages, a rig's input files."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, SpinnerColumn, TextColumn, TimeElapsedColumn

if TYPE_CHECKING:
    from collections.abc import Iterable

    from tracking.rig import Rig

EXIT_INTERRUPTED = 130  # the shell's code for a command ended by Ctrl-C

err_console = Console(stderr=True, highlight=False, soft_wrap=True, markup=False)  # file names are never markup
console = Console(highlight=False, soft_wrap=True, markup=False)


def rig_inputs(rig: Rig) -> list[Path]:
    """Every file a rig reads: itself, its calibration files and its video files (devices and streams are not files)."""
    from tracking.sources import SourceKind, source_kind

    files = [rig.path]
    for cam in rig.cameras:
        files.append(rig.resolve(cam.calibration))
        if source_kind(cam.source) == SourceKind.FILE:
            files.append(rig.resolve(cam.source))
    return files


def warn_rig(rig: Rig) -> None:
    """The rig's warnings (defaults that cost accuracy), one line each on stderr."""
    warn_lines(getattr(rig, "warnings", ()))


def warn_lines(lines: Iterable[str]) -> None:
    """Warnings met while working (a calibration's size taken from the first frame), one line each on stderr."""
    for line in lines:
        err_console.print(f"topside: warning: {line}", markup=False)


def progress_bar() -> Progress:
    """The progress bar on stderr (a spinner when the total is unknown), gone when the work is done."""
    return Progress(SpinnerColumn(), TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                    TimeElapsedColumn(), console=err_console, transient=True)


def one_line(text: object) -> str:
    """A message on one line."""
    return " ".join(str(text).split())
