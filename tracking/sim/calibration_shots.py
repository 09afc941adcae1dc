"""Calibration shots (the paper's experiment 1): a chessboard in the scene seen from many viewpoints.

Writes DIR/calibration_shots/<camera>/shot_NN.png (lossless), DIR/calibration_shots/board.yaml
(the board as `topside calibrate --board` takes it) and the true camera DIR/calibration/<camera>.yaml.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import yaml
from rich.progress import Progress

from tracking.camera import save_camera
from tracking.sim.render import CameraRenderer, FrameState
from tracking.sim.scenario import CameraSpec, Scenario
from tracking.sim.scene import Body, Plate
from tracking.sim.textures import chessboard_texture
from tracking.sim.transforms import apply, look_at, make_T
from tracking.sim.weather import Light

BOARD_CENTRE = np.array([0.0, -40.0, 3.0])  # jacket frame: held up on the vessel's stern
BOARD_R = np.column_stack([[-1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]])  # faces ahead (-y), x to starboard
MAX_TILT_DEG = 40.0
MAX_ROLL_DEG = 25.0
FILL_RANGE = (0.35, 0.75)  # fraction of the image width the board spans
EDGE_MARGIN_PX = 12.0
MAX_TRIES = 2000


def board_string(inner: tuple[int, int], square: float) -> str:
    """The board as `topside calibrate --board` takes it."""
    return f"chessboard:{inner[0]}x{inner[1]}:{square:g}"


def inner_corner_points(inner: tuple[int, int], square: float) -> np.ndarray:
    """(N, 3) inner corners in the board (plate) frame, row by row."""
    cols, rows = inner
    xs = (np.arange(cols) - (cols - 1) / 2) * square
    ys = ((rows - 1) / 2 - np.arange(rows)) * square
    return np.array([[x, y, 0.0] for y in ys for x in xs])


def rotation_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Rotation (3, 3) turning direction a onto direction b."""
    a, b = a / np.linalg.norm(a), b / np.linalg.norm(b)
    axis = np.cross(a, b)
    s, c = np.linalg.norm(axis), float(a @ b)
    if s < 1e-12:
        return np.eye(3)
    return cv2.Rodrigues(axis / s * np.arctan2(s, c))[0]


def shot_poses(cam: CameraSpec, board_size: tuple[float, float], inner_pts: np.ndarray, count: int,
               rng: np.random.Generator) -> list[np.ndarray]:
    """T_jacket_camera of `count` varied viewpoints that keep the whole board in the picture."""
    T_jb = make_T(BOARD_R, BOARD_CENTRE)
    K = np.array([[cam.K[0], 0, cam.K[2]], [0, cam.K[1], cam.K[3]], [0, 0, 1.0]])
    outline = np.array([[sx * board_size[0] / 2, sy * board_size[1] / 2, 0] for sx in (-1, 1) for sy in (-1, 1)])
    poses: list[np.ndarray] = []
    for _ in range(MAX_TRIES):
        if len(poses) == count:
            break
        yaw, pitch = np.radians(rng.uniform(-MAX_TILT_DEG, MAX_TILT_DEG, 2))
        fill = rng.uniform(*FILL_RANGE)
        dist = board_size[0] * cam.K[0] / (fill * cam.width)
        view = np.array([np.sin(yaw) * np.cos(pitch), np.sin(pitch), np.cos(yaw) * np.cos(pitch)])  # plate frame
        centre = apply(T_jb, np.zeros((1, 3)))[0]
        T_jc = look_at(centre + BOARD_R @ (dist * view), centre, np.radians(rng.uniform(-MAX_ROLL_DEG, MAX_ROLL_DEG)))
        # turn the camera so the board centre lands on a random pixel: boards reach every part of the image
        ray = np.linalg.solve(K, [rng.uniform(0, cam.width), rng.uniform(0, cam.height), 1.0])
        T_jc[:3, :3] = T_jc[:3, :3] @ rotation_between(ray, np.array([0.0, 0.0, 1.0]))
        T_cb = np.linalg.inv(T_jc) @ T_jb
        pts = apply(T_cb, np.vstack([outline, inner_pts]))
        px, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), K, np.array(cam.dist))
        px = px.reshape(-1, 2)
        if (px.min(axis=0) >= EDGE_MARGIN_PX).all() and (px[:, 0] <= cam.width - EDGE_MARGIN_PX).all() and \
                (px[:, 1] <= cam.height - EDGE_MARGIN_PX).all():
            poses.append(T_jc)
    return poses


def write_calibration_shots(sc: Scenario, out: Path, quiet: bool = False) -> list[Path]:
    """Render the chessboard shots of every camera of the scenario; returns the files written."""
    spec = sc.calibration
    assert spec is not None
    inner = (spec.inner_corners[0], spec.inner_corners[1])
    tex = chessboard_texture(inner, spec.square)
    board = Body("board", plates=[Plate("board", np.eye(4), max(tex.size_m))])
    shots_dir = out / "calibration_shots"
    shots_dir.mkdir(parents=True, exist_ok=True)
    (shots_dir / "board.yaml").write_text(yaml.safe_dump(
        {"board": board_string(inner, spec.square), "inner_corners": list(inner), "square": spec.square}))
    light = Light(sc.weather, sc.seed, [])
    written = []
    with Progress(disable=quiet) as progress:
        for ci, cam in enumerate(sc.cameras):
            from tracking.sim.command import camera_model

            save_camera(out / "calibration" / f"{cam.name}.yaml", camera_model(cam))
            renderer = CameraRenderer(cam, [board], {"board": tex}, sc.weather, light, sc.layout.sea_z,
                                      seed=sc.seed * 1000 + ci)
            rng = np.random.default_rng([sc.seed, 23, ci])
            poses = shot_poses(cam, tex.size_m, inner_corner_points(inner, spec.square), spec.shots, rng)
            cam_dir = shots_dir / cam.name
            cam_dir.mkdir(exist_ok=True)
            task = progress.add_task(f"calibration shots {cam.name}", total=len(poses))
            for k, T_jc in enumerate(poses):
                state = FrameState(time=float(k), T_jacket_camera=T_jc,
                                   T_jacket_body={"board": make_T(BOARD_R, BOARD_CENTRE)}, light=1.0, seed=k)
                img, _ = renderer.render(state)
                path = cam_dir / f"shot_{k:02d}.png"
                cv2.imwrite(str(path), img)
                written.append(path)
                progress.advance(task)
    return written
