"""Renderer: sea and sky, shaded structures, textured marker plates, lens distortion.

Each frame is drawn as an ideal pinhole image on a canvas a little larger than the picture, then
warped through the camera's distortion with cv2.remap (a per-camera map computed once by
inverting OpenCV's distortion model). Structures are convex polygons in far-to-near order
(painter's algorithm, long members cut short so the order holds), filled with anti-aliased edges
at 1/16 px vertex precision. Plates are warped from exact-edged textures into a SUPERSAMPLE x
supersampled window (bilinear) and area-averaged down, so each pixel holds its true coverage.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from tracking.sim.scenario import CameraSpec, WeatherSpec
from tracking.sim.scene import Body, Plate
from tracking.sim.textures import Texture
from tracking.sim.transforms import inv_T
from tracking.sim.weather import (
    AMBIENT,
    DIFFUSE,
    FOG_ALBEDO,
    PENUMBRA_M,
    Light,
    NoiseBank,
    extinction,
    motion_blur,
    rain_streaks,
)

SUPERSAMPLE = 4
MAX_SUPER_PIXELS = 4_000_000  # per plate window; the factor drops for huge close-ups
NEAR = 0.3  # m, near clipping plane
SHIFT = 4  # fractional bits of polygon vertices
BACKGROUND_STEP = 8  # sky and sea are computed on a grid this much coarser
UNDISTORT_ITERATIONS = 60
UNDISTORT_TOLERANCE = 1e-12  # normalized units (~1e-9 px)
SEGMENT_PIECE_M = 8.0  # m, thin members are cut this short for depth sorting
MARKER_DEPTH_BIAS = 0.3  # m: a plate is drawn after the leg it is fixed to
SKY_HORIZON = np.array([0.93, 0.86, 0.78])  # BGR albedo-like radiance
SKY_ZENITH = np.array([0.80, 0.55, 0.35])
SEA_NEAR = np.array([0.32, 0.24, 0.10])
SEA_FAR = np.array([0.55, 0.46, 0.33])


@dataclass(frozen=True)
class Segment:
    """A thin member drawn facing the camera (slings, crane booms), jacket frame."""

    p0: np.ndarray
    p1: np.ndarray
    width: float
    albedo: tuple[float, float, float]


@dataclass
class FrameState:
    """Everything that changes between frames, at one capture time."""

    time: float
    T_jacket_camera: np.ndarray
    T_jacket_body: dict[str, np.ndarray]  # jacket, topside, vessel
    light: float
    segments: list[Segment] = field(default_factory=list)
    blur_px: tuple[float, float] = (0.0, 0.0)
    seed: int = 0


@dataclass
class _BodyMesh:
    name: str
    verts: np.ndarray  # (V, 3)
    faces: list[np.ndarray]  # vertex index arrays
    centroids: np.ndarray  # (F, 3)
    normals: np.ndarray  # (F, 3)
    albedo: np.ndarray  # (F, 3)
    two_sided: np.ndarray  # (F,)
    plates: list[Plate]
    groups: list[tuple[np.ndarray, np.ndarray]]  # faces with n vertices: (face ids (F_n,), vertex ids (F_n, n))


def _mesh(body: Body) -> _BodyMesh:
    verts, faces, start = [], [], 0
    for f in body.faces:
        verts.append(f.verts)
        faces.append(np.arange(start, start + len(f.verts)))
        start += len(f.verts)
    return _BodyMesh(
        body.name, np.vstack(verts) if verts else np.zeros((0, 3)), faces,
        np.array([f.verts.mean(axis=0) for f in body.faces]).reshape(-1, 3),
        np.array([f.normal for f in body.faces]).reshape(-1, 3),
        np.array([f.albedo for f in body.faces]).reshape(-1, 3),
        np.array([f.two_sided for f in body.faces], bool), list(body.plates), _groups(faces))


def _groups(faces: list[np.ndarray]) -> list[tuple[np.ndarray, np.ndarray]]:
    sizes = sorted({len(f) for f in faces})
    out = []
    for n in sizes:
        fids = np.array([i for i, f in enumerate(faces) if len(f) == n])
        out.append((fids, np.array([faces[i] for i in fids])))
    return out


def distort_normalized(x: np.ndarray, y: np.ndarray, dist: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """OpenCV's distortion (k1 k2 p1 p2 [k3 [k4 k5 k6]]) of normalized coordinates."""
    d = np.zeros(8)
    d[: len(dist)] = dist
    k1, k2, p1, p2, k3, k4, k5, k6 = d
    r2 = x * x + y * y
    radial = (1 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1 + r2 * (k4 + r2 * (k5 + r2 * k6)))
    return (x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x),
            y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y)


