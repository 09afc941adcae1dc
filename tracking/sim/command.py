"""`topside simulate`: render a scenario into videos, rig, calibration files and ground truth."""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

from tracking.camera import CameraModel, save_camera
from tracking.errors import InputError
from tracking.outputs import check_writable, discard, partial_dir, replace_dir
from tracking.rig import CameraEntry, save_rig
from tracking.sim.motion import CranePath
from tracking.sim.render import CameraRenderer
from tracking.sim.scenario import CameraSpec, Scenario, dump_scenario, load_scenario, validate_scenario
from tracking.sim.truth import frame_rows, truth_table, write_frames
from tracking.sim.video import TIME_BASE, VideoWriter, pts_of
from tracking.sim.world import World

MAX_START_OFFSET = 0.5  # s: cameras start up to this late on the common clock
CLOCK_STREAM = 23  # seed stream of the cameras' clock errors (one generator per camera)
CAMERA_SURVEY_STREAM = 31  # seed stream of the cameras' survey errors (one generator per camera)
MOUNTS = {"stern": "vessel", "fixed": "fixed", "drone": "drone"}  # a camera kind's mount in the rig
TRUTH_RIG_FILE = "truth_rig.yaml"  # the rig with the true clocks and marker poses: for benchmarks, never the tracker
SCENARIO_FILE = "scenario.yaml"  # written last: a folder holding it is a finished simulation's


@dataclass(frozen=True)
class FramePlan:
    """When one camera captures: common-clock times and PTS of the frames it keeps."""

    capture_times: np.ndarray
    pts: np.ndarray  # ticks of TIME_BASE
    time_offset: float


def frame_seed(seed: int, cam_index: int, k: int) -> int:
    """Reproducible per-frame seed for noise and rain."""
    return int(np.random.SeedSequence([seed, 17, cam_index, k]).generate_state(1)[0])


def plan_frames(cam: CameraSpec, index: int, duration: float, seed: int) -> FramePlan:
    """Capture times of a camera: its own start offset, its frame rate, occasional lost frames."""
    rng = np.random.default_rng([seed, 19, index])
    offset = cam.time_offset if cam.time_offset is not None else round(float(rng.uniform(0, MAX_START_OFFSET)), 6)
    n = int(np.floor((duration - offset) * cam.fps + 1e-9)) + 1 if duration >= offset else 0
    ticks = np.array([pts_of(k / cam.fps) for k in range(n)], dtype=np.int64)
    keep = rng.random(n) >= cam.drop_rate
    keep[:1] = True
    ticks = ticks[keep]
    return FramePlan(offset + ticks * float(TIME_BASE), ticks, offset)


def clock_error(sc: Scenario, index: int, seed: int) -> float:
    """How far camera index's clock is off: true time_offset minus the rig's, s (uniform within ±sc.clock_error_s)."""
    if sc.clock_error_s == 0.0:
        return 0.0
    return round(float(np.random.default_rng([seed, CLOCK_STREAM, index]).uniform(-1.0, 1.0)) * sc.clock_error_s, 6)


def effective_duration(scenario: Scenario, duration: float | None) -> float:
    """The run's length: the cut, else the scenario's duration, else the procedure's own length."""
    full = scenario.duration or CranePath.from_spec(scenario.motion).length
    return min(duration, full) if duration is not None else full


def camera_model(cam: CameraSpec) -> CameraModel:
    """The true camera model of a camera spec: exact, so its stated RMS reprojection error is 0."""
    K = np.array([[cam.K[0], 0, cam.K[2]], [0, cam.K[1], cam.K[3]], [0, 0, 1.0]])
    return CameraModel(K=K, dist=np.array(cam.dist, float), width=cam.width, height=cam.height, rms=0.0)


def _progress() -> Progress:
    return Progress(TextColumn("[bold]{task.description}"), BarColumn(), MofNCompleteColumn(),
                    TextColumn("{task.fields[fps]:.1f} frames/s"), TimeRemainingColumn())


def check_out_folder(out: Path, scenario: str) -> None:
    """A one-line error unless out is new, empty, or an earlier simulation's folder that holds no input of this run."""
    if out.exists() and not out.is_dir():
        raise InputError(out, "is a file (expected a folder to write the simulation into)", "--out")
    if out.is_dir() and any(out.iterdir()) and not (out / SCENARIO_FILE).is_file():
        raise InputError(out, f"holds other files (expected a new or empty folder, or an earlier simulation's, "
                              f"which has {SCENARIO_FILE})", "--out")
    source = Path(scenario)
    if source.is_file() and out.is_dir() and source.resolve().is_relative_to(out.resolve()):
        raise InputError(out, f"holds the scenario {source} that this run reads (expected another folder)", "--out")
    check_writable(out, "--out")


