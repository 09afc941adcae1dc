"""Opening recordings in Rerun's viewer (the `rerun` binary that ships with rerun-sdk), and stopping it again."""

from __future__ import annotations

import ctypes
import ipaddress
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
import urllib.parse
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from tracking.errors import InputError

SPLIT_UNITS = {"ns": 1e-9, "us": 1e-6, "µs": 1e-6, "ms": 1e-3, "s": 1.0}
GRPC_PORT = 9876
WEB_PORT = 9090
VIEWER_MEMORY_LIMIT = "2GB"  # a six-hour session: the viewer drops the oldest data beyond this, the file keeps all
LATE_JOIN_S = 6.0  # s: a web page opened late is sent about this much of the past, so opening it after six hours
# costs what opening it after one does. The page takes what it is sent in arrival order, at most 10 ms of each of its
# frames (re_viewer's receive_messages), so the present waits behind all of it: on the tests' one-cone installation
# with the other core busy, a page sent 33 s of the past came within 5 s of the live clock 44 s after opening, one sent
# this (and fewer chunks: viewer.superintendent) 19 s after (results/web_late_open_pictures.md). The trend's past fills
# in as the page stays open. Rerun drops the oldest temporal data first, static data only after, the layout never.
VIEW_OVERHEAD_BYTES_PER_S = {"superintendent": 10_000, "all": 100_000}  # per camera, what a live viewer's stream
# carries beyond the camera's images: its detections drawn (superintendent), or the detections, poses and health as
# recorded (all). Measured on config2-procedure5, 4 cameras at 15 FPS, 920×600, the live path flat out into a file
VIEW_FIGURE_BYTES_PER_S = 45_000  # per cone, its figures (text, bull's-eye, trend): 6 parts, a chunk each per
# batch (viewer.session.BATCH_TICK_S), mostly their schemas; measured on the tests' one-cone installation, 28 s:
# 1188 KiB in 339 chunks (43 kB/s; 62 kB/s in 9 chunks a batch before)
MIN_SERVER_MEMORY_BYTES = 4 << 20  # a web server sent videos keeps at least this: two 2-second keyframe intervals
# of four cameras at 2 Mbit/s, so the oldest kept frame has its keyframe
MIN_PICTURES_SERVER_BYTES = 512 << 10  # one sent pictures (each a JPEG of its own) and figures: the layout and the
# static figures weigh kilobytes
STDIN = "-"  # rerun's data source for its standard input: what a live session feeds (viewer/feed.py)
# Rerun's analytics pipeline (re_analytics, native/pipeline.rs) starts nothing when CI is set ("Analytics disabled on
# CI"); FORCE_RERUN_ANALYTICS would override that, so it is dropped. The user's own analytics.json is left alone.
ANALYTICS_OFF = {"CI": "1"}
ANALYTICS_FORCE_VAR = "FORCE_RERUN_ANALYTICS"
RRD_MAGIC = b"RRF"  # every .rrd starts with a FourCC, RRF2 in the files Rerun 0.41 writes
PR_SET_PDEATHSIG = 1  # prctl option: the signal a child gets when its parent dies (linux/prctl.h)
STOP_TIMEOUT_S = 5.0  # SIGTERM, then SIGKILL for whatever of the viewer's process group is still there
READY_TIMEOUT_S = 60.0  # the web server answers within a second; a loaded machine gets a margin
POLL_S = 0.05
STOP_SIGNALS = tuple(getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, name))
VIEW_TMP_PREFIX = "topside-view-"
CLEANUP_TIMEOUT_S = 5.0  # the folder's warden tries this long to remove it (a dying viewer may still be writing there)
# The warden of a temporary folder: it leaves its parent (so topside's only child is its viewer), waits for the end of
# its standard input, which comes when topside ends however it ends (a SIGKILL included: the kernel closes the pipe),
# and removes the folder.
WARDEN = """
import os, shutil, sys, time
if os.fork():
    os._exit(0)
sys.stdin.buffer.read()
deadline = time.monotonic() + float(sys.argv[2])
while os.path.lexists(sys.argv[1]) and time.monotonic() < deadline:
    shutil.rmtree(sys.argv[1], ignore_errors=True)
    time.sleep(0.1)
"""
ANSI = re.compile(r"\x1b\[[0-9;]*m")


