"""Markers seen mirrored (from behind, or reflected) never reach the poses; white-on-black prints are found and fitted
(tracking.mirror, tracking.detection with inverted=True), on rendered markers whose truth is exact."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from tests.synthetic import PlacedMarker, render, true_corners
from tracking.camera import CameraModel
from tracking.detection import MarkerDetector
from tracking.mirror import drop_mirrored, mirror_ambiguous, mirror_turn, mirror_turns
from tracking.pose import estimate_pose
from tracking.rig import Marker, Rig

K = np.array([[800.0, 0.0, 640.0], [0.0, 800.0, 360.0], [0.0, 0.0, 1.0]])
DIST = np.zeros(5)
SIZE = (1280, 720)
SIDE = 0.0405  # the caliscope board's markers, m
DICT = cv2.aruco.DICT_4X4_1000


def board_rig(ids: tuple[int, ...] = (5, 8), dictionary: str = "DICT_4X4_1000") -> Rig:
    """Jacket markers on one face, 6 cm apart, and one topside marker above them."""
    markers = [Marker(id=i, body="jacket", cone="A", face="astern", center=[0.06 * k, 0.0, 0.0])
               for k, i in enumerate(ids)]
    markers.append(Marker(id=0, body="topside", cone="A", face="astern", center=[0.0, 0.0, 0.1]))
    return Rig(dictionary=dictionary, marker_size=SIDE, markers=markers)


def placements(rig: Rig, distance: float = 0.6) -> list[PlacedMarker]:
    """The rig's jacket markers square on to the camera at distance (of the rig's marker size)."""
    R_body_marker = rig.markers[0].T_body_marker[:3, :3]
    T_camera_body = np.eye(4)
    T_camera_body[:3, :3] = np.diag([1.0, -1.0, -1.0]) @ R_body_marker.T  # the face looks at the camera
    T_camera_body[:3, 3] = [0.0, 0.0, distance]
    out = []
    for m in rig.markers:
        if m.body != "jacket":
            continue
        out.append(PlacedMarker(m.id, T_camera_body @ m.T_body_marker, rig.marker_size))
    return out


def mirrored(image: np.ndarray, m: PlacedMarker) -> np.ndarray:
    """The image with a square-on marker's plate flipped left to right in place: its reflection (or its back, printed
    through), at the same place."""
    corners = true_corners(K, DIST, m)
    (x0, y0), (x1, y1) = np.floor(corners.min(axis=0)).astype(int) - 6, np.ceil(corners.max(axis=0)).astype(int) + 6
    out = image.copy()
    out[y0:y1, x0:x1] = image[y0:y1, x0:x1][:, ::-1]
    return out


def poses_of(rig: Rig, image: np.ndarray) -> dict:
    camera = CameraModel(K, DIST, *SIZE)
    found = MarkerDetector(rig.dictionary, camera=camera).detect(image)
    return {d.id: estimate_pose(d, camera, rig.marker_size) for d in found.markers}


def test_the_ids_a_mirror_can_read_come_from_the_dictionary_and_the_rig() -> None:
    assert mirror_ambiguous(board_rig((5, 8, 9))) == {8, 9}  # in DICT_4X4_1000, 8 and 9 are their own mirror images
    assert mirror_ambiguous(board_rig((5, 6, 7))) == frozenset()  # 0's mirror reads as 871, not on the board
    assert mirror_ambiguous(board_rig(tuple(range(1, 40)), "DICT_6X6_250")) == frozenset()  # the offshore default


def test_a_mirrored_marker_is_dropped_and_a_true_one_kept() -> None:
    rig = board_rig()
    ambiguous = mirror_ambiguous(rig)
    camera = CameraModel(K, DIST, *SIZE)
    true = poses_of(rig, render(K, DIST, SIZE, placements(rig), DICT))
    assert set(true) == {5, 8}
    kept, dropped = drop_mirrored(true, rig.marker_by_id, ambiguous, SIDE, camera)
    assert set(kept) == {5, 8} and dropped == []  # marker 5 puts 8 where it is seen
    placed = placements(rig)
    mirror = poses_of(rig, mirrored(render(K, DIST, SIZE, placed, DICT), placed[1]))
    assert set(mirror) == {5, 8}  # the mirror image of 8 reads as 8: the bits cannot tell
    kept, dropped = drop_mirrored(mirror, rig.marker_by_id, ambiguous, SIDE, camera)
    assert set(kept) == {5} and dropped == [8]
    alone = {8: mirror[8]}  # nothing unambiguous of its body to confirm it
    assert drop_mirrored(alone, rig.marker_by_id, ambiguous, SIDE, camera) == ({}, [8])


def test_a_lone_self_mirroring_marker_is_confirmed_by_the_other_body() -> None:
    """A topside whose only marker (8) reads the same in a mirror: the jacket's marker 5 puts it there, as the mated
    rig would (lifted 2 cm and turned 5°: the bodies move apart); its mirror image, turned a quarter turn, is
    dropped."""
    rig = Rig(dictionary="DICT_4X4_1000", marker_size=SIDE, markers=[
        Marker(id=5, body="jacket", cone="A", face="astern", center=[0.0, 0.0, 0.0]),
        Marker(id=8, body="topside", cone="A", face="astern", center=[0.0, 0.0, 0.08])])
    assert mirror_ambiguous(rig) == {8}
    jacket = placements(rig)[0]
    lift = np.eye(4)
    lift[:3, :3] = cv2.Rodrigues(np.array([0.0, 0.0, np.radians(5.0)]))[0]
    lift[:3, 3] = [0.01, 0.0, 0.02]  # topside frame in the jacket frame
    T_camera_body = jacket.T_camera_marker @ np.linalg.inv(rig.markers[0].T_body_marker)
    topside = PlacedMarker(8, T_camera_body @ lift @ rig.markers[1].T_body_marker, SIDE)
    camera = CameraModel(K, DIST, *SIZE)
    ambiguous = mirror_ambiguous(rig)
    image = render(K, DIST, SIZE, [jacket, topside], DICT)
    kept, dropped = drop_mirrored(poses_of(rig, image), rig.marker_by_id, ambiguous, SIDE, camera)
    assert set(kept) == {5, 8} and dropped == []
    mirror = poses_of(rig, mirrored(image, topside))
    assert set(mirror) == {5, 8}
    kept, dropped = drop_mirrored(mirror, rig.marker_by_id, ambiguous, SIDE, camera)
    assert set(kept) == {5} and dropped == [8]


@pytest.mark.parametrize("distance", [0.6, 1.4])
def test_white_on_black_markers_are_found_and_fitted(distance: float) -> None:
    rig = board_rig((5, 6))
    placed = placements(rig, distance=distance)
    image = cv2.bitwise_not(render(K, DIST, SIZE, placed, DICT))  # the negative: white markers on black
    camera = CameraModel(K, DIST, *SIZE)
    assert not MarkerDetector(rig.dictionary, camera=camera).detect(image).markers
    found = MarkerDetector(rig.dictionary, camera=camera, inverted=True).detect(image).markers
    assert [d.id for d in found] == [5, 6]
    for d, m in zip(found, placed, strict=True):
        assert np.abs(d.corners - true_corners(K, DIST, m)).max() < 0.1  # px: the edge fit on the negative


def reflected(image: np.ndarray, markers: list[PlacedMarker], upside_down: bool = False) -> np.ndarray:
    """The image with the region holding markers mirrored left to right where it is (a reflector beside or behind
    them), or upside down (the sea beneath them: a left-right mirror turned half round)."""
    corners = np.concatenate([true_corners(K, DIST, m) for m in markers])
    (x0, y0), (x1, y1) = np.floor(corners.min(axis=0)).astype(int) - 6, np.ceil(corners.max(axis=0)).astype(int) + 6
    out = image.copy()
    out[y0:y1, x0:x1] = image[y0:y1, x0:x1][::-1] if upside_down else image[y0:y1, x0:x1][:, ::-1]
    return out


def pair_rig(topside_at: list[float]) -> Rig:
    """1 m markers: DICT_4X4_1000's 8 on the jacket at the origin, 9 on the topside at topside_at (jacket frame)."""
    return Rig(dictionary="DICT_4X4_1000", marker_size=1.0, markers=[
        Marker(id=8, body="jacket", cone="A", face="astern", center=[0.0, 0.0, 0.0]),
        Marker(id=9, body="topside", cone="A", face="astern", center=topside_at)])