def undistort_normalized(xd: np.ndarray, yd: np.ndarray, dist: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Inverse of distort_normalized by fixed-point iteration, to UNDISTORT_TOLERANCE."""
    x, y = xd.copy(), yd.copy()
    for _ in range(UNDISTORT_ITERATIONS):
        fx, fy = distort_normalized(x, y, dist)
        ex, ey = xd - fx, yd - fy
        x, y = x + ex, y + ey
        if max(np.abs(ex).max(initial=0), np.abs(ey).max(initial=0)) < UNDISTORT_TOLERANCE:
            break
    return x, y


def clip_near(pts: np.ndarray) -> np.ndarray:
    """Clip a polygon (N, 3) in camera coordinates to z >= NEAR (Sutherland-Hodgman)."""
    out = []
    n = len(pts)
    for i in range(n):
        a, b = pts[i], pts[(i + 1) % n]
        ina, inb = a[2] >= NEAR, b[2] >= NEAR
        if ina:
            out.append(a)
        if ina != inb:
            s = (NEAR - a[2]) / (b[2] - a[2])
            out.append(a + s * (b - a))
    return np.array(out).reshape(-1, 3)


class CameraRenderer:
    """Renders frames of one camera."""

    def __init__(self, cam: CameraSpec, bodies: list[Body], textures: dict[str, Texture],
                 weather: WeatherSpec, light: Light, sea_z: float, seed: int = 0) -> None:
        self.cam = cam
        self.K = np.array([[cam.K[0], 0, cam.K[2]], [0, cam.K[1], cam.K[3]], [0, 0, 1.0]])
        self.dist = np.array(cam.dist, float)
        self.size = (cam.width, cam.height)
        self.meshes = [_mesh(b) for b in bodies]
        self.textures = textures
        self.weather = weather
        self.light = light
        self.sea_z = sea_z
        self.beta = extinction(weather)
        self._build_maps()
        self._build_background_grid()
        self.noise = NoiseBank((cam.height, cam.width, 3), weather.noise, seed)

    # ---- per-camera precomputation -------------------------------------------------------
    def _build_maps(self) -> None:
        """Canvas intrinsics: the ideal image must cover every pixel of the distorted picture."""
        w, h = self.size
        border = np.concatenate([np.column_stack([np.arange(w), np.zeros(w)]),
                                 np.column_stack([np.arange(w), np.full(w, h - 1)]),
                                 np.column_stack([np.zeros(h), np.arange(h)]),
                                 np.column_stack([np.full(h, w - 1), np.arange(h)])]).astype(np.float64)
        iu, iv = self._ideal_pixels(border[:, 0], border[:, 1])
        x0 = int(np.floor(min(iu.min(), 0))) - 3
        y0 = int(np.floor(min(iv.min(), 0))) - 3
        x1 = int(np.ceil(max(iu.max(), w - 1))) + 3
        y1 = int(np.ceil(max(iv.max(), h - 1))) + 3
        self.canvas_origin = (x0, y0)
        self.canvas_size = (x1 - x0 + 1, y1 - y0 + 1)
        self.Kc = self.K.copy()
        self.Kc[0, 2] -= x0
        self.Kc[1, 2] -= y0
        self._maps: tuple[np.ndarray, np.ndarray] | None = None

    def _ideal_pixels(self, u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        fx, fy, cx, cy = self.K[0, 0], self.K[1, 1], self.K[0, 2], self.K[1, 2]
        xu, yu = undistort_normalized((u - cx) / fx, (v - cy) / fy, self.dist)
        return fx * xu + cx, fy * yu + cy

    @property
    def maps(self) -> tuple[np.ndarray, np.ndarray]:
        """cv2.remap maps from the distorted picture to the ideal canvas (built on first use)."""
        if self._maps is None:
            w, h = self.size
            u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
            iu, iv = self._ideal_pixels(u, v)
            x0, y0 = self.canvas_origin
            self._maps = cv2.convertMaps((iu - x0).astype(np.float32), (iv - y0).astype(np.float32), cv2.CV_16SC2)
        return self._maps

    def _build_background_grid(self) -> None:
        cw, ch = self.canvas_size
        gw, gh = cw // BACKGROUND_STEP + 2, ch // BACKGROUND_STEP + 2
        u = (np.arange(gw) * BACKGROUND_STEP + (BACKGROUND_STEP - 1) / 2 - self.Kc[0, 2]) / self.Kc[0, 0]
        v = (np.arange(gh) * BACKGROUND_STEP + (BACKGROUND_STEP - 1) / 2 - self.Kc[1, 2]) / self.Kc[1, 1]
        uu, vv = np.meshgrid(u, v)
        self.bg_rays = np.stack([uu, vv, np.ones_like(uu)], axis=-1)  # (gh, gw, 3)

    # ---- drawing -------------------------------------------------------------------------
    def _fog(self, dist: np.ndarray | float) -> np.ndarray | float:
        return np.exp(-self.beta * np.asarray(dist)) if self.beta > 0 else np.ones_like(np.asarray(dist, float))

    def _background(self, T_jc: np.ndarray, level: float) -> np.ndarray:
        R, c = T_jc[:3, :3], T_jc[:3, 3]
        d = self.bg_rays @ R.T
        norm = np.linalg.norm(d, axis=-1)
        elev = d[..., 2] / norm
        sky_t = np.clip(elev * 3.0, 0, 1)[..., None]
        sky = SKY_HORIZON * (1 - sky_t) + SKY_ZENITH * sky_t
        height = max(c[2] - self.sea_z, 0.5)
        down = np.maximum(-elev, 1e-4)
        dist = height / down
        hit = (c[:2] + d[..., :2] / norm[..., None] * dist[..., None])
        ripple = 0.03 * (np.sin(hit[..., 0] * 0.9 + hit[..., 1] * 0.4) + np.sin(hit[..., 1] * 1.3 - hit[..., 0] * 0.2))
        far = np.clip(1 - np.exp(-dist / 400.0), 0, 1)[..., None]
        sea = SEA_NEAR * (1 - far) + SEA_FAR * far + ripple[..., None] * (1 - far)
        if self.beta > 0:
            t = np.exp(-self.beta * dist)[..., None]
            sea = sea * t + FOG_ALBEDO * (1 - t)
            sky = sky * 0.15 + FOG_ALBEDO * 0.85 if self.weather.fog > 0.2 else sky * 0.5 + FOG_ALBEDO * 0.5
        blend = np.clip(0.5 + elev / 0.002, 0, 1)[..., None]  # soft horizon
        img = (sea * (1 - blend) + sky * blend) * (255.0 * level)
        small = np.clip(img, 0, 255).astype(np.uint8)
        cw, ch = self.canvas_size
        big = cv2.resize(small, (small.shape[1] * BACKGROUND_STEP, small.shape[0] * BACKGROUND_STEP),
                         interpolation=cv2.INTER_LINEAR)
        return np.ascontiguousarray(big[:ch, :cw])

    def _project(self, P: np.ndarray) -> np.ndarray:
        z = P[:, 2:3]
        return np.hstack([self.Kc[0, 0] * P[:, :1] / z + self.Kc[0, 2], self.Kc[1, 1] * P[:, 1:2] / z + self.Kc[1, 2]])

    def _polygon_items(self, T_cj: np.ndarray, state: FrameState, items: list) -> None:
        cw, ch = self.canvas_size
        fog_rgb = FOG_ALBEDO * state.light
        for mesh in self.meshes:
            T_jb = state.T_jacket_body[mesh.name]
            T = T_cj @ T_jb
            if mesh.centroids.size:
                R, t = T[:3, :3], T[:3, 3]
                V = mesh.verts @ R.T + t
                C = mesh.centroids @ R.T + t
                facing = np.einsum("ij,ij->i", mesh.normals @ R.T, -C) > 0
                dists = np.linalg.norm(C, axis=1)
                lam = np.maximum(mesh.normals @ T_jb[:3, :3].T @ self.light.sun, 0)
                shade = state.light * (AMBIENT + DIFFUSE * lam)
                tr = self._fog(dists)[:, None]
                colours = np.clip((mesh.albedo * shade[:, None] * tr + fog_rgb * (1 - tr)) * 255.0, 0, 255)
                zok = V[:, 2] >= NEAR
                z = np.where(zok, V[:, 2], 1.0)
                uv = np.column_stack([self.Kc[0, 0] * V[:, 0] / z + self.Kc[0, 2],
                                      self.Kc[1, 1] * V[:, 1] / z + self.Kc[1, 2]])
                for fids, idx in mesh.groups:
                    puv = uv[idx]  # (F, n, 2)
                    allz = zok[idx].all(axis=1)
                    anyz = zok[idx].any(axis=1)
                    lo, hi = puv.min(axis=1), puv.max(axis=1)
                    inside = (hi[:, 0] >= -1) & (lo[:, 0] <= cw) & (hi[:, 1] >= -1) & (lo[:, 1] <= ch)
                    vis = (facing[fids] | mesh.two_sided[fids]) & anyz & (inside | ~allz)
                    for k in np.nonzero(vis)[0]:
                        f = fids[k]
                        if allz[k]:
                            poly = puv[k]
                        else:
                            P = clip_near(V[idx[k]])
                            if len(P) < 3:
                                continue
                            poly = self._project(P)
                        items.append((dists[f], 0, poly, tuple(colours[f].tolist())))
            for plate in mesh.plates:
                Tp = T @ plate.T_body_plate
                n, c = Tp[:3, 2], Tp[:3, 3]
                if n @ -c <= 0 or c[2] < NEAR:
                    continue
                items.append((float(np.linalg.norm(c)) - MARKER_DEPTH_BIAS, 1, (plate, Tp, T_jb @ plate.T_body_plate),
                              None))
        for seg in state.segments:
            self._segment_items(T_cj, seg, state.light, items)

    def _segment_items(self, T_cj: np.ndarray, seg: Segment, level: float, items: list) -> None:
        p0 = T_cj[:3, :3] @ seg.p0 + T_cj[:3, 3]
        p1 = T_cj[:3, :3] @ seg.p1 + T_cj[:3, 3]
        n = max(1, int(np.linalg.norm(p1 - p0) / SEGMENT_PIECE_M))
        s = np.linspace(0.0, 1.0, n + 1)[:, None]
        pts = p0 + s * (p1 - p0)
        mids = (pts[:-1] + pts[1:]) / 2
        side = np.cross(p1 - p0, mids)
        norm = np.linalg.norm(side, axis=1, keepdims=True)
        side = side * (seg.width / 2) / np.maximum(norm, 1e-9)
        d = np.linalg.norm(mids, axis=1)
        t = self._fog(d)[:, None]
        cols = np.clip((np.array(seg.albedo) * level * AMBIENT * 1.3 * t + FOG_ALBEDO * level * (1 - t)) * 255, 0, 255)
        for k in range(n):
            quad = np.array([pts[k] - side[k], pts[k + 1] - side[k], pts[k + 1] + side[k], pts[k] + side[k]])
            P = quad if (quad[:, 2] >= NEAR).all() else clip_near(quad)
            if len(P) < 3:
                continue
            items.append((float(d[k]), 0, self._project(P), tuple(cols[k].tolist())))

    def _draw_plate(self, canvas: np.ndarray, plate: Plate, T_cp: np.ndarray, T_jp: np.ndarray,
                    state: FrameState) -> bool:
        """Composite one plate; False when nothing of it is in the canvas."""
        tex = self.textures[plate.key]
        W, Hm = tex.size_m
        corners = np.array([[-W / 2, Hm / 2, 0], [W / 2, Hm / 2, 0], [W / 2, -Hm / 2, 0], [-W / 2, -Hm / 2, 0]])
        P = corners @ T_cp[:3, :3].T + T_cp[:3, 3]
        if (P[:, 2] < NEAR).any():
            return False
        uv = self._project(P)
        cw, ch = self.canvas_size
        x0, y0 = max(int(np.floor(uv[:, 0].min())) - 1, 0), max(int(np.floor(uv[:, 1].min())) - 1, 0)
        x1, y1 = min(int(np.ceil(uv[:, 0].max())) + 2, cw), min(int(np.ceil(uv[:, 1].max())) + 2, ch)
        if x1 <= x0 or y1 <= y0:
            return False
        w, h = x1 - x0, y1 - y0
        S = SUPERSAMPLE
        while S > 1 and w * h * S * S > MAX_SUPER_PIXELS:
            S //= 2
        edge_px = max(np.linalg.norm(uv[1] - uv[0]), np.linalg.norm(uv[3] - uv[0]))
        cells = W / tex.cell
        level, per_cell = tex.level_for(edge_px / cells * S)
        m = tex.cell / per_cell  # metres per texel
        A_tex = np.array([[m, 0, 0.5 * m - W / 2], [0, -m, Hm / 2 - 0.5 * m], [0, 0, 1]])
        H_plate = self.Kc @ np.column_stack([T_cp[:3, 0], T_cp[:3, 1], T_cp[:3, 3]])
        shift = np.array([[S, 0, S * -x0 + (S - 1) / 2], [0, S, S * -y0 + (S - 1) / 2], [0, 0, 1]])
        H = shift @ H_plate @ A_tex
        warped = cv2.warpPerspective(level, H, (w * S, h * S), flags=cv2.INTER_LINEAR,
                                     borderMode=cv2.BORDER_CONSTANT, borderValue=(0, 0, 0, 0))
        if S > 1:
            warped = cv2.resize(warped, (w, h), interpolation=cv2.INTER_AREA)
        val, alpha = warped[..., 0], warped[..., 1]
        normal_w = T_jp[:3, 2]
        lam = max(0.0, float(normal_w @ self.light.sun))
        shade = self._plate_shade(plate, H_plate, (x0, y0, w, h), lam, state)
        t = float(self._fog(np.linalg.norm(T_cp[:3, 3])))
        roi = canvas[y0:y1, x0:x1].astype(np.float32)
        fog = (FOG_ALBEDO * 255.0 * state.light * (1 - t)).astype(np.float32)
        lit = (val * shade * (255.0 * t))[..., None] + alpha[..., None] * fog
        out = roi * (1 - alpha[..., None]) + lit
        canvas[y0:y1, x0:x1] = np.clip(out + 0.5, 0, 255).astype(np.uint8)
        return True

    def _plate_shade(self, plate: Plate, H_plate: np.ndarray, roi: tuple[int, int, int, int], lam: float,
                     state: FrameState) -> np.ndarray | float:
        base = state.light * AMBIENT
        sun = state.light * DIFFUSE * lam
        line = self.light.shadows.get(plate.key)
        if self.weather.shadows <= 0 or line is None or sun <= 0:
            return base + sun
        x0, y0, w, h = roi
        Hi = np.linalg.inv(H_plate)
        u, v = np.meshgrid(np.arange(x0, x0 + w, dtype=np.float64), np.arange(y0, y0 + h, dtype=np.float64))
        q = Hi[:, 0, None, None] * u + Hi[:, 1, None, None] * v + Hi[:, 2, None, None]
        X, Y = q[0] / q[2], q[1] / q[2]
        d = X * np.cos(line.angle) + Y * np.sin(line.angle) - line.offset(state.time)
        s = np.clip(0.5 + d / (2 * PENUMBRA_M), 0, 1)
        return (base + sun * (1 - self.weather.shadows * s)).astype(np.float32)

    def _items(self, state: FrameState) -> list:
        """Everything to draw, far to near: (depth, kind, data, colour); kind 0 polygon, 1 plate."""
        items: list = []
        self._polygon_items(inv_T(state.T_jacket_camera), state, items)
        items.sort(key=lambda it: -it[0])
        return items

    def _square(self, plate: Plate, T_cp: np.ndarray) -> np.ndarray:
        s = plate.marker_size / 2
        sq = np.array([[-s, s, 0], [s, s, 0], [s, -s, 0], [-s, -s, 0]]) @ T_cp[:3, :3].T + T_cp[:3, 3]
        return self._project(sq)

    def render_ideal(self, state: FrameState) -> tuple[np.ndarray, dict[int, float]]:
        """Ideal pinhole canvas and the unoccluded fraction of every marker drawn."""
        canvas = self._background(state.T_jacket_camera, state.light)
        items = self._items(state)
        drawn: list[tuple[int, np.ndarray, int]] = []  # marker id, square polygon, item index
        for k, (_, kind, data, colour) in enumerate(items):
            if kind == 0:
                cv2.fillPoly(canvas, [np.round(data * (1 << SHIFT)).astype(np.int32)], colour, cv2.LINE_AA, SHIFT)
            elif self._draw_plate(canvas, data[0], data[1], data[2], state) and data[0].marker_id is not None:
                drawn.append((data[0].marker_id, self._square(data[0], data[1]), k))
        return canvas, self._unoccluded(items, drawn)

    def visibility(self, state: FrameState) -> dict[int, float]:
        """Unoccluded fraction of every marker facing the camera, without drawing."""
        items = self._items(state)
        drawn = [(d[0].marker_id, self._square(d[0], d[1]), k) for k, (_, kind, d, _) in enumerate(items)
                 if kind == 1 and d[0].marker_id is not None]
        return self._unoccluded(items, drawn)

    def _unoccluded(self, items: list, drawn: list[tuple[int, np.ndarray, int]]) -> dict[int, float]:
        out = {}
        for mid, square, k in drawn:
            x0, y0 = np.floor(square.min(axis=0)).astype(int) - 1
            x1, y1 = np.ceil(square.max(axis=0)).astype(int) + 2
            mask = np.zeros((y1 - y0, x1 - x0), np.uint8)
            off = np.array([x0, y0])
            cv2.fillPoly(mask, [np.round((square - off) * 16).astype(np.int32)], 255, cv2.LINE_8, SHIFT)
            full = int(np.count_nonzero(mask))
            for _, kind, data, _ in items[k + 1:]:
                uv = data if kind == 0 else self._plate_outline(data[0], data[1])
                if uv is None or uv[:, 0].max() < x0 or uv[:, 0].min() > x1 or uv[:, 1].max() < y0 or \
                        uv[:, 1].min() > y1:
                    continue
                cv2.fillPoly(mask, [np.round((uv - off) * 16).astype(np.int32)], 0, cv2.LINE_8, SHIFT)
            out[mid] = np.count_nonzero(mask) / full if full else 0.0
        return out

    def _plate_outline(self, plate: Plate, T_cp: np.ndarray) -> np.ndarray | None:
        """Canvas outline of a whole plate (it hides what is behind it)."""
        h = plate.size / 2
        P = np.array([[-h, h, 0], [h, h, 0], [h, -h, 0], [-h, -h, 0]]) @ T_cp[:3, :3].T + T_cp[:3, 3]
        return None if (P[:, 2] < NEAR).any() else self._project(P)

    def finish(self, canvas: np.ndarray, state: FrameState) -> np.ndarray:
        """Distort the ideal canvas into the picture and add the lens's and the motion's blur, rain and noise."""
        img = cv2.remap(canvas, *self.maps, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        if self.weather.lens_blur > 0:
            img = cv2.GaussianBlur(img, (0, 0), self.weather.lens_blur)
        if self.weather.motion_blur:
            img = motion_blur(img, *state.blur_px)
        if self.weather.rain > 0:
            rng = np.random.default_rng([state.seed, 7])
            img = rain_streaks(img, self.weather.rain, rng, self.cam.exposure, self.K[1, 1], 0.25)
        return self.noise.add(img, state.seed)

    def render(self, state: FrameState) -> tuple[np.ndarray, dict[int, float]]:
        """Final picture (H, W, 3) uint8 BGR and each drawn marker's unoccluded fraction."""
        canvas, fractions = self.render_ideal(state)
        return self.finish(canvas, state), fractions
