"""`topside check` on a simulated clip: a sound rig passes; a swapped id, a centre 0.3 m off, a wrong face, a blind
cone and a wrong camera survey are each flagged by name; clocks; the command's exit codes and its recording."""

from __future__ import annotations

import copy
import dataclasses
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

from tests.synthetic import simulated_once
from tracking.camera import UNSTATED_RMS_PX
from tracking.check import (
    CameraCheck,
    CameraRun,
    CheckReport,
    MarkerSight,
    camera_clock,
    check_runs,
    cone_checks,
    run_cameras,
)
from tracking.estimate import ConeEstimate
from tracking.estimator.noise import TILT_FLOOR_RAD
from tracking.images import VideoHealth
from tracking.pipeline import CameraTracker
from tracking.rig import load_rig

SCENARIO = "config2-procedure5"  # A by a stern camera (34 m) and a drone, D by two drones; the topside still 5 s
DURATION_S = 6.0
SECONDS = 5.0
TOPSIDE = [sys.executable, "-m", "tracking.cli"]


@pytest.fixture(scope="session")
def clip(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Every test here shares one simulated clip."""
    return simulated_once(tmp_path_factory, SCENARIO, DURATION_S)


@pytest.fixture(scope="module")
def runs(clip: Path) -> dict[str, CameraRun]:
    """Every camera's first SECONDS, detected once with the simulation's own rig."""
    return run_cameras(load_rig(clip / "rig.yaml"), SECONDS)


def rig_file(clip: Path, folder: Path, change=None, name: str = "rig.yaml") -> Path:
    """The clip's rig, changed as a rigger might have entered it wrongly, written into folder (paths made absolute)."""
    data = yaml.safe_load((clip / "rig.yaml").read_text())
    for cam in data["cameras"]:
        cam["source"], cam["calibration"] = str(clip / cam["source"]), str(clip / cam["calibration"])
    if change is not None:
        change(data)
    (folder / name).write_text(yaml.safe_dump(data, sort_keys=False))
    return folder / name


def checked(clip: Path, runs: dict[str, CameraRun], folder: Path, change=None) -> CheckReport:
    """The check of a changed rig on the clip's frames: their detections measured again with that rig (detection does
    not depend on the rig's geometry; CameraTracker.measure is what process does after detecting)."""
    rig = load_rig(rig_file(clip, folder, change))
    again = {}
    for name, run in runs.items():
        entry = next(c for c in rig.cameras if c.name == name)
        tracker = CameraTracker(rig, entry, run.tracker.camera, run.tracker.detector)
        again[name] = dataclasses.replace(run, tracker=tracker,
                                          results=[tracker.measure(r.frame, r.detections) for r in run.results])
    return check_runs(rig, again, SECONDS)


def markers(data: dict) -> dict[int, dict]:
    return {m["id"]: m for m in data["markers"]}


def only_a_and_d(data: dict) -> None:
    """The clip's rig without cones B and C (no marker there: their σ rests on the topside's rotation)."""
    data["cones"] = {k: v for k, v in data["cones"].items() if k in "AD"}


STERN_SURVEY_SIGMA_M = 0.1  # a stern camera surveyed as a crew would (total station, the vessel at rest)


def surveyed(clip: Path):
    """A change to the clip's rig: the stern camera surveyed where it is (truth.csv), to STERN_SURVEY_SIGMA_M."""
    truth = pd.read_csv(clip / "truth.csv").iloc[0][["camera_stern_A_x", "camera_stern_A_y",
                                                     "camera_stern_A_z"]].to_numpy(float)

    def change(data: dict) -> None:
        data["cameras"][0].update(position=truth.tolist(), position_sigma=STERN_SURVEY_SIGMA_M)
    return change


def sound(clip: Path):
    """A change to the clip's rig that makes it sound: cones A and D, and the stern camera surveyed. Cone A rests on
    that camera's depth from its markers' size, 34 m off at 4.6 px a cell: unsurveyed, 5 s of frames leave it at σ
    28 mm, above the 25 mm a ready cone has (its views' persistent errors do not average away)."""
    return lambda data: (only_a_and_d(data), surveyed(clip)(data))


def named(report: CheckReport) -> set[int]:
    return set(report.disagreeing_markers)


# --- a sound rig ------------------------------------------------------------------------------------------------------

def test_a_sound_rig_is_ready(clip: Path, runs: dict[str, CameraRun], tmp_path: Path) -> None:
    unsurveyed = checked(clip, runs, tmp_path, only_a_and_d)
    [problem] = unsurveyed.problems()
    assert problem.startswith("cone A: weak: seen by drone_A, stern_A; σ 2") and "above the 25 mm" in problem
    report = checked(clip, runs, tmp_path, sound(clip))
    assert report.ready, report.problems()
    assert not report.disagreements
    assert [(c.cone, c.verdict) for c in report.cones] == [("A", "ready"), ("D", "ready")]
    assert {c.cone: c.cameras for c in report.cones} == {"A": ("drone_A", "stern_A"), "D": ("drone_D1", "drone_D2")}
    for cone in report.cones:
        assert 0.002 < cone.sigma_m.max() <= 0.025
    seen = {c.camera: {s.marker for s in c.sights if s.counts} for c in report.cameras}
    assert seen == {"stern_A": {0, 1}, "drone_A": {2, 3}, "drone_D1": {4, 5}, "drone_D2": {6, 7}}
    stern = next(c for c in report.cameras if c.camera == "stern_A")
    sight = next(s for s in stern.sights if s.marker == 0)
    assert sight.distance_m == pytest.approx(34.0, abs=0.5)  # the stern camera at y = -45, the marker at -11.1
    assert sight.angle_deg < 10 and 4 < sight.cell_px < 6 and sight.reprojection_px < 0.2
    truth = pd.read_csv(clip / "truth.csv").iloc[0]
    assert stern.T_jacket_camera is not None  # placed where the filter has it, within a few cm of the truth
    assert np.linalg.norm(stern.T_jacket_camera[:3, 3] - truth[["camera_stern_A_x", "camera_stern_A_y",
                                                                 "camera_stern_A_z"]].to_numpy(float)) < 0.1
    for c in report.cameras:
        assert not c.clock.problems and c.clock.declared_fps == 30.0 and c.clock.frames >= 145


def test_cones_without_markers_are_weak_and_a_far_one_blind(clip: Path, runs: dict[str, CameraRun],
                                                             tmp_path: Path) -> None:
    """Cones B and C (no marker: the topside's rotation) show σ over 25 mm after 5 s; a cone 160 m off stays above the
    report limit: blind, by name."""
    def far_cone(data: dict) -> None:
        data["cones"]["E"] = [-150.0, 0.0, 1.5]

    report = checked(clip, runs, tmp_path, lambda data: (surveyed(clip)(data), far_cone(data)))
    verdicts = {c.cone: c for c in report.cones}
    assert {k: v.verdict for k, v in verdicts.items()} == {"A": "ready", "B": "weak", "C": "weak", "D": "ready",
                                                           "E": "blind"}
    assert verdicts["E"].sigma_m.max() > 0.05
    assert verdicts["E"].reason.startswith("no marker at E: from the topside's rigid pose")
    assert "above the 50 mm report limit: it would show NO DATA" in verdicts["E"].reason  # whole: no pair
    for cone, lever in (("B", 25), ("C", 25), ("E", 163)):  # x 12-13.1 m, the topside markers at A and D along y
        assert "tilt about the line through its topside markers at A and D" in verdicts[cone].reason
        said = re.search(r"(\d+) m off, each milliradian misread moves it (\d+) mm; the tracker allows that tilt "
                         rf"{TILT_FLOOR_RAD * 1000:g} mrad at least: σ about (\d+) mm there$", verdicts[cone].reason)
        assert said and int(said[1]) == int(said[2]) == lever
        assert abs(int(said[3]) - lever * TILT_FLOOR_RAD * 1000) <= 1  # the tracker's floor on that tilt's σ
        assert verdicts[cone].sigma_m.max() >= 0.95 * int(said[3]) / 1000  # the filter's σ holds it
    assert "tilt" not in verdicts["A"].reason + verdicts["D"].reason
    assert "cone E: blind: no marker at E" in "\n".join(report.problems())
    assert not report.disagreements and not report.ready


def test_a_cone_shown_on_some_axes_says_which_are_withheld(clip: Path) -> None:
    """A cone one camera sees square on, its depth's σ above the limit: the filter withheld Δx alone, and the verdict
    names it (an estimate withheld whole says NO DATA alone, as above)."""
    rig = load_rig(clip / "rig.yaml")
    cone = rig.paired_cones()[0]
    topside = next(m.id for m in rig.markers if m.cone == cone and m.body == "topside")
    sight = MarkerSight("stern_A", topside, 70, 1.0, 34.0, 5.0, 6.0, 0.1)
    e = ConeEstimate(10.0, cone, np.array([np.nan, 0.01, 0.2]), ("stern_A",), np.diag([0.06, 0.005, 0.005]) ** 2,
                     withheld="σ too large")
    [verdict] = [c for c in cone_checks(rig, [e], [sight]) if c.cone == cone]
    assert verdict.verdict == "weak" and "it would show NO DATA on Δx (its other axes alone)" in verdict.reason


# --- planted faults -----------------------------------------------------------------------------------------------

def test_swapped_ids_are_named(clip: Path, runs: dict[str, CameraRun], tmp_path: Path) -> None:
    """Jacket markers 0 (A/ahead) and 2 (A/port) entered with each other's ids (pairs kept consistent)."""
    def swap(data: dict) -> None:
        only_a_and_d(data)
        ms = markers(data)
        ms[0]["id"], ms[2]["id"] = 2, 0
        for p in data["pairs"]:
            p["jacket"] = {0: 2, 2: 0}.get(p["jacket"], p["jacket"])

    report = checked(clip, runs, tmp_path, swap)
    assert {0, 2} <= named(report) and not report.ready
    tilts = {d.camera: d for d in report.disagreements if d.normal_deg > 45 and not d.against}
    assert set(tilts) == {"stern_A", "drone_A"}  # each sees one jacket and one topside marker: the topside tilts 90°
    assert 0 in tilts["stern_A"].markers and 2 in tilts["drone_A"].markers


def test_a_centre_off_by_0_3_m_is_named(clip: Path, runs: dict[str, CameraRun], tmp_path: Path) -> None:
    """Jacket marker 6 (D/astern) entered 0.3 m higher than it is (its pair's mated entered to match)."""
    def raise_six(data: dict) -> None:
        only_a_and_d(data)
        markers(data)[6]["center"][2] += 0.3
        next(p for p in data["pairs"] if p["jacket"] == 6)["mated"][2] -= 0.3

    report = checked(clip, runs, tmp_path, raise_six)
    assert 6 in named(report) and named(report) <= {4, 5, 6, 7}
    (finding,) = report.disagreements
    assert finding.offset_m == pytest.approx(0.3, abs=0.05) and finding.offset_m > 5 * finding.sigma_m
    assert f"disagree on cone D's offset by {finding.offset_m:.2f} m" in finding.reason  # the number it tested above


def test_a_wrong_face_is_named(clip: Path, runs: dict[str, CameraRun], tmp_path: Path) -> None:
    """Topside marker 7 (D/astern) entered on the port face."""
    def port_seven(data: dict) -> None:
        sound(clip)(data)
        markers(data)[7]["face"] = "port"

    report = checked(clip, runs, tmp_path, port_seven)
    assert 7 in named(report) and named(report) <= {4, 5, 6, 7}
    tilt = next(d for d in report.disagreements if d.camera == "drone_D2")
    assert tilt.normal_deg == pytest.approx(90, abs=10)
    assert "marker 7 (topside D/port)" in tilt.reason


def test_a_turned_marker_the_rig_does_not_know_is_named(clip: Path, runs: dict[str, CameraRun],
                                                         tmp_path: Path) -> None:
    """The rig says topside marker 5 is mounted turned 90°; it is upright."""
    def turn_five(data: dict) -> None:
        only_a_and_d(data)
        markers(data)[5]["rotation_deg"] = 90.0

    report = checked(clip, runs, tmp_path, turn_five)
    assert 5 in named(report) and not report.ready


def test_a_camera_survey_against_its_markers(clip: Path, runs: dict[str, CameraRun], tmp_path: Path) -> None:
    """stern_A's surveyed position: right (within 0.3 m, used) or 3 m off (refused and reported)."""
    truth = pd.read_csv(clip / "truth.csv").iloc[0][["camera_stern_A_x", "camera_stern_A_y",
                                                     "camera_stern_A_z"]].to_numpy(float)

    def surveyed(offset: list[float]):
        def change(data: dict) -> None:
            only_a_and_d(data)
            data["cameras"][0].update(position=(truth + offset).tolist(), position_sigma=0.2)
        return change

    good = checked(clip, runs, tmp_path, surveyed([0.0, 0.0, 0.0]))
    stern = next(c for c in good.cameras if c.camera == "stern_A")
    assert not stern.survey_conflict and stern.survey_m is not None and stern.survey_m < 0.3 and good.ready
    bad = checked(clip, runs, tmp_path, surveyed([0.0, 3.0, 0.0]))
    stern = next(c for c in bad.cameras if c.camera == "stern_A")
    assert stern.survey_conflict and stern.survey_m == pytest.approx(3.0, abs=0.5)
    assert any(p.startswith("stern_A: its surveyed position is") for p in bad.problems()) and not bad.ready


# --- clocks -----------------------------------------------------------------------------------------------------------

def health(fps: float) -> VideoHealth:
    return VideoHealth(source="cam.mp4", interval_s=1.0 / fps)


def test_a_clock_at_its_rate_with_a_dropped_frame() -> None:
    times = np.delete(np.arange(150) / 30.0, 40)
    clock = camera_clock("cam", times, health(30.0))
    assert clock.dropped == 1 and clock.irregular == 0 and clock.measured_fps == pytest.approx(30.0)
    assert not clock.problems


def test_clock_problems() -> None:
    slow = camera_clock("cam", np.arange(120) / 25.0, health(30.0))  # declares 30, delivers 25: every step 1.2
    assert slow.measured_fps == pytest.approx(25.0) and "runs at 25.000 fps, not the 30.000" in slow.problems[0]
    drifting = camera_clock("cam", np.arange(150) / 30.3, health(30.0))  # 1 % fast
    assert drifting.measured_fps == pytest.approx(30.3) and "runs at 30.300 fps, not the 30.000" in drifting.problems[0]
    gappy = camera_clock("cam", np.arange(0, 300, 2) / 30.0, health(30.0))  # every other frame lost
    assert gappy.dropped == 149 and "149 of 299 frames dropped" in gappy.problems[0]
    jitter = np.arange(150) / 30.0 + np.random.default_rng(0).uniform(-0.012, 0.012, 150)
    assert camera_clock("cam", jitter, health(30.0)).irregular > 10
    assert camera_clock("cam", np.array([1.0]), health(30.0)).problems == ["1 frame: no interval to measure"]



def test_a_camera_whose_rig_markers_were_all_dropped_as_mirrored_says_so_not_that_it_saw_none() -> None:
    clock = camera_clock("drone2", np.arange(150) / 30.0, health(30.0))
    mirrored = CameraCheck("drone2", clock, (), {}, None, unplaced="no rig marker in any of its frames", mirrored=(8,))
    assert mirrored.problems == ["drone2: never placed, so none of its frames is used: its rig markers (8) were seen "
                                 "only mirrored (the board's back, or a reflection) and nothing confirmed them: a "
                                 "marker of another id in its view would"]
    blind = dataclasses.replace(mirrored, mirrored=())
    assert blind.problems == ["drone2: sees no marker of the rig in 150 frames"]


# --- the command ------------------------------------------------------------------------------------------------------

def test_the_command_flags_a_wrong_face_and_records_the_installation(clip: Path, tmp_path: Path) -> None:
    def port_seven(data: dict) -> None:
        sound(clip)(data)
        markers(data)[7]["face"] = "port"

    rig = rig_file(clip, tmp_path, port_seven)
    rrd = tmp_path / "check.rrd"
    proc = subprocess.run([*TOPSIDE, "check", "--rig", str(rig), "--seconds", str(SECONDS), "--rrd", str(rrd)],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    out = proc.stdout
    assert "disagrees: drone_D2: its jacket markers [6] and topside markers [7] put the topside" in out
    assert "marker 7 (topside D/port)" in out and "NOT READY" in out and "markers 6, 7 disagree" in out
    assert "cone A: ready: seen by drone_A, stern_A" in out
    assert "next: correct the rig where a marker was entered wrongly" in out
    assert f"topside survey --rig {rig} -o surveyed.yaml" in out
    assert "topside sync" not in out  # the clip's clocks keep their rate and the rig states none uncertain
    assert f"wrote {rrd}" in out

    from viewer.readback import chunks_by_entity

    entities = set(chunks_by_entity(rrd))
    for name in ("stern_A", "drone_A", "drone_D1", "drone_D2"):
        assert {f"/world/cameras/{name}", f"/world/cameras/{name}/image", f"/world/estimated/{name}"} <= entities
    assert {"/world/jacket/markers/6", "/world/topside/markers/7/face", "/world/jacket/stabbing_cones", "/check",
            "/world/topside"} <= entities


def test_the_command_passes_a_sound_rig(clip: Path, tmp_path: Path) -> None:
    rig = rig_file(clip, tmp_path, sound(clip))
    proc = subprocess.run([*TOPSIDE, "check", "--rig", str(rig), "--seconds", str(SECONDS)], capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "READY: every cone is ready and every marker agrees with the rig" in proc.stdout


@pytest.mark.parametrize(("args", "fragment"), [
    (["--seconds", "0"], "--seconds"),
    (["--seconds", "nan"], "--seconds"),
    (["--rrd", "RIG"], "is an input of this command"),
])
def test_the_command_refuses_bad_input(clip: Path, tmp_path: Path, args: list[str], fragment: str) -> None:
    rig = rig_file(clip, tmp_path)
    proc = subprocess.run([*TOPSIDE, "check", "--rig", str(rig), *[str(rig) if a == "RIG" else a for a in args]],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2 and fragment in proc.stderr and len(proc.stderr.strip().splitlines()) == 1, \
        proc.stderr


def test_a_rig_with_a_bad_orientation_is_refused_in_one_line(clip: Path, tmp_path: Path) -> None:
    def not_a_rotation(data: dict) -> None:
        markers(data)[3]["R"] = [[1, 0, 0], [0, 1, 0], [0, 0, 2]]

    rig = rig_file(clip, tmp_path, not_a_rotation)
    proc = subprocess.run([*TOPSIDE, "check", "--rig", str(rig)], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2 and "markers[3].R: not orthonormal" in proc.stderr, proc.stderr


def test_copy_is_deep() -> None:
    """(Guards the helpers: a rig change never leaks into the next test's rig.)"""
    data = {"markers": [{"id": 1, "center": [0.0, 0.0, 0.0]}]}
    copied = copy.deepcopy(data)
    markers(copied)[1]["center"][2] += 1
    assert data["markers"][0]["center"][2] == 0.0


# --- the markers' size, and cameras never placed ----------------------------------------------------------------------

def test_a_wrong_marker_size_is_named_before_anything_it_causes(clip: Path, runs: dict[str, CameraRun],
                                                                 tmp_path: Path) -> None:
    """The plate's side (1.5 m) entered as marker_size with stern_A surveyed: the first finding names the marker size
    (the survey then looks 17 m off, which it also says); without a survey nothing fixes the scale, and a warning says
    so; 0.1 m puts the topside through its cones."""
    truth = pd.read_csv(clip / "truth.csv").iloc[0][["camera_stern_A_x", "camera_stern_A_y",
                                                     "camera_stern_A_z"]].to_numpy(float)

    def size(value: float, survey: bool):
        def change(data: dict) -> None:
            only_a_and_d(data)
            data["marker_size"] = value
            if survey:
                data["cameras"][0].update(position=truth.tolist(), position_sigma=0.2)
        return change

    surveyed = checked(clip, runs, tmp_path, size(1.5, True))
    assert not surveyed.ready and surveyed.problems()[0].startswith("marker_size: the markers look 0.67× their stated")
    plain = checked(clip, runs, tmp_path, size(1.0, False))
    assert any("nothing fixes the scale" in w for w in plain.warnings)  # and nothing else is wrong but A's σ (above)
    assert [p.startswith("cone A: weak") for p in plain.problems()] == [True]
    through = checked(clip, runs, tmp_path, size(0.1, False))
    assert not through.ready and set(through.below) == {"A", "D"} and min(through.below.values()) < -1.0
    assert any("below its cone tip" in p for p in through.problems())


def test_a_camera_never_placed_says_why(clip: Path, runs: dict[str, CameraRun], tmp_path: Path) -> None:
    """Cone A's jacket markers left out of the rig: stern_A and drone_A see no jacket marker of it, are never placed,
    and the check says so and why, a line each."""
    def change(data: dict) -> None:
        only_a_and_d(data)
        data["markers"] = [m for m in data["markers"] if m["id"] not in (0, 2)]
        data["pairs"] = [p for p in data["pairs"] if p["jacket"] not in (0, 2)]

    report = checked(clip, runs, tmp_path, change)
    unplaced = {c.camera: c.unplaced for c in report.cameras if c.unplaced}
    assert set(unplaced) == {"stern_A", "drone_A"}
    assert all(why.startswith("no jacket marker of the rig in its view") for why in unplaced.values())
    assert sum(p.startswith(("stern_A: never placed", "drone_A: never placed")) for p in report.problems()) == 2


def test_the_command_prints_a_rig_error_first(clip: Path, tmp_path: Path) -> None:
    """A marker size of 0.1 m for the 1 m markers: check prints the rig error right after its header, exits 1."""
    def tiny(data: dict) -> None:
        only_a_and_d(data)
        data["marker_size"] = 0.1

    rig = rig_file(clip, tmp_path, tiny)
    proc = subprocess.run([*TOPSIDE, "check", "--rig", str(rig), "--seconds", "2"], capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    lines = proc.stdout.splitlines()
    assert lines[0].startswith("checked ") and lines[1].startswith("rig error: cone A: the offset puts the topside")
    assert "nothing fixes the scale" in proc.stderr and "NOT READY" in proc.stdout


def test_a_single_cameras_depth_is_named_as_the_reason(clip: Path) -> None:
    """A cone whose σ lies along its one camera's line of sight: the reason says so and what would measure that axis;
    a σ across the view, or two cameras, say nothing of depth."""
    from tracking.check import depth_reason
    from tracking.estimate import ConeEstimate

    rig = load_rig(clip / "rig.yaml")
    camera = np.eye(4)
    camera[:3, 3] = np.array(rig.cones["A"]) + np.array([0.0, -40.0, 0.0])
    along = np.diag([1e-4, 4e-3, 1e-4])  # σ 63 mm along y, the camera's line of sight to A
    estimate = ConeEstimate(0.0, "A", np.zeros(3), ("stern_A",), along, {"stern_A": camera})
    assert "along stern_A's line of sight, 40 m" in depth_reason(estimate, ("stern_A",), rig, "A")
    across = dataclasses.replace(estimate, covariance=np.diag([4e-3, 1e-4, 1e-4]))
    assert depth_reason(across, ("stern_A",), rig, "A") == ""
    assert depth_reason(estimate, ("stern_A", "drone_A"), rig, "A") == ""



def test_a_calibrations_stated_error_is_named_where_it_holds_the_cone_up() -> None:
    """The camera whose calibration error alone leaves the most of a cone's σ is named, with that σ, when it is half
    the σ or more (a calibration that states none, with the error taken for it); nothing otherwise."""
    from tracking.camera import CameraModel
    from tracking.check import LENS_NOTE_SHARE, lens_reason

    lens = {"cam_1": np.array([0.03, 0.02, 0.0]), "cam_2": np.array([0.005, 0.005, 0.005])}
    K = np.array([[2000.0, 0, 460], [0, 2000.0, 300], [0, 0, 1]])
    calibrations = {"cam_1": CameraModel(K, np.zeros(5), 920, 600, rms=0.9),
                    "cam_2": CameraModel(K, np.zeros(5), 920, 600, rms=0.3)}
    text = lens_reason(lens, calibrations, worst=0.04)
    assert "cam_1's calibration states 0.90 px RMS error" in text and "σ 30 mm" in text
    unstated = {**calibrations, "cam_1": dataclasses.replace(calibrations["cam_1"], rms=None)}
    assert "cam_1's calibration states no error, taken as 0.50 px RMS error" in lens_reason(lens, unstated, 0.04)
    assert lens_reason(lens, calibrations, worst=0.031 / LENS_NOTE_SHARE) == ""
    assert lens_reason({}, calibrations, worst=0.04) == ""
    fitted = lens_reason(lens, calibrations, 0.04, used={"cam_1": 1.2})  # its fits leave more than it states
    assert "cam_1's calibration states 0.90 px RMS error and its fits of the markers leave 1.20 px" in fitted
    assert "fits" not in lens_reason(lens, calibrations, 0.04, used={"cam_1": 0.9})


def test_a_poor_calibration_is_named_as_the_reason(clip: Path, runs: dict[str, CameraRun], tmp_path: Path) -> None:
    """Every camera's calibration stating 2 px of error (a poor one): the cones' σ is mostly what that leaves, and
    the reason names a camera's calibration; the clip's own (no error stated) names none."""
    rms_px = 2.0
    rig = load_rig(rig_file(clip, tmp_path))
    again = {}
    for name, run in runs.items():
        entry = next(c for c in rig.cameras if c.name == name)
        tracker = CameraTracker(rig, entry, dataclasses.replace(run.tracker.camera, rms=rms_px),
                                run.tracker.detector)
        again[name] = dataclasses.replace(run, tracker=tracker,
                                          results=[tracker.measure(r.frame, r.detections) for r in run.results])
    poor = check_runs(rig, again, SECONDS)
    assert any(f"calibration states {rms_px:.2f} px RMS error" in c.reason for c in poor.cones)
    assert not any("calibration states" in c.reason for c in check_runs(rig, runs, SECONDS).cones)


def test_a_calibration_that_states_no_error_is_named(clip: Path, runs: dict[str, CameraRun], tmp_path: Path) -> None:
    """The simulator's calibrations state theirs (exact: 0 px), so check names none; a calibration without one (a
    camera maker's, ROS's) is named with the file and the field, and its lens model's error is taken as
    UNSTATED_RMS_PX in the σ floor (without it, the real webcams' σ held 51-79 % of their errors within 2σ)."""
    rig = load_rig(rig_file(clip, tmp_path))
    assert not any("avg_reprojection_error" in w for w in check_runs(rig, runs, SECONDS).warnings)
    name = rig.cameras[0].name
    run = runs[name]
    tracker = CameraTracker(rig, rig.cameras[0], dataclasses.replace(run.tracker.camera, rms=None),
                            run.tracker.detector)
    results = [tracker.measure(r.frame, r.detections) for r in run.results]
    assert {r.observation.model_px for r in results if r.observation is not None} == {UNSTATED_RMS_PX}
    unstated = {**runs, name: dataclasses.replace(run, tracker=tracker, results=results)}
    named = [w for w in check_runs(rig, unstated, SECONDS).warnings if "avg_reprojection_error" in w]
    assert named == [f"{rig.resolve(rig.cameras[0].calibration)}: avg_reprojection_error: not stated, so {name}'s lens "
                     f"model error is taken as {UNSTATED_RMS_PX:g} px, the top of what a sound calibration leaves (a "
                     "calibration by `topside calibrate` states its own; a better one lowers every σ that camera's "
                     "view gives)"]
