"""Time from opening Rerun's web viewer to its first figure, in headless Chromium (software WebGL) at tablet size.

live: `topside live --web --speed 1` on a simulated scene (config2-procedure5, 4 cameras at 15 FPS, 920×600), the
page opened OPEN_AFTER_S into the session, for both --viewer-scope values (superintendent: the viewer gets only what
its layout shows; all: everything recorded).
recording: `topside view --web` on a 10-minute live recording (the scene looped through the live path, 1-minute
segments, the superintendent's layout): the whole of it, its last minute (--from), and one segment file alone.

Phases, in seconds from opening the page: the viewer running (its WebHandle), its state listing the layout's views
with capture-time data, and the first figure: every cone's bull's-eye ring drawn in its state colour (read from a
frame's pixels, the frames watched as the browser makes them: DevTools' screencast, which stamps each). Also: the
live viewer's lag behind the live clock when the figure shows (the clock from the session's first "<camera>: live"
line, printed with the first frame of the replay, capture time ~0). All on this machine's 2 cores, shared with the
tracker (and with whatever else runs: the load average is reported).

Run: .venv/bin/python -m benchmarks.web_first_figure [--repeats 3] [--screenshots docs]
     .venv/bin/python -m benchmarks.web_first_figure --late 60,180 [--scopes superintendent] [--busy-core]
Results: benchmarks/results/web_first_figure.md; web_late_open.md (web_late_open_busy.md with --busy-core)
"""

from __future__ import annotations

import argparse
import math
import os
import socket
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from benchmarks.report import write_results
from benchmarks.scenes import CACHE, render_scene
from tests.browser import TABLET, ViewerState, serving, web_viewer
from viewer.superintendent import ROOT

SCENARIO = "config2-procedure5"
CLIP_S = 20.0
RECORDING_MIN = 10.0
SEGMENT_S = 60.0
OPEN_AFTER_S = 4.0  # the tablet's page is opened this long into the live session
FOLLOW_S = 120.0  # --late: a page opened late has its lag sampled every SAMPLE_S for this long
SAMPLE_S = 10.0
LONG_FOLLOW_S = 600.0  # --long: the lag followed this long (the "staying there for ten minutes")
TIMEOUT_S = 120.0
TARGET_LIVE_S = 5.0
TOPSIDE = [sys.executable, "-m", "tracking.cli"]
# A 2560x1600 page at device scale 1. At device scale 2 (such a tablet's 1280x800 CSS pixels) headless Chromium gave
# Rerun's canvas 1280x800 pixels and its UI laid out in 640x400 points: everything twice as large, figures cut off.
LARGE_TABLET = {"width": 2560, "height": 1600}


@dataclass
class Timing:
    """One opening of the page: seconds from opening it to each phase (NaN: never within the timeout)."""

    case: str
    handle: float
    views: float
    figure: float  # when the browser made the first frame showing it
    lag: float = math.nan  # live: the live clock minus the viewer's newest capture time, when the figure showed
    renderer: str = ""
    note: str = ""


def free_port() -> int:
    """A TCP port nobody listens on."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def cones_of(rig: Path) -> list[str]:
    """The cones a rig's superintendent layout has a column for."""
    from tracking.rig import load_rig

    r = load_rig(rig)
    return r.all_cones()


def layout_ready(cones: list[str]) -> Callable[[ViewerState], bool]:
    """The viewer's state lists every cone's bull's-eye and has capture-time data."""
    wanted = {f"/{ROOT}/targets/{c}" for c in cones}
    return lambda s: wanted <= {o for _, _, o in s.views} and s.timelines.get("capture_time", (0, None))[1] is not None


def open_page(url: str, cones: list[str], case: str, viewport: dict[str, int] | None = None,
              shot: Path | None = None, live_start: float | None = None) -> Timing:
    """Open the page (at the tablet's size unless told) and time its phases; a screenshot of the figure when asked."""
    with web_viewer(url, viewport or TABLET) as page:
        page.page.wait_for_function("() => window._handle !== undefined", timeout=TIMEOUT_S * 1000)
        handle = time.monotonic() - page.opened
        page_renderer = page.renderer()
        try:
            views, _ = page.wait_for_state(layout_ready(cones), TIMEOUT_S)
            figure, _, _ = page.wait_for_rings(len(cones), TIMEOUT_S)
        except TimeoutError as exc:
            return Timing(case, handle, math.nan, math.nan, renderer=page_renderer, note=str(exc)[:80])
        lag = page.lag(live_start) if live_start is not None else math.nan
        if shot is not None:
            time.sleep(2.0)  # a later moment than the first figure: the images decoded, the trend begun
            page.screenshot(shot)
    return Timing(case, handle, views, figure, lag, page_renderer)


