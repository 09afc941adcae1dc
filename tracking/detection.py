"""ArUco marker detection: ids and corners (TL, TR, BR, BL) in distorted pixel coordinates."""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path

import cv2
import numpy as np

from tracking.camera import OPENCV_READ_ERRORS, CameraModel, open_storage, present, read_integer
from tracking.corners import refine_corners_batch
from tracking.errors import InputError


class Refinement(StrEnum):
    """How marker corners are refined to sub-pixel accuracy."""

    NONE = "none"
    SUBPIX = "subpix"
    CONTOUR = "contour"
    APRILTAG = "apriltag"
    EDGES = "edges"  # OpenCV's detector with EDGES_START, then the edge fit of tracking.corners
    BLURRED = "blurred"  # the same edge fit with its blurred-profile model on small cells (blurry lenses)

    @property
    def fits_edges(self) -> bool:
        """Whether corners get tracking.corners' edge fit."""
        return self in (Refinement.EDGES, Refinement.BLURRED)


_CV_REFINE = {
    Refinement.NONE: cv2.aruco.CORNER_REFINE_NONE,
    Refinement.SUBPIX: cv2.aruco.CORNER_REFINE_SUBPIX,
    Refinement.CONTOUR: cv2.aruco.CORNER_REFINE_CONTOUR,
    Refinement.APRILTAG: cv2.aruco.CORNER_REFINE_APRILTAG,
}
EDGES_START = Refinement.NONE  # OpenCV refinement that Refinement.EDGES starts from (best in benchmarks/corners.py)
DEFAULT_REFINEMENT = Refinement.EDGES  # unbiased: benchmarks/results/corners.md
RAIN_FILTER_PX = 5  # grey opening that erases bright streaks thinner than this before a second detection pass
RAIN_STREAK_LEVELS = 25  # a pixel this much brighter than the rain-filtered image is part of a bright streak ...
RAIN_STREAK_SHARE = 0.003  # ... and a frame with this share of such pixels has rain: the second pass runs (rain lights
# several times this share, fog and noise alone less: docs/method.md#detection-and-corners)
RAIN_REFINE_MIN_CELL_PX = 6.0  # edge-fit on the opened image only for markers whose cells (and quiet zone) survive it
SUBPIX_WIN = 3  # px half-window for CORNER_REFINE_SUBPIX; tuned in benchmarks/corners.py
SUBPIX_MAX_ITER = 50
SUBPIX_MIN_ACCURACY = 0.01  # px
MIN_MARKER_BITS = 2  # code cells a side of a custom dictionary's markers (predefined ones: 4 to 7)
MAX_MARKER_BITS = 16
MAX_DICTIONARY_MARKERS = 100_000  # predefined dictionaries hold at most 1000
SHOWN_CHARS = 40  # of a bad marker string, in its error


@dataclass(frozen=True)
class MarkerDetection:
    """One detected marker."""

    id: int
    corners: np.ndarray  # (4, 2) distorted pixels, TL TR BR BL


@dataclass
class Detections:
    """All markers found in one frame."""

    markers: list[MarkerDetection]
    rejected: list[np.ndarray] = field(default_factory=list)  # (4, 2) candidates with no valid code

    @property
    def ids(self) -> list[int]:
        """Ids found, in detection order."""
        return [m.id for m in self.markers]


def load_dictionary(name_or_path: str) -> cv2.aruco.Dictionary:
    """A predefined dictionary (DICT_6X6_250) or a custom one from an OpenCV YAML file."""
    if name_or_path.startswith("DICT_"):
        if not hasattr(cv2.aruco, name_or_path):
            raise InputError("--dictionary", f"unknown ArUco dictionary {name_or_path!r} "
                                             "(expected e.g. DICT_6X6_250 or a dictionary YAML file)")
        return cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, name_or_path))
    path = Path(name_or_path)
    if not path.exists():
        raise InputError(path, "dictionary file not found (expected e.g. DICT_6X6_250 or a YAML file)")
    return read_dictionary(path)


