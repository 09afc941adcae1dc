"""`topside live`: every camera tracked live and fused, recorded in segments, and streamed to the superintendent's
view (a native or web Rerun viewer the tool starts) and to Foxglove.

A session never overwrites an earlier one's record, and however it ends (done, Ctrl-C, SIGTERM, a failure) it keeps
what was recorded under its final names and stops the viewer it started.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from tracking.cli.common import console, err_console, rig_inputs, warn_lines, warn_rig
from tracking.cli.options import (
    VIEW_IMAGE_RATE_DEFAULT,
    VIEW_IMAGE_WIDTH_DEFAULT,
    WEB_PORT_DEFAULT,
    Layout,
    ViewerScope,
    WebPortOption,
    finite,
)
from tracking.cli.track_summary import print_cones, warn_cones
from tracking.cone_tally import ConeTallies
from tracking.errors import InputError
from tracking.outputs import Outputs, check_outputs

if TYPE_CHECKING:
    import subprocess

    from tracking.estimate import ConeEstimate
    from tracking.live import LiveTracker
    from tracking.offsets_csv import OffsetsWriter
    from tracking.rig import Rig
    from viewer.foxglove_live import FoxgloveStream
    from viewer.session import Recorder
    from viewer.superintendent import ConeReading

CONES_PERIOD_S = 1.0  # the cones' line on a terminal changes at most this often (wall time): readable, and cheap
LIVE_SEGMENT_MIN = 1.0  # a minute a file: quick to open, and `topside view --from --to` picks the window
LIVE_ESTIMATE_PERIOD_S = 1 / 30  # the recording keeps a cone's estimates at up to 30 Hz (the CSV keeps all)
GRPC_PORT_DEFAULT = 9876  # viewer.playback.GRPC_PORT
FOXGLOVE_PORT_DEFAULT = 8765  # Foxglove's own default for a WebSocket server

RigOption = Annotated[Path, typer.Option(help="Rig file; each camera's source is a device index, a stream URL "
                                              "(rtsp://, http://) or a video file replayed at its frame rate.")]
RrdOption = Annotated[Path | None, typer.Option(help="Recording to write, in segments STEM-NNN.rrd (default: "
                                                     "live-DATE-TIME.rrd in recordings/).")]
OutOption = Annotated[Path | None, typer.Option("-o", "--out", help="Offsets CSV, written as they are measured "
                                                                    "(default: beside the recording).")]
SpawnOption = Annotated[bool, typer.Option("--spawn", help="Stream to a native viewer.")]
WebOption = Annotated[bool, typer.Option("--web", help="Serve the web viewer (a tablet on the stern).")]
BindOption = Annotated[str, typer.Option(help="Address (or host name) of this machine the viewer's servers listen on "
                                              "(--web, --spawn).")]
StaleOption = Annotated[float, typer.Option(help="Seconds after which a cone shows NO DATA.", callback=finite(0.0))]
SegmentOption = Annotated[float, typer.Option(help="Minutes of capture time per recording file.",
                                              callback=finite(0.0))]
SpeedOption = Annotated[float, typer.Option(help="Replay speed of video files (1: real time; inf: flat out).",
                                            callback=finite(0.0, allow_inf=True))]
DurationOption = Annotated[float | None, typer.Option(help="Stop after this many seconds of capture time.",
                                                      callback=finite(0.0))]
LoopOption = Annotated[bool, typer.Option("--loop", help="Replay video files again and again, capture times running "
                                                         "on, until --duration or Ctrl-C (soak tests).")]
LayoutOption = Annotated[Layout, typer.Option(help="Layout stored in the recording: superintendent or analysis.")]
ScopeOption = Annotated[ViewerScope, typer.Option(help="What the viewer (--web, --spawn) of the superintendent's "
                                                       "layout gets: superintendent (what it shows) or all "
                                                       "(everything recorded: for a workstation; a tablet's page "
                                                       "falls behind on it).")]
ViewImageRateOption = Annotated[float, typer.Option(help="Pictures a second of each camera the superintendent's scope "
                                                          "sends the viewer, as JPEGs (0: its video, every frame: "
                                                          "about 8 times the bytes).", min=0.0, max=100.0)]
ViewImageWidthOption = Annotated[int, typer.Option(help="Width, px, the superintendent's scope scales its pictures "
                                                         "down to.", min=64, max=8192)]
GrpcPortOption = Annotated[int, typer.Option(help="Port of the viewer's gRPC server (--web, --spawn).", min=1,
                                             max=65535)]
FoxgloveOption = Annotated[bool, typer.Option("--foxglove", help="Stream the archive's channels to Foxglove (a "
                                                                 "WebSocket server, ws://<bind>:<port>).")]
PortOption = Annotated[int, typer.Option("--port", help="Port of the Foxglove WebSocket server (with --foxglove).",
                                         min=1, max=65535)]


def live(
    rig: RigOption,
    rrd: RrdOption = None,
    out: OutOption = None,
    spawn: SpawnOption = False,
    web: WebOption = False,
    bind: BindOption = "127.0.0.1",
    stale: StaleOption = 0.5,
    segment_minutes: SegmentOption = LIVE_SEGMENT_MIN,
    speed: SpeedOption = 1.0,
    duration: DurationOption = None,
    loop: LoopOption = False,
    layout: LayoutOption = Layout.SUPERINTENDENT,
    viewer_scope: ScopeOption = ViewerScope.SUPERINTENDENT,
    view_image_rate: ViewImageRateOption = VIEW_IMAGE_RATE_DEFAULT,
    view_image_width: ViewImageWidthOption = VIEW_IMAGE_WIDTH_DEFAULT,
    web_port: WebPortOption = WEB_PORT_DEFAULT,
    grpc_port: GrpcPortOption = GRPC_PORT_DEFAULT,
    foxglove: FoxgloveOption = False,
    port: PortOption = FOXGLOVE_PORT_DEFAULT,
) -> None:
    """Track every camera live, fuse them, record, and stream to the superintendent's view (and Foxglove)."""
    from tracking.rig import load_rig
    from tracking.sources import check_sources
    from viewer.playback import resolve_bind, start_live_viewer, web_viewer_url

    if spawn and web:
        raise InputError("--spawn/--web", "choose one viewer")
    the_rig = load_rig(rig)
    check_sources(the_rig)  # a missing or unreadable video, or files mixed with devices: refused before any file
    rrd, out = _session_files(the_rig, rrd, out)
    fox_address = _check_ports(bind, spawn, web, foxglove, port, grpc_port, web_port)
    warn_rig(the_rig)  # once the inputs are accepted: bad input stays the one line on stderr
    kept = server_bytes(the_rig, viewer_scope, view_image_rate, view_image_width) if web else None
    viewer_process = start_live_viewer(web, bind, grpc_port, web_port, kept) if spawn or web else None
    if web:
        console.print(f"web viewer: {web_viewer_url(resolve_bind(bind), grpc_port, web_port)}")
    session = LiveSession(the_rig, rrd, out, viewer_process=viewer_process, stale_s=stale)
    written = ""
    try:
        if fox_address is not None:
            session.fox = _foxglove(the_rig, fox_address, port, warn=not (spawn or web))
        replay_over = session.record(speed, duration, segment_minutes * 60, layout, viewer_scope, loop,
                                     view_image_rate, view_image_width)
        if replay_over and viewer_process is not None:  # the files ended: what they showed stays on view
            session.finish()
            written = session.written()
            session.print_summary()
            what = f"the web viewer keeps serving at {web_viewer_url(resolve_bind(bind), grpc_port, web_port)}" \
                if web else "the viewer keeps showing it"
            err_console.print(f"the replay has ended; {what} until Ctrl-C", markup=False)
            viewer_process.wait()  # Ctrl-C, SIGTERM, or the viewer's window closed
    except KeyboardInterrupt:
        if not written:
            err_console.print("stopped")
    finally:
        session.close()
    if not written:
        session.print_summary()


