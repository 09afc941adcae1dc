"""A small, exact marker renderer for tests: supersampled, with lens distortion, known poses.

Independent of the tracker and of the simulator. Pixel centres are at integer coordinates
(OpenCV's convention); each pixel averages SUPERSAMPLE² sub-samples.
"""

from __future__ import annotations

import fcntl
import os
import shutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import pytest

from tracking.sim.transforms import T_to_pose

SUPERSAMPLE = 8
BACKGROUND = 90
WHITE = 235
BLACK = 20
UNDISTORT_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 40, 1e-12)


@dataclass(frozen=True)
class PlacedMarker:
    """A marker with its pose in the camera frame."""

    id: int
    T_camera_marker: np.ndarray  # (4, 4)
    size: float  # black square edge, m


def marker_cells(dictionary: int, marker_id: int) -> np.ndarray:
    """(n+4, n+4) float cells in [0, 1]: one white quiet-zone cell, black border, code bits."""
    d = cv2.aruco.getPredefinedDictionary(dictionary)
    n = d.markerSize
    img = cv2.aruco.generateImageMarker(d, marker_id, n + 2, borderBits=1)
    return np.pad(img.astype(np.float64) / 255.0, 1, constant_values=1.0)


def true_corners(K: np.ndarray, dist: np.ndarray, m: PlacedMarker) -> np.ndarray:
    """(4, 2) distorted pixel positions of the corners TL TR BR BL."""
    h = m.size / 2
    obj = np.array([[-h, h, 0], [h, h, 0], [h, -h, 0], [-h, -h, 0]], dtype=np.float64)
    R, t = m.T_camera_marker[:3, :3], m.T_camera_marker[:3, 3]
    px, _ = cv2.projectPoints(obj, cv2.Rodrigues(R)[0], t, K, dist)
    return px.reshape(4, 2)


def scale_error(corners: np.ndarray, truth: np.ndarray) -> float:
    """Least-squares scale error of corners (4, 2) about the true centre, from truth (4, 2): + = reads large."""
    radial = truth - truth.mean(axis=0)
    return float(np.sum((corners - truth) * radial) / np.sum(radial * radial))


def render(K: np.ndarray, dist: np.ndarray, size: tuple[int, int], markers: list[PlacedMarker],
           dictionary: int = cv2.aruco.DICT_6X6_250, noise: float = 0.0, blur: float = 0.0,
           seed: int = 0, ss: int = SUPERSAMPLE, background: float = BACKGROUND) -> np.ndarray:
    """Grayscale (H, W) uint8 image of the markers on a plain background (markers must not overlap)."""
    w, h = size
    image = np.full((h, w), float(background))
    for m in sorted(markers, key=lambda m: -m.T_camera_marker[2, 3]):
        if m.T_camera_marker[:3, 2] @ m.T_camera_marker[:3, 3] >= 0:
            continue  # seen from behind
        cells = marker_cells(dictionary, m.id)
        ncell = cells.shape[0]
        plate = m.size * ncell / (ncell - 2)  # marker plus one quiet-zone cell each side
        corners = true_corners(K, dist, PlacedMarker(m.id, m.T_camera_marker, plate))
        x0, y0 = np.floor(corners.min(axis=0)).astype(int) - 2
        x1, y1 = np.ceil(corners.max(axis=0)).astype(int) + 3
        x0, y0, x1, y1 = max(x0, 0), max(y0, 0), min(x1, w), min(y1, h)
        if x1 <= x0 or y1 <= y0:
            continue
        offs = (np.arange(ss) + 0.5) / ss - 0.5
        us = (np.arange(x0, x1)[:, None] + offs[None, :]).reshape(-1)
        vs = (np.arange(y0, y1)[:, None] + offs[None, :]).reshape(-1)
        U, V = np.meshgrid(us, vs)
        pts = np.stack([U.ravel(), V.ravel()], axis=1).reshape(-1, 1, 2)
        ideal = cv2.undistortPoints(pts, K, dist, criteria=UNDISTORT_CRITERIA).reshape(-1, 2)
        # ray (x, y, 1) meets the marker plane z_m = 0: solve with the plane in camera coordinates
        R, t = m.T_camera_marker[:3, :3], m.T_camera_marker[:3, 3]
        rays = np.hstack([ideal, np.ones((len(ideal), 1))])
        n = R[:, 2]
        s = (n @ t) / (rays @ n)
        P = rays * s[:, None] - t
        local = P @ R  # marker-frame coordinates
        gx = (local[:, 0] / plate + 0.5) * ncell
        gy = (0.5 - local[:, 1] / plate) * ncell
        inside = (gx >= 0) & (gx < ncell) & (gy >= 0) & (gy < ncell) & (s > 0)
        value = np.full(len(gx), np.nan)
        gi = np.clip(gx.astype(int), 0, ncell - 1)
        gj = np.clip(gy.astype(int), 0, ncell - 1)
        value[inside] = BLACK + (WHITE - BLACK) * cells[gj[inside], gi[inside]]
        value = value.reshape(y1 - y0, ss, x1 - x0, ss)
        region = image[y0:y1, x0:x1]
        cover = np.isfinite(value)
        filled = np.where(cover, value, region[:, None, :, None])
        image[y0:y1, x0:x1] = filled.mean(axis=(1, 3))
    if blur > 0:
        image = cv2.GaussianBlur(image, (0, 0), blur)
    if noise > 0:
        image = image + np.random.default_rng(seed).normal(0, noise, image.shape)
    return np.clip(np.round(image), 0, 255).astype(np.uint8)


