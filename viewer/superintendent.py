"""The superintendent's live view: per cone the offset in large figures, green/amber/red, NO DATA (grey) with why.

Every cone gets the same column, observed or not: figures, live image, bull's-eye, 60-s trend.
Entity layout:
    superintendent/cones/<cone>              markdown: state, concentricity ± 2σ and Δx Δy Δz in large figures
    superintendent/targets/<cone>            bull's-eye in mm, as seen from the vessel's stern facing the jacket:
                                             port to the right, astern (away from the vessel) up
        .../tolerance, .../compass           the ±150 mm circle and cross, the port/astern words (static)
        .../state                            the ring in the cone's state colour (grey: NO DATA)
        .../offset                           the cone's point (its radius is 2σ); beyond the ring, drawn on the ring
        .../beyond                           ... with an arrow pointing the way and the distance
        .../why                              NO DATA: the reason, in the middle
    superintendent/trend/<cone>              the last minute's concentricity, r + 2σ and 150 mm: three series, one
                                             entity (a chunk per batch, not three: what a late page takes first)
    superintendent/no_camera/<cone>          markdown in the image's place until a camera has measured the cone (a
                                             cone without markers: that none will, and where its offset comes from)
    superintendent/cameras                   markdown: every camera's state, frame rate, age and markers
The live image per cone is the 2-D view of the camera that measures that cone most.
Each part is logged with the same components every time (empty ones where it is gone), so that a batch of its rows is
one chunk: a web page opened late takes its backlog chunk by chunk before the present (viewer.playback.LATE_JOIN_S).
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from enum import StrEnum

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from tracking.estimate import (
    AXIS_NAMES,
    WITHHELD_BELOW,
    WITHHELD_CLOCKS,
    WITHHELD_COMPARING,
    WITHHELD_SCALE,
    WITHHELD_SIGMA,
    WITHHELD_WARMING,
    ConeEstimate,
    axes_above,
    sigma_text,
)
from tracking.estimator.noise import REPORT_MAX_SIGMA_M, REPORT_WARMUP_S, REPORT_WARMUP_SIGMA_SIDES
from tracking.live import STALE_S, CameraHealth
from tracking.rig import Rig
from tracking.sources import CameraState
from viewer.recording import TIMELINE, TOLERANCE_M, concentricity, set_capture_time

ROOT = "superintendent"
CONFIDENCE_SIGMAS = 2.0  # amber when the offset is inside the tolerance but its 2σ bound is not
CIRCLE_POINTS = 97
TOLERANCE_MM = TOLERANCE_M * 1000
TARGET_REACH = 1.6  # the bull's-eye spans this many tolerances each way: room for the arrow beyond the ring
ARROW_MM = 0.35 * TOLERANCE_MM  # a cone beyond the ring: an arrow this long from its point on the ring
MIN_DOT_MM = 8.0  # the cone's dot is its 2σ, but never smaller than this
STATE_RING_PX = 3.0  # the state ring's half-width, UI points (the same on every screen)
TREND_S = 60.0
VIEW_BEHIND_S = 3.0  # a view whose input is this far behind the live clock shows its cones grey: its figures are old
WALL_CLOCK_AFTER = 1e9  # capture times beyond this are Unix times (live cameras), shown as the time of day
WHY_Y_MM = 0.5 * TOLERANCE_MM  # NO DATA's reason: inside the ring, below its centre (clear of the compass words)
ARROW_PX = 2.5  # the arrow beyond the ring's half-width, UI points
NOWHERE = np.zeros((0, 2))  # an empty batch: the part is gone from the view from this time on
TARGET_COLORS = {"green": (40, 200, 80), "amber": (255, 170, 0), "red": (230, 40, 40), "none": (140, 140, 140)}
RING_COLOR = (200, 200, 200)
TOLERANCE_LINE_COLOR = (230, 40, 40)
BOUND_COLOR = (150, 150, 150)
TREND_COLOR = (40, 120, 230)  # reads on the web viewer's light theme and the native viewer's dark one
# Words, not emoji or arrows: the viewer's font (Inter) lacks them, and a missing glyph makes the native viewer panic.
CAMERA_WORDS = {CameraState.STARTING: "starting", CameraState.LIVE: "LIVE", CameraState.FROZEN: "FROZEN",
                CameraState.LOST: "LOST", CameraState.ENDED: "ended"}
ROW_SHARES = [3.5, 2.5, 4, 2]  # figures, image, bull's-eye, trend: the same in every column


class ConeState(StrEnum):
    """What the superintendent is told about a cone."""

    GREEN = "green"  # inside the tolerance, with margin
    AMBER = "amber"  # inside, but within 2σ of its edge
    RED = "red"  # outside the tolerance
    NO_DATA = "none"  # no estimate, or its newest measurement is too old


HEADLINES = {ConeState.GREEN: "in tolerance", ConeState.AMBER: "CHECK: at the edge",
             ConeState.RED: "OUTSIDE tolerance", ConeState.NO_DATA: "NO DATA"}


@dataclass(frozen=True)
class ConeReading:
    """One cone's reading for the superintendent."""

    cone: str
    state: ConeState
    concentricity: float  # horizontal distance of the cone from its target, m (NaN when unknown)
    sigma: float  # 1σ of the concentricity, m
    offset: np.ndarray  # (3,) Δx Δy Δz, m
    age: float  # now minus the newest accepted measurement, s
    cameras: tuple[str, ...]
    withheld: str = ""  # why the estimator withheld the offset (tracking.estimate.WITHHELD_*), when it says
    now: float = np.nan  # the live clock the reading was made at (capture time)
    behind: float = 0.0  # how far the view this reading is for is behind the live clock, s (viewer.feed)
    axis_sigma: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))  # (3,) m, the estimate's σ per axis
    # where it states one (for NO DATA: which axis its cameras do not see well enough)


