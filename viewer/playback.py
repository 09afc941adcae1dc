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
    if web:
        warn_if_exposed(bind)
    subprocess.run(viewer_command(recording, web, bind), check=False)


GRPC_PORT = 9876
WEB_PORT = 9090
VIEWER_MEMORY_LIMIT = "2GB"  # a six-hour session: the viewer drops the oldest data beyond this, the file keeps all


def warn_if_exposed(bind: str) -> None:
    """One line on stderr when a viewer listens beyond this machine."""
    if bind not in LOOPBACK:
        print(f"warning: the viewer is exposed on {bind}; anyone on that network can see the installation",
              file=sys.stderr)


def start_live_viewer(web: bool, bind: str = "127.0.0.1", grpc_port: int = GRPC_PORT, web_port: int = WEB_PORT
                      ) -> tuple[str, subprocess.Popen]:
    """Start a viewer that a live session streams to: (its gRPC URL, the process)."""
    if not web and not has_display():
        raise InputError("--spawn", "no display for the native viewer (use --web for a browser or tablet)")
    cmd = [rerun_binary(), "--port", str(grpc_port), "--memory-limit", VIEWER_MEMORY_LIMIT, "--expect-data-soon"]
    if web:
        warn_if_exposed(bind)
        cmd = [rerun_binary(), "--serve-web", "--bind", bind, "--port", str(grpc_port),
               "--web-viewer-port", str(web_port), "--server-memory-limit", VIEWER_MEMORY_LIMIT]
    process = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return f"rerun+http://127.0.0.1:{grpc_port}/proxy", process
