"""`topside report`: one self-contained HTML page per installation from its recording or archive (no truth needed).

The page answers, in this order: did every cone land within the tolerance, when, how sure (a verdict per cone); how
each cone came in and what happened after (plots: concentricity with its 2σ band and the tolerance, Δx Δy Δz with
theirs, NO DATA shaded with its reason, the set-down marked); what each camera did (a timeline) and the clocks and
survey the rig stated; the moments to open the recording at; and exactly what it summarises (software, rig and
calibration digests, the archive's manifest and signature). Plots are matplotlib PNGs embedded as base64, the style
sheet inline: the page fetches nothing. The numbers come from tracking.installation_report.
"""

from __future__ import annotations

import base64
import io
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import jinja2
import numpy as np
import pandas as pd
from matplotlib.axes import Axes
from matplotlib.figure import Figure  # no pyplot: no backend, no display, no figures kept open
from matplotlib.patches import Rectangle

from tracking.errors import InputError, one_line
from tracking.estimate import TOLERANCE_M
from tracking.installation_report import (
    CONFIDENCE_SIGMAS,
    NO_ESTIMATE,
    CameraSpan,
    ConeSummary,
    Event,
    Period,
    Summary,
    Verdict,
    concentricity,
    has_number,
    summarise,
)
from viewer.archive.file import software_version
from viewer.installation_record import SHORT_HASH, InstallationRecord

TEMPLATE = "report.html.j2"
DPI = 100  # a 10-inch-wide figure is 1000 px: the page's width
CONE_FIGURE_IN = (10.0, 5.2)
TIMELINE_ROW_IN = 0.45
CONTEXT_S = 2.0  # an event's command opens the recording this long before it: its approach shows
WALL_CLOCK_AFTER = 1e9  # capture times beyond this are Unix times (live cameras): shown as UTC
VERDICT_COLORS = {Verdict.WITHIN: "#28c850", Verdict.EDGE: "#ffaa00", Verdict.OUTSIDE: "#e62828",
                  Verdict.NOT_LANDED: "#8c8c8c", Verdict.NO_DATA: "#8c8c8c"}  # the tablet's (viewer.superintendent)
SPAN_COLORS = {CameraSpan.LIVE: "#28c850", CameraSpan.NO_MARKERS: "#ffd27a", CameraSpan.FROZEN: "#5aa0ff",
               CameraSpan.LOST: "#e62828", CameraSpan.ENDED: "#b4b4b4", CameraSpan.NOT_STARTED: "#e6e6e6"}
INTEGRITY_COLORS = {"whole": "#28c850", "recovered": "#ffaa00", "interrupted": "#ffaa00", "damaged": "#e62828"}
AXIS_COLORS = ("#e63c3c", "#3cb43c", "#3c78f0")  # Δx Δy Δz, as the recording's axes
NO_DATA_SHADE = "#c8c8c8"
SET_DOWN_COLOR = "#000000"


def clock(t: float) -> str:
    """A capture time for people: UTC time of day for Unix times (live cameras), else seconds."""
    if t > WALL_CLOCK_AFTER:
        return time.strftime("%H:%M:%S", time.gmtime(t)) + f".{int((t % 1) * 10)} UTC"
    return f"{t:.2f} s"