def cone_reading(estimate: ConeEstimate | None, cone: str, now: float, last_measurement: float | None,
                 stale_s: float = STALE_S, behind: float = 0.0) -> ConeReading:
    """Classify a cone's newest estimate against the tolerance and its age; for a view behind the live clock by
    more than VIEW_BEHIND_S, NO DATA (its figures are that old)."""
    age = np.inf if last_measurement is None else max(0.0, now - last_measurement)
    late = behind > VIEW_BEHIND_S
    if estimate is None or not np.all(np.isfinite(estimate.offset[:2])) or age > stale_s or late:  # (Δz may be
        # withheld alone: the concentricity stands without it)
        offset = np.full(3, np.nan) if estimate is None else estimate.offset
        withheld = estimate.withheld if estimate is not None and age <= stale_s else ""
        axis_sigma = estimate.sigma if estimate is not None else np.full(3, np.nan)
        return ConeReading(cone, ConeState.NO_DATA, np.nan, np.nan, offset, age, (), withheld, now, behind, axis_sigma)
    dx, dy = estimate.offset[:2]
    r = concentricity(estimate.offset)
    cov = estimate.covariance[:2, :2] if estimate.covariance is not None else np.zeros((2, 2))
    u = np.array([dx, dy]) / r if r > 0 else np.array([1.0, 0.0])
    sigma = float(np.sqrt(max(u @ cov @ u, 0.0)))
    if r > TOLERANCE_M:
        state = ConeState.RED
    elif r + CONFIDENCE_SIGMAS * sigma > TOLERANCE_M:
        state = ConeState.AMBER
    else:
        state = ConeState.GREEN
    return ConeReading(cone, state, r, sigma, estimate.offset, age, estimate.cameras, now=now, behind=behind,
                       axis_sigma=estimate.sigma)


