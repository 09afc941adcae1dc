"""Rerun's web viewer in a real browser: headless Chromium (Debian's) driven by Playwright, read through the viewer's
own state (the page's WebHandle.viewer_state(), Rerun's Viewer Control API) and its pixels.

Used by tests/viewer/test_web_viewer.py and benchmarks/web_first_figure.py. Never `playwright install`: it downloads
a browser of its own; this drives the system's chromium (apt-get install chromium).
"""

from __future__ import annotations

import base64
import math
import shutil
import signal
import subprocess
import tempfile
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from itertools import pairwise
from pathlib import Path

import cv2
import numpy as np

CHROMIUM_CANDIDATES = ("/usr/bin/chromium", "chromium", "chromium-browser")
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-quic", "--no-first-run", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync"]
# WebGL in software (no GPU here): Mesa's llvmpipe through ANGLE when Mesa's EGL is installed (libegl-mesa0,
# libgl1-mesa-dri), else Chromium's SwiftShader. llvmpipe drew the first figure in about half SwiftShader's time.
LLVMPIPE_ARGS = ["--use-gl=angle", "--use-angle=gl-egl", "--ignore-gpu-blocklist"]
SWIFTSHADER_ARGS = ["--disable-gpu", "--use-angle=swiftshader", "--enable-unsafe-swiftshader"]
MESA_EGL = ("/usr/lib/x86_64-linux-gnu/libEGL_mesa.so.0", "/usr/lib/aarch64-linux-gnu/libEGL_mesa.so.0",
            "/usr/lib64/libEGL_mesa.so.0")
# With a DevTools client attached (Playwright), every console message is serialised to it: the viewer's DEBUG log
# (whole shader sources) took 3 of its first 6 s. A tablet's browser has no client attached; the page's console.debug
# is silenced so that the measurements see what a tablet does.
QUIET_CONSOLE = "console.debug = () => {};"
STATE_COLORS = ((40, 200, 80), (255, 170, 0), (230, 40, 40), (140, 140, 140))  # viewer.superintendent TARGET_COLORS
RING_MIN_PX = 300  # a drawn state ring covers ~1200 px at 1280x800; its exact colour, nowhere else on the page
POLL_S = 0.1
TABLET = {"width": 1280, "height": 800}  # CSS pixels of a 10-inch tablet (a 2560x1600 one at device scale 2)


def software_gl() -> str:
    """'llvmpipe' when Mesa's EGL is installed, else 'swiftshader'."""
    return "llvmpipe" if any(Path(p).is_file() for p in MESA_EGL) else "swiftshader"


def chromium_args(gl: str | None = None) -> list[str]:
    """Chromium's command-line flags for a headless run with software WebGL (llvmpipe or swiftshader)."""
    return CHROMIUM_ARGS + (LLVMPIPE_ARGS if (gl or software_gl()) == "llvmpipe" else SWIFTSHADER_ARGS)


def chromium() -> str | None:
    """The system's Chromium executable, or None."""
    for candidate in CHROMIUM_CANDIDATES:
        found = shutil.which(candidate)
        if found:
            return found
    return None


def _varint(data: bytes, i: int) -> tuple[int, int]:
    value = shift = 0
    while True:
        byte = data[i]
        i += 1
        value |= (byte & 0x7F) << shift
        shift += 7
        if byte < 0x80:
            return value, i


def protobuf_fields(data: bytes) -> list[tuple[int, int | bytes]] | None:
    """A protobuf message's fields in wire order (number, varint or bytes), or None when data is not one."""
    out: list[tuple[int, int | bytes]] = []
    i = 0
    try:
        while i < len(data):
            key, i = _varint(data, i)
            number, wire = key >> 3, key & 7
            if number == 0:
                return None
            if wire == 0:
                value, i = _varint(data, i)
            elif wire in (1, 5):
                size = 8 if wire == 1 else 4
                value, i = data[i:i + size], i + size
            elif wire == 2:
                size, i = _varint(data, i)
                value, i = data[i:i + size], i + size
            else:
                return None
            if i > len(data):
                return None
            out.append((number, value))
    except IndexError:
        return None
    return out


def _text(value: int | bytes) -> str:
    return value.decode(errors="replace") if isinstance(value, bytes) else str(value)


