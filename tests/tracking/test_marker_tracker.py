"""The stateful MarkerTracker against the stateless MarkerDetector on real H.264 clips."""

from fractions import Fraction
from pathlib import Path

import av
import cv2
import numpy as np
import pytest

from tests.synthetic import BACKGROUND, PlacedMarker, render
from tracking.detection import MarkerDetector, Refinement
from tracking.images import video_frames
from tracking.marker_tracker import MarkerTracker, Roi, merge_rois
from tracking.pipeline import CameraTracker
from tracking.rig import load_rig

CLIP_SIZE = (480, 270)
PATCH = 96  # px, square patch one marker is rendered into
PATCH_F = 600.0  # px focal length of the patch camera
MARKER_DISTANCE = 11.0  # m: a 1 m marker ~55 px across
STILL_ID, MOVING_ID = 7, 23
STILL_AT = (60, 90)  # top-left of the still marker's patch
CORNER_AGREEMENT_PX = 0.05


def marker_patch(marker_id: int, roll_deg: float) -> np.ndarray:
    """(PATCH, PATCH) uint8: a 1 m marker facing the camera, rolled in plane, on the renderer's background."""
    K = np.array([[PATCH_F, 0, PATCH / 2 - 0.5], [0, PATCH_F, PATCH / 2 - 0.5], [0, 0, 1]])
    c, s = np.cos(np.radians(roll_deg)), np.sin(np.radians(roll_deg))
    T = np.eye(4)
    T[:3, :3] = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]) @ np.diag([1.0, -1.0, -1.0])
    T[:3, 3] = [0, 0, MARKER_DISTANCE]
    return render(K, np.zeros(5), (PATCH, PATCH), [PlacedMarker(marker_id, T, 1.0)], noise=0.0)


def encode(path: Path, frames: list[np.ndarray]) -> list[np.ndarray]:
    """Write grayscale frames as H.264 and read them back decoded."""
    with av.open(str(path), "w") as out:
        stream = out.add_stream("libx264", rate=15)
        stream.width, stream.height = CLIP_SIZE
        stream.pix_fmt = "yuv420p"
        stream.options = {"crf": "14", "preset": "ultrafast"}
        stream.codec_context.time_base = Fraction(1, 15)
        for k, gray in enumerate(frames):
            frame = av.VideoFrame.from_ndarray(np.dstack([gray] * 3), format="bgr24")
            frame.pts = k
            out.mux(stream.encode(frame))
        out.mux(stream.encode(None))
    return [f.gray for f in video_frames(path)]


def compose(placements: list[tuple[np.ndarray, int, int]]) -> np.ndarray:
    """A clip frame with patches pasted at (x, y) top-left positions (cut at the frame's edges)."""
    w, h = CLIP_SIZE
    frame = np.full((h, w), BACKGROUND, np.uint8)
    for patch, x, y in placements:
        x0, y0, x1, y1 = max(x, 0), max(y, 0), min(x + PATCH, w), min(y + PATCH, h)
        if x1 > x0 and y1 > y0:
            frame[y0:y1, x0:x1] = patch[y0 - y:y1 - y, x0 - x:x1 - x]
    return frame


@pytest.fixture(scope="module")
def patches() -> dict[int, np.ndarray]:
    """The two markers of the clips, rendered once."""
    return {STILL_ID: marker_patch(STILL_ID, 12.0), MOVING_ID: marker_patch(MOVING_ID, -20.0)}


def test_same_ids_and_corners_as_stateless_on_the_installation(installation: Path) -> None:
    rig = load_rig(installation / "rig.yaml")
    for entry in rig.cameras:
        plain = CameraTracker.from_rig(rig, entry, "edges")
        fast = CameraTracker.from_rig(rig, entry, "edges", roi_tracking=True)
        assert isinstance(fast.detector, MarkerTracker)
        count = 0
        for a, b in zip(plain.run(), fast.run(), strict=True):
            assert a.detections.ids == b.detections.ids and len(a.detections.ids) >= 2
            for m, n in zip(a.detections.markers, b.detections.markers, strict=True):
                assert np.abs(m.corners - n.corners).max() < CORNER_AGREEMENT_PX
            assert sorted(a.poses) == sorted(b.poses)
            count += 1
        assert count > 1 and fast.detector.full_searches < count  # most frames searched around the markers only