def no_data_reason(reading: ConeReading, stale_s: float = STALE_S, short: bool = False) -> str:
    """Why a cone shows NO DATA (short: a few words, for the bull's-eye)."""
    if reading.behind > VIEW_BEHIND_S:
        return (f"view behind by {reading.behind:.0f} s" if short
                else f"this view is {reading.behind:.0f} s behind the live clock (it cannot keep up): what it "
                     "shows is that old")
    if not np.isfinite(reading.age):
        return "no measurement yet"
    if reading.age > stale_s:
        return (f"newest {reading.age:.1f} s old" if short
                else f"newest measurement {reading.age:.1f} s old (limit {stale_s:.1f} s)")
    if reading.withheld in (WITHHELD_SCALE, WITHHELD_BELOW):
        return reading.withheld if short else (
            f"{reading.withheld}: the markers do not look the size the rig states, or the offset would put the topside "
            "through its cones; a number from this rig would be wrong (topside check names the field)")
    if reading.withheld == WITHHELD_CLOCKS:
        return WITHHELD_CLOCKS if short else (
            "the topside moves while its cameras' clocks are known only to the rig's time_offset_sigma, so where it "
            "is at a frame's time is not known well enough: measure the clocks with topside sync")
    if reading.withheld == WITHHELD_COMPARING:
        return WITHHELD_COMPARING if short else (
            "two cameras see this cone and one has too few frames yet to tell whether they agree: real lenses put the "
            "same offset millimetres apart, which no single frame shows (shown within half a second)")
    sigma = reading.axis_sigma
    figures = f" (σ {sigma_text(sigma)})" if np.isfinite(sigma).all() else ""
    warm = np.isfinite(sigma).all() and (sigma <= REPORT_MAX_SIGMA_M).all() and reading.withheld == WITHHELD_SIGMA
    if reading.withheld == WITHHELD_WARMING or (warm and not short):  # (a recording made before 'warming up' was
        # said: its warm-up rows say σ too large at a σ within 50 mm; the ring's short label keeps what was recorded)
        return WITHHELD_WARMING if short else (
            f"warming up: for the first {REPORT_WARMUP_S:g} s after the topside is placed a cone is shown only with "
            f"σ below {REPORT_WARMUP_SIGMA_SIDES:.1%} of a marker side, {REPORT_WARMUP_SIGMA_SIDES * 1e3:.0f} mm for "
            f"1 m markers{figures}: the cameras' first poses are not yet settled")
    if short:
        return WITHHELD_SIGMA
    poor = axes_above(sigma, REPORT_MAX_SIGMA_M)
    along = f" along {poor} (a camera seeing it from another side would measure that)" if poor else ""
    known = axes_text(reading.offset, sigma)
    return (f"1σ above {REPORT_MAX_SIGMA_M * 1e3:.0f} mm{figures}: the cameras do not see this cone well "
            f"enough{along}" + (f". Measured: {known}" if known else ""))


def axes_text(offset: np.ndarray, sigma: np.ndarray) -> str:
    """The axes an offset (3,) m shows, each with its 2σ from sigma (3,) m, e.g. 'Δy +12 ±8 · Δz +1234 ±40 mm (2σ)';
    empty when it shows none."""
    parts = [f"{a} {v * 1000:+.0f} ±{CONFIDENCE_SIGMAS * s * 1000:.0f}"
             for a, v, s in zip(AXIS_NAMES, offset, sigma, strict=True) if np.isfinite(v)]
    return " · ".join(parts) + " mm (2σ)" if parts else ""


def cones_line(readings: Sequence[ConeReading], stale_s: float = STALE_S) -> str:
    """Every cone on one line of text, for a terminal or a log: its state, the horizontal distance from its target
    and its σ, Δx Δy Δz in mm; or NO DATA and why, e.g. 'A GREEN 42±6 mm (Δx +30 Δy -29 Δz +412) · D NO DATA
    (newest 2.1 s old)'."""
    parts = []
    for r in readings:
        if r.state == ConeState.NO_DATA:
            why = no_data_reason(r, stale_s, short=True)
            known = axes_text(r.offset, r.axis_sigma) if why == WITHHELD_SIGMA else ""
            parts.append(f"{r.cone} NO DATA ({why}{'; ' + known if known else ''})")
            continue
        dx, dy, dz = (1000 * v for v in r.offset)
        parts.append(f"{r.cone} {r.state.name} {1000 * r.concentricity:.0f}±{1000 * r.sigma:.0f} mm "
                     f"(Δx {dx:+.0f} Δy {dy:+.0f} Δz {_mm(dz)})")
    return " · ".join(parts)