def _signed(value: int | bytes) -> int:
    """An int64 field's value (negative numbers travel as their 64-bit two's complement)."""
    value = int.from_bytes(value, "little") if isinstance(value, bytes) else value
    return value - (1 << 64) if value >= 1 << 63 else value


@dataclass
class ViewerState:
    """What the web viewer reports (GetStateResponse of Rerun's Viewer Control API, decoded by field number)."""

    views: list[tuple[str, str, str]] = field(default_factory=list)  # (class, name, origin)
    timelines: dict[str, tuple[int | None, int | None]] = field(default_factory=dict)  # name -> (start, end)

    @classmethod
    def decode(cls, data: bytes) -> ViewerState:
        """From the bytes of WebHandle.viewer_state(): views (field 5: id, class, name, origin) and the active
        recording's timelines (field 3.3: name, type, range)."""
        state = cls()
        for number, value in protobuf_fields(data) or []:
            sub = protobuf_fields(value) if isinstance(value, bytes) else None
            if sub is None:
                continue
            if number == 5:
                f = dict(sub)
                state.views.append((_text(f.get(2, b"")), _text(f.get(3, b"")), _text(f.get(4, b""))))
            elif number == 3:  # the active recording: its timelines (field 2: name, type, range start/end)
                for n, timeline in sub:
                    t = protobuf_fields(timeline) if n == 2 and isinstance(timeline, bytes) else None
                    if not t:
                        continue
                    f = dict(t)
                    name = dict(protobuf_fields(f[1]) or []).get(1, b"") if isinstance(f.get(1), bytes) else b""
                    span = dict(protobuf_fields(f[3]) or []) if isinstance(f.get(3), bytes) else None
                    state.timelines[_text(name)] = ((_signed(span.get(1, 0)), _signed(span[2]) if 2 in span else None)
                                                    if span is not None else (None, None))
        return state

    def view_names(self) -> set[str]:
        """The display names of every view."""
        return {name for _, name, _ in self.views}


@dataclass
class Browser:
    """A page of the web viewer, with the time it was opened (monotonic)."""

    page: object  # playwright.sync_api.Page
    opened: float = 0.0  # monotonic
    opened_epoch: float = 0.0  # wall clock (the screencast's frames carry wall-clock times)

    def state(self) -> ViewerState:
        """The viewer's state now (empty until the viewer has started)."""
        raw = self.page.evaluate("() => window._handle ? Array.from(window._handle.viewer_state()) : []")
        return ViewerState.decode(bytes(raw))

    def renderer(self) -> str:
        """The WebGL renderer the page gets (e.g. llvmpipe, SwiftShader)."""
        return self.page.evaluate("""() => {
            const gl = document.createElement('canvas').getContext('webgl2');
            const info = gl && gl.getExtension('WEBGL_debug_renderer_info');
            return info ? gl.getParameter(info.UNMASKED_RENDERER_WEBGL) : 'none'; }""")

    def screenshot(self, path: Path | None = None) -> np.ndarray:
        """The page as RGB (H, W, 3), saved as PNG too when a path is given."""
        png = self.page.screenshot(path=str(path) if path is not None else None)
        return cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)[:, :, ::-1]

    def lag(self, live_start: float, first_capture: float = 0.0) -> float:
        """The live clock minus the newest capture time the page holds, s (NaN before it holds any): live_start is
        when the session's first frame, of capture time first_capture, came (monotonic)."""
        end = self.state().timelines.get("capture_time", (None, None))[1]
        return time.monotonic() - live_start - (end / 1e9 - first_capture) if end is not None else math.nan

    def wait_for_state(self, ready, timeout: float) -> tuple[float, ViewerState]:
        """Poll the viewer's state until ready(state); (seconds since the page was opened, the state)."""
        deadline = time.monotonic() + timeout
        while True:
            state = self.state()
            if ready(state):
                return time.monotonic() - self.opened, state
            if time.monotonic() > deadline:
                raise TimeoutError(f"the viewer's state never became ready: views {sorted(state.view_names())}, "
                                   f"timelines {state.timelines}")
            time.sleep(POLL_S)

    def wait_for_rings(self, columns: int, timeout: float) -> tuple[float, float, np.ndarray]:
        """Watch the page's frames as the compositor makes them (DevTools screencast) until each of `columns` equal
        columns shows a bull's-eye ring in a state colour: (seconds from opening the page to that frame, to its
        arrival here, the frame as RGB)."""
        cdp = self.page.context.new_cdp_session(self.page)
        frames: list[tuple[float, float, bytes]] = []  # (made, wall time, epoch s), (arrived, monotonic), PNG

        def on_frame(event: dict) -> None:
            frames.append((event["metadata"].get("timestamp", time.time()), time.monotonic(),
                           base64.b64decode(event["data"])))
            cdp.send("Page.screencastFrameAck", {"sessionId": event["sessionId"]})

        cdp.on("Page.screencastFrame", on_frame)
        cdp.send("Page.startScreencast", {"format": "png", "everyNthFrame": 1})
        deadline = time.monotonic() + timeout
        seen = 0
        try:
            while time.monotonic() < deadline:
                self.page.wait_for_timeout(POLL_S * 1000)  # lets Playwright deliver the frames' events
                for made, arrived, png in frames[seen:]:
                    image = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)[:, :, ::-1]
                    if all(n >= RING_MIN_PX for n in ring_pixels(image, columns)):
                        return made - self.opened_epoch, arrived - self.opened, image
                seen = len(frames)
        finally:
            cdp.send("Page.stopScreencast")
            cdp.detach()
        last = ring_pixels(self.screenshot(), columns)
        raise TimeoutError(f"no state ring in every column: {last} px")


