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
    params.cornerRefinementMethod = _CV_REFINE[EDGES_START if refinement == Refinement.EDGES else refinement]
    params.cornerRefinementWinSize = SUBPIX_WIN
    params.cornerRefinementMaxIterations = SUBPIX_MAX_ITER
    params.cornerRefinementMinAccuracy = SUBPIX_MIN_ACCURACY
    return params


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

    def _find(self, gray: np.ndarray, opened: np.ndarray | None
              ) -> tuple[list[np.ndarray], np.ndarray | None, list[np.ndarray]]:
        """Quads and ids: the plain pass, plus markers only the rain-filtered pass finds (rain cuts borders)."""
        corners, ids, rejected = self._detector.detectMarkers(gray)
        if opened is None:
            return list(corners), ids, list(rejected)
        corners2, ids2, _ = self._detector.detectMarkers(opened)
        if ids2 is None:
            return list(corners), ids, list(rejected)
        seen = set() if ids is None else set(ids.reshape(-1).tolist())
        extra = [(c, i) for c, i in zip(corners2, ids2.reshape(-1), strict=True) if int(i) not in seen]
        if not extra:
            return list(corners), ids, list(rejected)
        all_ids = np.concatenate([ids.reshape(-1) if ids is not None else np.zeros(0, int), [i for _, i in extra]])
        return list(corners) + [c for c, _ in extra], all_ids.reshape(-1, 1), list(rejected)

    def _refine(self, gray: np.ndarray, opened: np.ndarray | None, quads: np.ndarray) -> np.ndarray:
        """Edge-fit corners; on the rain-filtered image where the marker's cells are wide enough to survive it."""
        cells = self.dictionary.markerSize + 2
        if opened is None:
            return refine_corners_batch(gray, quads, self.camera, cells)[0]
        side = np.linalg.norm(np.diff(np.concatenate([quads, quads[:, :1]], axis=1), axis=1), axis=2).mean(axis=1)
        big = side / cells >= RAIN_REFINE_MIN_CELL_PX
        out = quads.copy()
        for mask, image in ((big, opened), (~big, gray)):
            if mask.any():
                out[mask] = refine_corners_batch(image, quads[mask], self.camera, cells)[0]
        return out

    def detect(self, gray: np.ndarray, keep_rejected: bool = False) -> Detections:
        """Markers in one grayscale (H, W) uint8 frame."""
        if gray.ndim == 3:
            gray = cv2.cvtColor(gray, cv2.COLOR_BGR2GRAY)
        opened = cv2.morphologyEx(gray, cv2.MORPH_OPEN, self._kernel) if self._kernel is not None else None
        corners, ids, rejected = self._find(gray, opened)
        markers = []
        if ids is not None:
            quads = np.array([c.reshape(4, 2) for c in corners], dtype=np.float64)
            if self.refinement == Refinement.EDGES:  # all markers of the frame in vectorised calls
                quads = self._refine(gray, opened, quads)
            for quad, i in zip(quads, ids.reshape(-1), strict=True):
                markers.append(MarkerDetection(id=int(i), corners=quad))
        markers.sort(key=lambda m: m.id)
        kept = [r.reshape(4, 2).astype(np.float64) for r in rejected] if keep_rejected else []
        return Detections(markers=markers, rejected=kept)
