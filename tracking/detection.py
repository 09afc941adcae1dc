"""ArUco marker detection: ids and corners (TL, TR, BR, BL) in distorted pixel coordinates."""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path

import cv2
import numpy as np

from tracking.camera import CameraModel
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
RAIN_REFINE_MIN_CELL_PX = 6.0  # edge-fit on the opened image only for markers whose cells (and quiet zone) survive it
SUBPIX_WIN = 3  # px half-window for CORNER_REFINE_SUBPIX; tuned in benchmarks/corners.py
SUBPIX_MAX_ITER = 50
SUBPIX_MIN_ACCURACY = 0.01  # px


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
    if not path.is_file():
        raise InputError(path, "dictionary file not found (expected e.g. DICT_6X6_250 or a YAML file)")
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    dictionary = cv2.aruco.Dictionary()
    ok = fs.isOpened() and dictionary.readDictionary(fs.root())
    fs.release()
    if not ok or dictionary.bytesList is None or len(dictionary.bytesList) == 0:
        raise InputError(path, "not an ArUco dictionary (expected nmarkers, markersize, marker_N)")
    return dictionary


def detector_parameters(refinement: Refinement = DEFAULT_REFINEMENT) -> cv2.aruco.DetectorParameters:
    """OpenCV detector parameters with our corner refinement."""
    params = cv2.aruco.DetectorParameters()
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


def detections(quads: np.ndarray, ids: np.ndarray, rejected: list[np.ndarray]) -> Detections:
    """Detections sorted by id from quads (B, 4, 2), ids (B,) and rejected candidates."""
    markers = sorted((MarkerDetection(id=int(i), corners=q) for q, i in zip(quads, ids, strict=True)),
                     key=lambda m: m.id)
    return Detections(markers=markers, rejected=[r.reshape(4, 2).astype(np.float64) for r in rejected])


class MarkerDetector:
    """Finds markers of one dictionary in grayscale frames."""

    def __init__(self, dictionary: str | cv2.aruco.Dictionary = "DICT_6X6_250",
                 refinement: Refinement = DEFAULT_REFINEMENT, camera: CameraModel | None = None,
                 rain_filter: int = RAIN_FILTER_PX) -> None:
        self.dictionary = load_dictionary(dictionary) if isinstance(dictionary, str) else dictionary
        self.refinement = Refinement(refinement)
        self.camera = camera  # with Refinement.EDGES, edges are fitted as straight lines in undistorted pixels
        self.rain_filter = rain_filter  # 0 switches the second pass off
        self._detector = cv2.aruco.ArucoDetector(self.dictionary, detector_parameters(self.refinement))
        self._kernel = np.ones((rain_filter, rain_filter), np.uint8) if rain_filter > 1 else None

    def opening(self, gray: np.ndarray) -> np.ndarray | None:
        """The rain-filtered (H, W) image (grey opening), or None when the rain pass is off."""
        return cv2.morphologyEx(gray, cv2.MORPH_OPEN, self._kernel) if self._kernel is not None else None

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

        On the rain-filtered image where the marker's cells are wide enough to survive it.
        """
        cells = self.dictionary.markerSize + 2
        blur_model = self.refinement == Refinement.BLURRED
        if opened is None:
            return refine_corners_batch(gray, quads, self.camera, cells, blur_model)
        side = np.linalg.norm(np.diff(np.concatenate([quads, quads[:, :1]], axis=1), axis=1), axis=2).mean(axis=1)
        big = side / cells >= RAIN_REFINE_MIN_CELL_PX
        out, ok = quads.copy(), np.zeros(len(quads), dtype=bool)
        for mask, image in ((big, opened), (~big, gray)):
            if mask.any():
                out[mask], ok[mask] = refine_corners_batch(image, quads[mask], self.camera, cells, blur_model)
        return out, ok

    def detect(self, gray: np.ndarray, keep_rejected: bool = False) -> Detections:
        """Markers in one grayscale (H, W) uint8 frame."""
        if gray.ndim == 3:
            gray = cv2.cvtColor(gray, cv2.COLOR_BGR2GRAY)
        opened = self.opening(gray)
        quads, ids, rejected = self.find(gray, opened)
        if len(ids) and self.refinement.fits_edges:  # all markers of the frame in vectorised calls
            quads = self.refine(gray, opened, quads)[0]
        return detections(quads, ids, rejected if keep_rejected else [])
