"""The superintendent's live view: per cone the offset in large figures, green/amber/red, NO DATA when stale.

Entity layout:
    superintendent/cones/<cone>          markdown: state, concentricity and Δx Δy Δz in large figures
    superintendent/targets/<cone>        bull's-eye: the ±150 mm circle and the cone's horizontal offset (mm)
    superintendent/cameras               markdown: every camera's state, frame rate, age and markers
The live image per cone is the 2-D view of the camera that measures that cone most.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from enum import StrEnum

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from tracking.filtering import ConeEstimate
from tracking.fusion import REPORT_MAX_SIGMA_M, REPORT_WARMUP_S, REPORT_WARMUP_SIGMA_M
from tracking.live import STALE_S, CameraHealth
from tracking.rig import Rig
from tracking.sources import CameraState
from viewer.recording import TOLERANCE_M, concentricity, set_capture_time

ROOT = "superintendent"
CONFIDENCE_SIGMAS = 2.0  # amber when the offset is inside the tolerance but its 2σ bound is not
CIRCLE_POINTS = 73
TARGET_REACH = 1.3  # the bull's-eye shows offsets up to this many tolerances; beyond, the point sits on its rim
TARGET_COLORS = {"green": (40, 200, 80), "amber": (255, 170, 0), "red": (230, 40, 40), "none": (128, 128, 128)}
# Words, not emoji: the viewer's font (Inter) has no emoji, and a missing glyph makes the native viewer panic.
CAMERA_WORDS = {CameraState.STARTING: "starting", CameraState.LIVE: "LIVE", CameraState.FROZEN: "FROZEN",
                CameraState.LOST: "LOST", CameraState.ENDED: "ended"}


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


def cone_reading(estimate: ConeEstimate | None, cone: str, now: float, last_measurement: float | None,
                 stale_s: float = STALE_S) -> ConeReading:
    """Classify a cone's newest estimate against the tolerance and its age."""
    age = np.inf if last_measurement is None else max(0.0, now - last_measurement)
    if estimate is None or not np.all(np.isfinite(estimate.offset)) or age > stale_s:
        offset = np.full(3, np.nan) if estimate is None else estimate.offset
        return ConeReading(cone, ConeState.NO_DATA, np.nan, np.nan, offset, age, ())
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
    return ConeReading(cone, state, r, sigma, estimate.offset, age, estimate.cameras)


def cone_markdown(reading: ConeReading, stale_s: float = STALE_S) -> str:
    """Large figures for one cone."""
    headline = f"# Cone {reading.cone}: {HEADLINES[reading.state]}"
    if reading.state == ConeState.NO_DATA:
        if not np.isfinite(reading.age):
            why = "no measurement yet"
        elif reading.age > stale_s:
            why = f"newest measurement {reading.age:.1f} s old (limit {stale_s:.1f} s)"
        else:
            why = ("the cameras do not see this cone well enough (1σ above "
                   f"{REPORT_MAX_SIGMA_M * 1e3:.0f} mm; {REPORT_WARMUP_SIGMA_M * 1e3:.0f} mm in the first "
                   f"{REPORT_WARMUP_S:g} s after the topside is placed)")
        return f"{headline}\n# NO DATA\n\n{why}"
    dx, dy, dz = reading.offset
    return (f"{headline}\n"
            f"# {reading.concentricity * 1000:.0f} mm\n"
            f"## ±{CONFIDENCE_SIGMAS * reading.sigma * 1000:.0f} mm (2σ) of {TOLERANCE_M * 1000:.0f}\n\n"
            f"### Δx {dx * 1000:+.0f} · Δy {dy * 1000:+.0f} · Δz {dz * 1000:+.0f} mm\n\n"
            f"rests on {', '.join(reading.cameras) or 'the filter alone'} · {reading.age:.2f} s old")


