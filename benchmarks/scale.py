"""Offline tracking at scale: frames per second on 1 and 2 local workers and on Ray in local mode, Ray's overhead per
task and the chunk size that amortises it, memory per worker, the cost per frame beside plain OpenCV's, and the wall
time of a six-hour eight-camera installation and of 100 installations projected from these costs.

Scene: `config2-procedure5-weather` (the demo's: three drones and a stern camera, fog 50 %, rain 30 %) at 15 FPS,
920×600, cached by benchmarks/scenes.py. Each timed run tracks every camera in chunks (tracking.parallel, the default
CHUNK_FRAMES) and fuses them on this process (the fused mode, offsets to a CSV), as `topside track` does: start-up
(spawning the workers or starting Ray, and importing the tracker in them) is timed apart from the run itself. The CSV
of every run is compared with the one-worker run's. Load average (`uptime`) is recorded before and after every timed
run: the machine is shared, and a load above its cores makes every number here slower and the speed-ups smaller.

Then the fusion split over time (benchmarks/scale_split.py): a long eight-camera installation tracked with 1 and 2
workers, fused in one pass and split; the split's agreement with the one pass per lead-in; the driver's own cost per
frame; and the projection of one six-hour, eight-camera installation on 1, 8 and 64 nodes.

Run: .venv/bin/python -m benchmarks.scale [--seconds 40] [--repeats 3] [--long-seconds 480 | --no-long]
Results: benchmarks/results/scale.md
"""

from __future__ import annotations

import argparse
import math
import os
import pickle
import platform
import statistics
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

from benchmarks import scale_split
from benchmarks.report import write_results
from benchmarks.scenes import render_scene
from tracking.detection import DEFAULT_REFINEMENT
from tracking.estimator import ESTIMATORS
from tracking.images import frames
from tracking.offsets_csv import write_offsets_csv
from tracking.parallel import (
    CHUNK_FRAMES,
    ChunkTask,
    InPlace,
    LocalPool,
    RayRunner,
    peak_rss_mb,
    plan_rig,
    run_chunk,
    track_chunks,
)
from tracking.pipeline import CameraTracker, TrackStats, track_rig
from tracking.rig import load_rig

SCENARIO = "config2-procedure5-weather"
SIZE = (920, 600)
FPS = 15.0
HOURS = 6.0  # the projected installation: six hours of eight cameras at 15 FPS
CAMERAS = 8
INSTALLATIONS = 100
NODES = (1, 8, 64)
CORES_PER_NODE = 16
AMORTISED = 0.01  # a chunk is long enough when its fixed costs are this share of its work


def load() -> float:
    """The 1-minute load average."""
    return os.getloadavg()[0]


def track_once(rig_path: Path, run, csv: Path) -> dict:
    """One timed run of the offline path on a started runner (None: pipeline.track_rig, one process with OpenCV's
    and the decoder's own threads, as `track` was before chunks): wall and this process's CPU, frames, markers."""
    rig = load_rig(rig_path)
    stats = TrackStats()
    sched: list = []
    before = load()
    t0, c0 = time.perf_counter(), time.process_time()
    source = track_rig(rig, stats=stats) if run is None else \
        track_chunks(rig, run, stats=stats, scheduler=sched, lean=True)  # a CSV alone: lean, as `track` does

    def measurements():
        for r in source:
            stats.add(r)
            yield from r.offsets
            if r.observation is not None:
                yield r.observation

    write_offsets_csv(csv, ESTIMATORS["fused"](rig, measurements()))
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    done = sched[0].done if sched else []
    return {"wall": wall, "main_cpu": cpu, "frames": sum(stats.frames.values()),
            "markers": sum(stats.markers.values()), "load": (before, load()), "chunks": len(done),
            "worker_cpu": sum(r.cpu_seconds for r in done) if done else cpu,
            "worker_rss": max((r.max_rss_mb for r in done), default=peak_rss_mb()),
            "workers": len({r.worker for r in done}), "csv": csv.read_bytes()}


CONFIGS = (("1 worker (--workers 1)", InPlace), ("2 workers (--workers 2)", lambda: LocalPool(2)),
           ("Ray local mode, 2 CPUs (--ray)", lambda: RayRunner("local", 2)),
           ("before: one process, OpenCV's own threads", lambda: None))