def live_runs(scene: Path, repeats: int, screenshots: Path | None) -> list[Timing]:
    """The page opened OPEN_AFTER_S into a live session, for each viewer scope."""
    out = []
    cones = cones_of(scene / "rig.yaml")
    for scope in ("superintendent", "all"):
        for k in range(repeats + (2 if screenshots is not None and scope == "superintendent" else 0)):
            work = CACHE / "web-first-figure" / f"live-{scope}-{k}-{os.getpid()}"
            cmd = [*TOPSIDE, "live", "--rig", str(scene / "rig.yaml"), "--web", "--speed", "1",
                   "--web-port", str(free_port()), "--grpc-port", str(free_port()), "--viewer-scope", scope,
                   "--rrd", str(work / "live.rrd")]
            with serving(cmd, "web viewer: ") as served:
                start = served.wait_printed(": live", TIMEOUT_S)  # a camera's first frame: capture time ~0
                time.sleep(OPEN_AFTER_S)  # into the replay
                shot, viewport = None, TABLET
                if screenshots is not None and scope == "superintendent" and k >= repeats:
                    viewport = TABLET if k == repeats else LARGE_TABLET
                    shot = screenshots / f"superintendent-tablet-{viewport['width']}x{viewport['height']}.png"
                size = f", {viewport['width']}×{viewport['height']}" if shot is not None else ""
                timing = open_page(served.url, cones,
                                   f"live, --viewer-scope {scope}{size}, page opened {OPEN_AFTER_S:g} s in",
                                   viewport, shot, start)
            out.append(timing)
            print(timing, flush=True)
            remove_tree(work)
    return out


@dataclass
class LateOpen:
    """A page opened late into a live session: its first figure, the past it was sent, its lag sampled after."""

    case: str
    figure: float  # s from opening to the first figure (NaN: never)
    history: float  # s of capture time the page held at its first figure (timeline end minus start)
    lags: list[tuple[float, float]]  # (s after opening, live clock minus the newest capture time shown)
    server_mb: float  # what the web server keeps for late pages (live's --server-memory-limit), MB
    cut: str = ""  # the session's line when it cut the viewer loose, if it did
    segments: tuple[int, int] = (0, 0)  # segment files written, and the session's length in whole minutes


def follow_lag(page, live_start: float, until: float) -> list[tuple[float, float]]:
    """The page's lag behind the live clock every SAMPLE_S until `until` (monotonic)."""
    out = []
    while (now := time.monotonic()) < until:
        out.append((now - page.opened, page.lag(live_start)))
        time.sleep(max(0.0, SAMPLE_S - (time.monotonic() - now)))
    return out


