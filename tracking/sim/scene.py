"""Scene geometry: jacket, topside, stabbing cones, marker plates and the crane vessel (SSCV).

Frames: jacket frame x to port, y astern, z up, metres; origin at the centre of the four leg tops.
The topside frame coincides with it when mated. The vessel frame coincides with the jacket frame
translated to the vessel's midship waterline (0, -145, -25) when the vessel is at rest.

Default dimensions (`Layout`), chosen for a ~10,000 t topside on a four-legged jacket:

- leg spacing 24 m port-starboard (x = ±12) by 20 m fore-aft (y = ±10); cones A port-ahead
  (+12, -10), B starboard-ahead (-12, -10), C starboard-astern (-12, +10), D port-astern (+12, +10).
  A and B are nearest the vessel, which lies ahead (-y) with its stern toward the jacket.
- jacket legs 2.0 m diameter, vertical above the water, leg tops 25 m above mean sea level
  (sea at z = -25); top frame beams (1.0 m) at z = -3 and X-braces down to the waterline.
- stabbing cones on the jacket leg tops: 1.5 m high, 1.4 m base diameter, tip at z = +1.5.
  The cone point of the rig and of the truth log is the cone tip.
- topside legs 2.0 m diameter, 8 m from leg bottom (z = 0 when mated) to the deck underside;
  deck box 44 x 36 x 6 m (z 8..14) with a 1 m deck-edge band; module block 36 x 28 x 14 m on top.
- marker plates 1.5 x 1.5 m, white, carrying a 1.0 m black ArUco square (quiet zone 0.25 m =
  two cells of a 6x6 marker); plate plane 0.1 m proud of the leg surface (1.1 m from the leg
  axis). Jacket marker centre at z = -1.0, topside marker centre at z = +1.0 when mated: a pair
  is in one plane when mated, the topside marker 2.0 m above the jacket marker.
- SSCV: semi-submersible, 200 m long, 100 m beam, stern at y = -45; deck 22 m above the water
  (z = -3); two crane houses at the stern corners; fixed cameras on the stern at z = +2.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from itertools import pairwise

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from tracking.rig import FACE_NORMALS, normal_rotation
from tracking.sim.transforms import make_T

CONES = ("A", "B", "C", "D")
CONE_SIGNS: dict[str, tuple[float, float]] = {"A": (1, -1), "B": (-1, -1), "C": (-1, 1), "D": (1, 1)}
LEG_FACETS = 10
MAX_SEGMENT_M = 2.5  # long faces are cut into pieces this long so depth sorting works
VESSEL_ORIGIN = np.array([0.0, -145.0, -25.0])  # midship waterline at rest, jacket frame

JACKET_ALBEDO = (0.15, 0.62, 0.80)  # BGR, yellow-painted steel
TOPSIDE_LEG_ALBEDO = (0.55, 0.56, 0.58)
DECK_ALBEDO = (0.62, 0.64, 0.66)
DECK_EDGE_ALBEDO = (0.10, 0.45, 0.75)
MODULE_ALBEDO = (0.78, 0.76, 0.72)
CONE_ALBEDO = (0.12, 0.30, 0.70)
PLATE_BACK_ALBEDO = (0.40, 0.40, 0.40)
LEG_BOTTOM_ALBEDO = (0.08, 0.08, 0.08)
HULL_ALBEDO = (0.20, 0.22, 0.45)
VESSEL_DECK_ALBEDO = (0.35, 0.36, 0.38)
CRANE_ALBEDO = (0.70, 0.70, 0.72)


class Layout(BaseModel):
    """Installation dimensions, metres."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    leg_spacing_x: float = Field(24.0, gt=4)
    leg_spacing_y: float = Field(20.0, gt=4)
    sea_z: float = Field(-25.0, lt=-5)
    jacket_leg_diameter: float = Field(2.0, gt=0.5, le=4)
    topside_leg_diameter: float = Field(2.0, gt=0.5, le=4)
    topside_leg_length: float = Field(8.0, gt=3)
    cone_height: float = Field(1.5, gt=0.2)
    cone_base_diameter: float = Field(1.4, gt=0.2)
    plate_size: float = Field(1.5, gt=0.5)
    plate_standoff: float = Field(0.1, ge=0)
    jacket_marker_z: float = -1.0
    topside_marker_z: float = 1.0
    deck_size: tuple[float, float] = (44.0, 36.0)
    stern_y: float = -45.0

    def cone_xy(self, cone: str) -> np.ndarray:
        """(2,) leg axis position of a cone in the jacket frame."""
        sx, sy = CONE_SIGNS[cone]
        return np.array([sx * self.leg_spacing_x / 2, sy * self.leg_spacing_y / 2])

    def cone_tip(self, cone: str) -> np.ndarray:
        """(3,) cone tip on the jacket, jacket frame (the cone point of rig and truth)."""
        return np.array([*self.cone_xy(cone), self.cone_height])

    def marker_center(self, cone: str, face: str, body: str) -> np.ndarray:
        """(3,) marker centre in its body frame for a plate on a named face of a cone's leg."""
        n = np.array(FACE_NORMALS[face])
        radius = (self.jacket_leg_diameter if body == "jacket" else self.topside_leg_diameter) / 2
        z = self.jacket_marker_z if body == "jacket" else self.topside_marker_z
        xy = self.cone_xy(cone) + (radius + self.plate_standoff) * n[:2]
        return np.array([xy[0], xy[1], z])


