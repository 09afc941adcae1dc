"""The installation in 3-D and the superintendent's figures, logged and read back through rerun's own API."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pandas as pd
import pytest
import rerun as rr

from tracking.estimate import ConeEstimate
from tracking.rig import DEFAULT_LEG_LENGTH_M, load_rig
from viewer.blueprint import LayoutSender, blueprint_paths
from viewer.installation import (
    BEYOND_COLOR,
    WITHIN_COLOR,
    cone_tips,
    dimensions,
    log_concentricity,
    log_installation,
    log_true_topside,
    marker_texture,
    true_topside_poses,
)
from viewer.readback import chunks_by_entity, component_rows
from viewer.recording import TOLERANCE_M
from viewer.superintendent import (
    ROOT,
    TARGET_COLORS,
    TOLERANCE_MM,
    ConeState,
    cone_reading,
    log_cone_reading,
    log_target_circle,
    marked_cones,
    superintendent_blueprint,
)

CONES = {"A": [12.0, -10.0, 1.5], "B": [-12.0, -10.0, 1.5], "C": [-12.0, 10.0, 1.5], "D": [12.0, 10.0, 1.5]}


def recording(path: Path) -> rr.RecordingStream:
    """A strict recording stream into a file."""
    rr.set_strict_mode(True)
    rec = rr.RecordingStream("topside")
    rec.set_sinks(rr.FileSink(path))
    return rec


def close(rec: rr.RecordingStream) -> None:
    rec.flush()
    rec.disconnect()


def packed(rgb: tuple[int, int, int]) -> int:
    """A colour as rerun stores it, 0xRRGGBBAA."""
    return (rgb[0] << 24) | (rgb[1] << 16) | (rgb[2] << 8) | 0xFF


def test_the_printed_faces_are_the_markers_themselves(installation: Path) -> None:
    rig = load_rig(installation / "rig.yaml")
    aruco = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, rig.dictionary))
    detector = cv2.aruco.ArucoDetector(aruco)
    for marker in rig.markers:
        texture = marker_texture(rig.dictionary, marker.id)
        framed = cv2.copyMakeBorder(texture, 20, 20, 20, 20, cv2.BORDER_CONSTANT, value=(255, 255, 255))
        _, ids, _ = detector.detectMarkers(cv2.cvtColor(framed, cv2.COLOR_RGB2GRAY))
        assert ids is not None and ids.ravel().tolist() == [marker.id]  # OpenCV reads the texture as that marker


def test_the_installation_is_drawn_from_the_rig(installation: Path, tmp_path: Path) -> None:
    rig = load_rig(installation / "rig.yaml").model_copy(update={"cones": CONES})
    rec = recording(tmp_path / "scene.rrd")
    log_installation(rec, rig)
    close(rec)
    chunks = chunks_by_entity(tmp_path / "scene.rrd")
    dims = dimensions(rig)
    _, lengths = component_rows(chunks["/world/jacket/legs"], "Cylinders3D:lengths")
    _, centers = component_rows(chunks["/world/jacket/legs"], "Cylinders3D:centers")
    assert lengths[0] == pytest.approx([DEFAULT_LEG_LENGTH_M] * 4)
    tops = np.array(centers[0])[:, 2] + DEFAULT_LEG_LENGTH_M / 2  # each leg ends at its cone's base
    assert tops == pytest.approx([CONES[c][2] - dims.cone_height for c in CONES])
    _, cone_vertices = component_rows(chunks["/world/jacket/stabbing_cones"], "Mesh3D:vertex_positions")
    assert np.array(cone_vertices[0])[:, 2].max() == pytest.approx(1.5)  # the tips are the rig's
    _, beams = component_rows(chunks["/world/jacket/frame"], "Cylinders3D:lengths")
    assert len(beams[0]) == 4  # the top frame: one beam per side of the four legs
    assert "/world/topside/legs" in chunks and "/world/topside/deck" in chunks  # moved by world/topside
    for marker in rig.markers:
        body = "jacket" if marker.body == "jacket" else "topside"
        _, texcoords = component_rows(chunks[f"/world/{body}/markers/{marker.id}/face"], "Mesh3D:vertex_texcoords")
        assert texcoords[0] == [[0, 0], [1, 0], [1, 1], [0, 1]]


def test_the_leg_diameter_comes_from_the_markers_unless_the_rig_gives_it(installation: Path) -> None:
    rig = load_rig(installation / "rig.yaml")
    assert dimensions(rig.model_copy(update={"leg_diameter": 3.2})).leg_diameter == 3.2
    tips = cone_tips(rig)
    assert set(tips) == {m.cone for m in rig.markers}
    assert 0 < dimensions(rig).leg_diameter < 10


def test_concentricity_lines_are_green_within_and_red_beyond_the_tolerance(tmp_path: Path) -> None:
    rec = recording(tmp_path / "lines.rrd")
    tip = np.array(CONES["A"])
    estimates = [ConeEstimate(1.0, "A", np.array([0.05, 0.08, 1.0]), ("cam",), np.eye(3) * 1e-4),
                 ConeEstimate(1.5, "A", np.array([0.30, -0.40, 0.5]), ("cam",), np.eye(3) * 1e-4),
                 ConeEstimate(2.0, "A", np.array([np.nan, 0.0, 0.0]), ("cam",))]
    log_concentricity(rec, {"A": tip}, estimates)
    close(rec)
    chunks = chunks_by_entity(tmp_path / "lines.rrd")["/world/concentricity/A"]
    times, strips = component_rows(chunks, "LineStrips3D:strips")
    _, colors = component_rows(chunks, "LineStrips3D:colors")
    _, labels = component_rows(chunks, "LineStrips3D:labels")
    assert times.tolist() == [1.0, 1.5]  # an estimate without every axis draws nothing
    assert np.array(strips[1][0]) == pytest.approx(np.array([tip, tip + estimates[1].offset]))
    assert [c[0] for c in colors] == [packed(WITHIN_COLOR), packed(BEYOND_COLOR)]
    assert labels[1][0].startswith("A 500 ± 20 mm")


def test_the_ghost_follows_the_truth(installation: Path, tmp_path: Path) -> None:
    rig = load_rig(installation / "rig.yaml").model_copy(update={"cones": CONES})
    truth = pd.DataFrame({"time": [0.0, 1.0], **{f"cone_{c}_{a}": [v, v] for c in CONES
                                                  for a, v in zip(("dx", "dy", "dz"), (0.1, -0.2, 2.0), strict=True)}})
    points = {c: np.array(p) for c, p in CONES.items()}
    times, poses = true_topside_poses(truth, points)
    rec = recording(tmp_path / "ghost.rrd")
    log_true_topside(rec, rig, times, poses)
    close(rec)
    chunks = chunks_by_entity(tmp_path / "ghost.rrd")
    _, translations = component_rows(chunks["/world/truth/topside"], "Transform3D:translation")
    np.testing.assert_allclose(np.array(translations).reshape(-1, 3), [[0.1, -0.2, 2.0]] * 2, atol=1e-6)
    assert "/world/truth/topside/legs" in chunks


def estimate(offset: list[float], sd: float = 0.005) -> ConeEstimate:
    return ConeEstimate(10.0, "A", np.array(offset), ("cam",), np.eye(3) * sd**2)


def test_a_cone_beyond_the_ring_is_drawn_on_it_with_an_arrow_and_its_distance(tmp_path: Path) -> None:
    rec = recording(tmp_path / "target.rrd")
    far = cone_reading(estimate([0.30, -0.40, 1.0]), "A", 10.1, 10.05)  # 500 mm: astern -0.4 is ahead, down
    log_cone_reading(rec, far, 10.1)
    near = cone_reading(estimate([0.03, 0.04, 1.0]), "A", 10.3, 10.25)
    log_cone_reading(rec, near, 10.3)
    stale = cone_reading(estimate([0.0, 0.0, 0.0]), "A", 11.0, 10.25)
    log_cone_reading(rec, stale, 11.0)
    close(rec)
    chunks = chunks_by_entity(tmp_path / "target.rrd")
    base = f"/{ROOT}/targets/A"
    _, points = component_rows(chunks[f"{base}/offset"], "Points2D:positions")
    on_ring = np.array(points[0][0])
    assert np.hypot(*on_ring) == pytest.approx(TOLERANCE_MM)  # on the ring, not beyond it
    assert on_ring == pytest.approx(np.array([0.6, 0.8]) * TOLERANCE_MM)  # port right, ahead down (y down)
    assert np.array(points[1][0]) == pytest.approx([30.0, -40.0])  # inside: where it is
    assert points[2] == []  # NO DATA: no point
    _, arrows = component_rows(chunks[f"{base}/beyond"], "Arrows2D:vectors")
    _, arrow_labels = component_rows(chunks[f"{base}/beyond"], "Arrows2D:labels")
    assert np.dot(arrows[0][0], on_ring) > 0 and arrow_labels[0] == ["500 mm"]  # outwards, with its distance
    assert arrows[1] == [] and arrows[2] == []
    _, ring = component_rows(chunks[f"{base}/state"], "LineStrips2D:colors")
    assert [r[0] for r in ring] == [packed(TARGET_COLORS[s]) for s in ("red", "green", "none")]  # NO DATA grey
    _, where = component_rows(chunks[f"{base}/why"], "Points2D:positions")
    _, why = component_rows(chunks[f"{base}/why"], "Points2D:labels")
    assert where[:2] == [[], []] and len(where[2]) == 1 and why == [[], [], ["NO DATA: newest 0.8 s old"]]  # says why
    assert stale.state == ConeState.NO_DATA
    assert all(len(chunks[f"{base}/{part}"]) == 1 for part in ("offset", "beyond", "why"))  # one chunk a batch
    _, trend = component_rows(chunks[f"/{ROOT}/trend/A"], "Scalars:scalars")  # concentricity, r + 2σ, tolerance
    assert trend[0][0] == pytest.approx(500.0) and np.isnan(trend[2][0])  # a gap while there is no data
    assert [row[2] for row in trend] == [TOLERANCE_MM] * 3
    assert far.concentricity > TOLERANCE_M > near.concentricity


def view_kinds(blueprint) -> list[list[str]]:
    """Per column of the superintendent's layout, the classes of its views, top to bottom."""
    columns = blueprint.root_container.contents[0].contents
    return [[type(v).__name__ for v in column.contents] for column in columns]