def configurations(rig_path: Path, repeats: int, work: Path) -> list[dict]:
    """1 worker (in this process), 2 worker processes, Ray local mode with 2 CPUs, and one process as before, taken
    in turn `repeats` times (a change of the machine's load falls on all of them): start-up, then the timed run."""
    out = [{"name": name, "startup": [], "runs": []} for name, _ in CONFIGS]
    for k in range(repeats):
        for (name, make), cfg in zip(CONFIGS, out, strict=True):
            t0 = time.perf_counter()
            run = make()
            if hasattr(run, "warm"):
                run.warm()
            cfg["startup"].append(time.perf_counter() - t0)
            try:
                r = track_once(rig_path, run, work / f"{name[:8]}-{k}.csv")
            finally:
                if run is not None:
                    run.close()
            print(f"{name}: {r['frames'] / r['wall']:.1f} frames/s ({r['wall']:.1f} s, load {r['load'][0]:.1f} -> "
                  f"{r['load'][1]:.1f})", flush=True)
            cfg["runs"].append(r)
    for cfg in out:
        cfg["best"] = min(cfg["runs"], key=lambda r: r["wall"])
        cfg["median_wall"] = statistics.median(r["wall"] for r in cfg["runs"])
        cfg["startup"] = statistics.median(cfg["startup"])
    return out


def ray_overhead(rig_path: Path, n: int = 200) -> dict:
    """Ray's cost per task in local mode: a round trip of an empty task, the throughput of many, and moving one
    chunk's results (pickled size of a real CHUNK_FRAMES chunk) through the object store."""
    import ray

    from tracking.parallel import ready

    rig = load_rig(rig_path)
    plan = plan_rig(rig)[0]
    chunk = plan.chunks[0]
    result = run_chunk(ChunkTask(Path(rig.path), chunk))
    payload = pickle.dumps(result)
    run = RayRunner("local", 2)
    try:
        run.warm()
        remote = ray.remote(num_cpus=1)(ready)
        t0 = time.perf_counter()
        for k in range(n // 4):
            ray.get(remote.remote(k))
        round_trip = (time.perf_counter() - t0) / (n // 4)
        t0 = time.perf_counter()
        ray.get([remote.remote(k) for k in range(n)])
        throughput = (time.perf_counter() - t0) / n  # seconds per task with 2 CPUs busy

        echo = ray.remote(num_cpus=1)(_echo)
        t0 = time.perf_counter()
        for _ in range(10):
            ray.get(echo.remote(result))
        moved = (time.perf_counter() - t0) / 10
    finally:
        run.close()
    return {"round_trip": round_trip, "per_task": throughput * 2, "payload_mb": len(payload) / 2**20,
            "payload_frames": len(result.results), "moved": moved}


def _echo(x: object) -> object:
    return x


def chunk_fixed_cost(rig_path: Path, repeats: int = 5) -> float:
    """Seconds a chunk costs before its first frame: the tracker built (calibration, detector) and the video opened
    at a keyframe, in a warm process."""
    from tracking.images import decoded_frames, open_video

    rig = load_rig(rig_path)
    plan = plan_rig(rig)[0]
    entry = next(c for c in rig.cameras if c.name == plan.camera)
    chunk = plan.chunks[-1]
    times = []
    for _ in range(repeats):
        t0 = time.process_time()
        CameraTracker.from_rig(rig, entry, DEFAULT_REFINEMENT)
        with open_video(rig.resolve(entry.source)) as container:
            next(iter(decoded_frames(container, entry.source, chunk=(chunk.start_pts, 1))))
        times.append(time.process_time() - t0)
    return statistics.median(times)


def per_frame_costs(rig_path: Path) -> dict:
    """CPU ms per frame of each stage of the offline path in one thread, and plain OpenCV's (PyAV decoding to grey,
    then the default ArucoDetector's detectMarkers) on the same videos, with the markers each finds."""
    from tracking.detection import detections, find_quads
    from tracking.offsets import observe_bodies
    from tracking.pose import estimate_pose

    rig = load_rig(rig_path)
    cost = dict.fromkeys(("decode", "opening and rain test", "plain pass", "rain pass", "edge fit", "poses",
                          "plain OpenCV: decode", "plain OpenCV: detectMarkers"), 0.0)
    found = {"topside": 0, "topside (rig markers)": 0, "plain OpenCV": 0, "plain OpenCV (rig markers)": 0}
    n = rainy = 0
    plain = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, rig.dictionary)),
                                    cv2.aruco.DetectorParameters())
    import av

    for entry in rig.cameras:
        tracker = CameraTracker.from_rig(rig, entry, DEFAULT_REFINEMENT)
        det = tracker.detector
        path = rig.resolve(entry.source)
        t = time.process_time()
        grays = [f for f in frames(path, entry.time_offset)]
        cost["decode"] += time.process_time() - t
        for f in grays:
            g = f.gray
            t = time.process_time()
            opened = det.opening(g)
            rain = det.rainy(g, opened)
            t1 = time.process_time()
            quads, ids, _ = find_quads(det._detector, g)
            t2 = time.process_time()
            if rain:
                q2, i2, _ = find_quads(det._detector, opened)
                extra = ~np.isin(i2, ids)
                quads, ids = np.concatenate([quads, q2[extra]]), np.concatenate([ids, i2[extra]])
            t3 = time.process_time()
            if len(ids):
                quads = det.refine(g, opened, quads)[0]
            t4 = time.process_time()
            d = detections(quads, ids, [])
            poses = {m.id: estimate_pose(m, tracker.camera, rig.marker_size) for m in d.markers
                     if m.id in tracker.markers}
            observe_bodies(tracker.bodies, poses, tracker.camera, entry.name, f.time, rig.marker_size)
            t5 = time.process_time()
            cost["opening and rain test"] += t1 - t
            cost["plain pass"] += t2 - t1
            cost["rain pass"] += t3 - t2
            cost["edge fit"] += t4 - t3
            cost["poses"] += t5 - t4
            found["topside"] += len(d.markers)
            found["topside (rig markers)"] += len(poses)
            rainy += rain
            n += 1
        t = time.process_time()
        with av.open(str(path)) as container:
            stream = container.streams.video[0]
            plain_grays = [fr.to_ndarray(format="gray") for fr in container.decode(stream)]
        cost["plain OpenCV: decode"] += time.process_time() - t
        t = time.process_time()
        for g in plain_grays:
            _, ids, _ = plain.detectMarkers(g)
            ids = [] if ids is None else ids.reshape(-1).tolist()
            found["plain OpenCV"] += len(ids)
            found["plain OpenCV (rig markers)"] += sum(i in rig.marker_by_id for i in ids)
        cost["plain OpenCV: detectMarkers"] += time.process_time() - t
    return {"ms": {k: 1000 * v / n for k, v in cost.items()}, "found": found, "frames": n, "rainy": rainy}