def pair_image(rig: Rig, T_jacket_topside: np.ndarray) -> tuple[np.ndarray, list[PlacedMarker]]:
    """The pair square on to the camera 15 m off (53 px a marker), the topside displaced by T_jacket_topside."""
    jacket = placements(rig, distance=15.0)[0]
    T_camera_body = jacket.T_camera_marker @ np.linalg.inv(rig.markers[0].T_body_marker)
    topside = PlacedMarker(9, T_camera_body @ T_jacket_topside @ rig.markers[1].T_body_marker, 1.0)
    return render(K, DIST, SIZE, [jacket, topside], DICT), [jacket, topside]


@pytest.mark.parametrize("topside_at", [[0.0, 0.0, 3.5], [-3.0, 0.0, 3.0]], ids=["above", "diagonal"])
def test_a_pair_of_self_mirroring_markers_confirms_itself_where_a_mirror_would_not(topside_at: list[float]) -> None:
    """A camera that sees only a pair of self-mirroring markers (8 on the jacket, 9 on the topside above it or
    diagonally off it: both read as themselves in a mirror, turned a quarter turn) keeps both, mated and hovering 2 m
    above, 0.5 m sideways; every mirror image of the pair (each plate flipped where it is, the region flipped left to
    right, or upside down) is dropped: it puts 9 a quarter turn round from where any set-down would."""
    rig = pair_rig(topside_at)
    ambiguous = mirror_ambiguous(rig)
    assert ambiguous == {8, 9}
    turns = mirror_turns(rig)
    assert set(turns) == {8, 9} and abs(np.linalg.det(turns[8])) == 1.0 and turns[8][0, 0] == 0.0  # a quarter turn
    camera = CameraModel(K, DIST, *SIZE)
    for lift in ([0.0, 0.0, 0.0], [0.5, 0.0, 2.0]):
        T_jacket_topside = np.eye(4)
        T_jacket_topside[:3, 3] = lift
        image, (jacket, topside) = pair_image(rig, T_jacket_topside)
        seen = poses_of(rig, image)
        assert set(seen) == {8, 9}
        assert drop_mirrored(seen, rig.marker_by_id, ambiguous, 1.0, camera) == ({}, [8, 9])  # without the turns
        kept, dropped = drop_mirrored(seen, rig.marker_by_id, ambiguous, 1.0, camera, turns)
        assert set(kept) == {8, 9} and dropped == []
        for mirror in (mirrored(mirrored(image, jacket), topside), reflected(image, [jacket, topside]),
                       reflected(image, [jacket, topside], upside_down=True)):
            poses = poses_of(rig, mirror)
            assert set(poses) == {8, 9}
            assert drop_mirrored(poses, rig.marker_by_id, ambiguous, 1.0, camera, turns) == ({}, [8, 9])