@dataclass
class Face:
    """A flat convex polygon of a structure, in its body frame."""

    verts: np.ndarray  # (N, 3)
    normal: np.ndarray  # (3,) outward
    albedo: tuple[float, float, float]
    two_sided: bool = False


@dataclass
class Plate:
    """A marker or board plate: a textured square in its body frame, frame as OpenCV ArUco's."""

    key: str  # texture key, e.g. "marker:7"
    T_body_plate: np.ndarray  # (4, 4)
    size: float  # plate edge, m
    marker_id: int | None = None
    marker_size: float = 1.0


@dataclass
class Body:
    """Faces and plates fixed to one body (jacket, topside or vessel)."""

    name: str
    faces: list[Face] = field(default_factory=list)
    plates: list[Plate] = field(default_factory=list)


def _split(a: float, b: float, max_len: float) -> np.ndarray:
    n = max(1, int(np.ceil(abs(b - a) / max_len)))
    return np.linspace(a, b, n + 1)


def vertical_cylinder(cx: float, cy: float, z0: float, z1: float, radius: float,
                      albedo: tuple[float, float, float], cuts: np.ndarray | None = None) -> list[Face]:
    """Prism of LEG_FACETS facets approximating a vertical cylinder, cut into short pieces."""
    faces = []
    zs = cuts if cuts is not None else _split(z0, z1, MAX_SEGMENT_M)
    r = radius / np.cos(np.pi / LEG_FACETS)
    for i in range(LEG_FACETS):
        a0, a1 = 2 * np.pi * i / LEG_FACETS, 2 * np.pi * (i + 1) / LEG_FACETS
        am = (a0 + a1) / 2
        n = np.array([np.cos(am), np.sin(am), 0.0])
        p0 = np.array([cx + r * np.cos(a0), cy + r * np.sin(a0)])
        p1 = np.array([cx + r * np.cos(a1), cy + r * np.sin(a1)])
        for za, zb in pairwise(zs):
            verts = np.array([[*p0, za], [*p1, za], [*p1, zb], [*p0, zb]])
            faces.append(Face(verts, n, albedo))
    return faces


def disc(cx: float, cy: float, z: float, radius: float, up: bool, albedo: tuple[float, float, float]) -> Face:
    """Horizontal polygonal cap facing up or down."""
    r = radius / np.cos(np.pi / LEG_FACETS)
    a = 2 * np.pi * np.arange(LEG_FACETS) / LEG_FACETS
    verts = np.column_stack([cx + r * np.cos(a), cy + r * np.sin(a), np.full(LEG_FACETS, z)])
    return Face(verts if up else verts[::-1], np.array([0.0, 0.0, 1.0 if up else -1.0]), albedo)


