"""The `topside` command run inside the test's own process: the same entry point (`tracking.cli.main`), its exit
status and what it wrote to the file descriptors, without a new interpreter's 1-2 s of start-up per run."""

from __future__ import annotations

import faulthandler
import signal
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import pytest

Run = Callable[..., subprocess.CompletedProcess]  # run(*args): the command's finished process


def run_topside(args: list[str], cwd: Path | None, capfd: pytest.CaptureFixture[str],
                monkeypatch: pytest.MonkeyPatch) -> tuple[int, str, str]:
    """`topside ARGS` in cwd (None: here): (exit status, stdout, stderr). An exception the command lets escape
    fails the test, as a traceback would show in a terminal."""
    from tracking.cli import main

    if cwd is not None:
        monkeypatch.chdir(cwd)
    monkeypatch.setattr(sys, "argv", ["topside", *args])
    sigterm = signal.getsignal(signal.SIGTERM)
    capfd.readouterr()
    try:
        main()
        code = 0
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
    finally:
        signal.signal(signal.SIGTERM, sigterm)
        if hasattr(signal, "SIGUSR1"):
            faulthandler.unregister(signal.SIGUSR1)  # it wrote to this run's captured stderr
    out, err = capfd.readouterr()
    return code, out, err


def topside_runner(capfd: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
                   ) -> Run:
    """`run(*args)`: `topside ARGS` in this process, as a finished process (exit status, stdout, stderr)."""

    def run(*args: str | Path) -> subprocess.CompletedProcess:
        argv = [str(a) for a in args]
        code, out, err = run_topside(argv, None, capfd, monkeypatch)
        return subprocess.CompletedProcess(["topside", *argv], code, out, err)

    return run