def test_every_cone_gets_the_same_column_observed_or_not(installation: Path) -> None:
    rig = load_rig(installation / "rig.yaml").model_copy(update={"cones": CONES})
    blueprint = superintendent_blueprint(rig, {"A": "cam-ahead"})
    kinds = view_kinds(blueprint)
    shares = [list(column.row_shares) for column in blueprint.root_container.contents[0].contents]
    assert len(kinds) == 4 and all(len(k) == 4 for k in kinds) and len({tuple(s) for s in shares}) == 1
    assert kinds[0][1] == "Spatial2DView" and kinds[1][1] == "TextDocumentView"  # an image, or why there is none
    assert all(k[0] == "TextDocumentView" and k[2] == "Spatial2DView" and k[3] == "TimeSeriesView" for k in kinds)
    images = [column.contents[1].name for column in blueprint.root_container.contents[0].contents]
    assert images == ["A: cam-ahead", "B: no markers", "C: no markers", "D: no markers"]  # the rig's pairs: at A only
    assert superintendent_blueprint(rig, {}).root_container.contents[0].contents[0].contents[1].name == \
        "A: no camera yet"


def test_a_paired_cone_without_a_surveyed_tip_gets_its_column(installation: Path) -> None:
    rig = load_rig(installation / "rig.yaml")
    rig = rig.model_copy(update={"cones": {"B": CONES["B"]}})  # tips surveyed at B only; the pairs are at A
    columns = superintendent_blueprint(rig, {}).root_container.contents[0].contents
    images = [column.contents[1].name for column in columns]
    assert images == ["A: no camera yet", "B: no markers"]  # the live session logs both: the layout shows both


