"""What a tracked installation's record says after the lift, read from tables alone (no truth): per cone whether and
when it landed, its concentricity then against the tolerance and how sure, how close it came before and how far it
strayed after, and when it had no number and why; per camera when it delivered frames, saw markers, went silent or
ended. Pure: pandas tables in, frozen dataclasses out; viewer/installation_record.py reads the tables from a
recording or an archive, viewer/report.py draws the page.

The model:
- a cone's concentricity r = |(Δx, Δy)|, the horizontal distance from its target (the tolerance applies to it; Δz is
  the approach), and its σ along the offset's direction, σ_r² = uᵀ C_xy u with u = (Δx, Δy) / r: the tablet's
  (viewer.superintendent.cone_reading);
- a cone has landed when its Δz is at most LANDED_DZ_M and stays so in every later estimate with a number for at
  least LANDED_HOLD_S and to the end of the record; the landing is the first estimate of that last run (a topside
  lifted off and set down again lands at its last set-down);
- its verdict rests on the estimate at landing, as the tablet colours it: within (r + 2σ at most the tolerance),
  at the edge (r within, r + 2σ beyond), outside (r beyond); not landed; or no data (no estimate with a number);
- NO DATA: every run of estimates without a number (their stated reason), and every stretch longer than GAP_S with
  no estimate at all (no camera measured the cone, or no frames came); runs of one reason less than MERGE_S apart
  are one;
- a camera's timeline from its frames: live while frames come no further than CAMERA_GAP_S apart (no markers where
  its frames held none), lost in a longer silence, ended after its last frame when the record goes on; a state the
  live tracker stated (frozen, lost, ended) names the silence it covers.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum

import numpy as np
import pandas as pd

from tracking.estimate import TOLERANCE_M, ConeEstimate

CONFIDENCE_SIGMAS = 2.0  # the verdict's margin, as the tablet's amber (viewer.superintendent.CONFIDENCE_SIGMAS)
LANDED_DZ_M = 0.05  # a landed topside sits within this of its cone tips: bearings and shims (tracking.scale's
# BELOW_CONES_M) and a few σ of Δz (2-7 mm on the simulator's set-downs); a hovering topside is 0.2 m up or more
LANDED_HOLD_S = 1.0  # Δz must stay down this long: one estimate dipping at the end of a record is not a landing
GAP_S = 1.0  # no estimate for this long is NO DATA of its own: at 15 FPS a camera gives one every 67 ms
MERGE_S = 0.5  # a cone shown for less than this between two NO DATA periods of one reason: one period (a cone at
# the σ limit flickers between shown and withheld from frame to frame)
CAMERA_GAP_S = 1.0  # a camera silent this long is lost (tracking.live.LOST_AFTER_S, the live tracker's)
NO_ESTIMATE = "no estimate (no camera measured the cone)"
COLUMNS = ("time", "cone", "dx", "dy", "dz", "sdx", "sdy", "sdz", "cxx", "cxy", "cyy", "cameras", "withheld")


class Verdict(StrEnum):
    """A cone's outcome, worst last."""

    WITHIN = "within tolerance"
    EDGE = "at the edge"  # the concentricity is within, its 2σ bound is not
    OUTSIDE = "OUTSIDE tolerance"
    NOT_LANDED = "not landed"
    NO_DATA = "NO DATA"


class CameraSpan(StrEnum):
    """What a camera was doing over a stretch of the record."""

    LIVE = "live"  # frames with markers
    NO_MARKERS = "no markers"  # frames, none with a marker
    FROZEN = "frozen"  # the live tracker saw the image stop changing
    LOST = "lost"  # no frames for longer than CAMERA_GAP_S
    ENDED = "ended"  # after its last frame, while the record goes on
    NOT_STARTED = "not started"  # before its first frame


@dataclass(frozen=True)
class Moment:
    """A cone's estimate at one time: offset (3,) m, concentricity and its 1σ, m."""

    time: float
    offset: tuple[float, float, float]
    concentricity: float
    sigma: float

    @property
    def bound(self) -> float:
        """The concentricity plus CONFIDENCE_SIGMAS σ, m."""
        return self.concentricity + CONFIDENCE_SIGMAS * self.sigma


@dataclass(frozen=True)
class Period:
    """A stretch of capture time [start, end) and what it was (a NO DATA reason, a camera's state)."""

    start: float
    end: float
    what: str
    detail: str = ""

    @property
    def duration(self) -> float:
        return self.end - self.start


