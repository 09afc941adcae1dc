"""Builds the worked example from the simulator, written out as a crew would have it: the cameras' videos,
calibration photos per camera, the marker survey table and the rig file (calibrations are made by
`topside calibrate`, as the field guide says). Run from the repository: `.venv/bin/python docs/example/build.py`.

The simulator's truth is kept as truth.csv (cone offsets only) so that `topside evaluate` can score the run.
"""

from __future__ import annotations

import csv
import shutil
import tempfile
from pathlib import Path

import cv2
import pandas as pd
import yaml

from tracking.sim.command import run_simulate
from tracking.sim.scenario import CalibrationSpec, dump_scenario, load_scenario

HERE = Path(__file__).resolve().parent
CAMERAS = ("stern_A", "drone_A", "drone_D1")  # cone A seen by two cameras, D by one; B and C by none
SECONDS = 8.0
SHOTS = 12  # calibration photos per camera
JPEG_QUALITY = 90  # as a camera writes them


def write_scenario(folder: Path) -> Path:
    """The set-down of configuration 2 with three of its cameras, as a scenario file."""
    sc = load_scenario("config2-setdown")
    sc = sc.model_copy(update={"name": "example", "cameras": [c for c in sc.cameras if c.name in CAMERAS],
                               "duration": SECONDS})
    path = folder / "scenario.yaml"
    path.write_text(dump_scenario(sc))
    return path


def calibration_photos(folder: Path, camera: str, seed: int) -> None:
    """SHOTS chessboard photos of one camera (the simulator's calibration shots, another seed per camera), as JPEG."""
    sc = load_scenario("calibration-shots")
    sc = sc.model_copy(update={"seed": seed, "calibration": CalibrationSpec(shots=SHOTS)})
    with tempfile.TemporaryDirectory() as tmp:
        spec = Path(tmp) / "shots.yaml"
        spec.write_text(dump_scenario(sc))
        run_simulate(str(spec), Path(tmp) / "out", quiet=True)
        out = folder / "calibration-photos" / camera
        out.mkdir(parents=True, exist_ok=True)
        for png in sorted((Path(tmp) / "out" / "calibration_shots" / "camera").glob("*.png")):
            image = cv2.imread(str(png))
            cv2.imwrite(str(out / f"{png.stem}.jpg"), image, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])


def survey_table(rig: dict, path: Path) -> None:
    """The marker survey as a surveyor hands it over: id, body, cone, face, centre (m, jacket frame when mated)."""
    with path.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["id", "body", "cone", "face", "x", "y", "z"])
        for m in rig["markers"]:
            w.writerow([m["id"], m["body"], m["cone"], m["face"], *m["center"]])


def flow(item: object) -> str:
    """One YAML item on one line."""
    return yaml.safe_dump(item, default_flow_style=True, sort_keys=False, width=10_000).removesuffix("...\n").strip()


def rig_text(rig: dict) -> str:
    """The rig as a person writes it: one line per cone, marker, pair and camera."""
    lines = [f"{key}: {flow(rig[key])}" for key in ("name", "dictionary", "marker_size")]
    for key in ("cones", "markers", "pairs", "cameras"):
        lines.append(f"{key}:")
        items = rig[key].items() if isinstance(rig[key], dict) else rig[key]
        lines += [f"  {k}: {flow(v)}" for k, v in items] if isinstance(rig[key], dict) else \
                 [f"  - {flow(v)}" for v in items]
    return "\n".join(lines) + "\n"


def main() -> None:
    """Simulate, then keep what a crew would have."""
    for name in ("calibration-photos", "calibration"):
        shutil.rmtree(HERE / name, ignore_errors=True)
    with tempfile.TemporaryDirectory() as tmp:
        sim = Path(tmp) / "sim"
        run_simulate(str(write_scenario(Path(tmp))), sim, quiet=True)
        for camera in CAMERAS:
            shutil.copy(sim / f"{camera}.mp4", HERE / f"{camera}.mp4")
        rig = yaml.safe_load((sim / "rig.yaml").read_text())
        rig["name"] = "Worked example: configuration 2, set-down"
        (HERE / "rig.yaml").write_text(rig_text(rig))
        survey_table(rig, HERE / "survey.csv")
        truth = pd.read_csv(sim / "truth.csv")
        truth[["time", *[c for c in truth.columns if c.startswith("cone_")]]].to_csv(
            HERE / "truth.csv", index=False, float_format="%.6f")
    for k, camera in enumerate(CAMERAS):
        calibration_photos(HERE, camera, seed=11 + k)


if __name__ == "__main__":
    main()