def cone(cx: float, cy: float, z0: float, height: float, radius: float,
         albedo: tuple[float, float, float]) -> list[Face]:
    """Upward cone as triangular facets."""
    faces = []
    slope = radius / height
    for i in range(LEG_FACETS):
        a0, a1 = 2 * np.pi * i / LEG_FACETS, 2 * np.pi * (i + 1) / LEG_FACETS
        am = (a0 + a1) / 2
        n = np.array([np.cos(am), np.sin(am), slope])
        n /= np.linalg.norm(n)
        verts = np.array([[cx + radius * np.cos(a0), cy + radius * np.sin(a0), z0],
                          [cx + radius * np.cos(a1), cy + radius * np.sin(a1), z0],
                          [cx, cy, z0 + height]])
        faces.append(Face(verts, n, albedo))
    return faces


def box(lo: tuple[float, float, float], hi: tuple[float, float, float],
        albedo: tuple[float, float, float], max_len: float = 1e9) -> list[Face]:
    """Axis-aligned box as six faces; side faces cut into pieces no longer than max_len."""
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    faces = []
    for xs in pairwise(_split(x0, x1, max_len)):
        for ys in pairwise(_split(y0, y1, max_len)):
            faces.append(Face(np.array([[xs[0], ys[0], z1], [xs[1], ys[0], z1], [xs[1], ys[1], z1],
                                        [xs[0], ys[1], z1]]), np.array([0, 0, 1.0]), albedo))
            faces.append(Face(np.array([[xs[0], ys[0], z0], [xs[0], ys[1], z0], [xs[1], ys[1], z0],
                                        [xs[1], ys[0], z0]]), np.array([0, 0, -1.0]), albedo))
    for xa, xb in pairwise(_split(x0, x1, max_len)):
        faces.append(Face(np.array([[xa, y0, z0], [xb, y0, z0], [xb, y0, z1], [xa, y0, z1]]),
                          np.array([0, -1.0, 0]), albedo))
        faces.append(Face(np.array([[xa, y1, z0], [xa, y1, z1], [xb, y1, z1], [xb, y1, z0]]),
                          np.array([0, 1.0, 0]), albedo))
    for ya, yb in pairwise(_split(y0, y1, max_len)):
        faces.append(Face(np.array([[x0, ya, z0], [x0, ya, z1], [x0, yb, z1], [x0, yb, z0]]),
                          np.array([-1.0, 0, 0]), albedo))
        faces.append(Face(np.array([[x1, ya, z0], [x1, yb, z0], [x1, yb, z1], [x1, ya, z1]]),
                          np.array([1.0, 0, 0]), albedo))
    return faces


def tube(p0: np.ndarray, p1: np.ndarray, width: float, albedo: tuple[float, float, float],
         max_len: float = MAX_SEGMENT_M * 2) -> list[Face]:
    """Square-section member from p0 to p1, cut into pieces no longer than max_len."""
    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    axis = (p1 - p0) / np.linalg.norm(p1 - p0)
    ref = np.array([0, 0, 1.0]) if abs(axis[2]) < 0.9 else np.array([1.0, 0, 0])
    u = np.cross(axis, ref)
    u /= np.linalg.norm(u)
    v = np.cross(axis, u)
    h = width / 2
    ts = _split(0.0, float(np.linalg.norm(p1 - p0)), max_len)
    faces = []
    for n, w in ((u, v), (v, -u), (-u, -v), (-v, u)):
        for ta, tb in pairwise(ts):
            a, b = p0 + ta * axis, p0 + tb * axis
            verts = np.array([a + h * n - h * w, b + h * n - h * w, b + h * n + h * w, a + h * n + h * w])
            faces.append(Face(verts, n.copy(), albedo))
    return faces


def _plate_back(plate: Plate) -> Face:
    h = plate.size / 2
    corners = np.array([[-h, h, 0], [-h, -h, 0], [h, -h, 0], [h, h, 0]], float)
    T = plate.T_body_plate
    verts = corners @ T[:3, :3].T + T[:3, 3] - 0.01 * T[:3, 2]
    return Face(verts, -T[:3, 2].copy(), PLATE_BACK_ALBEDO)