def late_runs(scene: Path, opens: list[float], scopes: list[str], follow_s: float = FOLLOW_S) -> list[LateOpen]:
    """The page opened at each of `opens` s into a live session of the scene looped, per scope; its lag followed."""
    from tracking.cli.live import server_bytes
    from tracking.cli.options import VIEW_IMAGE_RATE_DEFAULT, VIEW_IMAGE_WIDTH_DEFAULT, ViewerScope
    from tracking.rig import load_rig

    rig = load_rig(scene / "rig.yaml")
    cones = cones_of(scene / "rig.yaml")
    out = []
    for scope in scopes:
        for open_s in opens:
            work = CACHE / "web-first-figure" / f"late-{scope}-{open_s:g}-{os.getpid()}"
            cmd = [*TOPSIDE, "live", "--rig", str(scene / "rig.yaml"), "--web", "--speed", "1", "--loop",
                   "--web-port", str(free_port()), "--grpc-port", str(free_port()), "--viewer-scope", scope,
                   "--rrd", str(work / "live.rrd"), "--segment-minutes", "1"]
            case = f"{scope}, opened {open_s:g} s in"
            with serving(cmd, "web viewer: ") as served:
                start = served.wait_printed(": live", TIMEOUT_S)  # a camera's first frame: capture time ~0
                time.sleep(max(0.0, start + open_s - time.monotonic()))
                with web_viewer(served.url, TABLET) as page:
                    try:
                        figure, _, _ = page.wait_for_rings(len(cones), TIMEOUT_S)
                        span = page.state().timelines.get("capture_time", (None, None))
                        history = (span[1] - span[0]) / 1e9 if None not in span else math.nan
                    except TimeoutError:
                        figure, history = math.nan, math.nan
                    lags = follow_lag(page, start, page.opened + follow_s)
                cut = next((line.strip() for _, line in served.lines if "cut loose" in line), "")
                minutes = int((time.monotonic() - start) // 60)
            written = len(list(work.glob("live-[0-9][0-9][0-9].rrd")))  # every segment closed and renamed
            kept = server_bytes(rig, ViewerScope(scope), VIEW_IMAGE_RATE_DEFAULT, VIEW_IMAGE_WIDTH_DEFAULT)
            run = LateOpen(case, figure, history, lags, kept / 1e6, cut, (written, minutes))
            print(run, flush=True)
            out.append(run)
            remove_tree(work)
    return out


def late_lines(runs: list[LateOpen], longest: bool) -> list[str]:
    """The late-open table: first figure, past sent, lag at 30 s and the worst after it."""
    lines = ["## Pages opened late", "",
             "`--late`: `topside live --web --speed 1 --loop` on the scene, the page opened N s in and its lag "
             f"(the live clock minus the newest capture time it holds) sampled every {SAMPLE_S:g} s "
             f"for {FOLLOW_S:g} s{f' ({LONG_FOLLOW_S:g} s for the longest)' if longest else ''}. Past "
             "held: the capture time the page held at its first figure (newest first: what the server kept, "
             "viewer.playback.late_join_bytes, arrives after it). Target: first figure ≤ 10 s, lag ≤ 5 s within 30 s "
             "and after.", "",
             "| case | server keeps | first figure [s] | past held then [s] | lag at 30 s [s] | "
             "worst lag after 30 s [s] | segments written / minutes run | lags every 10 s [s] |",
             "|---|---:|---:|---:|---:|---:|---:|---|"]
    for r in runs:
        at30 = [lag for t, lag in r.lags if t >= 30.0]
        worst = max((lag for lag in at30 if math.isfinite(lag)), default=math.nan)
        lines.append(f"| {r.case} | {r.server_mb:.0f} MB | {fmt(r.figure)} | {fmt(r.history)} "
                     f"| {fmt(at30[0]) if at30 else '–'} | {fmt(worst)} | {r.segments[0]} / {r.segments[1]} "
                     f"| {' '.join(fmt(lag) for _, lag in r.lags)} |")
    cut = [f"- {r.case}: {r.cut}" for r in runs if r.cut]
    return lines + (["", *cut] if cut else [])


def remove_tree(path: Path) -> None:
    """A benchmark's own folder, gone."""
    import shutil

    shutil.rmtree(path, ignore_errors=True)


def ten_minute_recording(scene: Path) -> Path:
    """A 10-minute live recording of the scene looped (cached): the live path flat out, 1-minute segments."""
    from tracking.cli.live import LIVE_ESTIMATE_PERIOD_S
    from tracking.live import LiveTracker
    from tracking.rig import load_rig
    from viewer.session import Recorder

    folder = CACHE / f"web-recording-{SCENARIO}-{RECORDING_MIN:g}min"
    rrd = folder / "live.rrd"
    if (folder / "live.segments.csv").is_file():
        return rrd
    remove_tree(folder)
    rig = load_rig(scene / "rig.yaml")
    recorder = Recorder(rig, rrd, segment_s=SEGMENT_S, layout="superintendent",
                        estimate_period_s=LIVE_ESTIMATE_PERIOD_S)
    with LiveTracker(rig, speed=math.inf, loop_until=RECORDING_MIN * 60) as tracker:
        for update in tracker.updates():
            recorder.on_update(update)
    recorder.close()
    return rrd


def recording_runs(rrd: Path, cones: list[str], repeats: int) -> list[tuple[Timing, float, float]]:
    """`topside view --web` on the whole recording, its last minute, one segment: (timing, MB, server start s)."""
    segments = sorted(rrd.parent.glob(f"{rrd.stem}-*.rrd"))
    last_start = float(np.loadtxt(rrd.with_name(f"{rrd.stem}.segments.csv"), delimiter=",", skiprows=1,
                                  usecols=1)[-1])
    cases = [("10-minute recording, whole", [str(rrd)], sum(s.stat().st_size for s in segments)),
             ("10-minute recording, last minute (--from)", [str(rrd), "--from", f"{last_start:g}"],
              segments[-1].stat().st_size),
             ("one 1-minute segment file", [str(segments[len(segments) // 2])],
              segments[len(segments) // 2].stat().st_size)]
    out = []
    for case, args, size in cases:
        for _ in range(repeats):
            cmd = [*TOPSIDE, "view", *args, "--web", "--web-port", str(free_port()), "--grpc-port", str(free_port())]
            with serving(cmd, "http://") as served:
                timing = open_page("http://" + served.url, cones, case)
            print(timing, f"{size / 1e6:.0f} MB, server {served.up_s:.1f} s", flush=True)
            out.append((timing, size / 1e6, served.up_s))
    return out


def median(values: list[float]) -> float:
    """Median of the finite values (NaN when none)."""
    finite = [v for v in values if math.isfinite(v)]
    return float(np.median(finite)) if finite else math.nan


def fmt(v: float) -> str:
    """A time for the table, '–' for never."""
    return f"{v:.1f}" if math.isfinite(v) else "–"


def figure(runs: list[Timing]) -> str:
    """The first figure's median time."""
    return fmt(median([t.figure for t in runs]))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--screenshots", type=Path, default=None, help="save the tablet screenshots here")
    parser.add_argument("--skip-recording", action="store_true")
    parser.add_argument("--late", default="", help="only the late opens: seconds into the session, e.g. 60,180,1800")
    parser.add_argument("--scopes", default="superintendent,all")
    parser.add_argument("--long", type=float, default=None, help="with --late: one more open this many seconds in, "
                        "the first scope only (e.g. 1800: a page opened after half an hour)")
    parser.add_argument("--busy-core", action="store_true", help="with --late: one core kept busy by a spinning "
                        "process (as a second test worker, or a tablet slower than this machine)")
    args = parser.parse_args()
    scene = render_scene(SCENARIO, (920, 600), CLIP_S)
    if args.long is not None and not args.late:
        parser.error("--long goes with --late")
    if args.late:
        load = os.getloadavg()
        scopes = args.scopes.split(",")
        spinner = subprocess.Popen([sys.executable, "-c", "while True: pass"]) if args.busy_core else None
        try:
            runs = late_runs(scene, [float(v) for v in args.late.split(",")], scopes)
            if args.long is not None:
                runs += late_runs(scene, [args.long], scopes[:1], LONG_FOLLOW_S)
        finally:
            if spinner is not None:
                spinner.kill()
        busy = ", one of them kept busy by a spinning process" if args.busy_core else ""
        lines = ["# A page opened late into a live session", "",
                 f"{SCENARIO}, 4 cameras at 15 FPS, 920×600, looped; headless Chromium at {TABLET['width']}×"
                 f"{TABLET['height']}, software WebGL, on the same {os.cpu_count()} cores as the tracker{busy}; load "
                 f"average {load[0]:.1f} before, {os.getloadavg()[0]:.1f} after.", "",
                 *late_lines(runs, args.long is not None)]
        write_results("web_late_open_busy" if args.busy_core else "web_late_open", lines, echo=True)
        return
    load = os.getloadavg()
    live = live_runs(scene, args.repeats, args.screenshots)
    recorded = [] if args.skip_recording else recording_runs(ten_minute_recording(scene), cones_of(scene / "rig.yaml"),
                                                             args.repeats)
    load_after = os.getloadavg()
    renderers = sorted({t.renderer for t in live + [t for t, _, _ in recorded] if t.renderer})
    lines = ["# Time to the first figure in Rerun's web viewer", "",
             f"`benchmarks/web_first_figure.py --repeats {args.repeats}`: headless Chromium (Debian's) at "
             f"{TABLET['width']}×{TABLET['height']} CSS pixels, WebGL in software ({'; '.join(renderers)}), "
             f"rerun-sdk's web viewer; {SCENARIO}, 4 cameras at 15 FPS, 920×600. Seconds from opening the page, "
             f"medians of {args.repeats} (every run below). First figure: the first frame the browser made with "
             "every cone's bull's-eye ring drawn (DevTools' screencast). Live lag: the live clock (from the "
             "session's first `<camera>: live` line) minus the viewer's newest capture time, then. Target live: "
             f"≤ {TARGET_LIVE_S:g} s.", "",
             f"Machine: {os.cpu_count()} cores shared by the browser, the tracker (live) and other work; load "
             f"average {load[0]:.1f} before, {load_after[0]:.1f} after.", "",
             "| case | data | viewer running | views listed | first figure | live lag |",
             "|---|---:|---:|---:|---:|---:|"]
    for case in dict.fromkeys(t.case for t in live):
        runs = [t for t in live if t.case == case]
        lines.append(f"| {case} | stream | {fmt(median([t.handle for t in runs]))} "
                     f"| {fmt(median([t.views for t in runs]))} | {figure(runs)} "
                     f"| {fmt(median([t.lag for t in runs]))} |")
    for case in dict.fromkeys(t.case for t, _, _ in recorded):
        runs = [(t, mb, s) for t, mb, s in recorded if t.case == case]
        lines.append(f"| {case} (server up in {fmt(median([s for _, _, s in runs]))} s) | {runs[0][1]:.0f} MB "
                     f"| {fmt(median([t.handle for t, _, _ in runs]))} | {fmt(median([t.views for t, _, _ in runs]))} "
                     f"| {figure([t for t, _, _ in runs])} | |")
    lines += ["", "Every run:", "", "| case | viewer running | views listed | first figure | live lag | note |",
              "|---|---:|---:|---:|---:|---|"]
    for t in live + [t for t, _, _ in recorded]:
        lines.append(f"| {t.case} | {fmt(t.handle)} | {fmt(t.views)} | {figure([t])} | {fmt(t.lag)} | {t.note} |")
    write_results("web_first_figure", lines, echo=True)


if __name__ == "__main__":
    main()
