"""The superintendent's view in a real browser: `topside live --web` opened by headless Chromium at tablet size."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.browser import chromium, serving, stopped_after, web_viewer
from tests.viewer.test_playback import free_port
from viewer.superintendent import ROOT

START_TIMEOUT_S = 90.0
PAGE_TIMEOUT_S = 60.0  # the viewer's 43 MB of WebAssembly, compiled and run on a loaded 2-core machine in software GL


@pytest.mark.skipif(chromium() is None, reason="no chromium binary (apt-get install chromium; .ci/run does)")
def test_the_live_web_view_shows_every_cone_panel_on_a_tablet(installation: Path, tmp_path: Path) -> None:
    web_port, grpc_port = free_port(), free_port()
    proc = subprocess.Popen([sys.executable, "-m", "tracking.cli", "live", "--rig", str(installation / "rig.yaml"),
                             "--rrd", str(tmp_path / "live.rrd"), "--web", "--web-port", str(web_port),
                             "--grpc-port", str(grpc_port), "--speed", "0.03"],  # 0.8 s of video over 27 s: its cone
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)  # shown for its last 0.2 s (7 s)
    with stopped_after(proc) as output:
        deadline = time.monotonic() + START_TIMEOUT_S
        line = ""
        while "web viewer: http" not in line and time.monotonic() < deadline and proc.poll() is None:
            line = proc.stdout.readline()
        assert f"127.0.0.1:{web_port}" in line, proc.stderr.read() if proc.poll() is not None else line
        url = line.split("web viewer: ", 1)[1].strip()
        with web_viewer(url) as page:
            column = {f"/{ROOT}/cones/A", f"/{ROOT}/targets/A", f"/{ROOT}/trend/A"}
            t_views, state = page.wait_for_state(
                lambda s: column <= {origin for _, _, origin in s.views}
                and s.timelines.get("capture_time", (None, None))[1] is not None, PAGE_TIMEOUT_S)
            _, t_ring, image = page.wait_for_rings(1, PAGE_TIMEOUT_S)  # a state ring (TimeoutError without one)
            page.screenshot(tmp_path / "tablet.png")
        assert {name for _, name, _ in state.views} >= {"cone A", "cameras"}
        assert image.shape[:2] == (800, 1280)  # a 10-inch tablet's page
        assert t_views <= t_ring <= PAGE_TIMEOUT_S
    assert proc.returncode in (0, 130), output[0]



@pytest.mark.skipif(chromium() is None, reason="no chromium binary (apt-get install chromium; .ci/run does)")
def test_a_window_of_a_live_recording_opens_with_the_superintendents_layout(installation: Path,
                                                                            tmp_path: Path) -> None:
    proc = subprocess.run([sys.executable, "-m", "tracking.cli", "live", "--rig", str(installation / "rig.yaml"),
                           "--rrd", str(tmp_path / "live.rrd"), "--speed", "inf", "--segment-minutes", str(0.25 / 60)],
                          capture_output=True, text=True, timeout=180)
    assert proc.returncode == 0, proc.stderr
    web_port, grpc_port = free_port(), free_port()
    view = subprocess.Popen([sys.executable, "-m", "tracking.cli", "view", str(tmp_path / "live.rrd"), "--from",
                             "100.3", "--web", "--web-port", str(web_port), "--grpc-port", str(grpc_port)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)  # cut inside a segment
    with stopped_after(view) as output:
        url = view.stdout.readline().strip()
        assert url.startswith(f"http://127.0.0.1:{web_port}/"), view.stderr.read() if view.poll() else url
        with web_viewer(url) as page:  # `rrd split` alone left the window an empty layout: no view at all
            _, state = page.wait_for_state(lambda s: f"/{ROOT}/targets/A" in {o for _, _, o in s.views},
                                           PAGE_TIMEOUT_S)
        assert {"cone A", "cameras"} <= {name for _, name, _ in state.views}
    assert view.returncode in (0, 130), output[0]


LATE_OPEN_S = 14.0  # issue 37: a tablet opened a minute into a set-down showed the installation that far back; the
# server keeps LATE_JOIN_S of the past, so a page opened this late meets what one opened hours in does
LAG_LIMIT_S = 5.0  # the view's lag behind the live clock, within ...
LAG_WITHIN_S = 90.0  # ... this long of opening the page: that it catches up, not how fast (a timed claim is the
# benchmark's: web_first_figure.py --late). With a spinning process on the second core, a page drawing in software
# came within 5 s 19 s after opening; in a full suite's run, still 5.4 s behind at 30 s


@pytest.mark.skipif(chromium() is None, reason="no chromium binary (apt-get install chromium; .ci/run does)")
def test_a_page_opened_late_into_a_live_session_shows_the_present(installation: Path, tmp_path: Path) -> None:
    from tests.conftest import T0
    from viewer.playback import LATE_JOIN_S

    assert LATE_OPEN_S > 2 * LATE_JOIN_S  # the server has dropped the oldest of what it was sent
    web_port = free_port()
    cmd = [sys.executable, "-m", "tracking.cli", "live", "--rig", str(installation / "rig.yaml"), "--rrd",
           str(tmp_path / "live.rrd"), "--web", "--web-port", str(web_port), "--grpc-port", str(free_port()),
           "--speed", "1", "--loop"]
    with serving(cmd, "web viewer: ", START_TIMEOUT_S) as served:
        assert f"127.0.0.1:{web_port}" in served.url
        started = served.wait_printed(": live", START_TIMEOUT_S)  # the first frame, of capture time T0
        time.sleep(LATE_OPEN_S)
        with web_viewer(served.url) as page:
            page.wait_for_rings(1, PAGE_TIMEOUT_S)
            lags = [page.lag(started, T0)]
            while not lags[-1] <= LAG_LIMIT_S and time.monotonic() - page.opened < LAG_WITHIN_S:
                time.sleep(1.0)
                lags.append(page.lag(started, T0))
        assert served.process.poll() is None  # the session runs on
        assert -1.0 <= lags[-1] <= LAG_LIMIT_S, f"lag behind the live clock, every second: {lags}"
    assert served.process.returncode in (0, 130), "".join(line for _, line in served.lines[-80:])