UP = np.array([0.0, 0.0, 1.0])


def look_at(eye: np.ndarray, target: np.ndarray, up: np.ndarray = UP) -> np.ndarray:
    """T_world_camera (4, 4) of an OpenCV camera (x right, y down, z forward) at eye looking at target."""
    z = target - eye
    z = z / np.linalg.norm(z)
    x = np.cross(z, up)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    T = np.eye(4)
    T[:3, :3] = np.column_stack([x, y, z])
    T[:3, 3] = eye
    return T


PAPER_K = np.array([[1258.27, 0.0, 468.746], [0.0, 1259.0, 296.561], [0.0, 0.0, 1.0]])
PAPER_SIZE = (920, 600)
PAPER_DIST = np.array([-0.08, 0.03, 0.0, 0.0, 0.0])  # mild barrel distortion for the rendered installations


# --- a small installation on disk: cone A, two faces, two cameras, H.264 videos -------------------------

CONE_A = np.array([-12.0, -12.0, 0.0])
MATED_RISE = 1.8  # topside marker centre above the jacket marker centre when mated, m
JACKET_MARKER_Z = -1.5
FACES = {"ahead": (1, 2), "port": (3, 4)}  # face -> (jacket id, topside id)


def marker_centres() -> dict[int, tuple[str, str, np.ndarray]]:
    """id -> (body, face, centre in its body frame)."""
    out = {}
    for face, (jid, sid) in FACES.items():
        normal = {"ahead": np.array([0.0, -1.0, 0.0]), "port": np.array([1.0, 0.0, 0.0])}[face]
        base = CONE_A + 0.8 * normal + np.array([0.0, 0.0, JACKET_MARKER_Z])
        out[jid] = ("jacket", face, base)
        out[sid] = ("topside", face, base + np.array([0.0, 0.0, MATED_RISE]))
    return out


def rig_dict(cameras: list[dict]) -> dict:
    """The rig file content of the small installation."""
    markers = [{"id": i, "body": b, "cone": "A", "face": f, "center": c.round(6).tolist()}
               for i, (b, f, c) in marker_centres().items()]
    pairs = [{"cone": "A", "face": f, "jacket": j, "topside": s, "mated": [0.0, 0.0, MATED_RISE]}
             for f, (j, s) in FACES.items()]
    return {"name": "synthetic", "dictionary": "DICT_6X6_250", "marker_size": 1.0,
            "cones": {"A": CONE_A.tolist()}, "markers": markers, "pairs": pairs, "cameras": cameras}


def face_T(face: str) -> np.ndarray:
    """R_body_marker of a face as the rig defines it (computed here independently)."""
    z = {"ahead": np.array([0.0, -1.0, 0.0]), "port": np.array([1.0, 0.0, 0.0])}[face]
    y = np.array([0.0, 0.0, 1.0])
    return np.column_stack([np.cross(y, z), y, z])


CAMERA_EYES = {"cam-ahead": np.array([-9.0, -32.0, 4.0]), "cam-port": np.array([8.0, -8.0, 3.0])}


