"""Build benchmarks/real/<session>/ from the real footage in ../shared/data/caliscope/ (four webcams, a hand-held
ChArUco board): a rig, the cameras' calibrations and their times files. Run it again to rebuild them:

    .venv/bin/python benchmarks/real/build.py [--data ../shared/data/caliscope]

The rig splits the board's ten markers into two bodies: the upper five (ids 0-4) are the "topside", the lower five
(ids 5-9) the "jacket", one cone A at the board's centre. The board is rigid, so the topside is mated at every
instant: the true offset is zero, whatever the board does, and no tracker had a hand in that truth. The board is
`CharucoBoard((4, 5), 0.054, 0.0405, DICT_4X4_1000)`, printed white on black (inverted), so the rig says
`inverted: true`; its plane faces astern (+y) with its top up (+z), x to port.

Calibrations: each camera's `matrix`, `distortions` and `size` from the session's camera_array.toml (caliscope fitted
them to footage like this: consistent with it, not independent truth). Times: each frame's capture time from the
session's timestamps.csv (sync_index, cam_id, [frame_index,] frame_time): frame_index where it is given, else the
camera's rows in sync_index order, written as tracking.frame_times' `frame,time` CSV, seconds after the session's
first frame.
"""

from __future__ import annotations

import argparse
import sys
import tomllib
from pathlib import Path

import cv2
import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from tracking.camera import CameraModel, save_camera
from tracking.outputs import write_text
from tracking.rig import CameraEntry, Marker, Rig, save_rig

HERE = Path(__file__).resolve().parent
SESSIONS = ("charuco_calibration", "post_optimization")
DATA = HERE.parents[2] / "shared" / "data" / "caliscope"
TOPSIDE_IDS = range(0, 5)  # the board's upper five markers
CONE = "A"


def board() -> cv2.aruco.CharucoBoard:
    """The session's board (charuco.toml: 4 columns, 5 rows, squares 5.4 cm, markers 0.75 of a square)."""
    return cv2.aruco.CharucoBoard((4, 5), 0.054, 0.0405, cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_1000))


def markers(b: cv2.aruco.CharucoBoard) -> list[Marker]:
    """The board's markers in the jacket frame, the board's centre at the origin: board x (right, as printed) is
    jacket -x, board y (down) is jacket -z, the printed face looks astern."""
    size = 0.054 * np.array(b.getChessboardSize(), dtype=float)  # (width, height) of the board, m
    out = []
    for i, corners in zip(b.getIds().ravel(), b.getObjPoints(), strict=True):
        bx, by = np.asarray(corners)[:, :2].mean(axis=0)
        center = [float(-(bx - size[0] / 2)), 0.0, float(-(by - size[1] / 2))]
        out.append(Marker(id=int(i), body="topside" if i in TOPSIDE_IDS else "jacket", cone=CONE, face="astern",
                          center=[round(c, 6) for c in center]))
    return out


def times(session: Path) -> dict[int, pd.DataFrame]:
    """Each camera's frame,time table from the session's timestamps.csv, seconds after the session's first frame."""
    df = pd.read_csv(session / "calibration" / "extrinsic" / "timestamps.csv")
    t0 = df["frame_time"].min()
    out = {}
    for cam, rows in df.groupby("cam_id"):
        rows = rows.sort_values("sync_index")
        frame = rows["frame_index"].to_numpy() if "frame_index" in rows else np.arange(len(rows))
        out[int(cam)] = pd.DataFrame({"frame": frame.astype(int), "time": (rows["frame_time"] - t0).round(6)})
    return out


def build(session: str, data: Path) -> Path:
    """Write benchmarks/real/<session>/: rig.yaml, calibration/cam_N.yaml, times/cam_N.csv."""
    src = data / session
    out = HERE / session
    array = tomllib.loads((src / "camera_array.toml").read_text())["cameras"]
    cameras = []
    for cam, table in sorted(times(src).items()):
        c = array[str(cam)]
        save_camera(out / "calibration" / f"cam_{cam}.yaml",
                    CameraModel(np.array(c["matrix"]), np.array(c["distortions"]), *c["size"], rms=c.get("error")))
        write_text(out / "times" / f"cam_{cam}.csv", table.to_csv(index=False))
        video = src / "calibration" / "extrinsic" / f"cam_{cam}.mp4"
        cameras.append(CameraEntry(name=f"cam_{cam}", calibration=f"calibration/cam_{cam}.yaml",
                                   source=str(Path(*[".."] * 4, *video.resolve().relative_to(HERE.parents[2]).parts)),
                                   times=f"times/cam_{cam}.csv", mount="moving"))
    rig = Rig(name=f"caliscope-{session}", dictionary="DICT_4X4_1000", inverted=True, marker_size=0.0405,
              cones={CONE: [0.0, 0.0, 0.0]}, markers=markers(board()), cameras=cameras)
    save_rig(out / "rig.yaml", rig)
    return out / "rig.yaml"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", type=Path, default=DATA, help="the caliscope folder of ../shared/data")
    args = parser.parse_args()
    for session in SESSIONS:
        print(build(session, args.data))


if __name__ == "__main__":
    main()