@dataclass
class Served:
    """A topside command serving the viewer: its process, URL, and every line it printed with its time."""

    process: subprocess.Popen
    url: str
    up_s: float  # seconds from the start until it printed the URL
    lines: list[tuple[float, str]]  # (monotonic time, line)

    def printed(self, prefix: str = "", suffix: str = "") -> float | None:
        """When it first printed a line with this start and end (monotonic), or None."""
        return next((t for t, line in self.lines if line.startswith(prefix) and line.rstrip().endswith(suffix)),
                    None)

    def wait_printed(self, suffix: str, timeout: float) -> float:
        """When it printed a line ending so (monotonic), waited for; RuntimeError with its output if it ends or the
        timeout passes first."""
        deadline = time.monotonic() + timeout
        while (at := self.printed(suffix=suffix)) is None:
            if self.process.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"no line ending {suffix!r}: {''.join(t for _, t in self.lines)}")
            time.sleep(0.05)
        return at


def stop(proc: subprocess.Popen, timeout: float = 60.0) -> str:
    """SIGTERM a topside command started with pipes, then SIGKILL if it has not ended within timeout s (after
    SIGUSR1, on which topside prints every thread's stack): the tail of what it printed, to name where it hung."""
    proc.send_signal(signal.SIGTERM)
    try:
        out, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        if proc.poll() is None:
            proc.send_signal(signal.SIGUSR1)
            time.sleep(2.0)
            proc.kill()
            note = f"(killed {timeout:.0f} s after SIGTERM)"
        else:
            note = "(it ended; a process it started kept its output open)"
        try:
            out, err = proc.communicate(timeout=10.0)
        except subprocess.TimeoutExpired as exc:  # that process still holds the pipes: what came, and let go
            out, err = _text(exc.stdout), _text(exc.stderr)
            for pipe in (proc.stdout, proc.stderr):
                if pipe is not None:
                    pipe.close()
        err = f"{note}\n{err or ''}"
    return f"{(out or '')[-2000:]}{(err or '')[-6000:]}"


@contextmanager
def stopped_after(proc: subprocess.Popen) -> Iterator[list[str]]:
    """The block, then stop(proc); what it printed in the list yielded, and under any failure of the block."""
    output: list[str] = []
    try:
        yield output
    except Exception as exc:
        output.append(stop(proc))
        exc.add_note(f"the session printed:\n{output[0]}")
        raise
    finally:
        if not output:
            output.append(stop(proc))


def _text(data: bytes | str | None) -> str:
    """A pipe's partial output, as text."""
    return data.decode(errors="replace") if isinstance(data, bytes) else (data or "")