def test_a_pair_whose_mirror_image_reads_as_the_pair_confirms_nothing() -> None:
    """9 diagonally off 8 the other way, (-1, 1) in 8's frame: a left-right mirror turned a quarter turn maps that
    diagonal onto itself, so the pair's mirror image would read exactly as the pair: it stays dropped."""
    rig = pair_rig([3.0, 0.0, 3.0])
    image, _ = pair_image(rig, np.eye(4))
    seen = poses_of(rig, image)
    assert set(seen) == {8, 9}
    assert drop_mirrored(seen, rig.marker_by_id, mirror_ambiguous(rig), 1.0, CameraModel(K, DIST, *SIZE),
                         mirror_turns(rig)) == ({}, [8, 9])


def test_a_pair_a_mirror_explains_better_than_a_set_down_confirms_nothing() -> None:
    """The topside 6 m sideways of its cone: under the set-down prior the pair's vector is likelier a mirror's of a
    topside 3.5 m sideways and 2.5 m up (χ² 12.9) than the rig's (36), so the camera waits for it to come in."""
    rig = pair_rig([0.0, 0.0, 3.5])
    T_jacket_topside = np.eye(4)
    T_jacket_topside[:3, 3] = [6.0, 0.0, 0.0]
    seen = poses_of(rig, pair_image(rig, T_jacket_topside)[0])
    assert set(seen) == {8, 9}
    assert drop_mirrored(seen, rig.marker_by_id, mirror_ambiguous(rig), 1.0, CameraModel(K, DIST, *SIZE),
                         mirror_turns(rig)) == ({}, [8, 9])


def test_a_mirror_turn_is_learnt_from_the_dictionary() -> None:
    """DICT_4X4_50's self-mirroring ids: 8, 9 and 47 read a quarter turn round in a mirror, 17 unturned (its pair's
    mirror image would land where the rig's does: it confirms nothing); an id whose mirror reads as another has none."""
    for i in (8, 9, 47):
        assert np.array_equal(mirror_turn("DICT_4X4_50", i), [[0.0, 1.0], [-1.0, 0.0]])
    assert np.array_equal(mirror_turn("DICT_4X4_50", 17), np.eye(2))
    assert mirror_turn("DICT_4X4_1000", 0) is None  # its mirror reads as 871