@dataclass(frozen=True)
class ConeSummary:
    """One cone over the record."""

    cone: str
    verdict: Verdict
    landed: Moment | None  # the estimate at landing
    closest: Moment | None  # the smallest concentricity before landing (the whole record when it did not land)
    excursion: Moment | None  # the largest concentricity from landing on
    last: Moment | None  # the newest estimate with a number
    no_data: tuple[Period, ...]
    shown: float  # share of its estimates with a number, 0..1
    estimates: int

    @property
    def headline(self) -> str:
        """The verdict in a few words, with the numbers it rests on (mm)."""
        if self.landed is not None:
            m = self.landed
            return (f"{self.verdict.value}: {m.concentricity * 1e3:.0f} ± {CONFIDENCE_SIGMAS * m.sigma * 1e3:.0f} mm "
                    f"(2σ) of {TOLERANCE_M * 1e3:.0f}")
        if self.last is not None:
            return f"{self.verdict.value}: last {self.last.offset[2]:.2f} m above its cone"
        reasons = sorted({p.what for p in self.no_data})
        return f"{self.verdict.value}: {'; '.join(reasons) or 'no estimate'}"


@dataclass(frozen=True)
class Event:
    """A moment worth opening the recording at."""

    time: float
    subject: str  # a cone or a camera
    what: str


def estimates_table(estimates: list[ConeEstimate]) -> pd.DataFrame:
    """One row per estimate (COLUMNS): offset and 1σ per axis, the horizontal covariance (m²), the cameras (joined by
    spaces) and why it was withheld; rows by time, then cone."""
    rows = []
    for e in estimates:
        cov = e.covariance if e.covariance is not None else np.full((3, 3), np.nan)
        sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
        rows.append((e.time, e.cone, *(float(v) for v in e.offset), *sd, cov[0, 0], cov[0, 1], cov[1, 1],
                     " ".join(e.cameras), e.withheld))
    table = pd.DataFrame(rows, columns=list(COLUMNS))
    return table.sort_values(["time", "cone"], kind="stable").reset_index(drop=True)


def concentricity(table: pd.DataFrame) -> tuple[np.ndarray, np.ndarray]:
    """(r, σ_r) per row, m: NaN where the row has no number (σ NaN where it has no covariance)."""
    dx, dy = table["dx"].to_numpy(float), table["dy"].to_numpy(float)
    r = np.hypot(dx, dy)
    safe = np.where(r > 0, r, 1.0)
    ux, uy = np.where(r > 0, dx / safe, 1.0), np.where(r > 0, dy / safe, 0.0)
    var = ux * ux * table["cxx"].to_numpy(float) + 2 * ux * uy * table["cxy"].to_numpy(float) \
        + uy * uy * table["cyy"].to_numpy(float)
    return r, np.sqrt(np.clip(var, 0.0, None))


def has_number(table: pd.DataFrame) -> np.ndarray:
    """Rows whose offset is known on every axis."""
    return np.isfinite(table[["dx", "dy", "dz"]].to_numpy(float)).all(axis=1)


def _moment(table: pd.DataFrame, r: np.ndarray, s: np.ndarray, i: int) -> Moment:
    row = table.iloc[i]
    return Moment(float(row["time"]), (float(row["dx"]), float(row["dy"]), float(row["dz"])), float(r[i]), float(s[i]))


def landing_index(times: np.ndarray, dz: np.ndarray, known: np.ndarray) -> int | None:
    """The row of the landing: the first of the last run of known rows with Δz ≤ LANDED_DZ_M that reaches the last
    known row and lasts LANDED_HOLD_S; None when the cone did not land."""
    rows = np.flatnonzero(known)
    if not rows.size:
        return None
    down = dz[rows] <= LANDED_DZ_M
    if not down[-1]:
        return None
    up = np.flatnonzero(~down)
    first = rows[up[-1] + 1] if up.size else rows[0]
    return int(first) if times[rows[-1]] - times[first] >= LANDED_HOLD_S else None


