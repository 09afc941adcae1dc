"""Opening recordings in Rerun's viewer (the `rerun` binary that ships with rerun-sdk)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

from tracking.errors import InputError

LOOPBACK = {"127.0.0.1", "localhost", "::1"}


def rerun_binary() -> str:
    """Path of the `rerun` command installed with rerun-sdk."""
    local = Path(sys.executable).parent / "rerun"
    return str(local) if local.exists() else (shutil.which("rerun") or "rerun")


def has_display() -> bool:
    """True when a native window can open."""
    return sys.platform in ("darwin", "win32") or bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def viewer_command(recording: Path, web: bool = False, bind: str = "127.0.0.1") -> list[str]:
    """The rerun command line that opens a recording."""
    cmd = [rerun_binary(), str(recording)]
    if web:
        cmd += ["--web-viewer", "--bind", bind]
    return cmd


def open_viewer(recording: Path, web: bool = False, bind: str = "127.0.0.1") -> None:
    """Open the recording; a one-line error when it is missing or no display is available for the native viewer."""
    if not recording.is_file():
        raise InputError(recording, "recording not found (expected a .rrd file)")
    if not web and not has_display():
        raise InputError(recording, "no display for the native viewer (use --web, or open the file on a desktop)")
    if web and bind not in LOOPBACK:
        print(f"warning: the web viewer is exposed on {bind}; anyone on that network can see the recording",
              file=sys.stderr)
    subprocess.run(viewer_command(recording, web, bind), check=False)