def png(fig: Figure) -> str:
    """A figure as a data: URL (base64 PNG)."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=DPI, bbox_inches="tight")
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode()


def _shade(ax: Axes, periods: tuple[Period, ...] | list[Period], label: bool) -> None:
    """NO DATA periods as grey bands, each reason written once in the first band that shows it."""
    said: set[str] = set()
    for p in periods:
        ax.axvspan(p.start, max(p.end, p.start + 1e-3), color=NO_DATA_SHADE, alpha=0.5, lw=0)
        if label and p.what not in said:
            said.add(p.what)
            ax.text(p.start, 0.97, f" NO DATA: {p.what}", transform=ax.get_xaxis_transform(), va="top",
                    fontsize=8, color="#555555", clip_on=True)


def _band(ax: Axes, t: np.ndarray, value: np.ndarray, sigma: np.ndarray, color: str, label: str) -> None:
    """A series and its ±2σ band (gaps where it has no number)."""
    ax.plot(t, value, color=color, lw=1.6, label=label)
    ax.fill_between(t, value - CONFIDENCE_SIGMAS * sigma, value + CONFIDENCE_SIGMAS * sigma, color=color, alpha=0.2,
                    lw=0)


def cone_figure(rows: pd.DataFrame, c: ConeSummary, span: tuple[float, float]) -> str:
    """One cone: concentricity with its 2σ band and the tolerance; Δx, Δy with theirs; Δz; NO DATA shaded with its
    reason; the set-down, the closest approach and the largest excursion marked."""
    rows = rows.sort_values("time")
    t = rows["time"].to_numpy(float)
    r, s = concentricity(rows)
    known = has_number(rows)
    r, s = np.where(known, r, np.nan) * 1e3, s * 1e3
    fig = Figure(figsize=CONE_FIGURE_IN)
    a0, a1, a2 = fig.subplots(3, 1, sharex=True, height_ratios=[2.2, 1.6, 1.2])
    _band(a0, t, r, s, "#1f5fbf", "concentricity ± 2σ")
    a0.axhline(TOLERANCE_M * 1e3, color=VERDICT_COLORS[Verdict.OUTSIDE], lw=1.5, label=f"{TOLERANCE_M * 1e3:.0f} mm")
    a0.set_ylabel("concentricity [mm]")
    a0.set_ylim(0, max(np.nanmax(np.concatenate([r + 2 * s, [0.0]])) if known.any() else 0.0,
                       1.6 * TOLERANCE_M * 1e3))
    for k, axis in enumerate(("dx", "dy")):
        _band(a1, t, rows[axis].to_numpy(float) * 1e3, rows[f"sd{axis[1]}"].to_numpy(float) * 1e3,
              AXIS_COLORS[k], f"Δ{axis[1]} ± 2σ")
    a1.axhline(0, color="#888888", lw=0.8)
    a1.set_ylabel("Δx Δy [mm]")
    _band(a2, t, rows["dz"].to_numpy(float), rows["sdz"].to_numpy(float), AXIS_COLORS[2], "Δz ± 2σ")
    a2.axhline(0, color="#888888", lw=0.8)
    a2.set_ylabel("Δz [m]")
    a2.set_xlabel("capture time [s]")
    for ax in (a0, a1, a2):
        _shade(ax, c.no_data, ax is a0)
        if c.landed is not None:
            ax.axvline(c.landed.time, color=SET_DOWN_COLOR, lw=1.2, ls="--")
        ax.grid(alpha=0.3)
    if c.landed is not None:
        a0.annotate(f"set down {clock(c.landed.time)}", (c.landed.time, 0.03), xycoords=("data", "axes fraction"),
                    fontsize=8, ha="right", rotation=90, va="bottom")
    for m, marker, name in ((c.closest, "v", "closest"), (c.excursion, "^", "largest after")):
        if m is not None:
            a0.plot([m.time], [m.concentricity * 1e3], marker=marker, color="#000000", ms=7, ls="none", label=name)
    a0.legend(loc="upper right", fontsize=8, ncols=4)
    a1.legend(loc="upper right", fontsize=8, ncols=2)
    a0.set_xlim(*span)
    a0.set_title(f"cone {c.cone}: {c.headline}", loc="left", fontsize=11, color=VERDICT_COLORS[c.verdict]
                 if c.verdict != Verdict.WITHIN else "#1a7f37")
    return png(fig)


def timeline_figure(cameras: dict[str, list[Period]], frames: pd.DataFrame, span: tuple[float, float]) -> str:
    """Every camera's spans as coloured bars, its markers per frame drawn in its row."""
    names = list(cameras)
    fig = Figure(figsize=(CONE_FIGURE_IN[0], 0.9 + TIMELINE_ROW_IN * max(1, len(names))))
    ax = fig.subplots()
    for k, name in enumerate(names):
        for p in cameras[name]:
            ax.broken_barh([(p.start, max(p.end - p.start, 1e-3))], (k - 0.4, 0.8), color=SPAN_COLORS[p.what])
        f = frames[frames["camera"] == name]
        most = max(float(np.nanmax(f["markers"])) if f["markers"].notna().any() else 0.0, 1.0)
        ax.plot(f["time"], k + 0.35 - 0.7 * f["markers"] / most, color="#333333", lw=0.7)
    handles = [Rectangle((0, 0), 1, 1, color=SPAN_COLORS[s]) for s in CameraSpan]
    ax.legend(handles, [s.value for s in CameraSpan], loc="lower center", bbox_to_anchor=(0.5, 1.0),
              ncols=len(CameraSpan), fontsize=8, frameon=False)
    ax.set_yticks(range(len(names)), names)
    ax.set_ylim(len(names) - 0.5, -0.5)
    ax.set_xlim(*span)
    ax.set_xlabel("capture time [s] — the line in each bar: markers seen per frame (up: more)")
    ax.grid(axis="x", alpha=0.3)
    return png(fig)


