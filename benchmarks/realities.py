"""Field realities: clocks off by up to ±0.5 s and markers 20 mm and 1° off their survey (the simulator's -realities
variants), tracked with the rig as given (a), after `topside sync` (b), after sync and `topside survey` (c), and with
the perfect rig (the simulator's truth_rig.yaml: true clocks and marker poses). Results:
benchmarks/results/realities.md.

Run: .venv/bin/python benchmarks/realities.py [--only config2-procedure5-realities] [--survey-seconds 60]

Renders and detections are shared with benchmarks/accuracy.py's cache (benchmarks/.cache/, 15 FPS, fog 50 % and
rain 30 %). Every rig's measurements come from the same detections, re-timed by its clocks. A clock common to every
camera cannot be told from footage (the truth's clock is the simulator's): after sync the estimates are on the
reference camera's clock, and are scored on it (their times shifted by the reference's true clock error); the nominal
rig's estimates are scored as stamped.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))

from accuracy import CACHE, detect, frame, render, z_scores

from tracking.clocks import synced_rig, synchronise
from tracking.estimator import ESTIMATORS
from tracking.evaluate import evaluate_runs
from tracking.geometry import rotvec, skew
from tracking.offsets import BodyObservation, PairOffset
from tracking.rig import Rig, load_rig
from tracking.survey import survey_markers, surveyed_rig

REPO = Path(__file__).resolve().parents[1]
RESULTS = REPO / "benchmarks" / "results" / "realities.md"
VARIANTS = ("config2-setdown-realities", "config1-procedure1-realities", "config2-procedure5-realities")
FPS = 15.0
SURVEY_SECONDS = 60.0  # the issue: markers from 60 s of footage before the lift
MODE = "fused"  # the live filter, `topside track`'s default
SYNC_TARGET_S = 0.010
SURVEY_TARGET_M, SURVEY_TARGET_DEG = 0.005, 0.2
CASES = ("nominal", "synced", "surveyed", "exact_clocks_surveyed", "perfect")
CASE_LABEL = {"nominal": "(a) rig as given", "synced": "(b) after sync", "surveyed": "(c) after sync + survey",
              "exact_clocks_surveyed": "(c') true clocks + survey", "perfect": "perfect rig"}


def retimed(detections: list, given: Rig, rig: Rig) -> list:
    """Detections (camera, time on the given rig's clocks, corners) on another rig's clocks, in time order."""
    shift = {c.name: o.time_offset - c.time_offset for c, o in zip(given.cameras, rig.cameras, strict=True)}
    return sorted(((cam, t + shift[cam], corners) for cam, t, corners in detections), key=lambda d: d[1])


def measure_on(rig: Rig, given: Rig, detections: list) -> list:
    """Pair offsets and body observations of the detections, with this rig's markers and clocks."""
    from accuracy import measure

    return measure(rig, retimed(detections, given, rig))


def score(estimates: pd.DataFrame, truth: pd.DataFrame, monitored: list[str], shift: float) -> dict:
    """Per axis e_MAE, |e|max, σ_e at the monitored cones, and the 2σ/3σ coverage of the stated σ."""
    est = estimates[estimates["cone"].isin(monitored)].copy()
    est["time"] = est["time"] + shift
    ev = evaluate_runs("run", [(est, truth)])
    z = np.concatenate(list(z_scores(est, truth).values()) or [np.zeros(0)])
    z = z[np.isfinite(z)]
    shown = est.dropna(subset=["dx"])
    return {"axes": {a: (s.mae, s.max_abs, s.std) for a, s in ev.axes.items()},
            "within2": float(np.mean(z <= 2)) if z.size else float("nan"),
            "beyond3": float(np.mean(z > 3)) if z.size else float("nan"),
            "shown": len(shown) / max(len(est), 1)}


def survey_errors(rig: Rig, truth: Rig) -> list[dict]:
    """Per marker: its centre's and rotation's error against the truth, m and degrees."""
    true = truth.marker_by_id
    out = []
    for m in rig.markers:
        t = true[m.id]
        out.append({"id": m.id, "body": m.body, "centre": np.subtract(m.center, t.center),
                    "tilt": float(np.degrees(np.linalg.norm(rotvec(m.R_body_marker @ t.R_body_marker.T))))})
    return out


def unobservable(given: Rig, truth: Rig, cones: list[str]) -> dict[str, np.ndarray]:
    """Per cone, the offset error (3,) m that no footage can remove: each body's markers moved rigidly together (the
    least-squares rigid motion of its markers' survey errors, centres and tilts weighted by the rig's survey σ) film the
    same as that body moved the other way, so only the prior knows it; the topside's minus the jacket's, at the cone's
    tip (at its topside marker's centre where the rig has no tip)."""
    sp, st = given.survey_sigma.position()[:, None], given.survey_sigma.tilt_rad()[:, None]  # per body axis
    tips = {p.cone: np.array(given.cones.get(p.cone, given.marker_by_id[p.topside].center), float)
            for p in given.all_pairs()}
    moved = {}
    for body in ("jacket", "topside"):
        rows, rhs = [], []
        for m in given.markers:
            if m.body != body:
                continue
            t = truth.marker_by_id[m.id]
            r = np.array(m.center, float)
            rows.append(np.hstack([np.eye(3), -skew(r)]) / sp)  # d = v + φ × r
            rhs.append(np.subtract(t.center, m.center) / sp[:, 0])
            rows.append(np.hstack([np.zeros((3, 3)), np.eye(3)]) / st)  # θ = φ
            rhs.append(rotvec(t.R_body_marker @ m.R_body_marker.T) / st[:, 0])
        moved[body] = np.linalg.lstsq(np.vstack(rows), np.concatenate(rhs), rcond=None)[0]
    out = {}
    for cone in cones:
        at = {b: g[:3] + np.cross(g[3:], tips[cone]) for b, g in moved.items()}
        out[cone] = at["topside"] - at["jacket"]
    return out


def run(name: str, survey_seconds: float) -> dict:
    """One variant: every case's estimates scored, the clocks and markers against the truth, the costs."""
    scene = render(name, FPS)
    given, truth_rig = load_rig(scene / "rig.yaml"), load_rig(scene / "truth_rig.yaml")
    t0 = time.perf_counter()
    detections = detect(name, scene)
    cost_file = scene / "cost.json"
    cost = json.loads(cost_file.read_text()) if cost_file.is_file() else {}
    cost.setdefault("track_s", time.perf_counter() - t0)
    cost_file.write_text(json.dumps(cost))
    truth = pd.read_csv(scene / "truth.csv")
    duration = float(truth["time"].max())
    camera_minutes = len(given.cameras) * duration / 60
    monitored = given.paired_cones()
    rigs: dict[str, Rig] = {"nominal": given}
    timings: dict[str, float] = {}

    t0 = time.perf_counter()
    nominal = measure_on(given, given, detections)
    timings["measure_s"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    clocks = synchronise(given, [m for m in nominal if isinstance(m, PairOffset)])
    timings["sync_s"] = time.perf_counter() - t0
    rigs["synced"] = synced_rig(given, clocks)
    measured = {"nominal": nominal, "synced": measure_on(rigs["synced"], given, detections)}
    start = min(m.time for m in measured["synced"])
    window = [m for m in measured["synced"] if m.time <= start + survey_seconds]
    t0 = time.perf_counter()
    fit = survey_markers(rigs["synced"], window)
    timings["survey_s"] = time.perf_counter() - t0
    window_cams = {m.camera for m in window if isinstance(m, BodyObservation)}
    timings["survey_camera_minutes"] = len(window_cams) * min(survey_seconds, duration) / 60
    rigs["surveyed"] = surveyed_rig(rigs["synced"], fit)
    rigs["perfect"] = truth_rig
    measured["surveyed"] = measure_on(rigs["surveyed"], given, detections)
    measured["perfect"] = measure_on(rigs["perfect"], given, detections)
    # what each step can do with the other's input exact: the survey on true clocks, sync on true marker poses
    true_clocks = given.model_copy(update={"cameras": [c.model_copy(update={"time_offset": t.time_offset,
                                                                            "time_offset_sigma": 0.0})
                                                       for c, t in zip(given.cameras, truth_rig.cameras, strict=True)]})
    on_true_clocks = measure_on(true_clocks, given, detections)
    start = min(m.time for m in on_true_clocks)
    t0 = time.perf_counter()
    exact_fit = survey_markers(true_clocks, [m for m in on_true_clocks if m.time <= start + survey_seconds])
    timings["survey_true_clocks_s"] = time.perf_counter() - t0
    rigs["exact_clocks_surveyed"] = surveyed_rig(true_clocks, exact_fit)
    measured["exact_clocks_surveyed"] = measure_on(rigs["exact_clocks_surveyed"], given, detections)
    ref = next(c.camera for c in clocks if c.reference)
    true_markers = given.model_copy(update={"markers": truth_rig.markers, "survey_sigma": None})
    clocks_true_markers = synchronise(true_markers, [m for m in measure_on(true_markers, given, detections)
                                                     if isinstance(m, PairOffset)], reference=ref)

    error = {c.name: t.time_offset - c.time_offset for c, t in zip(given.cameras, truth_rig.cameras, strict=True)}
    scores = {}
    for case in CASES:
        t0 = time.perf_counter()
        est = frame(list(ESTIMATORS[MODE](rigs[case], measured[case])))
        timings[f"filter_{case}_s"] = time.perf_counter() - t0
        shift = error[ref] if case in ("synced", "surveyed") else 0.0
        scores[case] = score(est, truth, monitored, shift)
    sync_rows = []
    for c, e in zip(clocks, clocks_true_markers, strict=True):
        true = error[c.camera] - error[ref]
        sync_rows.append({"camera": c.camera, "true": true, "before": -true if not c.reference else 0.0,
                          "after": (c.change - true) if c.known else -true, "sigma": c.sigma, "known": c.known,
                          "reference": c.reference, "note": c.note,
                          "exact_markers": (e.change - true, e.sigma if e.known else None, e.note)})
    return {"name": name, "duration": duration, "cameras": len(given.cameras), "camera_minutes": camera_minutes,
            "monitored": monitored, "scores": scores, "sync": sync_rows, "cost": {**cost, **timings},
            "floor": unobservable(given, truth_rig, monitored),
            "survey_before": survey_errors(given, truth_rig),
            "survey_after": survey_errors(rigs["surveyed"], truth_rig),
            "survey_fit": {"frames": fit.frames, "rms_px": fit.rms_px, "iterations": fit.iterations,
                           "seconds": min(survey_seconds, duration),
                           "learnt": {s.id: s.learnt for s in fit.markers}}}


def accuracy_table(r: dict) -> list[str]:
    lines = [f"### Accuracy at the monitored cones ({', '.join(r['monitored'])}), live filter", "",
             "| rig | axis | e_MAE [mm] | abs(e)max [mm] | σ_e [mm] | within 2σ | beyond 3σ | shown |",
             "| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: |"]
    for case in CASES:
        s = r["scores"][case]
        for k, (axis, (mae, emax, sd)) in enumerate(s["axes"].items()):
            cov = (f"{s['within2']:.1%} | {s['beyond3']:.2%} | {s['shown']:.0%}" if k == 0 else " | | ")
            lines.append(f"| {CASE_LABEL[case] if k == 0 else ''} | {axis} | {mae * 1e3:.1f} | {emax * 1e3:.1f} | "
                         f"{sd * 1e3:.1f} | {cov} |")
    perfect = r["scores"]["perfect"]["axes"]
    for case in ("surveyed", "exact_clocks_surveyed"):
        ratio = [r["scores"][case]["axes"][a][0] / perfect[a][0] for a in perfect]
        lines += ["", f"{CASE_LABEL[case].split(' ')[0]} against the perfect rig, e_MAE per axis: "
                      f"{' / '.join(f'{x:.2f}x' for x in ratio)} (target ≤ 1.5x: "
                      f"{'met' if max(ratio) <= 1.5 else '**not met**'})."]
    return lines


def sync_table(r: dict) -> list[str]:
    lines = ["### Clocks (against the reference's, ms)", "",
             "| camera | true error | after sync | stated σ | within 10 ms | note | sync with the true marker poses |",
             "| --- | ---: | ---: | ---: | --- | --- | --- |"]
    for s in r["sync"]:
        sigma = "—" if s["sigma"] is None or not s["known"] else f"{s['sigma'] * 1e3:.1f}"
        ok = "reference" if s["reference"] else ("yes" if abs(s["after"]) <= SYNC_TARGET_S else "**no**")
        off, exact_sigma, exact_note = s["exact_markers"]
        exact = ("" if s["reference"] else f"{off * 1e3:+.1f} (σ {exact_sigma * 1e3:.1f})" if exact_sigma is not None
                 else f"not measured: {exact_note}")
        lines.append(f"| {s['camera']} | {s['true'] * 1e3:+.1f} | {s['after'] * 1e3:+.1f} | {sigma} | {ok} | "
                     f"{'' if s['known'] else 'not measured: ' + s['note']} | {exact} |")
    return lines


def floor_table(r: dict) -> list[str]:
    """The error no footage can remove, against the target's 1.5x of the perfect rig's e_MAE."""
    floor = np.abs(np.array(list(r["floor"].values())))  # (cones, 3)
    perfect = r["scores"]["perfect"]["axes"]
    lines = ["### What no footage can tell", "",
             "Each body's markers moved together (the rigid part of their survey errors, weighed by the rig's survey "
             "σ) film exactly as that body moved the other way, so no camera, clock or solver can tell it: only a "
             "datum surveyed to the millimetre can. Its offset at each monitored cone, topside's minus jacket's, "
             "is a bias that `topside survey` cannot remove (the tracker's σ holds it: the rig's `survey_sigma`).", "",
             "| axis | " + " | ".join(f"cone {c} [mm]" for c in r["floor"]) + " | mean [mm] | 1.5x perfect e_MAE [mm] "
             "| target reachable |", "| --- | " + " | ".join("---:" for _ in r["floor"]) + " | ---: | ---: | --- |"]
    for k, axis in enumerate(perfect):
        mean = float(floor[:, k].mean())
        bound = 1.5 * perfect[axis][0]
        lines.append(f"| {axis} | " + " | ".join(f"{v * 1e3:.1f}" for v in floor[:, k]) +
                     f" | {mean * 1e3:.1f} | {bound * 1e3:.1f} | {'yes' if mean <= bound else '**no**'} |")
    return lines


def survey_table(r: dict) -> list[str]:
    f = r["survey_fit"]
    lines = [f"### Markers (first {f['seconds']:.0f} s, {f['frames']} camera frames, RMS {f['rms_px']:.2f} px, "
             f"{f['iterations']} iterations)", "",
             "| marker | body | centre error before [mm] | after [mm] | tilt before [°] | after [°] | σ cut by | "
             "within 5 mm / 0.2° |", "| ---: | --- | ---: | ---: | ---: | ---: | ---: | --- |"]
    for b, a in zip(r["survey_before"], r["survey_after"], strict=True):
        ok = np.linalg.norm(a["centre"]) <= SURVEY_TARGET_M and a["tilt"] <= SURVEY_TARGET_DEG
        lines.append(f"| {b['id']} | {b['body']} | {np.linalg.norm(b['centre']) * 1e3:.1f} | "
                     f"{np.linalg.norm(a['centre']) * 1e3:.1f} | {b['tilt']:.2f} | {a['tilt']:.2f} | "
                     f"{f['learnt'][b['id']]:.0%} | {'yes' if ok else '**no**'} |")
    return lines


def cost_line(r: dict) -> str:
    c, cm = r["cost"], r["camera_minutes"]
    return (f"Cost, seconds per camera-minute ({r['cameras']} cameras × {r['duration']:.0f} s = {cm:.1f} "
            f"camera-minutes; 2 cores shared): detection {c['track_s'] / cm:.1f} (shared by every command that reads "
            "the videos), "
            f"measurement {c['measure_s'] / cm:.1f}, sync's fit {c['sync_s'] / cm:.2f}, survey's fit "
            f"{c['survey_s'] / max(c['survey_camera_minutes'], 1e-9):.1f} (on its {c['survey_camera_minutes']:.1f} "
            f"camera-minutes), the live filter {c['filter_nominal_s'] / cm:.1f}.")


def header(survey_seconds: float) -> list[str]:
    return ["# Field realities: clocks off, markers off their survey", "",
            "The simulator's `-realities` variants, with fog 50 % and rain 30 %, 920×600 at 15 FPS (CRF 22): every "
            "camera's clock off by a uniform draw within ±0.5 s, every marker's centre off its surveyed position by "
            "σ 20 mm per axis and its face turned by σ 1° per axis; the rig the tracker gets has the nominal clocks "
            "(stating `time_offset_sigma` 0.29 s, the draw's σ) and poses, and states `survey_sigma: {position_m: "
            "0.02, tilt_deg: 1.0}`. Tracked by the live filter (`topside track`'s default) with (a) that rig, (b) the "
            "rig `topside sync` writes, (c) the rig `topside survey` then writes from the first "
            f"{survey_seconds:.0f} s (or the whole run when shorter), and the perfect rig (true clocks and marker "
            "poses, no survey σ). Each step with the other's input exact: (c') the survey on the true clocks, and "
            "in the clocks table sync on the true marker poses. After sync the estimates are on the reference "
            "camera's clock and are scored on it "
            "(a clock common to every camera cannot be told from footage); (a) is scored as stamped. Errors at the "
            "monitored cones, over the estimates shown; within 2σ / beyond 3σ: the reported axis-samples whose error "
            "is within twice / beyond three times their stated σ (an honest σ: ≥ 90 % and ≤ 2 %); shown: the share of "
            "estimates not withheld (σ above 50 mm). The filter carries each marker's survey σ as a consider state "
            "and widens σ by the topside's motion over the largest clock σ of the cameras an estimate rests on, so "
            "where clocks are not measured and the topside moves, few estimates are shown and e_MAE covers only "
            "those. Reproduce: `.venv/bin/python benchmarks/realities.py` (renders and detections shared "
            "with benchmarks/accuracy.py's cache).", ""]


def section_file(name: str) -> Path:
    """Where a variant's section of the results is kept until every variant has one."""
    return CACHE / f"realities-{name}.md"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", action="append", choices=VARIANTS)
    parser.add_argument("--survey-seconds", type=float, default=SURVEY_SECONDS)
    parser.add_argument("--combine", action="store_true", help="only write the results from the kept sections")
    args = parser.parse_args()
    for name in [] if args.combine else args.only or VARIANTS:
        t0 = time.perf_counter()
        r = run(name, args.survey_seconds)
        print(f"{name}: {time.perf_counter() - t0:.0f} s", flush=True)
        lines = [f"## {name} ({r['duration']:.0f} s, {r['cameras']} cameras)", "", *accuracy_table(r), "",
                 *floor_table(r), "", *sync_table(r), "", *survey_table(r), "", cost_line(r), ""]
        print("\n".join(lines), flush=True)
        section_file(name).write_text("\n".join(lines))
    sections = [section_file(n).read_text() for n in VARIANTS if section_file(n).is_file()]
    missing = [n for n in VARIANTS if not section_file(n).is_file()]
    if missing:
        print(f"results not written: no section yet for {', '.join(missing)}")
        return
    from tracking.outputs import write_text

    write_text(RESULTS, "\n".join(header(args.survey_seconds) + sections))
    print(f"wrote {RESULTS}")


if __name__ == "__main__":
    main()