def cone_markdown(reading: ConeReading, stale_s: float = STALE_S) -> str:
    """Large figures for one cone (three lines: they fit a tablet's column); NO DATA says why."""
    if reading.state == ConeState.NO_DATA:
        return f"# {reading.cone}: NO DATA\n\n{no_data_reason(reading, stale_s)}"
    dx, dy, dz = reading.offset
    return (f"# {reading.cone}: {reading.concentricity * 1000:.0f} mm\n\n"
            f"**{HEADLINES[reading.state]}** · ±{CONFIDENCE_SIGMAS * reading.sigma * 1000:.0f} mm (2σ) of "
            f"{TOLERANCE_MM:.0f}\n\n"
            f"Δx {dx * 1000:+.0f} · Δy {dy * 1000:+.0f} · Δz {_mm(dz * 1000)} mm · "
            f"{', '.join(reading.cameras) or 'the filter alone'} · {reading.age:.2f} s old"
            + (f" at {clock_text(reading.now)}" if np.isfinite(reading.now) else ""))


def _mm(value: float) -> str:
    """A signed figure in mm, or '—' for an axis withheld (its σ above the limit)."""
    return f"{value:+.0f}" if np.isfinite(value) else "—"


def clock_text(t: float) -> str:
    """A capture time as the superintendent compares it with a clock: the time of day (live cameras' Unix times),
    else seconds of the replay."""
    return time.strftime("%H:%M:%S", time.localtime(t)) if t > WALL_CLOCK_AFTER else f"{t:.1f} s"


def cameras_markdown(cameras: Mapping[str, CameraHealth], now: float) -> str:
    """Every camera's state, frame rate, age of its newest frame, markers."""
    lines = ["| camera | state | fps | newest frame | markers | skipped |", "|---|---|---:|---:|---:|---:|"]
    for name, h in sorted(cameras.items()):
        age = "—" if h.last_capture is None else f"{max(0.0, now - h.last_capture):.2f} s"
        state = CAMERA_WORDS[h.state] + (f" ({h.detail})" if h.detail and h.detail != "ready" else "")
        lines.append(f"| {name} | {state} | {h.fps:.1f} | {age} | {h.markers} | {h.skipped / max(h.frames, 1):.0%} |")
    return "\n".join(lines)


def screen_xy(offset_m: np.ndarray) -> np.ndarray:
    """A horizontal offset (dx, dy) in m as bull's-eye coordinates in mm (2-D views have y down): port to the right,
    astern up, as the superintendent on the stern sees the jacket."""
    return np.array([offset_m[0], -offset_m[1]]) * 1000


def circle(radius: float) -> np.ndarray:
    """(CIRCLE_POINTS, 2) closed circle about the origin."""
    a = np.linspace(0, 2 * np.pi, CIRCLE_POINTS)
    return np.c_[radius * np.cos(a), radius * np.sin(a)]


def no_camera_text(cone: str, marked: bool) -> str:
    """What a cone's column shows in its image's place while no camera has measured it (marked: the rig has marker
    pairs at the cone)."""
    if marked:
        return f"No camera has measured cone {cone}'s markers yet: its image appears here when one does."
    return (f"No markers at cone {cone}: no camera measures it. Its offset follows from the other cones' (the "
            "topside is one rigid body).")


def marked_cones(rig: Rig) -> set[str]:
    """The cones with marker pairs in the rig."""
    return set(rig.paired_cones())