def rerun_binary() -> str:
    """Path of the `rerun` executable installed with rerun-sdk (the real one, not its Python wrapper script)."""
    if os.environ.get("RERUN_CLI_PATH"):  # the override the wrapper honours
        return os.environ["RERUN_CLI_PATH"]
    try:
        import rerun_cli

        bundled = Path(rerun_cli.__file__).parent
        for exe in (bundled / "Rerun.app" / "Contents" / "MacOS" / "Rerun", bundled / "rerun",
                    bundled / "rerun.exe"):
            if exe.is_file():
                return str(exe)
    except ImportError:
        pass
    local = Path(sys.executable).parent / "rerun"
    return str(local) if local.exists() else (shutil.which("rerun") or "rerun")


def rerun_env() -> dict[str, str]:
    """Environment for every `rerun` process the tool starts: analytics off, and an `ffmpeg` on PATH.

    The viewer needs ffmpeg to decode H.264 video streams; the one shipped with imageio-ffmpeg is linked as `ffmpeg`
    into the venv's bin when the system has none.
    """
    env = {k: v for k, v in os.environ.items() if k != ANALYTICS_FORCE_VAR} | ANALYTICS_OFF
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


viewer_env = rerun_env  # its former name, still imported elsewhere


def has_display() -> bool:
    """True when a native window can open."""
    return sys.platform in ("darwin", "win32") or bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def resolve_bind(bind: str) -> str:
    """The numeric address --bind names (an address or a host name), checked to be one of this machine's."""
    try:
        infos = socket.getaddrinfo(bind, None, type=socket.SOCK_STREAM)
    except (socket.gaierror, UnicodeError) as exc:
        reason = exc.strerror if isinstance(exc, socket.gaierror) else "not a host name"
        raise InputError("--bind", f"{bind!r} does not resolve ({reason}); expected an address or host name of "
                                   "this machine") from None
    candidates = sorted({(family, sockaddr[0]) for family, _, _, _, sockaddr in infos},
                        key=lambda c: (c[0] != socket.AF_INET, c[1]))  # IPv4 first: what a tablet reaches
    for family, address in candidates:
        try:
            with socket.socket(family, socket.SOCK_STREAM) as probe:
                probe.bind((address, 0))
        except OSError:
            continue
        return address
    found = ", ".join(a for _, a in candidates)
    named = repr(bind) if found == bind else f"{bind!r} ({found})"
    raise InputError("--bind", f"{named} is not an address of this machine; expected one of its own, or 127.0.0.1")


def is_loopback(address: str) -> bool:
    """True for an address only this machine reaches."""
    try:
        return ipaddress.ip_address(address).is_loopback
    except ValueError:
        return address == "localhost"


def warn_if_exposed(address: str) -> None:
    """One line on stderr when a viewer listens beyond this machine."""
    if not is_loopback(address):
        print(f"warning: the viewer is exposed on {address}; anyone on that network can see the installation",
              file=sys.stderr)


def url_host(address: str) -> str:
    """How a URL names the machine at a bound address (a wildcard address: by its host name)."""
    ip = ipaddress.ip_address(address)
    if ip.is_unspecified:
        return socket.gethostname()
    return f"[{address}]" if ip.version == 6 else address


def connect_host(address: str) -> str:
    """Where a process on this machine reaches a server bound to the address."""
    ip = ipaddress.ip_address(address)
    if ip.is_unspecified:
        return "127.0.0.1" if ip.version == 4 else "[::1]"
    return f"[{address}]" if ip.version == 6 else address


def grpc_url(host: str, grpc_port: int) -> str:
    """The gRPC URL of a Rerun server (the proxy SDKs log to and viewers read from)."""
    return f"rerun+http://{host}:{grpc_port}/proxy"


def web_viewer_url(address: str, grpc_port: int = GRPC_PORT, web_port: int = WEB_PORT) -> str:
    """The page to open in a browser: the web viewer, told where its data is (the query quoted: '+' is a space), its
    welcome screen off (offline, as on a vessel, its examples fail to load with a notice over the right column)."""
    host = url_host(address)
    return f"http://{host}:{web_port}/?url={urllib.parse.quote(grpc_url(host, grpc_port), safe='')}&hide_welcome_screen"


def check_port_free(address: str, port: int, option: str) -> None:
    """A one-line error when something on this machine already listens on the port."""
    family = socket.AF_INET6 if ipaddress.ip_address(address).version == 6 else socket.AF_INET
    try:
        with socket.socket(family, socket.SOCK_STREAM) as probe:
            probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as servers do: TIME_WAIT is no obstacle
            probe.bind((address, port))
    except OSError as exc:
        raise InputError(option, f"cannot listen on {address} port {port} ({exc.strerror}); expected a free "
                                 "port") from None