def fusion_cost(rig_path: Path) -> float:
    """CPU ms per frame of the fused filter alone on this process (measurements made beforehand)."""
    rig = load_rig(rig_path)
    results = list(track_chunks(rig, InPlace()))
    measurements = [m for r in results for m in r.measurements]
    t = time.process_time()
    for _ in ESTIMATORS["fused"](rig, iter(measurements)):
        pass
    return 1000 * (time.process_time() - t) / len(results)


def profile_top(rig_path: Path, lines: int = 16) -> list[str]:
    """pyinstrument's view of one camera's first chunk tracked in one thread: the call tree's top lines."""
    from pyinstrument import Profiler

    rig = load_rig(rig_path)
    plan = plan_rig(rig)[0]
    profiler = Profiler(interval=0.001)
    profiler.start()
    run_chunk(ChunkTask(Path(rig.path), plan.chunks[0]))
    profiler.stop()
    text = profiler.output_text(unicode=False, color=False, short_mode=True).splitlines()
    start = next((i for i, ln in enumerate(text) if "run_chunk" in ln), 0)
    return [ln.rstrip() for ln in text[start:start + lines] if ln.strip()]


def project(c_worker: float, f_main: float, overhead: float, chunk_fixed: float, chunk: int, efficiency: float
            ) -> list[tuple[str, int, int, int, float, str]]:
    """Wall time of one installation and of INSTALLATIONS on 1, 8, 64 nodes: (what, nodes, cores, installations
    fused at once, s, bound by)."""
    frames = HOURS * 3600 * FPS * CAMERAS
    per_frame = c_worker * (1 + (overhead + chunk_fixed) / (chunk * c_worker)) / efficiency  # core-seconds per frame
    out = []
    for what, installs in (("one installation, one pass", 1), (f"{INSTALLATIONS} installations", INSTALLATIONS)):
        for nodes in NODES:
            cores = nodes * CORES_PER_NODE
            drivers = min(installs, math.ceil(cores * f_main / (per_frame + f_main)))  # the drivers' share of the cores
            compute = installs * frames * (per_frame + f_main) / cores
            driver = math.ceil(installs / drivers) * frames * f_main
            bound = "fusion on the driver" if driver > compute else "tracking on the workers"
            out.append((what, nodes, cores, drivers, max(compute, driver), bound))
    return out