def server_bytes(rig: Rig, scope: ViewerScope, image_rate: float, image_width: int) -> int:
    """What the web server keeps for a page opened late (viewer.playback.late_join_bytes): the superintendent's
    scope sends pictures at image_rate and image_width (0: the videos), "all" the videos; each cone's figures."""
    from tracking.sources import byte_rate
    from viewer.playback import late_join_bytes
    from viewer.session import view_bytes_per_s

    rates = [byte_rate(rig, c) for c in rig.cameras]
    pictures = scope == ViewerScope.SUPERINTENDENT and image_rate > 0
    if scope == ViewerScope.SUPERINTENDENT:
        rates = [view_bytes_per_s(r, image_rate, image_width) for r in rates]
    return late_join_bytes(rates, scope.value, len(rig.all_cones()), videos=not pictures)


def _session_files(rig: Rig, rrd: Path | None, out: Path | None) -> tuple[Path, Path]:
    """The recording and the offsets CSV (defaults: recordings/live-<date>-<time>.rrd, the CSV beside it), checked
    to be writable and not an earlier session's record."""
    rrd = rrd or Path("recordings") / f"live-{time.strftime('%Y%m%d-%H%M%S')}.rrd"
    out = out or rrd.with_name(f"{rrd.stem}-offsets.csv")
    check_outputs({"--out": out, "--rrd": rrd}, rig_inputs(rig))
    for path, option in ((out, "--out"), (rrd.with_name(f"{rrd.stem}.segments.csv"), "--rrd"),
                         (rrd.with_name(f"{rrd.stem}-000.rrd"), "--rrd")):
        if path.exists():
            raise InputError(path, "exists (an earlier session's record; a live session never overwrites one): "
                                   "expected another name", option)
    return rrd, out