def log_target_circle(rec: rr.RecordingStream, cone: str, marked: bool = True) -> None:
    """Static parts of a cone's bull's-eye, in mm: the ±tolerance circle and cross, the directions, the trend's
    series styles, and (until a camera measures the cone) the note in its image's place."""
    r = TOLERANCE_MM
    base = f"{ROOT}/targets/{cone}"
    rr.log(f"{base}/tolerance", rr.LineStrips2D([circle(r), [[-r, 0], [r, 0]], [[0, -r], [0, r]]],
                                                colors=RING_COLOR, radii=1.0), static=True, recording=rec)
    reach = TARGET_REACH * r
    rr.log(f"{base}/compass", rr.Points2D([[0.85 * reach, 0], [0, -0.9 * reach]], radii=0.5, colors=RING_COLOR,
                                          labels=["port", "astern"]), static=True, recording=rec)
    rr.log(f"{ROOT}/trend/{cone}", rr.SeriesLines(colors=[TREND_COLOR, BOUND_COLOR, TOLERANCE_LINE_COLOR],
                                                  widths=[2.5, 1.0, 1.5],
                                                  names=["concentricity [mm]", "+2σ [mm]", f"{TOLERANCE_MM:.0f} mm"]),
           static=True, recording=rec)
    rr.log(f"{ROOT}/no_camera/{cone}", rr.TextDocument(no_camera_text(cone, marked), media_type=rr.MediaType.MARKDOWN),
           static=True, recording=rec)


def log_cone_reading(rec: rr.RecordingStream, reading: ConeReading, now: float, stale_s: float = STALE_S) -> None:
    """One cone's large figures, its bull's-eye (a point beyond the ring is drawn on it, with an arrow and its
    distance) and its trend."""
    set_capture_time(rec, now)
    cone = reading.cone
    rr.log(f"{ROOT}/cones/{cone}", rr.TextDocument(cone_markdown(reading, stale_s), media_type=rr.MediaType.MARKDOWN),
           recording=rec)
    base = f"{ROOT}/targets/{cone}"
    color = TARGET_COLORS[reading.state.value]
    rr.log(f"{base}/state", rr.LineStrips2D([circle(TOLERANCE_MM)], colors=color,
                                            radii=rr.components.Radius.ui_points(STATE_RING_PX)), recording=rec)
    if reading.state == ConeState.NO_DATA:
        log_points(rec, f"{base}/offset")
        log_arrow(rec, f"{base}/beyond")
        log_points(rec, f"{base}/why", [0.0, WHY_Y_MM], 0.5, color,
                   f"NO DATA: {no_data_reason(reading, stale_s, short=True)}")
        log_trend(rec, cone, np.nan, np.nan)  # a gap in the trend, not a line across the time without data
        return
    log_points(rec, f"{base}/why")
    mm = reading.concentricity * 1000
    xy = screen_xy(reading.offset[:2])
    dot = max(MIN_DOT_MM, CONFIDENCE_SIGMAS * reading.sigma * 1000)
    label = f"{mm:.0f} mm"
    if mm > TOLERANCE_MM:  # beyond the ring: on the ring, with an arrow the way it is off
        u = xy / np.hypot(*xy)
        log_points(rec, f"{base}/offset", u * TOLERANCE_MM, dot, color, None)  # the arrow has it
        log_arrow(rec, f"{base}/beyond", u * TOLERANCE_MM, u * ARROW_MM, color, label)
    else:
        log_points(rec, f"{base}/offset", xy, dot, color, label)
        log_arrow(rec, f"{base}/beyond")
    log_trend(rec, cone, mm, mm + CONFIDENCE_SIGMAS * reading.sigma * 1000)


def log_points(rec: rr.RecordingStream, path: str, xy: Sequence[float] | np.ndarray | None = None, radius: float = 0.0,
               color: Sequence[int] = (0, 0, 0), label: str | None = None) -> None:
    """One point of a bull's-eye (mm), or none (xy None): always the same four components (an empty label list, not
    a left-out one: the viewer would otherwise keep an earlier row's label)."""
    if xy is None:
        rr.log(path, rr.Points2D(NOWHERE, radii=[], colors=[], labels=[]), recording=rec)
        return
    rr.log(path, rr.Points2D(np.reshape(xy, (1, 2)), radii=[radius], colors=[color],
                             labels=[] if label is None else [label]), recording=rec)