def _autogroup() -> str:
    """Whether the kernel groups the CPU's shares by session."""
    try:
        return "on" if Path("/proc/sys/kernel/sched_autogroup_enabled").read_text().strip() == "1" else "off"
    except OSError:
        return "unknown"


def hours(s: float) -> str:
    return f"{s / 3600:.1f} h" if s >= 3600 else f"{s / 60:.0f} min"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=40.0)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--long-seconds", type=float, default=scale_split.LONG_SECONDS)
    parser.add_argument("--no-long", action="store_true", help="Leave out the long installation (the split).")
    args = parser.parse_args()
    scene = render_scene(SCENARIO, SIZE, args.seconds, FPS)
    rig_path = scene / "rig.yaml"
    plans = plan_rig(load_rig(rig_path))
    start_load = load()
    print(f"scene {scene.name}: {sum(p.frames for p in plans)} frames, {sum(len(p.chunks) for p in plans)} chunks; "
          f"load {start_load:.1f}", flush=True)
    with tempfile.TemporaryDirectory() as tmp:
        configs = configurations(rig_path, args.repeats, Path(tmp))
    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)  # the stages alone, in one thread as in a worker
    costs = per_frame_costs(rig_path)
    cv2.setNumThreads(threads)
    fusion = fusion_cost(rig_path)
    overhead = ray_overhead(rig_path)
    fixed = chunk_fixed_cost(rig_path)
    top = profile_top(rig_path)
    long = None
    if not args.no_long:
        with tempfile.TemporaryDirectory() as tmp:
            long = scale_split.measure(Path(tmp), args.long_seconds)
    end_load = load()

    one, two, ray_cfg, _ = (c["best"] for c in configs)
    identical = all(r["csv"] == one["csv"] for c in configs for r in c["runs"])
    speedup2 = one["wall"] / two["wall"]
    ray_vs = ray_cfg["wall"] / two["wall"] - 1
    c_worker = one["worker_cpu"] / one["frames"]  # one thread, CPU s per frame in the worker
    f_main = two["main_cpu"] / two["frames"]  # the main process's CPU per frame with two workers
    chunk_ms = c_worker * CHUNK_FRAMES * 1000
    amortise = math.ceil((overhead["per_task"] + fixed) / (AMORTISED * c_worker))
    loads = [r["load"] for c in configs for r in c["runs"]]
    busiest = max(max(a, b) for a, b in loads)
    cores = os.cpu_count() or 1

    lines = [
        "# Offline tracking at scale",
        "",
        f"`benchmarks/scale.py`, {time.strftime('%Y-%m-%d %H:%M')}, {platform.machine()}, {cores} cores, python "
        f"{platform.python_version()}: {args.seconds:g} s of `{SCENARIO}` at {FPS:g} FPS, {SIZE[0]}×{SIZE[1]}, "
        f"{len(plans)} cameras ({one['frames']} frames, {sum(len(p.chunks) for p in plans)} chunks of "
        f"≥ {CHUNK_FRAMES} frames starting at keyframes). Tracked in chunks and fused (fused mode, offsets CSV) as "
        "`topside track --workers N` / `--ray` does; each configuration run in turn, "
        f"{args.repeats} rounds, the best and the median; start-up (median) timed apart.",
        "",
        f"**Load average (1 min) during the timed runs: {min(min(a, b) for a, b in loads):.1f} to {busiest:.1f}** "
        f"on {cores} cores, this benchmark's own busy processes (1 to 3) included (start of the benchmark "
        f"{start_load:.1f}, end {end_load:.1f})"
        + (". The machine was **not quiet**: other jobs took cores, so the speed-ups below are lower than on an idle "
           "machine. Under load they also mislead: Linux shares the CPU between sessions (autogroup "
           f"{_autogroup()}), so two workers in the command's session may get little more of it than one, while Ray's "
           "workers, started in a session of their own, get a share of their own."
           if busiest > cores + 0.5 else ": quiet (no more than its own processes)."),
        "",
        "| runs on | start-up s | run s (best; median) | frames/s | × 1 worker | main process CPU ms/frame | "
        "peak RSS per worker MB | same CSV as 1 worker |",
        "|---|---:|---:|---:|---:|---:|---:|---|",
    ]
    for c in configs:
        b = c["best"]
        lines.append(f"| {c['name']} | {c['startup']:.1f} | {b['wall']:.1f}; {c['median_wall']:.1f} | "
                     f"{b['frames'] / b['wall']:.1f} | {one['wall'] / b['wall']:.2f} | "
                     f"{1000 * b['main_cpu'] / b['frames']:.2f} | {b['worker_rss']:.0f} | "
                     f"{'yes' if all(r['csv'] == one['csv'] for r in c['runs']) else 'NO'} |")
    lines += [
        "",
        f"- Targets: 2 workers ≥ 1.8× one worker: **{speedup2:.2f}×** ({'met' if speedup2 >= 1.8 else 'NOT met'}); "
        f"Ray local mode within 15 % of `--workers 2`: **{100 * ray_vs:+.1f} %** "
        f"({'met' if abs(ray_vs) <= 0.15 else 'NOT met'}); identical outputs: **{'yes' if identical else 'NO'}** "
        "(every run's CSV byte for byte; the .rrd and MCAP are compared by tests/tracking/test_parallel.py).",
        "- *1 worker* runs the chunks in this process, one after the other, on one core (OpenCV and the decoder on "
        "one thread, as in every worker); its peak RSS is this whole process (fusion included). *before*: "
        "`pipeline.track_rig`, the cameras merged in one process with OpenCV's and the decoder's own threads, as "
        "`track` ran before chunks. *Main process CPU*: merging, fusion and the CSV, plus receiving the workers' "
        "results.",
        "- *Start-up*: spawning the worker processes and importing the tracker in them, or starting Ray (`ray.init`, "
        "local) and its workers. `topside track` pays it once per command, `topside batch` once per manifest.",
        "",
        "## Ray's overhead per task",
        "",
        "| what | measured |",
        "|---|---:|",
        f"| round trip of an empty task (submit, run, get), one at a time | {1000 * overhead['round_trip']:.2f} ms |",
        f"| an empty task, many in flight on 2 CPUs (CPU time per task) | {1000 * overhead['per_task']:.2f} ms |",
        f"| a {overhead['payload_frames']}-frame chunk's results: pickled size | {overhead['payload_mb']:.2f} MB |",
        f"| ... sent to a task and back through the object store | {1000 * overhead['moved']:.1f} ms |",
        f"| a chunk's own fixed cost (tracker built, video opened at its keyframe) | {1000 * fixed:.1f} ms |",
        f"| a frame tracked in a worker (decode, detection, poses; one thread) | {1000 * c_worker:.2f} ms |",
        "",
        f"A chunk of the default {CHUNK_FRAMES} frames is {chunk_ms / 1000:.1f} s of work; Ray's per-task cost and the "
        f"chunk's own fixed cost ({1000 * (overhead['per_task'] + fixed):.0f} ms together) are "
        f"{100 * (overhead['per_task'] + fixed) / (chunk_ms / 1000):.1f} % of it. They fall below "
        f"{100 * AMORTISED:g} % from **{amortise} frames** a chunk; longer chunks only balance the load worse "
        "(a camera's last chunk waits for its slowest).",
        "",
        "## The cost per frame, beside plain OpenCV",
        "",
        f"One thread, CPU ms per frame over all {costs['frames']} frames of the scene's cameras "
        f"({costs['rainy']} of them with rain detected, so the second pass ran). Plain OpenCV: PyAV decoding to grey "
        "(`to_ndarray(format='gray')`) and `cv2.aruco.ArucoDetector(dictionary, DetectorParameters())."
        "detectMarkers`, in the same run.",
        "",
        "| stage | topside ms/frame | plain OpenCV ms/frame |",
        "|---|---:|---:|",
        f"| decode to grey | {costs['ms']['decode']:.2f} | {costs['ms']['plain OpenCV: decode']:.2f} |",
        f"| grey opening and rain test | {costs['ms']['opening and rain test']:.2f} | — |",
        f"| detection, plain pass | {costs['ms']['plain pass']:.2f} | "
        f"{costs['ms']['plain OpenCV: detectMarkers']:.2f} |",
        f"| detection, rain pass (frames with rain only) | {costs['ms']['rain pass']:.2f} | — |",
        f"| corner edge fit | {costs['ms']['edge fit']:.2f} | — |",
        f"| poses, pair offsets, body observation | {costs['ms']['poses']:.2f} | — |",
        f"| fusion (main process) | {fusion:.2f} | — |",
    ]
    ours = sum(v for k, v in costs["ms"].items() if not k.startswith("plain OpenCV")) + fusion
    theirs = costs["ms"]["plain OpenCV: decode"] + costs["ms"]["plain OpenCV: detectMarkers"]
    found = costs["found"]
    lines += [
        f"| **total** | **{ours:.2f}** | **{theirs:.2f}** |",
        f"| markers found (all ids) | {found['topside']} | {found['plain OpenCV']} |",
        f"| markers found (rig markers) | {found['topside (rig markers)']} "
        f"({found['topside (rig markers)'] / max(found['plain OpenCV (rig markers)'], 1):.1f}×) | "
        f"{found['plain OpenCV (rig markers)']} |",
        "",
        "The rain pass runs only on frames where rain is detected (over 0.3 % of the pixels 25 grey levels above the "
        "grey opening); without rain it is skipped and detection costs about half (on three 4 s clips, markers and "
        "corners identical to both passes on every one of 1398 frames).",
        "",
        "pyinstrument, one camera's first chunk in one thread (seconds):",
        "",
        "```",
        *top,
        "```",
        "",
        "## Projected wall time",
        "",
        f"Model: an installation is {HOURS:g} h × {CAMERAS} cameras × {FPS:g} FPS = "
        f"{HOURS * 3600 * FPS * CAMERAS / 1e6:.2f} M frames. Tracking costs "
        f"c = {1000 * c_worker:.2f} ms of a core per frame (measured above, one worker), plus per chunk of "
        f"{CHUNK_FRAMES} frames Ray's {1000 * overhead['per_task']:.1f} ms and the chunk's {1000 * fixed:.0f} ms, "
        f"divided by the parallel efficiency measured here with 2 workers ({speedup2 / 2:.2f}). Fusion is "
        f"sequential: one driver per installation spends f = {1000 * f_main:.2f} ms per frame "
        "(the main process's CPU with 2 workers: merging, receiving results, fusion, CSV). Installations are fused "
        "D at a time, D = ⌈cores × f / (c + f)⌉ (the drivers' share of the cores), each on a core of its own. Wall "
        "time = the larger of all the CPU over all the cores (installations × frames × (c + f) / cores) and the "
        "drivers' time (⌈installations / D⌉ × frames × f). Assumed: videos on storage every node reads at the "
        "needed rate (8 cameras at 1.6 Mbit/s: 13 Mbit/s per installation in real time; flat out a core reads "
        "~1 MB/s, 1024 cores ~1 GB/s), nodes as fast as this machine's cores, results sent to the drivers as fast "
        "as measured here (0.85 MB per 160-frame chunk), no failures or stragglers; memory per node: a worker per "
        "core at the peak RSS above, and D drivers.",
        "",
        "| what | nodes × 16 cores | fused at once (D) | wall time | bound by |",
        "|---|---:|---:|---:|---|",
    ]
    rows = project(c_worker, f_main, overhead["per_task"], fixed, CHUNK_FRAMES, speedup2 / 2)
    for what, nodes, ncores, drivers, seconds, bound in rows:
        lines.append(f"| {what} | {nodes} ({ncores} cores) | {drivers} | {hours(seconds)} | {bound} |")
    single = HOURS * 3600 * FPS * CAMERAS * f_main
    lines += [
        "",
        f"Fused in one pass (`--one-pass-fusion`, and every run before the split), one installation cannot take "
        f"less than its fusion, {hours(single)} ({1 / f_main:.0f} frames/s on one core), however many cores track "
        "its chunks: the filter applies every measurement in capture-time order. The split over time (below) "
        "fuses its segments on the workers too; a campaign of many installations scales with the nodes (several "
        "`batch --ray ADDRESS` commands against one cluster give the D drivers of this model).",
    ]
    if long is not None:
        lines += ["", *scale_split.section(long, (overhead["per_task"] + fixed) / CHUNK_FRAMES, speedup2 / 2)]
    write_results("scale", lines, echo=True)


if __name__ == "__main__":
    main()