def cameras_markdown(cameras: Mapping[str, CameraHealth], now: float) -> str:
    """Every camera's state, frame rate, age of its newest frame, markers."""
    lines = ["| camera | state | fps | newest frame | markers | skipped |", "|---|---|---:|---:|---:|---:|"]
    for name, h in sorted(cameras.items()):
        age = "—" if h.last_capture is None else f"{max(0.0, now - h.last_capture):.2f} s"
        state = CAMERA_WORDS[h.state] + (f" ({h.detail})" if h.detail and h.detail != "ready" else "")
        lines.append(f"| {name} | {state} | {h.fps:.1f} | {age} | {h.markers} | {h.skipped / max(h.frames, 1):.0%} |")
    return "\n".join(lines)


def log_target_circle(rec: rr.RecordingStream, cone: str) -> None:
    """Static ±tolerance circle and cross of a cone's bull's-eye, in mm."""
    a = np.linspace(0, 2 * np.pi, CIRCLE_POINTS)
    r = TOLERANCE_M * 1000
    rr.log(f"{ROOT}/targets/{cone}/tolerance", rr.LineStrips2D(
        [np.c_[r * np.cos(a), r * np.sin(a)], [[-r, 0], [r, 0]], [[0, -r], [0, r]]],
        colors=(200, 200, 200), radii=1.0), static=True, recording=rec)


def log_cone_reading(rec: rr.RecordingStream, reading: ConeReading, now: float) -> None:
    """One cone's large figures and its point on the bull's-eye (x to port right, astern down)."""
    set_capture_time(rec, now)
    rr.log(f"{ROOT}/cones/{reading.cone}", rr.TextDocument(cone_markdown(reading), media_type=rr.MediaType.MARKDOWN),
           recording=rec)
    point = f"{ROOT}/targets/{reading.cone}/offset"
    if reading.state == ConeState.NO_DATA:
        rr.log(point, rr.Clear(recursive=False), recording=rec)
        return
    xy = reading.offset[:2] * 1000
    reach = TARGET_REACH * TOLERANCE_M * 1000
    xy = xy if np.hypot(*xy) <= reach else xy * reach / np.hypot(*xy)  # far off: on the rim, pointing the way
    rr.log(point, rr.Points2D([xy], radii=max(6.0, 2000 * reading.sigma),
                              colors=TARGET_COLORS[reading.state.value],
                              labels=[f"{reading.concentricity * 1000:.0f} mm"]), recording=rec)


def log_camera_health(rec: rr.RecordingStream, cameras: Mapping[str, CameraHealth], now: float) -> None:
    """The camera table."""
    set_capture_time(rec, now)
    rr.log(f"{ROOT}/cameras", rr.TextDocument(cameras_markdown(cameras, now), media_type=rr.MediaType.MARKDOWN),
           recording=rec)


def superintendent_blueprint(rig: Rig, cone_cameras: Mapping[str, str]) -> rrb.Blueprint:
    """A column per cone (figures, live image, bull's-eye) above the camera table."""
    cones = sorted(rig.cones) or sorted({p.cone for p in rig.all_pairs()})
    columns = []
    for cone in cones:
        views: list = [rrb.TextDocumentView(origin=f"{ROOT}/cones/{cone}", name=f"cone {cone}")]
        if cone in cone_cameras:
            views.append(rrb.Spatial2DView(origin=f"world/cameras/{cone_cameras[cone]}",
                                           name=f"{cone}: {cone_cameras[cone]}"))
        views.append(rrb.Spatial2DView(origin=f"{ROOT}/targets/{cone}", name=f"{cone} Δx Δy [mm]"))
        columns.append(rrb.Vertical(*views, row_shares=[2, 3, 2][:len(views)] if len(views) == 3 else [2, 2]))
    return rrb.Blueprint(
        rrb.Vertical(rrb.Horizontal(*columns, name="cones"),
                     rrb.TextDocumentView(origin=f"{ROOT}/cameras", name="cameras"), row_shares=[5, 1]),
        rrb.TimePanel(state="collapsed"), rrb.SelectionPanel(state="collapsed"), rrb.BlueprintPanel(state="collapsed"))