def check_recording(path: Path) -> None:
    """A one-line error unless the file is a complete Rerun recording (`rerun rrd verify`: ~1 GB/s, cached)."""
    if not path.is_file():
        raise InputError(path, "recording not found (expected a .rrd file)")
    with path.open("rb") as f:
        head = f.read(len(RRD_MAGIC) + 1)
    if not head:
        raise InputError(path, "is empty (expected a Rerun recording, .rrd)")
    if not head.startswith(RRD_MAGIC):
        raise InputError(path, f"is not a Rerun recording (it starts with {head!r}; a .rrd starts with RRF)")
    proc = subprocess.run([rerun_binary(), "rrd", "verify", str(path)], capture_output=True, text=True,
                          errors="replace", check=False, env=rerun_env())
    lines = [ANSI.sub("", line).strip() for line in (proc.stderr + proc.stdout).splitlines() if line.strip()]
    if proc.returncode == 0 and any(line.startswith("1 file verified") for line in lines):
        return
    problems = [re.sub(r'^"[^"]*"\S*: ', "", line) for line in lines if not line.startswith("Error: Verification")]
    reason = problems[0] if problems else f"rerun rrd verify exited with status {proc.returncode}"
    if "footer" in reason.lower():
        raise InputError(path, f"is incomplete ({reason}): still being written, or cut short; "
                               f"`rerun rrd merge {path} -o <new>.rrd` recovers what it holds")
    if proc.returncode == 0:  # verify read no message at all: a bare header
        reason = "no data"
    raise InputError(path, f"is not a readable Rerun recording ({reason})")


def viewer_command(recording: Path, web: bool = False, address: str = "127.0.0.1", grpc_port: int | None = None,
                   web_port: int = WEB_PORT) -> list[str]:
    """The rerun command line that opens a recording; its servers listen on the address only."""
    if web:
        return [rerun_binary(), "--serve-web", str(recording), "--bind", address,
                "--port", str(GRPC_PORT if grpc_port is None else grpc_port), "--web-viewer-port", str(web_port)]
    # the native viewer hosts a gRPC server too; "auto": a free port, not a viewer already running on the default
    port = "auto" if grpc_port is None else str(grpc_port)
    return [rerun_binary(), str(recording), "--bind", address, "--port", port]


def late_join_bytes(image_bytes_per_s: list[float], scope: str, cones: int, videos: bool) -> int:
    """What a live web server keeps for a page opened late, bytes: LATE_JOIN_S of the viewer's stream, from each
    camera's images (bytes/s: its video, tracking.sources.byte_rate, or its pictures, viewer.session.view_bytes_per_s),
    the scope's overhead per camera and the figures of `cones` cones; at least two keyframe intervals when `videos`."""
    rate = (sum(image_bytes_per_s) + VIEW_OVERHEAD_BYTES_PER_S[scope] * len(image_bytes_per_s)
            + VIEW_FIGURE_BYTES_PER_S * cones)
    return max(MIN_SERVER_MEMORY_BYTES if videos else MIN_PICTURES_SERVER_BYTES, int(LATE_JOIN_S * rate))


def live_viewer_command(web: bool, address: str = "127.0.0.1", grpc_port: int = GRPC_PORT, web_port: int = WEB_PORT,
                        server_bytes: int | None = None) -> list[str]:
    """The rerun command line of a viewer that a live session streams to through its standard input ("-": an .rrd
    stream, viewer/feed.py); its servers listen on the address only. server_bytes: what the web server keeps for
    late pages (late_join_bytes; default VIEWER_MEMORY_LIMIT)."""
    if web:  # newest first: a tablet that connects late draws the present first, then the backlog behind it
        limit = VIEWER_MEMORY_LIMIT if server_bytes is None else f"{server_bytes}B"
        return [rerun_binary(), "--serve-web", "--bind", address, "--port", str(grpc_port),
                "--web-viewer-port", str(web_port), "--server-memory-limit", limit, "--newest-first", STDIN]
    return [rerun_binary(), "--bind", address, "--port", str(grpc_port), "--memory-limit", VIEWER_MEMORY_LIMIT,
            "--expect-data-soon", STDIN]