def render_installation(folder, motion, times: dict[str, np.ndarray], dist: np.ndarray,
                        noise: float = 1.0) -> None:
    """Write rig.yaml, calibration/*.yaml, one H.264 video per camera and truth.csv; motion(t) -> offset (3,)."""
    import av
    import yaml

    from tracking.camera import CameraModel, save_camera

    folder.mkdir(parents=True, exist_ok=True)
    cams = []
    centres = marker_centres()
    poses = []  # the cameras' true poses for truth.csv: position and rotation vector, as the simulator writes them
    for name, eye in CAMERA_EYES.items():
        T_jacket_cam = look_at(eye, CONE_A + np.array([0.0, 0.0, JACKET_MARKER_Z + MATED_RISE / 2]))
        poses.append((name, T_to_pose(T_jacket_cam)))
        exact = CameraModel(PAPER_K, dist, *PAPER_SIZE, rms=0.0)  # the renderer's own camera: states 0 px
        save_camera(folder / f"calibration/{name}.yaml", exact)
        cams.append({"name": name, "calibration": f"calibration/{name}.yaml", "source": f"{name}.mp4",
                     "time_offset": float(times[name][0]), "mount": "drone"})  # the filter's loosest prior
        with av.open(str(folder / f"{name}.mp4"), "w") as out:
            stream = out.add_stream("libx264", rate=30)
            stream.width, stream.height = PAPER_SIZE
            stream.pix_fmt = "yuv420p"
            stream.options = {"crf": "12", "preset": "ultrafast"}
            stream.codec_context.time_base = __import__("fractions").Fraction(1, 1000)
            for k, t in enumerate(times[name]):
                placed = []
                for mid, (body, face, c) in centres.items():
                    T_body_m = np.eye(4)
                    T_body_m[:3, :3] = face_T(face)
                    T_body_m[:3, 3] = c + (motion(t) if body == "topside" else 0.0)
                    placed.append(PlacedMarker(mid, np.linalg.inv(T_jacket_cam) @ T_body_m, 1.0))
                gray = render(PAPER_K, dist, PAPER_SIZE, placed, noise=noise, seed=k)
                frame = av.VideoFrame.from_ndarray(np.dstack([gray] * 3), format="bgr24")
                frame.pts = round((t - times[name][0]) * 1000)
                frame.time_base = stream.codec_context.time_base
                out.mux(stream.encode(frame))
            out.mux(stream.encode(None))
    (folder / "rig.yaml").write_text(yaml.safe_dump(rig_dict(cams), sort_keys=False))
    t_all = np.arange(min(t[0] for t in times.values()) - 0.1, max(t[-1] for t in times.values()) + 0.1, 0.01)
    truth = np.array([motion(t) for t in t_all])
    header = ["time", "cone_A_dx", "cone_A_dy", "cone_A_dz",
              *(f"camera_{name}_{axis}" for name, _ in poses for axis in ("x", "y", "z", "rx", "ry", "rz"))]
    still = "".join(f",{v:.6f}" for _, pose in poses for v in pose)
    lines = [",".join(header)] + [f"{t:.4f},{a:.6f},{b:.6f},{c:.6f}{still}"
                                  for t, (a, b, c) in zip(t_all, truth, strict=True)]
    (folder / "truth.csv").write_text("\n".join(lines) + "\n")


def made_once(tmp_path_factory: pytest.TempPathFactory, name: str, make: Callable[[Path], None]) -> Path:
    """A folder `make` fills, made once per test run even when xdist's workers share it: under a lock in the run's
    common temporary folder, made under a temporary name and renamed when whole."""
    base = tmp_path_factory.getbasetemp()
    shared = base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base
    folder = shared / name
    with open(shared / f"{name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not folder.is_dir():
            partial = shared / f"{name}.partial"
            shutil.rmtree(partial, ignore_errors=True)
            make(partial)
            partial.rename(folder)
    return folder


def simulated_once(tmp_path_factory: pytest.TempPathFactory, scenario: str, duration: float) -> Path:
    """A simulated clip, rendered once per test run (made_once)."""
    from tracking.sim.command import run_simulate

    return made_once(tmp_path_factory, f"sim-{scenario}-{duration:g}s",
                     lambda folder: run_simulate(scenario, folder, duration=duration, quiet=True))