def read_dictionary(path: Path) -> cv2.aruco.Dictionary:
    """A custom dictionary from an OpenCV YAML file (nmarkers, markersize, marker_0 ..., optional maxCorrectionBits),
    as OpenCV's Dictionary.writeDictionary writes it; a one-line InputError naming the file and field otherwise.

    The fields are checked here and the dictionary built from the bits: OpenCV's readDictionary writes a marker
    string longer than markersize² past its buffer (a crash) and takes a shorter one with uninitialised bits.
    """
    fs = open_storage(path, "dictionary YAML file", cv2.FILE_STORAGE_FORMAT_AUTO)
    try:
        count = read_integer(fs, path, "nmarkers", 1, MAX_DICTIONARY_MARKERS, "the number of markers")
        bits = read_integer(fs, path, "markersize", MIN_MARKER_BITS, MAX_MARKER_BITS, "code cells a side")
        correction = 0
        if present(fs.getNode("maxCorrectionBits")):
            correction = read_integer(fs, path, "maxCorrectionBits", 0, bits * bits, "a number of bits")
        codes = [_marker_bits(fs, path, i, bits) for i in range(count)]
    finally:
        fs.release()
    byte_list = np.concatenate([cv2.aruco.Dictionary.getByteListFromBits(code) for code in codes])
    return cv2.aruco.Dictionary(byte_list, bits, correction)


def _marker_bits(fs: cv2.FileStorage, path: Path, index: int, bits: int) -> np.ndarray:
    """(bits, bits) uint8 code of marker_<index>: a quoted string of bits² zeros and ones, row by row."""
    key = f"marker_{index}"
    node = fs.getNode(key)
    expected = f"expected a quoted string of {bits * bits} zeros and ones"
    if not present(node):
        raise InputError(path, f"missing ({expected}; nmarkers says there are more)", key)
    if not node.isString():  # unquoted digits read as a number and lose their leading zeros
        raise InputError(path, f"not a string ({expected})", key)
    try:
        code = node.string()
    except OPENCV_READ_ERRORS:
        raise InputError(path, f"not readable text ({expected})", key) from None
    shown = f"{code[:SHOWN_CHARS]!r}{'...' if len(code) > SHOWN_CHARS else ''}"
    if len(code) != bits * bits:
        raise InputError(path, f"{shown} has {len(code)} characters ({expected})", key)
    if set(code) - {"0", "1"}:
        raise InputError(path, f"{shown} holds other characters ({expected})", key)
    return np.frombuffer(code.encode(), dtype=np.uint8).reshape(bits, bits) - ord("0")


def detector_parameters(refinement: Refinement = DEFAULT_REFINEMENT, inverted: bool = False
                        ) -> cv2.aruco.DetectorParameters:
    """OpenCV detector parameters with our corner refinement; inverted: the markers are printed white on black."""
    params = cv2.aruco.DetectorParameters()
    params.detectInvertedMarker = inverted
    refinement = Refinement(refinement)
    params.cornerRefinementMethod = _CV_REFINE[EDGES_START if refinement.fits_edges else refinement]
    params.cornerRefinementWinSize = SUBPIX_WIN
    params.cornerRefinementMaxIterations = SUBPIX_MAX_ITER
    params.cornerRefinementMinAccuracy = SUBPIX_MIN_ACCURACY
    return params