def marker_plate(layout: Layout, marker_id: int, body: str, cone: str, face: str,
                 marker_size: float) -> Plate:
    """The plate carrying one marker, placed as tracking.rig.Marker.T_body_marker places it."""
    R = normal_rotation(np.array(FACE_NORMALS[face]))
    center = layout.marker_center(cone, face, body)
    return Plate(f"marker:{marker_id}", make_T(R, center), layout.plate_size, marker_id, marker_size)


def jacket_body(layout: Layout) -> Body:
    """Jacket legs, cones, top frame and braces above the water."""
    body = Body("jacket")
    r = layout.jacket_leg_diameter / 2
    top_cuts = np.array([layout.sea_z, -16.0, -9.0, -5.0, -3.5, -2.5, -1.75, -1.0, -0.25, 0.0])
    xy = {c: layout.cone_xy(c) for c in CONES}
    for c in CONES:
        body.faces += vertical_cylinder(*xy[c], layout.sea_z, 0.0, r, JACKET_ALBEDO, top_cuts)
        body.faces.append(disc(*xy[c], 0.0, r, True, JACKET_ALBEDO))
        body.faces += cone(*xy[c], 0.0, layout.cone_height, layout.cone_base_diameter / 2, CONE_ALBEDO)
    frame_z = -3.0
    for a, b in (("A", "B"), ("B", "C"), ("C", "D"), ("D", "A")):
        pa, pb = np.array([*xy[a], frame_z]), np.array([*xy[b], frame_z])
        d = (pb - pa) / np.linalg.norm(pb - pa)
        body.faces += tube(pa + r * d, pb - r * d, 1.0, JACKET_ALBEDO)
        low = layout.sea_z + 1.0
        body.faces += tube(pa + r * d, np.array([*xy[b], low]) - r * d, 0.8, JACKET_ALBEDO)
        body.faces += tube(pb - r * d, np.array([*xy[a], low]) + r * d, 0.8, JACKET_ALBEDO)
    return body


def topside_body(layout: Layout) -> Body:
    """Topside legs, deck box with its deck-edge band, module block."""
    body = Body("topside")
    r = layout.topside_leg_diameter / 2
    top = layout.topside_leg_length
    cuts = np.array([0.0, 0.25, 1.0, 1.75, 2.5, 4.0, 6.0, top])
    for c in CONES:
        xy = layout.cone_xy(c)
        body.faces += vertical_cylinder(*xy, 0.0, top, r, TOPSIDE_LEG_ALBEDO, cuts)
        body.faces.append(disc(*xy, 0.0, r, False, LEG_BOTTOM_ALBEDO))
    dx, dy = layout.deck_size[0] / 2, layout.deck_size[1] / 2
    body.faces += box((-dx, -dy, top), (dx, dy, top + 1.0), DECK_EDGE_ALBEDO, 6.0)
    body.faces += box((-dx, -dy, top + 1.0), (dx, dy, top + 6.0), DECK_ALBEDO, 6.0)
    body.faces += box((-dx + 4, -dy + 4, top + 6.0), (dx - 4, dy - 4, top + 20.0), MODULE_ALBEDO, 7.0)
    return body


def vessel_body(layout: Layout) -> Body:
    """The SSCV in its own frame: upper hull box, columns, two crane houses at the stern."""
    body = Body("vessel")
    stern = layout.stern_y - VESSEL_ORIGIN[1]  # +100 in the vessel frame
    body.faces += box((-50, stern - 200, 0.0), (50, stern, 12.0), HULL_ALBEDO, 25.0)
    body.faces += box((-50, stern - 200, 12.0), (50, stern, 22.0), VESSEL_DECK_ALBEDO, 25.0)
    for sx in (-1, 1):
        body.faces += box((sx * 34 - 12, stern - 26, 22.0), (sx * 34 + 12, stern - 2, 42.0), CRANE_ALBEDO, 12.0)
    return body


def attach_plates(body: Body, plates: list[Plate]) -> None:
    """Add plates and their grey backs to a body."""
    for p in plates:
        body.plates.append(p)
        body.faces.append(_plate_back(p))