def _check_ports(bind: str, spawn: bool, web: bool, foxglove: bool, port: int, grpc_port: int, web_port: int
                 ) -> str | None:
    """Every port the session's servers will listen on checked free before anything starts; the Foxglove server's
    address (None without --foxglove)."""
    from viewer.playback import check_port_free, resolve_bind

    fox_address = resolve_bind(bind) if foxglove else None
    if fox_address is not None:
        check_port_free(fox_address, port, "--port")
    if spawn or web:
        check_port_free(resolve_bind(bind), grpc_port, "--grpc-port")
    if web:
        check_port_free(resolve_bind(bind), web_port, "--web-port")
    return fox_address


def _foxglove(rig: Rig, address: str, port: int, warn: bool) -> FoxgloveStream:
    """The Foxglove WebSocket server, its URL printed; warn: say when it listens beyond this machine (the viewers
    warn for themselves)."""
    from viewer.foxglove_live import FoxgloveStream
    from viewer.playback import url_host, warn_if_exposed

    if warn:
        warn_if_exposed(address)
    fox = FoxgloveStream(rig, address, port)
    console.print(f"foxglove: ws://{url_host(address)}:{fox.port}", markup=False)
    return fox


@dataclass
class LiveSession:
    """A live session's parts, each ended by close however the session ends: the recording, the offsets CSV (renamed
    onto its final name), the viewer the tool started and the Foxglove server."""

    rig: Rig
    rrd: Path
    out: Path
    outputs: Outputs = field(default_factory=Outputs)
    viewer_process: subprocess.Popen | None = None
    stale_s: float = 0.5  # a cone's newest measurement older than this: NO DATA
    fox: FoxgloveStream | None = None
    recorder: Recorder | None = None
    writer: OffsetsWriter | None = None
    finished: bool = False  # the recording closed and the files under their final names
    duration_over: bool = False  # the session ended after its --duration (not because its sources did)
    tally: ConeTallies = field(default_factory=ConeTallies)  # what each cone showed, and why not

    @property
    def rows(self) -> int:
        """Offsets written so far."""
        return self.writer.rows if self.writer is not None else 0

    def record(self, speed: float, duration: float | None, segment_s: float, layout: Layout,
               viewer_scope: ViewerScope, loop: bool = False, view_image_rate: float = 0.0,
               view_image_width: int = 640) -> bool:
        """Track every camera (video files replayed at speed, again and again with loop) until duration s of capture
        time (None: until stopped) into the recording, in segment_s files and streamed to the viewer the tool started
        (through its stdin, never waited for), and the offsets CSV; the cones on a line of the terminal. True when
        it ended because its sources did (a replay's files), False after duration."""
        from tracking.live import LiveTracker
        from tracking.offsets_csv import OffsetsWriter
        from viewer.feed import ViewerFeed
        from viewer.session import Recorder

        feed = None
        if self.viewer_process is not None and self.viewer_process.stdin is not None:
            feed = ViewerFeed(self.viewer_process.stdin)
        self.recorder = Recorder(self.rig, self.rrd, viewer=feed, segment_s=segment_s, stale_s=self.stale_s,
                                 layout=layout.value, estimate_period_s=LIVE_ESTIMATE_PERIOD_S,
                                 viewer_scope=viewer_scope.value, forward=[self.fox] if self.fox is not None else [],
                                 view_image_rate=view_image_rate, view_image_width=view_image_width)
        with OffsetsWriter(self.outputs.claim(self.out)) as self.writer:
            console.print(f"recording to {self.rrd.with_name(self.rrd.stem + '-*.rrd')} and {self.writer.path} "
                          f"(renamed {self.out.name} when the session ends)", markup=False, soft_wrap=True)
            with LiveTracker(self.rig, speed=speed, loop_until=math.inf if loop else None) as tracker, \
                    ConesLine(self.stale_s) as cones:
                console.print(f"live: {len(tracker.names)} cameras; Ctrl-C stops and keeps everything recorded")
                estimates = self._estimates(tracker, duration, cones)
                for e in estimates:
                    self.writer.write(e)
                    self.tally.add(e)
                return not self.duration_over

    def _estimates(self, tracker: LiveTracker, duration: float | None, cones: ConesLine) -> Iterator[ConeEstimate]:
        """The fused estimates as the cameras' frames come, each update recorded, its camera events and frames'
        warnings printed and the cones' line refreshed when due; they end after duration s of capture time."""
        start = None  # capture time of the first frame
        assert self.recorder is not None
        for update in tracker.updates():
            self.recorder.on_update(update)
            for event in update.events:
                err_console.print(f"{event.camera}: {event.state}" + (f" ({event.detail})" if event.detail else ""))
            yield from update.estimates
            for result in update.results:
                warn_lines(result.warnings)
                for m in result.measurements:
                    self.tally.measured(m)
            cones.show(self.recorder.readings)
            if update.results:
                start = update.results[0].time if start is None else start
                if duration is not None and update.results[-1].time - start >= duration:
                    self.duration_over = True
                    return

    def written(self) -> str:
        """The line saying what the session wrote."""
        return f"wrote {self.rows} rows to {self.out}; recording {self.rrd.with_name(self.rrd.stem + '-*.rrd')}"

    def print_summary(self) -> None:
        """What the session wrote, each cone's share shown and why not (track's cones table and warnings)."""
        console.print(self.written(), markup=False)
        print_cones(self.tally)
        warn_cones(self.tally)

    def finish(self) -> None:
        """Close the recording and keep what was measured under its final names (the viewer stays)."""
        if self.finished:
            return
        self.finished = True
        try:
            if self.recorder is not None:
                self.recorder.close()
        finally:
            self.outputs.commit()

    def close(self) -> None:
        """Close the recording, keep what was measured under its final names (the record of the lift, however the
        session ended), and stop the viewer and the Foxglove server."""
        from viewer.playback import stop_viewer

        try:
            self.finish()
        finally:
            if self.viewer_process is not None:  # the viewers the tool starts end with it
                stop_viewer(self.viewer_process)
            if self.fox is not None:
                self.fox.close()