def no_data_periods(table: pd.DataFrame, start: float, end: float) -> list[Period]:
    """A cone's NO DATA: runs of rows without a number, by their reason, and stretches over GAP_S without a row
    (before the first, between two, after the last up to end)."""
    times = table["time"].to_numpy(float)
    known = has_number(table)
    reasons = table["withheld"].fillna("").to_numpy(str)
    out: list[Period] = []
    edges = np.concatenate([[start], times, [end]])
    for g in np.flatnonzero(np.diff(edges) > GAP_S):
        out.append(Period(float(edges[g]), float(edges[g + 1]), NO_ESTIMATE))
    k = 0
    while k < len(times):
        if known[k]:
            k += 1
            continue
        why = reasons[k] or "withheld"
        j = k
        while j + 1 < len(times) and not known[j + 1] and (reasons[j + 1] or "withheld") == why \
                and times[j + 1] - times[j] <= GAP_S:
            j += 1
        stop = times[j + 1] if j + 1 < len(times) and times[j + 1] - times[j] <= GAP_S else times[j]
        out.append(Period(float(times[k]), float(max(stop, times[k])), str(why)))
        k = j + 1
    return merged(sorted(out, key=lambda p: p.start))


def merged(periods: list[Period]) -> list[Period]:
    """Periods of one reason less than MERGE_S apart as one (sorted by start)."""
    out: list[Period] = []
    for p in periods:
        same = [k for k, q in enumerate(out) if q.what == p.what and p.start - q.end < MERGE_S]
        if same:
            q = out[same[-1]]
            out[same[-1]] = Period(q.start, max(q.end, p.end), q.what, q.detail)
        else:
            out.append(p)
    return out


def cone_summary(table: pd.DataFrame, cone: str, start: float, end: float) -> ConeSummary:
    """One cone's verdict and events from its rows of an estimates table (COLUMNS) over the record [start, end]."""
    rows = table[table["cone"] == cone].sort_values("time", kind="stable").reset_index(drop=True)
    known = has_number(rows)
    periods = tuple(no_data_periods(rows, start, end))
    if not known.any():
        return ConeSummary(cone, Verdict.NO_DATA, None, None, None, None, periods, 0.0, len(rows))
    r, s = concentricity(rows)
    times = rows["time"].to_numpy(float)
    land = landing_index(times, rows["dz"].to_numpy(float), known)
    last = _moment(rows, r, s, int(np.flatnonzero(known)[-1]))
    before = known & (np.arange(len(rows)) < (land if land is not None else len(rows)))
    closest = _moment(rows, r, s, int(np.flatnonzero(before)[np.argmin(r[before])])) if before.any() else None
    if land is None:
        return ConeSummary(cone, Verdict.NOT_LANDED, None, closest, None, last, periods, float(known.mean()),
                           len(rows))
    after = known & (np.arange(len(rows)) >= land)
    excursion = _moment(rows, r, s, int(np.flatnonzero(after)[np.argmax(r[after])]))
    landed = _moment(rows, r, s, land)
    verdict = (Verdict.OUTSIDE if landed.concentricity > TOLERANCE_M else
               Verdict.EDGE if not landed.bound <= TOLERANCE_M else Verdict.WITHIN)  # a NaN σ is not within
    return ConeSummary(cone, verdict, landed, closest, excursion, last, periods, float(known.mean()), len(rows))


def camera_timeline(frames: pd.DataFrame, start: float, end: float, stated: pd.DataFrame | None = None
                    ) -> list[Period]:
    """One camera's spans over [start, end] from its frames (time, markers: NaN for a frame recorded but not
    searched), and the states the live tracker stated (time, state, detail), which name the silences they fall in."""
    times = frames["time"].to_numpy(float)
    order = np.argsort(times, kind="stable")
    times, markers = times[order], frames["markers"].to_numpy(float)[order]
    said = [] if stated is None else list(stated.sort_values("time").itertuples(index=False))
    out: list[Period] = []

    def silence(a: float, b: float, default: CameraSpan) -> None:
        named = [x for x in said if x.time <= b and x.state in (CameraSpan.FROZEN, CameraSpan.LOST, CameraSpan.ENDED)
                 and x.time >= a - CAMERA_GAP_S]
        state = named[-1].state if named else default
        out.append(Period(a, b, str(state), named[-1].detail if named else f"no frame for {b - a:.1f} s"))

    if not times.size:
        silence(start, end, CameraSpan.NOT_STARTED)
        return out
    if times[0] - start > CAMERA_GAP_S:
        silence(start, float(times[0]), CameraSpan.NOT_STARTED)
    k = 0
    while k < len(times):
        seeing = not markers[k] == 0  # NaN (not searched) counts as live
        j = k
        while j + 1 < len(times) and times[j + 1] - times[j] <= CAMERA_GAP_S and (not markers[j + 1] == 0) == seeing:
            j += 1
        following = times[j + 1] if j + 1 < len(times) and times[j + 1] - times[j] <= CAMERA_GAP_S else times[j]
        out.append(Period(float(times[k]), float(following),
                          str(CameraSpan.LIVE if seeing else CameraSpan.NO_MARKERS),
                          "" if seeing else "frames without a marker"))
        if j + 1 < len(times) and times[j + 1] - times[j] > CAMERA_GAP_S:
            silence(float(times[j]), float(times[j + 1]), CameraSpan.LOST)
        k = j + 1
    if end - times[-1] > CAMERA_GAP_S:
        silence(float(times[-1]), end, CameraSpan.ENDED)
    return out