@dataclass(frozen=True)
class Row:
    """One row of a table on the page: cells as text, and a CSS class."""

    cells: tuple[str, ...]
    css: str = ""


def mm(v: float) -> str:
    return "—" if not np.isfinite(v) else f"{v * 1e3:.0f}"


def verdict_rows(summary: Summary) -> list[Row]:
    """The verdict table: one row per cone."""
    out = []
    for c in summary.cones:
        landed = c.landed
        at = "—" if landed is None else clock(landed.time)
        figure = "—" if landed is None else (f"{mm(landed.concentricity)} ± {mm(CONFIDENCE_SIGMAS * landed.sigma)}")
        offsets = "—" if landed is None else " / ".join(f"{v * 1e3:+.0f}" for v in landed.offset)
        closest = "—" if c.closest is None else f"{mm(c.closest.concentricity)} at {clock(c.closest.time)}"
        after = "—" if c.excursion is None else f"{mm(c.excursion.concentricity)} at {clock(c.excursion.time)}"
        gaps = "; ".join(sorted({p.what for p in c.no_data})) or "none"
        out.append(Row((c.cone, c.verdict.value, at, figure, offsets, closest, after, f"{c.shown:.0%}", gaps),
                       c.verdict.name.lower()))
    return out


def camera_rows(record: InstallationRecord, summary: Summary) -> list[Row]:
    """Per camera: frames, share with markers, its troubles, and the clock and survey the rig stated for it."""
    entries = {c.name: c for c in record.rig.cameras} if record.rig is not None else {}
    out = []
    for name, spans in summary.cameras.items():
        f = record.frames[record.frames["camera"] == name]
        searched = f["markers"].notna()
        seen = f"{(f['markers'][searched] > 0).mean():.0%}" if searched.any() else "—"
        trouble = "; ".join(f"{p.what} {clock(p.start)} for {p.duration:.1f} s" for p in spans
                            if p.what in (CameraSpan.LOST, CameraSpan.FROZEN, CameraSpan.ENDED)) or "none"
        e = entries.get(name)
        if e is None:
            clocks, survey, mount = "—", "—", "—"
        else:
            clocks = f"{e.time_offset:+.3f} s ± " + (f"{e.time_offset_sigma * 1e3:.0f} ms" if e.time_offset_sigma
                                                     is not None else "? (not measured: taken as exact)")
            survey = (f"[{', '.join(f'{v:.2f}' for v in e.position)}] m ± {e.position_sigma * 1e3:.0f} mm"
                      if e.position is not None else "not surveyed")
            mount = e.mount.value if hasattr(e.mount, "value") else str(e.mount)
        out.append(Row((name, str(len(f)), seen, trouble, clocks, survey, mount),
                       "bad" if trouble != "none" else ""))
    return out


def rig_lines(record: InstallationRecord) -> list[str]:
    """What the rig states of the markers' survey."""
    rig = record.rig
    if rig is None:
        return ["the record carries no readable rig"]
    sigma = rig.survey_sigma
    refs = [str(m.id) for m in rig.markers if m.reference]
    return [f"marker size {rig.marker_size:.3f} m ({rig.dictionary}), {len(rig.markers)} markers, "
            f"{len(rig.cameras)} cameras, cones {', '.join(sorted(rig.cones)) or '—'}",
            "marker survey σ: " + (f"{np.max(sigma.position()) * 1e3:.0f} mm, "
                                   f"{np.degrees(np.max(sigma.tilt_rad())):.2g}°" if sigma is not None
                                   else "not stated (markers taken as exact)"),
            "datum markers (reference): " + (", ".join(refs) if refs else "none")]


def open_command(record: InstallationRecord, t: float, start: float) -> str:
    """How to open the record at time t."""
    if record.kind == "recording":
        return f"topside view {record.path.name} --from {max(start, t - CONTEXT_S):.2f}"
    return f"Foxglove: open {record.path.name}, seek to {clock(t)}"