class ConesLine:
    """Every cone's reading on the terminal during a live session, as the superintendent's view has it (the offsets
    in mm, or NO DATA and why), so an operator whose tablet fails still sees them: on a terminal one line kept under
    the camera events, rewritten at most every CONES_PERIOD_S; in a log, a timestamped line every progress
    interval (10 s)."""

    def __init__(self, stale_s: float) -> None:
        from rich.live import Live

        from tracking.cli.common import progress_interval

        self.stale_s = stale_s
        terminal = err_console.is_terminal
        self.period_s = CONES_PERIOD_S if terminal else progress_interval()
        self.live = Live(console=err_console, auto_refresh=False, transient=True) if terminal else None
        self.shown = -math.inf
        self.text = ""

    def __enter__(self) -> ConesLine:
        if self.live is not None:
            self.live.start()
        return self

    def __exit__(self, *exc: object) -> None:
        if self.live is not None:
            self.live.stop()
            if self.text:  # the last reading stays on the terminal
                err_console.print(self.text, markup=False)

    def show(self, readings: Callable[[], Sequence[ConeReading]]) -> None:
        """The cones' line from readings(), when one is due."""
        from rich.text import Text

        from tracking.cli.common import stamp
        from viewer.superintendent import cones_line

        now = time.monotonic()
        if now - self.shown < self.period_s:
            return
        found = readings()
        if not found:
            return
        self.shown = now
        self.text = f"cones: {cones_line(found, self.stale_s)}"
        if self.live is not None:
            self.live.update(Text(self.text), refresh=True)
        else:
            err_console.print(f"{stamp()} topside: {self.text}", markup=False)