class StopSignals:
    """In the block, SIGINT, SIGTERM and SIGHUP raise KeyboardInterrupt as Ctrl-C does; old handlers come back after.

    Only the first counts: later ones are ignored, so the cleanup it starts (bounded by timeouts) runs to its end.
    Inside deferred(), the interrupt waits for the block's end: a process being started is known before it comes.
    """

    def __init__(self) -> None:
        self.previous: dict[int, object] = {}
        self.deferring = False
        self.pending = False

    def __enter__(self) -> StopSignals:
        if threading.current_thread() is threading.main_thread():  # only the main thread may set handlers
            self.previous = {s: signal.signal(s, self._interrupt) for s in STOP_SIGNALS}
        return self

    def __exit__(self, *exc: object) -> None:
        for s, handler in self.previous.items():
            signal.signal(s, handler)

    def _interrupt(self, signum: int, frame: object) -> None:
        """The handler: ignore what follows, then interrupt (now, or at the end of deferred())."""
        for s in STOP_SIGNALS:
            signal.signal(s, signal.SIG_IGN)
        if self.deferring:
            self.pending = True
            return
        raise KeyboardInterrupt

    @contextmanager
    def deferred(self) -> Iterator[None]:
        """A signal received in this block interrupts at its end."""
        self.deferring = True
        try:
            yield
        finally:
            self.deferring = False
            if self.pending:
                raise KeyboardInterrupt


@contextmanager
def work_folder(prefix: str = VIEW_TMP_PREFIX) -> Iterator[Path]:
    """A temporary folder that does not outlive topside: removed when the block ends, and by a warden process
    (WARDEN) within about a second when topside is killed (kill -9 runs no handler and no finally)."""
    work = Path(tempfile.mkdtemp(prefix=prefix))
    warden = None
    try:
        warden = subprocess.Popen([sys.executable, "-I", "-S", "-c", WARDEN, str(work), str(CLEANUP_TIMEOUT_S)],
                                  stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                  start_new_session=True)  # a terminal's Ctrl-C is not its
        warden.wait()  # the warden's first process, gone at once; its fork waits on the pipe
        yield work
    finally:
        shutil.rmtree(work, ignore_errors=True)
        if warden is not None and warden.stdin is not None:
            warden.stdin.close()  # the warden finds the folder gone and ends


def die_with_parent() -> None:
    """In a child before it runs (Linux): SIGTERM it when topside ends, even killed with SIGKILL."""
    if sys.platform.startswith("linux"):
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGTERM)


def start_viewer_process(cmd: list[str], log: Path | None = None, tmp: Path | None = None) -> subprocess.Popen:
    """Start a rerun process in its own process group (stopped with everything it starts).

    log: where its output goes (default: the terminal); tmp: its TMPDIR (the native viewer leaves rerun-data-* there).
    """
    env = rerun_env()
    if tmp is not None:
        tmp.mkdir(parents=True, exist_ok=True)
        env["TMPDIR"] = str(tmp)
    out = log.open("wb") if log is not None else None
    try:
        return subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=out, stderr=subprocess.STDOUT if out else None,
                                env=env, start_new_session=True,  # own group: a terminal's Ctrl-C is ours to pass on
                                preexec_fn=die_with_parent)
    finally:
        if out is not None:
            out.close()


def last_words(log: Path | None) -> str:
    """": " and the last line a viewer wrote to its log, without colours; "" when there is none."""
    if log is None or not log.is_file():
        return ""
    lines = [ANSI.sub("", line).strip() for line in log.read_text(errors="replace").splitlines() if line.strip()]
    return f": {lines[-1]}" if lines else ""


def wait_listening(process: subprocess.Popen, address: str, port: int, log: Path | None,
                   timeout: float = READY_TIMEOUT_S) -> None:
    """Wait until the server answers on the port; SystemExit with its last words when it ends or never answers."""
    host = connect_host(address).strip("[]")
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if process.poll() is not None:
            raise SystemExit(f"topside: the viewer stopped before serving (status {process.returncode})"
                             f"{last_words(log)}")
        try:
            with socket.create_connection((host, port), timeout=1.0):
                return
        except OSError:
            time.sleep(POLL_S)
    raise SystemExit(f"topside: the viewer did not answer on {host}:{port} within {timeout:.0f} s{last_words(log)}")


def run_viewer(recording: Path, web: bool, address: str, grpc_port: int | None, web_port: int, work: Path,
               signals: StopSignals) -> None:
    """Run the viewer on a checked recording until it ends (window closed) or a signal stops it; stopped either way."""
    log = work / "rerun.log" if web else None  # the native viewer talks to its terminal as it always did
    process = None
    try:
        with signals.deferred():
            process = start_viewer_process(viewer_command(recording, web, address, grpc_port, web_port), log,
                                           work / "tmp")  # Rerun's own temporary files go with ours
        if web:
            wait_listening(process, address, web_port, log)
            print(web_viewer_url(address, GRPC_PORT if grpc_port is None else grpc_port, web_port), flush=True)
            print("serving the web viewer; Ctrl-C stops it", file=sys.stderr, flush=True)
        code = process.wait()
        if web or code != 0:
            raise SystemExit(f"topside: the viewer stopped by itself (status {code}){last_words(log)}")
    finally:
        if process is not None:
            stop_viewer(process)