def run_simulate(scenario: str, out: Path, seed: int | None = None, duration: float | None = None,
                 quiet: bool = False, clock_error_s: float | None = None,
                 survey_error: tuple[float, float] | None = None) -> dict[str, float]:
    """Render a scenario (YAML file or built-in name) into out; returns timing figures. clock_error_s and survey_error
    (σ of a marker's centre in m and of its tilt in degrees) replace the scenario's.

    Everything is written into a temporary folder beside out, which replaces out (new, empty, or an earlier
    simulation's) only once complete: a failure or Ctrl-C leaves out as it was."""
    sc = load_scenario(scenario)
    if seed is not None:
        sc = sc.model_copy(update={"seed": seed})
    if clock_error_s is not None:
        sc = validate_scenario({**sc.model_dump(mode="json"), "clock_error_s": clock_error_s}, "--clock-error")
    if survey_error is not None:
        error = {"position_m": survey_error[0], "tilt_deg": survey_error[1]}
        sc = validate_scenario({**sc.model_dump(mode="json"), "survey_error": error}, "--survey-error")
    if duration is not None and duration <= 0:
        raise InputError("--duration", f"must be positive, got {duration}")
    out = Path(out)
    check_out_folder(out, scenario)
    partial = partial_dir(out)
    try:
        if sc.calibration is not None:
            from tracking.sim.calibration_shots import write_calibration_shots

            write_calibration_shots(sc, partial, quiet=quiet)
            (partial / SCENARIO_FILE).write_text(dump_scenario(sc))
            figures: dict[str, float] = {}
        else:
            figures = render_scenario(sc, partial, effective_duration(sc, duration), quiet=quiet)
    except BaseException:
        discard(partial)
        raise
    replace_dir(partial, out)
    return figures


def camera_survey(sc: Scenario, index: int) -> dict:
    """The rig's surveyed position of camera index (its optical centre at rest, off by a normal draw of its
    position_sigma per axis) and that σ; empty without a survey."""
    cam = sc.cameras[index]
    if cam.position_sigma is None:
        return {}
    error = np.random.default_rng([sc.seed, CAMERA_SURVEY_STREAM, index]).normal(0.0, cam.position_sigma, 3)
    return {"position": (np.array(cam.position) + error).round(4).tolist(), "position_sigma": cam.position_sigma}


def write_rigs(sc: Scenario, world: World, out: Path) -> None:
    """The rig the tracker gets (nominal clocks and marker poses) and the true one (TRUTH_RIG_FILE) of a scenario whose
    cameras carry their true time_offset."""
    entries = [CameraEntry(name=c.name, calibration=f"calibration/{c.name}.yaml", source=f"{c.name}.mp4",
                           time_offset=c.time_offset or 0.0, mount=MOUNTS[c.kind], **camera_survey(sc, i))
               for i, c in enumerate(sc.cameras)]
    exact = [e.model_copy(update={"position": c.position}) if c.position_sigma else e
             for e, c in zip(entries, sc.cameras, strict=True)]
    save_rig(out / TRUTH_RIG_FILE, world.rig(exact, true=True))
    stated = {"time_offset_sigma": round(sc.clock_error_s / np.sqrt(3.0), 6)} if sc.clock_error_s else {}  # uniform
    nominal = [e.model_copy(update={"time_offset": round(e.time_offset - clock_error(sc, i, sc.seed), 6), **stated})
               for i, e in enumerate(entries)]  # what the installation believes its clocks are, and how well
    save_rig(out / "rig.yaml", world.rig(nominal))


def render_scenario(sc: Scenario, out: Path, duration: float, quiet: bool = False) -> dict[str, float]:
    """Write videos, calibration, rig, truth and the scenario for one run."""
    world = World(sc, duration, sc.seed)
    plans = [plan_frames(cam, i, duration, sc.seed) for i, cam in enumerate(sc.cameras)]
    cams = [cam.model_copy(update={"time_offset": plan.time_offset})
            for cam, plan in zip(sc.cameras, plans, strict=True)]
    sc = sc.model_copy(update={"cameras": cams, "duration": duration})
    (out / "calibration").mkdir(exist_ok=True)
    total = sum(len(p.pts) for p in plans)
    rows: list[list] = []
    render_s = encode_s = 0.0
    with _progress() as progress:
        task = progress.add_task("rendering", total=total, fps=0.0, visible=not quiet)
        done, t_start = 0, time.perf_counter()
        for ci, (cam, plan) in enumerate(zip(cams, plans, strict=True)):
            model = camera_model(cam)
            save_camera(out / "calibration" / f"{cam.name}.yaml", model)
            renderer = CameraRenderer(cam, world.bodies, world.textures, sc.weather, world.light,
                                      sc.layout.sea_z, seed=sc.seed * 1000 + ci)
            writer = VideoWriter(out / f"{cam.name}.mp4", cam.width, cam.height, cam.fps, sc.weather.crf,
                                 sc.weather.preset)
            progress.update(task, description=f"rendering {cam.name}")
            for k, (t, pts) in enumerate(zip(plan.capture_times, plan.pts, strict=True)):
                t0 = time.perf_counter()
                state = world.frame_state(cam, float(t), frame_seed(sc.seed, ci, k))
                img, unoccluded = renderer.render(state)
                t1 = time.perf_counter()
                writer.write(img, int(pts))
                encode_s += time.perf_counter() - t1
                render_s += t1 - t0
                rows += frame_rows(world, cam, model.K, model.dist, state.T_jacket_camera, state.T_jacket_body,
                                   unoccluded, k, float(pts * TIME_BASE), float(t))
                done += 1
                progress.update(task, advance=1, fps=done / (time.perf_counter() - t_start))
            writer.close()
    write_rigs(sc, world, out)
    times = np.arange(0.0, duration + 1e-9, 1.0 / sc.truth_rate)
    truth_table(world, times).to_csv(out / "truth.csv", index=False, float_format="%.6f")
    write_frames(out / "truth_frames.csv", rows)
    (out / SCENARIO_FILE).write_text(dump_scenario(sc))
    return {"frames": float(total), "render_s": render_s, "encode_s": encode_s}
