"""Stateful marker detection for live tracking: search where the markers were, the whole frame now and then.

A MarkerTracker follows the frames of one camera in order. Around each marker of the previous
frames it crops a region of interest (the marker's box moved by its last motion, grown by a margin
for motion and scale), shrinks crops of large markers so their smallest marker is about
ROI_SIDE_PX long, and runs OpenCV's detector there; the rain pass (grey opening) runs only on crops
where an expected marker was missed; a missing marker's crop grows for FORGET_AFTER frames. The
whole frame is searched for new markers every FULL_EVERY frames, while nothing is tracked, and
when asked (`search_everywhere`): with ArUco3 (a shrunk segmentation image) where the smallest
marker expected is large enough, else as MarkerDetector does. Corners get MarkerDetector's edge
fit on the full-resolution frame; a marker found in a shrunk image whose edge fit fails is found
again at full resolution. Ids come from OpenCV's decoding as in MarkerDetector. Speed and accuracy:
benchmarks/results/detection_speed.md.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from tracking.detection import (
    RAIN_REFINE_MIN_CELL_PX,
    Detections,
    MarkerDetector,
    destreaked,
    detections,
    detector_parameters,
    find_quads,
)

FULL_EVERY = 15  # frames between whole-frame searches while every tracked marker is found (1 s at 15 FPS)
IDLE_EVERY = 1  # frames between whole-frame searches while nothing is tracked
FORGET_AFTER = 15  # a marker missing this many frames is no longer searched around its last position (a
# missing marker is searched in a crop growing by ROI_LOST_GROWTH per frame, and by every whole-frame search)
ROI_MARGIN_SIDES = 0.6  # a crop reaches this many marker sides beyond the marker's predicted box ...
ROI_MARGIN_MIN_PX = 12.0  # ... and at least this far
ROI_MOTION_FRAMES = 2.0  # ... plus this many frames of the marker's last motion
ROI_LOST_GROWTH = 0.5  # the margin grows by this fraction per frame the marker has been missing ...
ROI_LOST_MAX = 3.0  # ... up to this many times its size
ROI_MAX_MARGIN_SIDES = 3.0  # no margin beyond this many marker sides
PREDICT_FRAMES = 2  # a missing marker is expected to move on at its last velocity for this many frames at most
ROI_MERGE_PX = 4  # crops closer than this are searched as one
ROI_SIDE_PX = 48.0  # crops are shrunk so their smallest marker is about this long (never enlarged)
ARUCO3_CANONICAL_PX = 16  # ArUco3 minSideLengthCanonicalImg: least marker side in its segmentation image
ARUCO3_SIDE_PX = 24.0  # the whole-frame search shrinks the frame so the smallest expected marker is this long ...
ARUCO3_MAX_SCALE = 0.75  # ... with ArUco3 when that shrinks it at least this much (ArUco3 misses small markers)
NEW_MARKER_SHRINK = 0.6  # markers not yet tracked may be this much smaller than the smallest tracked one
CONTOUR_POINTS_PER_SIDE = 2.8  # a square's contour has 4 (upright) to 2.8 (turned 45 deg) points per side length
ROI_MIN_SIZE = 0.5  # a crop's search skips contours of markers smaller than this fraction of its smallest one
REFINE_REACH_PX = 10.0  # the edge fit reads pixels up to this far beyond a marker's corners ...
REFINE_REACH_SIDES = 0.4  # ... or this many sides (quiet zone, coarse search and level samples)
MIN_ROI_PX = 8  # crops narrower than this (a marker leaving the frame) are not searched
MIN_MARKER_PX = 16.0  # smallest marker side the whole-frame search looks for


def quad_side(quad: np.ndarray) -> float:
    """Mean side length of a quad (4, 2), px."""
    return float(np.linalg.norm(quad - np.roll(quad, -1, axis=0), axis=1).mean())


@dataclass
class Track:
    """A marker being followed: its last corners and motion."""

    corners: np.ndarray  # (4, 2) distorted pixels, TL TR BR BL, when last seen
    velocity: np.ndarray  # (2,) px per frame of its centre
    seen: int  # frame number when last seen
    rain: bool = False  # last found by the rain-filtered pass
    side: float = 0.0  # mean side length, px

    def __post_init__(self) -> None:
        self.side = quad_side(self.corners)

    def predicted(self, frame: int) -> np.ndarray:
        """(4, 2) corners expected at a frame number, moving on at the last velocity."""
        return self.corners + self.velocity * min(frame - self.seen, PREDICT_FRAMES)

    def margin(self, frame: int) -> float:
        """Crop margin around the predicted box at a frame number, px."""
        missing = frame - self.seen - 1
        base = max(ROI_MARGIN_MIN_PX, ROI_MARGIN_SIDES * self.side) * min(1 + ROI_LOST_GROWTH * missing, ROI_LOST_MAX)
        motion = ROI_MOTION_FRAMES * float(np.linalg.norm(self.velocity)) * min(frame - self.seen, PREDICT_FRAMES)
        return min(base + motion, max(ROI_MARGIN_MIN_PX, ROI_MAX_MARGIN_SIDES * self.side))


@dataclass
class Roi:
    """A rectangle of the frame to search and the tracked ids expected in it."""

    x0: int
    y0: int
    x1: int  # exclusive
    y1: int  # exclusive
    ids: set[int]
    min_side: float  # px, the smallest expected marker

    def contains(self, quad: np.ndarray) -> bool:
        """True when the quad (4, 2) lies inside."""
        return bool(self.x0 <= quad[:, 0].min() and quad[:, 0].max() < self.x1
                    and self.y0 <= quad[:, 1].min() and quad[:, 1].max() < self.y1)

    def contains_box(self, other: Roi, pad: int) -> bool:
        """True when the other rectangle grown by pad px (clipped at 0) lies inside."""
        return (self.x0 <= max(other.x0 - pad, 0) and other.x1 + pad <= self.x1
                and self.y0 <= max(other.y0 - pad, 0) and other.y1 + pad <= self.y1)

    def overlaps(self, other: Roi) -> bool:
        """True when the two rectangles touch or nearly do."""
        m = ROI_MERGE_PX
        return (self.x0 - m < other.x1 and other.x0 - m < self.x1
                and self.y0 - m < other.y1 and other.y0 - m < self.y1)

    def union(self, other: Roi) -> Roi:
        """The bounding rectangle of both, expecting the ids of both."""
        return Roi(min(self.x0, other.x0), min(self.y0, other.y0), max(self.x1, other.x1), max(self.y1, other.y1),
                   self.ids | other.ids, min(self.min_side, other.min_side))


def box_roi(quad: np.ndarray, margin: float, shape: tuple[int, ...], ids: set[int], min_side: float) -> Roi | None:
    """The bounding box of a quad (4, 2) grown by margin px and clipped to a frame of shape (H, W), or None if empty."""
    h, w = shape[:2]
    x0, y0 = np.floor(quad.min(axis=0) - margin).astype(int)
    x1, y1 = np.ceil(quad.max(axis=0) + margin).astype(int) + 1
    x0, y0, x1, y1 = max(int(x0), 0), max(int(y0), 0), min(int(x1), w), min(int(y1), h)
    return Roi(x0, y0, x1, y1, ids, min_side) if x1 - x0 > MIN_ROI_PX and y1 - y0 > MIN_ROI_PX else None


def merge_rois(rois: list[Roi]) -> list[Roi]:
    """Rectangles merged until none overlap."""
    out: list[Roi] = []
    for roi in rois:
        merged = True
        while merged:
            merged = False
            for i, other in enumerate(out):
                if roi.overlaps(other):
                    roi = roi.union(out.pop(i))
                    merged = True
                    break
        out.append(roi)
    return out


def sized_parameters(params: cv2.aruco.DetectorParameters, min_side_px: float, image_size: int
                     ) -> cv2.aruco.DetectorParameters:
    """Parameters that skip contours too short for a marker of min_side_px in an image of longest side image_size.

    OpenCV's default (3 % of the image size) lets every speck of rain through in a small crop, and
    each costs a decoding attempt.
    """
    params.minMarkerPerimeterRate = float(min(CONTOUR_POINTS_PER_SIDE * min_side_px / image_size, 4.0))
    return params


def aruco3_parameters(base: cv2.aruco.DetectorParameters, min_side_px: float, image_size: int
                      ) -> cv2.aruco.DetectorParameters:
    """ArUco3 parameters that shrink a frame of longest side image_size until markers of min_side_px are ARUCO3_SIDE_PX.

    OpenCV scales the frame by c / (c + r * image_size) (c: minSideLengthCanonicalImg, r:
    minMarkerLengthRatioOriginalImg) and keeps contours at least c long in the scaled frame.
    """
    params = base
    params.useAruco3Detection = True
    scale = min(1.0, ARUCO3_SIDE_PX / max(min_side_px, 1.0))
    canonical = int(min(ARUCO3_CANONICAL_PX, max(4.0, 0.75 * min_side_px * scale)))
    params.minSideLengthCanonicalImg = canonical
    params.minMarkerLengthRatioOriginalImg = float(canonical * (1 / scale - 1) / image_size)
    return params


@dataclass(frozen=True)
class Candidate:
    """A marker found before refinement, and where."""

    quad: np.ndarray  # (4, 2) frame pixels
    coarse: bool  # found in a shrunk image: if the edge fit fails, search again at full resolution
    rain: bool = False  # found by the rain-filtered pass


class MarkerTracker:
    """Markers in the consecutive frames of one camera, found mostly near where they were (opt-in, stateful).

    Same interface as MarkerDetector.detect; with Refinement.EDGES (the default) crops are shrunk
    and the whole-frame search uses ArUco3, with other refinements both run at full resolution.
    """

    def __init__(self, detector: MarkerDetector, full_every: int = FULL_EVERY, idle_every: int = IDLE_EVERY) -> None:
        self.detector = detector  # dictionary, refinement, camera model and rain filter
        self.full_every = full_every
        self.idle_every = idle_every
        self.tracks: dict[int, Track] = {}
        self.frame = -1  # number of the frame being processed
        self.last_full = -(10 ** 9)  # frame number of the last whole-frame search
        self.full_searches = 0  # whole-frame searches so far (for benchmarks and tests)
        self._force_full = False
        self._edges = detector.refinement.fits_edges  # corners are re-fitted: coarse searches are fine
        self._params = detector_parameters(detector.refinement, detector.inverted)
        self._roi_detector = cv2.aruco.ArucoDetector(detector.dictionary, self._params)
        self._full: dict[tuple[int, int, bool], cv2.aruco.ArucoDetector] = {}
        self._buffer: np.ndarray | None = None  # reused (H, W) image the edges are fitted on

    def search_everywhere(self) -> None:
        """Search the whole of the next frame."""
        self._force_full = True

    def reset(self) -> None:
        """Forget every marker: the next frame is searched whole (a new source, a jump in time)."""
        self.tracks.clear()
        self._force_full = True

    def detect(self, gray: np.ndarray, keep_rejected: bool = False) -> Detections:
        """Markers in the next grayscale (H, W) uint8 frame of the camera."""
        if gray.ndim == 3:
            gray = cv2.cvtColor(gray, cv2.COLOR_BGR2GRAY)
        self.frame += 1
        found: dict[int, Candidate] = {}
        rejected: list[np.ndarray] | None = [] if keep_rejected else None
        opened_crops = self._search_rois(gray, set(self.tracks), found, rejected)
        opened_full = self._search_full(gray, found, rejected) if self._full_due() else None
        ids = np.array(sorted(found), dtype=int)
        quads = np.array([found[i].quad for i in ids], dtype=np.float64).reshape(-1, 4, 2)
        if len(ids) and self._edges:
            image = self._refinement_image(gray, quads, opened_full, opened_crops)
            if image is not None:
                quads, ok = self.detector.refine(image, None, quads)
            else:
                quads, ok = self.detector.refine(gray, opened_full if opened_full is not None
                                                 else self.detector.opening(gray), quads)
            for k in np.flatnonzero(~ok & np.array([found[i].coarse for i in ids], dtype=bool)):
                quads[k] = self._full_resolution(gray, int(ids[k]), quads[k])
        result = detections(quads, ids, rejected or [])
        self._update(result, {i: c.rain for i, c in found.items()})
        return result

    def _full_due(self) -> bool:
        """Whether this frame is searched whole."""
        since = self.frame - self.last_full
        due = self._force_full or since >= self.full_every or (not self.tracks and since >= self.idle_every)
        self._force_full = False
        return due

    def _search_full(self, gray: np.ndarray, found: dict[int, Candidate], rejected: list[np.ndarray] | None
                     ) -> np.ndarray | None:
        """The whole-frame search for markers not tracked yet; returns the rain-filtered frame if it made one.

        ArUco3 where the smallest marker expected is large enough to shrink the frame (with the edge
        fit), else the stateless detector's pass; the rain pass too while nothing is tracked.
        """
        self.last_full = self.frame
        self.full_searches += 1
        sides = [t.side for t in self.tracks.values()]
        min_side = max(NEW_MARKER_SHRINK * min(sides) if sides else MIN_MARKER_PX, MIN_MARKER_PX)
        aruco3 = self._edges and ARUCO3_SIDE_PX / min_side <= ARUCO3_MAX_SCALE
        detector, coarse = self._full_detector(min_side, max(gray.shape), aruco3), aruco3
        opened = self.detector.opening(gray) if not self.tracks else None
        quads, ids, rej = self.detector.find(gray, opened, detector)
        if rejected is not None:
            rejected += rej
        _add(found, quads, ids, coarse)
        return opened

    def _full_detector(self, min_side: float, image_size: int, aruco3: bool) -> cv2.aruco.ArucoDetector:
        """A whole-frame detector for markers of at least min_side px, ArUco3 or not (cached by whole pixels)."""
        key = (int(min_side), image_size, aruco3)
        if key not in self._full:
            base = detector_parameters(self.detector.refinement, self.detector.inverted)
            params = sized_parameters(base, int(min_side), image_size)
            if aruco3:
                params = aruco3_parameters(params, int(min_side), image_size)
            self._full[key] = cv2.aruco.ArucoDetector(self.detector.dictionary, params)
        return self._full[key]

    def _search_rois(self, gray: np.ndarray, wanted: set[int], found: dict[int, Candidate],
                     rejected: list[np.ndarray] | None) -> list[tuple[Roi, np.ndarray]]:
        """Search around the wanted tracked markers, both passes until every expected one is found.

        The pass that found a crop's markers last time goes first (in rain, mostly the filtered
        one). Returns the rain-filtered crops made.
        """
        opened_crops = []
        rain = self.detector.rain_filter > 1
        for roi in self._rois(gray.shape, wanted):
            crop = gray[roi.y0:roi.y1, roi.x0:roi.x1]
            coarse = self._shrink(roi) < 1
            order = (True, False) if rain and any(self.tracks[i].rain for i in roi.ids) else (False, True)
            for k, filtered in enumerate(order):
                if k > 0 and not roi.ids - set(found):
                    break
                if filtered and not rain:
                    continue
                image = crop
                if filtered:
                    image = self.detector.opening(crop)
                    opened_crops.append((roi, image))
                keep = rejected is not None and not filtered
                quads, ids, rej = self._search_crop(image, roi, keep)
                if keep:
                    rejected += rej
                _add(found, quads, ids, coarse, filtered)
        return opened_crops

    def _shrink(self, roi: Roi) -> float:
        """Scale a crop is searched at."""
        return min(1.0, ROI_SIDE_PX / max(roi.min_side, 1.0)) if self._edges else 1.0

    def _search_crop(self, crop: np.ndarray, roi: Roi, keep_rejected: bool
                     ) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
        """Quads (B, 4, 2) in frame pixels, ids (B,) and (if kept) rejected candidates (4, 2) in the crop of roi."""
        scale = self._shrink(roi)
        s = np.ones(2)
        if scale < 1.0:
            size = (max(1, round(crop.shape[1] * scale)), max(1, round(crop.shape[0] * scale)))
            s = np.array([size[0] / crop.shape[1], size[1] / crop.shape[0]])
            crop = cv2.resize(crop, size, interpolation=cv2.INTER_AREA)
        self._roi_detector.setDetectorParameters(
            sized_parameters(self._params, ROI_MIN_SIZE * roi.min_side * scale, max(crop.shape)))
        quads, ids, rejected = find_quads(self._roi_detector, crop)
        shift = np.array([roi.x0, roi.y0], dtype=np.float64)
        # pixel centres: shrunk pixel i covers source pixels [i / s, (i + 1) / s)
        quads = (quads + 0.5) / s - 0.5 + shift
        rejected = [(r.reshape(4, 2) + 0.5) / s - 0.5 + shift for r in rejected] if keep_rejected else []
        return quads, ids, rejected

    def _rois(self, shape: tuple[int, ...], ids: set[int]) -> list[Roi]:
        """Merged crops around the predicted boxes of the tracked markers with the given ids."""
        rois = []
        for i in sorted(ids):
            t = self.tracks[i]
            roi = box_roi(t.predicted(self.frame), t.margin(self.frame), shape, {i}, t.side)
            if roi is not None:
                rois.append(roi)
        return merge_rois(rois)

    def _full_resolution(self, gray: np.ndarray, marker_id: int, quad: np.ndarray) -> np.ndarray:
        """A marker's corners as the stateless detector finds them in a crop around quad (4, 2) (else quad)."""
        roi = box_roi(quad, max(ROI_MARGIN_MIN_PX, ROI_MARGIN_SIDES * quad_side(quad)), gray.shape, {marker_id}, 0)
        if roi is None:
            return quad
        crop = gray[roi.y0:roi.y1, roi.x0:roi.x1]
        opened = self.detector.opening(crop)
        quads, ids, _ = self.detector.find(crop, opened)
        if marker_id not in ids:
            return quad
        q = quads[list(ids).index(marker_id)][None] + np.array([roi.x0, roi.y0], dtype=np.float64)
        opened_frame = None  # refined on the full frame (the camera model is in frame pixels)
        if opened is not None:
            opened_frame = gray.copy()
            opened_frame[roi.y0:roi.y1, roi.x0:roi.x1] = opened
        return self.detector.refine(gray, opened_frame, q)[0][0]

    def _refinement_image(self, gray: np.ndarray, quads: np.ndarray, opened_full: np.ndarray | None,
                          opened_crops: list[tuple[Roi, np.ndarray]]) -> np.ndarray | None:
        """One (H, W) image to fit every marker's edges on, valid around the markers, or None to use MarkerDetector's.

        Around markers whose cells survive the rain filter it is the frame with its rain streaks taken from the
        rain-filtered one (destreaked), around the others the frame itself, as MarkerDetector.refine chooses; one
        image means one vectorised edge fit per frame. None when there is nothing to filter or the regions touch.
        """
        cells = self.detector.dictionary.markerSize + 2
        sides = np.array([quad_side(q) for q in quads])
        big = sides / cells >= RAIN_REFINE_MIN_CELL_PX
        if self.detector.rain_filter <= 1 or not big.any():
            return gray
        regions = [box_roi(q, max(REFINE_REACH_PX, REFINE_REACH_SIDES * side), gray.shape, set(), side)
                   for q, side in zip(quads, sides, strict=True)]
        if any(r is None for r in regions) or any(
                regions[i].overlaps(regions[j]) for i in np.flatnonzero(big) for j in np.flatnonzero(~big)):
            return None
        if self._buffer is None or self._buffer.shape != gray.shape:
            self._buffer = np.empty_like(gray)
        image = self._buffer  # valid only in the regions written below
        pad = self.detector.rain_filter  # an opening reaches this far: filter a padded crop, keep its inside
        for r, is_big in zip(regions, big, strict=True):
            window = (slice(r.y0, r.y1), slice(r.x0, r.x1))
            if not is_big:
                image[window] = gray[window]
            elif opened_full is not None:
                image[window] = destreaked(gray[window], opened_full[window])
            else:
                src = next((c for c in opened_crops if c[0].contains_box(r, pad)), None)
                if src is not None:
                    roi, crop = src
                    image[window] = destreaked(gray[window], crop[r.y0 - roi.y0:r.y1 - roi.y0,
                                                                   r.x0 - roi.x0:r.x1 - roi.x0])
                else:
                    y0, x0 = max(r.y0 - pad, 0), max(r.x0 - pad, 0)
                    crop = self.detector.opening(gray[y0:r.y1 + pad, x0:r.x1 + pad])
                    image[window] = destreaked(gray[window], crop[r.y0 - y0:r.y1 - y0, r.x0 - x0:r.x1 - x0])
        return image

    def _update(self, result: Detections, rain: dict[int, bool]) -> None:
        """Move the tracks to this frame's markers; forget those missing too long."""
        for m in result.markers:
            old = self.tracks.get(m.id)
            velocity = np.zeros(2)
            if old is not None:
                velocity = (m.corners.mean(axis=0) - old.corners.mean(axis=0)) / max(self.frame - old.seen, 1)
            self.tracks[m.id] = Track(m.corners.copy(), velocity, self.frame, rain.get(m.id, False))
        for i in [i for i, t in self.tracks.items() if self.frame - t.seen >= FORGET_AFTER]:
            del self.tracks[i]


def _add(found: dict[int, Candidate], quads: np.ndarray, ids: np.ndarray, coarse: bool, rain: bool = False
         ) -> None:
    """Add the ids not found yet (earlier passes win)."""
    for q, i in zip(quads, ids, strict=True):
        found.setdefault(int(i), Candidate(q, coarse, rain))