def log_arrow(rec: rr.RecordingStream, path: str, origin: np.ndarray | None = None, vector: np.ndarray = NOWHERE,
              color: Sequence[int] = (0, 0, 0), label: str = "") -> None:
    """The arrow beyond a bull's-eye's ring (mm), or none (origin None): always the same five components."""
    if origin is None:
        rr.log(path, rr.Arrows2D(origins=NOWHERE, vectors=NOWHERE, colors=[], radii=[], labels=[]), recording=rec)
        return
    rr.log(path, rr.Arrows2D(origins=[origin], vectors=[vector], colors=[color],
                             radii=rr.components.Radius.ui_points(ARROW_PX), labels=[label]), recording=rec)


def log_trend(rec: rr.RecordingStream, cone: str, concentricity_mm: float, bound_mm: float) -> None:
    """The trend's three series at once (log_target_circle's styles): concentricity, r + 2σ, the tolerance."""
    rr.log(f"{ROOT}/trend/{cone}", rr.Scalars([concentricity_mm, bound_mm, TOLERANCE_MM]), recording=rec)


def log_camera_health(rec: rr.RecordingStream, cameras: Mapping[str, CameraHealth], now: float) -> None:
    """The camera table."""
    set_capture_time(rec, now)
    rr.log(f"{ROOT}/cameras", rr.TextDocument(cameras_markdown(cameras, now), media_type=rr.MediaType.MARKDOWN),
           recording=rec)


def cone_column(cone: str, camera: str | None, marked: bool = True) -> rrb.Vertical:
    """One cone's column: figures, live image (or why there is none), bull's-eye, trend; the same sizes always."""
    reach = TARGET_REACH * TOLERANCE_MM
    image = (rrb.Spatial2DView(origin=f"world/cameras/{camera}", name=f"{cone}: {camera}") if camera is not None
             else rrb.TextDocumentView(origin=f"{ROOT}/no_camera/{cone}",
                                       name=f"{cone}: no camera yet" if marked else f"{cone}: no markers"))
    return rrb.Vertical(
        rrb.TextDocumentView(origin=f"{ROOT}/cones/{cone}", name=f"cone {cone}"),
        image,
        rrb.Spatial2DView(origin=f"{ROOT}/targets/{cone}", name=f"{cone} offset [mm]: port right, astern up",
                          visual_bounds=rrb.VisualBounds2D(x_range=[-reach, reach], y_range=[-reach, reach])),
        rrb.TimeSeriesView(origin=f"{ROOT}/trend/{cone}", name=f"{cone} concentricity, last minute [mm]",
                           plot_legend=rrb.PlotLegend(visible=False),
                           time_ranges=rrb.VisibleTimeRange(
                               TIMELINE, start=rrb.TimeRangeBoundary.cursor_relative(seconds=-TREND_S),
                               end=rrb.TimeRangeBoundary.cursor_relative(seconds=0.0))),
        row_shares=ROW_SHARES)


def superintendent_blueprint(rig: Rig, cone_cameras: Mapping[str, str]) -> rrb.Blueprint:
    """A column per cone (figures, live image, bull's-eye, trend) above the camera table."""
    marked = marked_cones(rig)
    columns = [cone_column(cone, cone_cameras.get(cone), cone in marked) for cone in rig.all_cones()]
    return rrb.Blueprint(
        rrb.Vertical(rrb.Horizontal(*columns, name="cones"),
                     rrb.TextDocumentView(origin=f"{ROOT}/cameras", name="cameras"), row_shares=[4, 1]),
        rrb.TimePanel(state="collapsed", timeline=TIMELINE),  # else the viewer may pick a camera's frame numbers
        rrb.SelectionPanel(state="collapsed"), rrb.BlueprintPanel(state="collapsed"))