def view_recording(recording: Path, start: float | None = None, end: float | None = None, web: bool = False,
                   bind: str = "127.0.0.1", grpc_port: int | None = None, web_port: int = WEB_PORT) -> None:
    """Open a recording (or a window of it) in Rerun's viewer, until it is closed or Ctrl-C/SIGTERM/SIGHUP.

    Refuses unreadable recordings and unusable addresses before starting anything; however it ends, the viewer's
    process group is stopped and the temporary files (a window cut from the recording, the server's log) removed.
    """
    address = resolve_bind(bind)
    if not web and not has_display():
        raise InputError(recording, "no display for the native viewer (use --web, or open the file on a desktop)")
    grpc = GRPC_PORT if web and grpc_port is None else grpc_port  # the native viewer's own default: a free one
    if web:
        check_port_free(address, web_port, "--web-port")
    if grpc is not None:  # taken by another viewer, Rerun would hand it the recording instead
        check_port_free(address, grpc, "--grpc-port")
    warn_if_exposed(address)
    with StopSignals() as signals, work_folder() as work:
        opened = window_recording(recording, start, end, work / "window")
        run_viewer(opened, web, address, grpc_port, web_port, work, signals)


def start_live_viewer(web: bool, bind: str = "127.0.0.1", grpc_port: int = GRPC_PORT, web_port: int = WEB_PORT,
                      server_bytes: int | None = None) -> subprocess.Popen:
    """Start a viewer that a live session streams to through its stdin (process.stdin, for viewer.feed.ViewerFeed),
    listening on --bind only; a web server keeps server_bytes for late pages (live_viewer_command)."""
    if not web and not has_display():
        raise InputError("--spawn", "no display for the native viewer (use --web for a browser or tablet)")
    address = resolve_bind(bind)
    warn_if_exposed(address)
    return subprocess.Popen(live_viewer_command(web, address, grpc_port, web_port, server_bytes), stdin=subprocess.PIPE,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=rerun_env(),
                            start_new_session=True, preexec_fn=die_with_parent)


def _group_alive(process: subprocess.Popen) -> bool:
    """True while any process of the viewer's group (its leader reaped as it exits) is still there."""
    process.poll()
    try:
        os.killpg(process.pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # a member we may not signal still exists
        return True
    return True


def stop_viewer(process: subprocess.Popen, timeout: float = STOP_TIMEOUT_S) -> None:
    """Stop a viewer and its whole process group: SIGTERM, then SIGKILL for whatever is left after the timeout."""
    if process.stdin is not None:  # a live viewer's input, if its feed has not closed it
        try:
            process.stdin.close()
        except OSError:
            pass
    try:
        os.killpg(process.pid, signal.SIGTERM)
    except ProcessLookupError:
        process.wait()
        return
    deadline = time.monotonic() + timeout
    while _group_alive(process) and time.monotonic() < deadline:
        time.sleep(POLL_S)
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
        check_recording(f)  # before serving or cutting: an unreadable file would show as an empty viewer
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
    part = parts[1] if start is not None else parts[0]
    layout = index.with_name(index.name.removesuffix(".segments.csv") + ".rbl") if index else None
    if layout is None or not layout.is_file():
        return part
    # `rrd split` leaves the part an empty layout: the session's own (live.rbl) goes back in
    window = work / "window.rrd"
    _rerun(["rrd", "merge", str(layout), str(part), "-o", str(window)], recording)
    return window


def _part_start(name: str, stem: str) -> float:
    """Start time of a `rerun rrd split` part, from its name <stem>_<start>__<end> (1_5s is 1.5 s), s."""
    match = re.fullmatch(r"(-?[\d_]+)(ns|us|µs|ms|s)", name[len(stem) + 1:].split("__")[0])
    if match is None:
        return -np.inf
    return float(match[1].replace("_", ".", 1)) * SPLIT_UNITS[match[2]]


def _rerun(args: list[str], recording: Path) -> None:
    """Run a `rerun` subcommand; a one-line error when it fails."""
    proc = subprocess.run([rerun_binary(), *args], capture_output=True, text=True, errors="replace", check=False,
                          env=rerun_env())
    if proc.returncode != 0:
        last = ANSI.sub("", (proc.stderr.strip().splitlines() or ["failed"])[-1])
        raise InputError(recording, f"rerun {args[0]} {args[1]}: {last}")