def seconds(duration: float) -> str:
    """A duration for people: hundredths below a second."""
    return f"{duration:.2f} s" if duration < 1 else f"{duration:.1f} s"


def events(cones: list[ConeSummary], cameras: dict[str, list[Period]]) -> list[Event]:
    """The moments to open the recording at, by time: each cone's closest approach, landing, largest excursion and
    NO DATA periods' starts (the whole-record ones left out), each camera's silences."""
    out: list[Event] = []
    for c in cones:
        if c.closest is not None:
            out.append(Event(c.closest.time, c.cone, f"closest approach before landing: "
                                                     f"{c.closest.concentricity * 1e3:.0f} mm"
                             if c.landed is not None else f"closest approach: {c.closest.concentricity * 1e3:.0f} mm"))
        if c.landed is not None:
            out.append(Event(c.landed.time, c.cone, f"landed: {c.landed.concentricity * 1e3:.0f} ± "
                                                    f"{CONFIDENCE_SIGMAS * c.landed.sigma * 1e3:.0f} mm, "
                                                    f"{c.verdict.value}"))
        if c.excursion is not None and c.landed is not None and c.excursion.time > c.landed.time:
            out.append(Event(c.excursion.time, c.cone, f"largest excursion after landing: "
                                                       f"{c.excursion.concentricity * 1e3:.0f} mm"))
        if c.verdict != Verdict.NO_DATA:
            out += [Event(p.start, c.cone, f"NO DATA for {seconds(p.duration)}: {p.what}") for p in c.no_data]
    for name, spans in cameras.items():
        out += [Event(p.start, name, f"{p.what} for {seconds(p.duration)}" + (f" ({p.detail})" if p.detail else ""))
                for p in spans if p.what in (CameraSpan.LOST, CameraSpan.FROZEN, CameraSpan.ENDED)]
    return sorted(out, key=lambda e: (e.time, e.subject))


@dataclass(frozen=True)
class Summary:
    """The installation: every cone's summary, every camera's timeline, the events, the record's span."""

    cones: tuple[ConeSummary, ...]
    cameras: dict[str, list[Period]]
    events: tuple[Event, ...]
    start: float
    end: float

    @property
    def verdict(self) -> str:
        """One line: did every cone land within the tolerance."""
        counts = {v: sum(c.verdict == v for c in self.cones) for v in Verdict}
        if self.cones and counts[Verdict.WITHIN] == len(self.cones):
            return f"every cone landed within ±{TOLERANCE_M * 1e3:.0f} mm (2σ)"
        parts = [f"{n} {v.value}" for v, n in counts.items() if n]
        return f"{len(self.cones)} cone{'s' if len(self.cones) != 1 else ''}: " + ", ".join(parts)


def summarise(estimates: pd.DataFrame, frames: pd.DataFrame, start: float, end: float,
              cones: list[str] | None = None, cameras: list[str] | None = None,
              stated: pd.DataFrame | None = None) -> Summary:
    """Every cone's summary and every camera's timeline over [start, end]: estimates (COLUMNS), frames (time,
    camera, markers), stated camera states (time, camera, state, detail); cones and cameras default to those in
    the tables."""
    cones = sorted(set(estimates["cone"])) if cones is None else cones
    cameras = sorted(set(frames["camera"])) if cameras is None else cameras
    summaries = tuple(cone_summary(estimates, c, start, end) for c in cones)
    timelines = {name: camera_timeline(frames[frames["camera"] == name], start, end,
                                       None if stated is None else stated[stated["camera"] == name])
                 for name in cameras}
    return Summary(summaries, timelines, tuple(events(list(summaries), timelines)), start, end)
