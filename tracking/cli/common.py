"""What every command of the command line shares: the two consoles (results on stdout; warnings, errors and
progress on stderr), the warning lines, progress (a bar on a terminal, timestamped lines in a log), the one-line rule
for messages, a rig's input files.

Output without a terminal (a log on the vessel, nohup, a pipe) is for reading later: tables keep their natural width
(rich would cut them at 80 columns), and progress is a plain timestamped line at least every PROGRESS_INTERVAL_S, so
a log shows the command was alive and how far it got."""

from __future__ import annotations

import math
import os
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, SpinnerColumn, TextColumn, TimeElapsedColumn

if TYPE_CHECKING:
    from collections.abc import Iterable
    from types import TracebackType

    from tracking.rig import Rig

EXIT_INTERRUPTED = 130  # the shell's code for a command ended by Ctrl-C
PROGRESS_INTERVAL_S = 10.0  # without a terminal, a progress line at least this often (a log shows the run is alive)
PROGRESS_INTERVAL_ENV = "TOPSIDE_PROGRESS_INTERVAL_S"  # overrides it (seconds; the tests use a short one)
LOG_WIDTH = 1000  # columns of a console that is no terminal: wide enough that no table is cut (tables do not expand)


def _console(stderr: bool) -> Console:
    """A console for results (stdout) or messages (stderr); without a terminal and without COLUMNS, wide."""
    made = Console(stderr=stderr, highlight=False, soft_wrap=True, markup=False)  # file names are never markup
    if not made.is_terminal and not os.environ.get("COLUMNS", "").isdigit():
        made.width = LOG_WIDTH
    return made


err_console = _console(stderr=True)
console = _console(stderr=False)


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


class Reporter(Protocol):
    """What the commands ask of progress (rich's Progress and ProgressLines both): tasks, counted up."""

    def add_task(self, description: str, total: float | None = ..., **fields: Any) -> Any: ...

    def advance(self, task_id: Any, advance: float = ...) -> None: ...

    def update(self, task_id: Any, **changes: Any) -> None: ...


def progress_interval() -> float:
    """Seconds between progress lines without a terminal: PROGRESS_INTERVAL_S, or the environment's (a positive
    number; anything else is ignored)."""
    try:
        value = float(os.environ.get(PROGRESS_INTERVAL_ENV, ""))
    except ValueError:
        return PROGRESS_INTERVAL_S
    return value if math.isfinite(value) and value > 0 else PROGRESS_INTERVAL_S


def progress_bar() -> Progress | ProgressLines:
    """Progress on stderr: on a terminal, a bar (a spinner when the total is unknown), gone when the work is done;
    elsewhere, timestamped lines (ProgressLines)."""
    if not err_console.is_terminal:
        return ProgressLines(progress_interval())
    return Progress(SpinnerColumn(), TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                    TimeElapsedColumn(), console=err_console, transient=True)


@dataclass
class _Task:
    description: str
    total: float | None
    unit: str
    done: float = 0.0


class ProgressLines:
    """Progress as plain lines on stderr for a log: one per task every interval s from a thread (whether or not the
    work advanced: a line that stops coming means the command stopped), and, after those, one when the work has
    ended well. Each line: local date and time to the millisecond, then the task, its count and the time it has
    taken, e.g. '2026-05-04 03:12:07.415 topside: tracking 4 cameras: 1200 of 4800 frames (25 %), 31 s'. Work done
    within one interval prints nothing, so bad input is still the one line on stderr."""

    def __init__(self, interval_s: float = PROGRESS_INTERVAL_S) -> None:
        self.interval_s = interval_s
        self._tasks: list[_Task] = []
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._started = time.monotonic()
        self._printed = False  # a line was printed: the work's end gets one too
        self._thread = threading.Thread(target=self._tick, name="progress-lines", daemon=True)

    def __enter__(self) -> ProgressLines:
        self._started = time.monotonic()
        self._thread.start()
        return self

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None,
                 tb: TracebackType | None) -> None:
        self._stop.set()
        self._thread.join()
        if kind is None and self._printed:
            self._print_all(ended=True)

    def add_task(self, description: str, total: float | None = None, unit: str = "", **fields: Any) -> int:
        """A task (its number). unit: what is counted ('frames'), for the lines."""
        with self._lock:
            self._tasks.append(_Task(description, total, unit))
            return len(self._tasks) - 1

    def advance(self, task_id: int, advance: float = 1) -> None:
        with self._lock:
            self._tasks[task_id].done += advance

    def update(self, task_id: int, description: str | None = None, total: float | None = None,
               advance: float | None = None, unit: str | None = None, **fields: Any) -> None:
        """As rich's: a new description, total, advance or unit."""
        with self._lock:
            task = self._tasks[task_id]
            task.description = description if description is not None else task.description
            task.total = total if total is not None else task.total
            task.unit = unit if unit is not None else task.unit
            task.done += advance or 0.0

    def _tick(self) -> None:
        while not self._stop.wait(self.interval_s):
            self._print_all()

    def _print_all(self, ended: bool = False) -> None:
        with self._lock:
            tasks = list(self._tasks)
        for task in tasks:
            self._print(task, ended)

    def _print(self, task: _Task, ended: bool = False) -> None:
        self._printed = True
        err_console.print(self.line(task, time.time(), time.monotonic() - self._started, ended), markup=False)

    @staticmethod
    def line(task: _Task, now: float, elapsed_s: float, ended: bool = False) -> str:
        """One progress line at wall time now (s since the epoch), elapsed_s into the work."""
        unit = f" {task.unit}" if task.unit else ""
        if task.total:
            count = f"{task.done:.0f} of {task.total:.0f}{unit} ({100 * task.done / task.total:.0f} %)"
        else:
            count = f"{task.done:.0f}{unit}" if task.done or unit else ""
        took = f"done in {elapsed_s:.0f} s" if ended else f"{elapsed_s:.0f} s"
        return f"{stamp(now)} topside: {task.description}: " + ", ".join(p for p in (count, took) if p)


def stamp(now: float | None = None) -> str:
    """Local date and time to the millisecond, as a log line starts: '2026-05-04 03:12:07.415'."""
    now = time.time() if now is None else now
    return time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(now)) + f".{int(now % 1 * 1000):03d}"


def one_line(text: object) -> str:
    """A message on one line."""
    return " ".join(str(text).split())
