"""Printable marker sheets: one page per marker of a rig, at print scale (`topside markers`).

A sheet is the marker's black square of the rig's marker_size (its border and code cells as cv2.aruco draws them
for the rig's dictionary, one cell per bit), a quiet zone of QUIET_CELLS cells around it in the other colour, and a
label band below holding the marker's id, body, cone and face, the size the square must measure, and how it is
mounted. The page is exactly that size: printed at 100 % (no "fit to page"), the square measures marker_size. An
inverted rig (white on black) prints each sheet's colours swapped, quiet zone included.

A PDF draws every black cell as a filled rectangle (sharp at any printer's resolution); a PNG is the same page
rasterised at a stated DPI, stored in the file. The page's top is the marker's top (its y axis, as the rig's
orientation has it): with rotation_deg the rig says the marker is turned, and the label says by how much.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from tracking.outputs import atomic_path
from tracking.rig import Marker, Rig

INCH_M = 0.0254
POINT_M = INCH_M / 72.0
QUIET_CELLS = 2  # ArUco's detector needs one cell of quiet zone; two keep a frame or a neighbour's edge off the code
LABEL_SHARE = 0.16  # the label band's height as a share of the black square's side ...
LABEL_MIN_M = 0.025  # ... but at least this (three lines of 3-5 mm text on a small marker)
CHAR_EM = 0.62  # a character's mean width in DejaVu Sans, in ems (to shrink a line that would not fit the page)
FORMATS = ("pdf", "png")
DEFAULT_DPI = 150.0  # a PNG's resolution: large-format printers print banners at 100-150 dpi
MAX_PNG_PIXELS = 200e6  # a page beyond this many pixels is refused (a 1 m marker at 150 dpi is 50 Mpx)


@dataclass(frozen=True)
class Sheet:
    """One marker's page: its code cells (True: black), sizes in metres, label lines, colours."""

    marker: Marker
    cells: np.ndarray  # (n, n) bool, the black square's cells (border included) as printed: True = black
    side_m: float  # the black square's side (the rig's marker_size)
    quiet_m: float  # the quiet zone's width on each side
    label_m: float  # the label band's height
    label: tuple[str, str, str]
    inverted: bool  # white on black: every colour swapped

    @property
    def page_m(self) -> tuple[float, float]:
        """The page's width and height."""
        width = self.side_m + 2 * self.quiet_m
        return width, width + self.label_m

    def cell_rows(self) -> Iterator[tuple[int, int, int]]:
        """The black cells as runs along each row: (row from the top, first column, columns)."""
        for r, row in enumerate(self.cells):
            c = 0
            while c < len(row):
                if row[c]:
                    start = c
                    while c < len(row) and row[c]:
                        c += 1
                    yield r, start, c - start
                else:
                    c += 1


def marker_cells(dictionary: str, marker_id: int) -> np.ndarray:
    """The marker's cells as cv2.aruco draws it (one pixel per cell, the black border included): (n, n), True black."""
    aruco = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, dictionary))
    n = int(aruco.markerSize) + 2
    return cv2.aruco.generateImageMarker(aruco, marker_id, n, borderBits=1) < 128


def mounting(marker: Marker) -> str:
    """How the sheet is mounted, as the rig's orientation has it."""
    if marker.R is not None or marker.quaternion is not None:
        return "mount it turned as the rig's orientation gives it (its top is the marker's y axis)"
    if marker.rotation_deg:
        return (f"mount it with this label below the square, then turned {marker.rotation_deg:g}° counter-clockwise "
                "as seen facing it (rotation_deg)")
    return "mount it upright, this label below the square"


def sheet(rig: Rig, marker: Marker) -> Sheet:
    """A marker's sheet."""
    cells = marker_cells(rig.dictionary, marker.id)
    side = rig.marker_size
    label = (f"marker {marker.id} · {marker.body} · cone {marker.cone} · face {marker.face} · {rig.dictionary}"
             + (" · white on black" if rig.inverted else ""),
             f"print at 100 % (actual size): the black square measures {side * 1000:.0f} mm", mounting(marker))
    return Sheet(marker, cells, side, QUIET_CELLS * side / len(cells), max(LABEL_SHARE * side, LABEL_MIN_M), label,
                 rig.inverted)


def sheet_name(marker: Marker, fmt: str) -> str:
    """The file a marker's sheet is written to."""
    return f"marker-{marker.id}-{marker.body}-{marker.cone}-{marker.face}.{fmt}".replace("/", "_")


def png_pixels(page: Sheet, dpi: float) -> int:
    """The pixels of a sheet's page at dpi."""
    width, height = page.page_m
    return int(round(width / INCH_M * dpi) * round(height / INCH_M * dpi))


def write_sheet(page: Sheet, path: Path, fmt: str, dpi: float = DEFAULT_DPI) -> None:
    """Write a sheet at print scale (atomically): a PDF with a rectangle per run of black cells, or a PNG at dpi."""
    from matplotlib.figure import Figure
    from matplotlib.patches import Rectangle

    width, height = page.page_m
    ink, paper = ("white", "black") if page.inverted else ("black", "white")
    fig = Figure(figsize=(width / INCH_M, height / INCH_M), dpi=dpi, facecolor=paper)
    ax = fig.add_axes((0.0, 0.0, 1.0, 1.0))
    ax.set_xlim(0.0, width)
    ax.set_ylim(0.0, height)
    ax.set_axis_off()
    cell = page.side_m / len(page.cells)
    top = height - page.quiet_m  # the square's top edge (y up on the page)
    for row, col, run in page.cell_rows():
        ax.add_patch(Rectangle((page.quiet_m + col * cell, top - (row + 1) * cell), run * cell, cell,
                               facecolor=ink, edgecolor="none", linewidth=0, antialiased=False))
    room_pt = (width - 2 * page.quiet_m / QUIET_CELLS) / POINT_M  # the page's width less half the quiet zones
    for k, text in enumerate(page.label):  # the first line larger; each no wider than the page
        size_pt = min((0.26 if k == 0 else 0.17) * page.label_m / POINT_M, room_pt / (CHAR_EM * len(text)))
        ax.text(page.quiet_m / QUIET_CELLS, page.label_m * (0.74 - 0.3 * k), text, color=ink, fontsize=size_pt,
                va="center", ha="left", family="DejaVu Sans")
    with atomic_path(path) as partial:
        fig.savefig(partial, format=fmt, dpi=dpi, facecolor=paper)