def test_a_cone_without_markers_says_so_in_its_images_place(installation: Path, tmp_path: Path) -> None:
    rig = load_rig(installation / "rig.yaml").model_copy(update={"cones": CONES})
    rec = recording(tmp_path / "notes.rrd")
    for cone in CONES:
        log_target_circle(rec, cone, cone in marked_cones(rig))
    close(rec)
    chunks = chunks_by_entity(tmp_path / "notes.rrd")
    notes = {cone: component_rows(chunks[f"/{ROOT}/no_camera/{cone}"], "TextDocument:text")[1][0][0] for cone in CONES}
    assert notes["A"].startswith("No camera has measured cone A's markers yet")
    assert notes["B"].startswith("No markers at cone B: no camera measures it.")  # not "yet": none ever will


def test_a_new_layout_clears_the_one_before(tmp_path: Path, installation: Path) -> None:
    rig = load_rig(installation / "rig.yaml").model_copy(update={"cones": CONES})
    rec = recording(tmp_path / "layouts.rrd")
    sender = LayoutSender("topside")
    first, second = superintendent_blueprint(rig, {}), superintendent_blueprint(rig, {"A": "cam-ahead"})
    sender.send(rec, first)
    sender.send(rec, second)
    close(rec)
    reader = rr.chunk.RrdReader(tmp_path / "layouts.rrd")
    [store] = reader.blueprints()
    cleared = set()
    for chunk in reader.stream(store=store):
        if any(name.startswith("Clear:") for name in chunk.to_record_batch().schema.names):
            cleared.add(chunk.entity_path.lstrip("/"))
    assert set(blueprint_paths(first)) <= cleared  # the viewer finds no container of the old layout left over
    assert not set(blueprint_paths(second)) & cleared
