"""Opening recordings in Rerun's viewer (the `rerun` binary that ships with rerun-sdk)."""

from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from tracking.errors import InputError

SPLIT_UNITS = {"ns": 1e-9, "us": 1e-6, "µs": 1e-6, "ms": 1e-3, "s": 1.0}
LOOPBACK = {"127.0.0.1", "localhost", "::1"}


def rerun_binary() -> str:
    """Path of the `rerun` command installed with rerun-sdk."""
    local = Path(sys.executable).parent / "rerun"
    return str(local) if local.exists() else (shutil.which("rerun") or "rerun")


def viewer_env() -> dict[str, str]:
    """Environment for Rerun's native viewer: an `ffmpeg` on PATH, which it needs to decode H.264 video streams.

    The one shipped with imageio-ffmpeg is linked as `ffmpeg` into the venv's bin when the system has none.
    """
    env = dict(os.environ)
    if shutil.which("ffmpeg"):
        return env
    import imageio_ffmpeg

    shim = Path(sys.executable).parent / "ffmpeg"
    if not shim.exists():
        try:
            shim.symlink_to(imageio_ffmpeg.get_ffmpeg_exe())
        except OSError:
            return env
    env["PATH"] = f"{shim.parent}{os.pathsep}{env.get('PATH', '')}"
    return env


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
    subprocess.run(viewer_command(recording, web, bind), check=False, env=viewer_env())


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
    process = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=viewer_env(),
                               start_new_session=True)  # its own group: `rerun` is a wrapper around the server
    return f"rerun+http://127.0.0.1:{grpc_port}/proxy", process


def stop_viewer(process: subprocess.Popen, timeout: float = 10.0) -> None:
    """Stop a live viewer and the server its `rerun` wrapper started (terminating the wrapper alone leaves it)."""
    try:
        os.killpg(process.pid, signal.SIGTERM)
    except ProcessLookupError:
        return
    try:
        process.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        pass
    time.sleep(0.5)  # the wrapper exits first; the server gets a moment to close, then whatever is left is killed
    try:
        os.killpg(process.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass
    process.wait()


def segment_index(recording: Path) -> Path | None:
    """The segments index of a segmented recording (given as its .rrd stem or the index itself), if any."""
    if recording.name.endswith(".segments.csv"):
        return recording
    index = recording.with_name(f"{recording.stem}.segments.csv")
    return index if index.is_file() else None


def segments_in_window(index: Path, start: float | None, end: float | None) -> list[Path]:
    """Segment files whose capture-time span overlaps [start, end]."""
    import pandas as pd

    try:
        df = pd.read_csv(index)
        files, first, last = df["file"], df["start"].astype(float), df["end"].astype(float)
    except (OSError, KeyError, ValueError, pd.errors.ParserError) as exc:
        raise InputError(index, f"is not a segments index ({exc}; expected columns file,start,end)") from None
    keep = (last >= (start if start is not None else -np.inf)) & (first <= (end if end is not None else np.inf))
    return [index.parent / f for f in files[keep]]


def window_recording(recording: Path, start: float | None, end: float | None, work: Path) -> Path:
    """One .rrd holding [start, end] of a recording or of its segments, cut by `rerun rrd merge/split`."""
    index = segment_index(recording)
    files = segments_in_window(index, start, end) if index else [recording]
    if not files:
        raise InputError(index, f"has no segment between {start} and {end} s", "--from/--to")
    for f in files:
        if not f.is_file():
            raise InputError(f, "recording not found (expected a .rrd file)")
    if start is None and end is None and len(files) == 1:
        return files[0]
    work.mkdir(parents=True, exist_ok=True)
    merged = files[0]
    if len(files) > 1:
        merged = work / "merged.rrd"
        _rerun(["rrd", "merge", *map(str, files), "-o", str(merged)], recording)
    if start is None and end is None:
        return merged
    cuts = [t for t in (start, end) if t is not None]
    split = work / "split"
    split.mkdir(exist_ok=True)
    _rerun(["rrd", "split", "-o", str(split), "--timeline", "capture_time",
            *[a for t in cuts for a in ("-t", str(round(t * 1e9)))], str(merged)], recording)
    parts = sorted(split.glob("*.rrd"), key=lambda p: _part_start(p.stem, merged.stem))
    return parts[1] if start is not None else parts[0]


def _part_start(name: str, stem: str) -> float:
    """Start time of a `rerun rrd split` part, from its name <stem>_<start>__<end> (1_5s is 1.5 s), s."""
    match = re.fullmatch(r"(-?[\d_]+)(ns|us|µs|ms|s)", name[len(stem) + 1:].split("__")[0])
    if match is None:
        return -np.inf
    return float(match[1].replace("_", ".", 1)) * SPLIT_UNITS[match[2]]


def _rerun(args: list[str], recording: Path) -> None:
    """Run a `rerun` subcommand; a one-line error when it fails."""
    proc = subprocess.run([rerun_binary(), *args], capture_output=True, text=True, check=False)
    if proc.returncode != 0:
        last = (proc.stderr.strip().splitlines() or ["failed"])[-1]
        raise InputError(recording, f"rerun {args[0]} {args[1]}: {last}")