def test_recovers_a_marker_that_leaves_and_comes_back(tmp_path: Path, patches: dict[int, np.ndarray]) -> None:
    # the moving marker slides right out of the frame, stays out, and slides back in
    xs = [300, 330, 360, 390, 420, 450, 480, 510, 510, 510, 480, 450, 420, 390, 360, 330, 330, 330, 330, 330]
    frames = encode(tmp_path / "leave.mp4", [compose([(patches[STILL_ID], *STILL_AT),
                                                      (patches[MOVING_ID], x, 120)]) for x in xs])
    stateless = MarkerDetector()
    tracker = MarkerTracker(MarkerDetector(), full_every=5)
    fully_inside = [x + PATCH <= CLIP_SIZE[0] for x in xs]
    back = fully_inside.index(True, xs.index(max(xs)))  # first frame fully back in
    seen_again = None
    for k, gray in enumerate(frames):
        expected = stateless.detect(gray)
        got = tracker.detect(gray)
        assert set(got.ids) <= {STILL_ID, MOVING_ID}  # never a wrong id
        assert STILL_ID in got.ids
        if MOVING_ID in got.ids and MOVING_ID in expected.ids:
            mine = got.markers[got.ids.index(MOVING_ID)].corners
            theirs = expected.markers[expected.ids.index(MOVING_ID)].corners
            assert np.abs(mine - theirs).max() < CORNER_AGREEMENT_PX
        if xs[k] >= CLIP_SIZE[0]:
            assert MOVING_ID not in got.ids
        if k >= back and MOVING_ID in got.ids and seen_again is None:
            seen_again = k
    assert seen_again is not None and seen_again - back <= tracker.full_every
    assert MOVING_ID in tracker.tracks  # followed to the end


def test_whole_frame_search_when_told(tmp_path: Path, patches: dict[int, np.ndarray]) -> None:
    # a second marker appears far from the first at frame 3; only a whole-frame search can find it
    frames = encode(tmp_path / "appear.mp4", [compose([(patches[STILL_ID], *STILL_AT)]
                                                      + ([(patches[MOVING_ID], 340, 150)] if k >= 3 else []))
                                             for k in range(8)])
    tracker = MarkerTracker(MarkerDetector(), full_every=1000)
    found = [tracker.detect(g).ids for g in frames[:5]]
    assert found == [[STILL_ID]] * 5 and tracker.full_searches == 1  # frame 0 only: the new one is not searched for
    assert MOVING_ID in MarkerDetector().detect(frames[4]).ids
    tracker.search_everywhere()
    assert tracker.detect(frames[5]).ids == [STILL_ID, MOVING_ID] and tracker.full_searches == 2
    assert tracker.detect(frames[6]).ids == [STILL_ID, MOVING_ID] and tracker.full_searches == 2  # now tracked
    tracker.reset()
    assert not tracker.tracks
    assert tracker.detect(frames[7]).ids == [STILL_ID, MOVING_ID] and tracker.full_searches == 3


def test_overlapping_regions_merge() -> None:
    rois = merge_rois([Roi(0, 0, 10, 10, {1}, 20.0), Roi(50, 50, 60, 60, {2}, 30.0), Roi(8, 8, 52, 52, {3}, 10.0)])
    assert len(rois) == 1
    assert (rois[0].x0, rois[0].y0, rois[0].x1, rois[0].y1, rois[0].ids, rois[0].min_side) == (0, 0, 60, 60,
                                                                                               {1, 2, 3}, 10.0)
    assert len(merge_rois([Roi(0, 0, 10, 10, {1}, 20.0), Roi(30, 0, 40, 10, {2}, 20.0)])) == 2


def test_color_frames_are_converted(patches: dict[int, np.ndarray]) -> None:
    gray = compose([(patches[STILL_ID], *STILL_AT)])
    assert MarkerTracker(MarkerDetector()).detect(cv2.cvtColor(gray, cv2.COLOR_GRAY2BGR)).ids == [STILL_ID]


@pytest.mark.parametrize("refinement", [Refinement.NONE, Refinement.SUBPIX])
def test_opencv_refinements_match_the_stateless_detector(tmp_path: Path, patches: dict[int, np.ndarray],
                                                        refinement: Refinement) -> None:
    # without the edge fit crops are searched at full resolution, so corners are OpenCV's own
    frames = encode(tmp_path / "slide.mp4", [compose([(patches[STILL_ID], *STILL_AT),
                                                      (patches[MOVING_ID], 250 + 7 * k, 120 - 3 * k)])
                                             for k in range(6)])
    stateless = MarkerDetector(refinement=refinement)
    tracker = MarkerTracker(MarkerDetector(refinement=refinement))
    for gray in frames:
        a, b = stateless.detect(gray), tracker.detect(gray)
        assert a.ids == b.ids == [STILL_ID, MOVING_ID]
        for m, n in zip(a.markers, b.markers, strict=True):
            assert np.abs(m.corners - n.corners).max() < 1e-3
    assert tracker.full_searches == 1