@contextmanager
def serving(cmd: list[str], marker: str, timeout: float = 120.0) -> Iterator[Served]:
    """A topside command printing a URL after `marker` within timeout s; its output (stdout and stderr) read and
    timed on, so a full pipe never stops it; SIGTERM after, then SIGKILL if it has not ended within 60 s."""
    stopping: list[Exception] = []
    t0 = time.monotonic()
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    lines: list[tuple[float, str]] = []

    def read() -> None:
        for line in proc.stdout:
            lines.append((time.monotonic(), line))

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    try:
        while not any(marker in line for _, line in lines):
            if proc.poll() is not None or time.monotonic() - t0 > timeout:
                raise RuntimeError(f"{' '.join(cmd)} printed no {marker!r} ({proc.returncode}): "
                                   f"{''.join(t for _, t in lines)}")
            time.sleep(0.02)
        t_url, line = next((t, line) for t, line in lines if marker in line)
        url = line.split(marker, 1)[1].strip().strip('"')
        yield Served(proc, url, t_url - t0, lines)
    except Exception as exc:  # what the command printed, under the failure (stacks too, if it had to be killed)
        stopping.append(exc)
        raise
    finally:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(timeout=60)
        except subprocess.TimeoutExpired:  # where it hangs, in its output: topside dumps its stacks on SIGUSR1
            proc.send_signal(signal.SIGUSR1)
            time.sleep(2.0)
            proc.kill()
            proc.wait()
        reader.join(timeout=10)
        for exc in stopping:
            exc.add_note("the command printed:\n" + "".join(text for _, text in lines[-80:]))


def ring_pixels(image: np.ndarray, columns: int) -> list[int]:
    """Pixels of exactly a state colour in each of `columns` equal vertical strips of an RGB image."""
    mask = np.zeros(image.shape[:2], dtype=bool)
    for color in STATE_COLORS:
        mask |= np.all(image == np.array(color, dtype=np.uint8), axis=2)
    edges = np.linspace(0, image.shape[1], columns + 1).astype(int)
    return [int(mask[:, a:b].sum()) for a, b in pairwise(edges)]


@contextmanager
def web_viewer(url: str, viewport: dict[str, int] | None = None, scale: float = 1.0,
               executable: str | None = None, gl: str | None = None) -> Iterator[Browser]:
    """Headless Chromium (a fresh profile, software WebGL: gl or software_gl()) on the viewer's page, its
    console.debug silenced; closed however the block ends."""
    from playwright.sync_api import sync_playwright

    executable = executable or chromium()
    if executable is None:
        raise FileNotFoundError("no chromium executable (apt-get install chromium)")
    with sync_playwright() as p, tempfile.TemporaryDirectory(prefix="topside-chromium-") as profile:
        context = p.chromium.launch_persistent_context(
            profile, executable_path=executable, headless=True, args=chromium_args(gl),
            viewport=viewport or TABLET, device_scale_factor=scale)
        try:
            page = context.pages[0] if context.pages else context.new_page()
            page.add_init_script(QUIET_CONSOLE)
            browser = Browser(page, time.monotonic(), time.time())
            page.goto(url)
            yield browser
        finally:
            context.close()


@dataclass
class StaticPage:
    """A file opened offline: what it looked like, what it asked the network for, what it said on its console."""

    image: np.ndarray  # RGB (H, W, 3), the whole page
    requests: list[str]  # every URL it asked for beyond the file itself (each refused)
    console: list[str]
    text: str  # the page's visible text


def open_offline(path: Path, out: Path | None = None, width: int = 1100, executable: str | None = None) -> StaticPage:
    """Open a local HTML file in headless Chromium with every network request refused and recorded; screenshot the
    whole page (to out as PNG too)."""
    from playwright.sync_api import sync_playwright

    executable = executable or chromium()
    if executable is None:
        raise FileNotFoundError("no chromium executable (apt-get install chromium)")
    url = Path(path).resolve().as_uri()
    requests: list[str] = []
    console: list[str] = []

    def refuse(route: object) -> None:
        requested = route.request.url
        if requested == url or requested.startswith("data:"):
            route.continue_()
        else:
            requests.append(requested)
            route.abort()

    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=executable, headless=True, args=CHROMIUM_ARGS)
        try:
            page = browser.new_page(viewport={"width": width, "height": 800}, offline=True)
            page.route("**/*", refuse)
            page.on("console", lambda m: console.append(m.text))
            page.goto(url, wait_until="load")
            png = page.screenshot(path=str(out) if out is not None else None, full_page=True)
            text = page.inner_text("body")
        finally:
            browser.close()
    image = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)[:, :, ::-1]
    return StaticPage(image, requests, console, text)