def find_quads(detector: cv2.aruco.ArucoDetector, image: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
    """One OpenCV pass: quads (B, 4, 2) float64, ids (B,) int and the rejected candidates (as OpenCV gives them)."""
    corners, ids, rejected = detector.detectMarkers(image)
    if ids is None:
        return np.zeros((0, 4, 2)), np.zeros(0, dtype=int), list(rejected)
    quads = np.array([c.reshape(4, 2) for c in corners], dtype=np.float64)
    return quads, ids.reshape(-1).astype(int), list(rejected)


def destreaked(gray: np.ndarray, opened: np.ndarray) -> np.ndarray:
    """(H, W) frame with its bright streaks (pixels RAIN_STREAK_LEVELS above the grey opening) taken from the opening
    and every other pixel as it was. The whole opening would also erase the rain, but on a noisy edge its minimum then
    maximum reads the marker smaller, the more so at low contrast (fog): docs/method.md#detection-and-corners."""
    return np.where(cv2.subtract(gray, opened) > RAIN_STREAK_LEVELS, opened, gray)


def detections(quads: np.ndarray, ids: np.ndarray, rejected: list[np.ndarray]) -> Detections:
    """Detections sorted by id from quads (B, 4, 2), ids (B,) and rejected candidates."""
    markers = sorted((MarkerDetection(id=int(i), corners=q) for q, i in zip(quads, ids, strict=True)),
                     key=lambda m: m.id)
    return Detections(markers=markers, rejected=[r.reshape(4, 2).astype(np.float64) for r in rejected])


class MarkerDetector:
    """Finds markers of one dictionary in grayscale frames."""

    def __init__(self, dictionary: str | cv2.aruco.Dictionary = "DICT_6X6_250",
                 refinement: Refinement = DEFAULT_REFINEMENT, camera: CameraModel | None = None,
                 rain_filter: int = RAIN_FILTER_PX, inverted: bool = False) -> None:
        self.dictionary = load_dictionary(dictionary) if isinstance(dictionary, str) else dictionary
        self.refinement = Refinement(refinement)
        self.camera = camera  # with Refinement.EDGES, edges are fitted as straight lines in undistorted pixels
        self.rain_filter = rain_filter  # 0 switches the second pass off
        self.inverted = inverted  # white markers on black: found as such, their edges fitted on the negative
        self._detector = cv2.aruco.ArucoDetector(self.dictionary, detector_parameters(self.refinement, inverted))
        self._kernel = np.ones((rain_filter, rain_filter), np.uint8) if rain_filter > 1 else None

    def opening(self, gray: np.ndarray) -> np.ndarray | None:
        """The rain-filtered (H, W) image (grey opening), or None when the rain pass is off."""
        return cv2.morphologyEx(gray, cv2.MORPH_OPEN, self._kernel) if self._kernel is not None else None

    def rainy(self, gray: np.ndarray, opened: np.ndarray) -> bool:
        """Whether a frame shows rain: enough bright streaks that the grey opening removed."""
        streaks = cv2.compare(cv2.subtract(gray, opened), RAIN_STREAK_LEVELS, cv2.CMP_GT)
        return cv2.countNonZero(streaks) > RAIN_STREAK_SHARE * gray.size

    def find(self, gray: np.ndarray, opened: np.ndarray | None, detector: cv2.aruco.ArucoDetector | None = None
             ) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
        """Unrefined quads (B, 4, 2) and ids (B,): the plain pass, plus ids only the rain-filtered pass finds."""
        detector = detector or self._detector
        quads, ids, rejected = find_quads(detector, gray)
        if opened is None:
            return quads, ids, rejected
        quads2, ids2, _ = find_quads(detector, opened)
        extra = ~np.isin(ids2, ids)  # rain cuts borders: the plain pass wins where both find an id
        return np.concatenate([quads, quads2[extra]]), np.concatenate([ids, ids2[extra]]), rejected

    def refine(self, gray: np.ndarray, opened: np.ndarray | None, quads: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Edge-fit corners (B, 4, 2) and which fits succeeded (B,) (failures keep their corners).

        Where the marker's cells are wide enough to survive the rain filter, on the frame with its rain streaks
        replaced by the filtered image (destreaked).
        """
        cells = self.dictionary.markerSize + 2
        blur_model = self.refinement == Refinement.BLURRED

        def fit(image: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            """The edge fit expects a dark square in a bright margin: a white print's negative (rain removed first)."""
            return refine_corners_batch(cv2.bitwise_not(image) if self.inverted else image, q, self.camera, cells,
                                        blur_model)

        if opened is None:
            return fit(gray, quads)
        side = np.linalg.norm(np.diff(np.concatenate([quads, quads[:, :1]], axis=1), axis=1), axis=2).mean(axis=1)
        big = side / cells >= RAIN_REFINE_MIN_CELL_PX
        out, ok = quads.copy(), np.zeros(len(quads), dtype=bool)
        for mask, image in ((big, destreaked(gray, opened) if big.any() else gray), (~big, gray)):
            if mask.any():
                out[mask], ok[mask] = fit(image, quads[mask])
        return out, ok

    def detect(self, gray: np.ndarray, keep_rejected: bool = False) -> Detections:
        """Markers in one grayscale (H, W) uint8 frame."""
        if gray.ndim == 3:
            gray = cv2.cvtColor(gray, cv2.COLOR_BGR2GRAY)
        opened = self.opening(gray)
        quads, ids, rejected = self.find(gray, opened if opened is not None and self.rainy(gray, opened) else None)
        if len(ids) and self.refinement.fits_edges:  # all markers of the frame in vectorised calls
            quads = self.refine(gray, opened, quads)[0]
        return detections(quads, ids, rejected if keep_rejected else [])