def event_rows(record: InstallationRecord, summary: Summary) -> list[Row]:
    """The events, each with how to open the record there."""
    def css(e: Event) -> str:
        return "bad" if any(w in e.what for w in ("NO DATA", "lost", "frozen", "ended", "OUTSIDE")) else ""

    return [Row((clock(e.time), e.subject, e.what, open_command(record, e.time, summary.start)), css(e))
            for e in summary.events]


def provenance_rows(record: InstallationRecord) -> list[tuple[str, str]]:
    """What the page summarises, exactly."""
    p = record.provenance
    commit = p.software_commit
    rows = [("file", f"{record.path.name} ({record.kind}, {record.path.stat().st_size / 1e6:.1f} MB)"),
            ("installation", p.installation or "—"),
            ("software", f"topside {p.software_version}, commit {commit}"),
            ("configuration SHA-256", p.configuration_sha256 or "—")]
    rows += [(f"SHA-256 of {name}", digest) for name, digest in p.files]
    rows += [("options", p.options or "—"), *p.people]
    rows.append(("signature", record.integrity.signature))
    return rows


def render(record: InstallationRecord, summary: Summary | None = None) -> str:
    """The report's HTML."""
    summary = summary or summarise(record.estimates, record.frames, *record.span, record.cones, record.cameras,
                                   record.stated)
    span = (summary.start, summary.end if summary.end > summary.start else summary.start + 1.0)
    cones = [(c, cone_figure(record.estimates[record.estimates["cone"] == c.cone], c, span)) for c in summary.cones]
    env = jinja2.Environment(loader=jinja2.PackageLoader("viewer", "templates"), autoescape=True,
                             undefined=jinja2.StrictUndefined)
    return env.get_template(TEMPLATE).render(
        record=record, summary=summary, cones=cones, clock=clock, verdicts=verdict_rows(summary),
        verdict_colors={v.name.lower(): c for v, c in VERDICT_COLORS.items()},
        integrity_color=INTEGRITY_COLORS.get(record.integrity.state, "#e62828"), banner=banner_color(summary),
        timeline=timeline_figure(summary.cameras, record.frames, span) if summary.cameras else None,
        cameras=camera_rows(record, summary), rig=rig_lines(record), events=event_rows(record, summary),
        provenance=provenance_rows(record), notes=record.notes.sort_values("time").itertuples(index=False),
        tolerance_mm=f"{TOLERANCE_M * 1e3:.0f}", sigmas=f"{CONFIDENCE_SIGMAS:g}", no_estimate=NO_ESTIMATE,
        short=SHORT_HASH, made=time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), version=software_version())


def banner_color(summary: Summary) -> str:
    """The headline's colour: green when every cone landed within, red when one is outside, amber otherwise."""
    if summary.cones and all(c.verdict == Verdict.WITHIN for c in summary.cones):
        return "#1a7f37"
    return "#b03a2e" if any(c.verdict == Verdict.OUTSIDE for c in summary.cones) else "#b07800"


def pdf(html: str) -> bytes:
    """The page as PDF (A4), laid out by WeasyPrint (no browser); a one-line InputError naming --pdf when WeasyPrint
    or its Pango library is missing."""
    try:
        import weasyprint
    except (ImportError, OSError) as exc:  # OSError: the package is there, its Pango library is not
        raise InputError("--pdf", f"needs WeasyPrint and the Pango library ({one_line(str(exc))[:120]}): pip install "
                                  "'topside[pdf]', and on Debian apt-get install libpango-1.0-0") from None
    return weasyprint.HTML(string=html).write_pdf()


def write_report(record: InstallationRecord, out: Path, writer: Callable[[Path, str], None],
                 pdf_out: Path | None = None, pdf_writer: Callable[[Path, bytes], None] | None = None) -> Summary:
    """Render a record's report into out with writer (tracking.outputs.write_text: a temporary file renamed), and as
    PDF into pdf_out with pdf_writer when given; returns its summary."""
    summary = summarise(record.estimates, record.frames, *record.span, record.cones, record.cameras, record.stated)
    html = render(record, summary)
    document = pdf(html) if pdf_out is not None else None  # before anything is written: a missing library is named
    writer(out, html)
    if pdf_out is not None and pdf_writer is not None and document is not None:
        pdf_writer(pdf_out, document)
    return summary
