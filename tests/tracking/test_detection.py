"""Detection on OpenCV's tutorial photos against the corners OpenCV's own test asserts."""

import json
import re
from pathlib import Path

import cv2
import numpy as np
import pytest

from tracking.detection import MarkerDetector, Refinement, load_dictionary
from tracking.errors import InputError
from tracking.images import read_gray

PHOTOS = ["singlemarkersoriginal.jpg", "gboriginal.jpg", "choriginal.jpg", "chocclusion_original.jpg"]


def _gold(shared_data: Path, photo: str) -> tuple[str, dict[int, np.ndarray]]:
    folder = shared_data / "aruco/opencv-tutorial"
    entry = json.loads((folder / "gold_corners.json").read_text())[photo]
    dictionary = entry["dictionary"]
    if not dictionary.startswith("DICT_"):
        dictionary = str(folder / dictionary)
    return dictionary, {int(k): np.array(v, dtype=float) for k, v in entry["markers"].items()}


@pytest.mark.parametrize("photo", PHOTOS)
def test_gold_corners(shared_data: Path, photo: str) -> None:
    dictionary, gold = _gold(shared_data, photo)
    found = MarkerDetector(dictionary, Refinement.NONE).detect(read_gray(shared_data / "aruco/opencv-tutorial" / photo))
    assert sorted(found.ids) == sorted(gold)
    for m in found.markers:
        assert np.abs(m.corners - gold[m.id]).max() <= 1.0


@pytest.mark.parametrize("photo", PHOTOS)
def test_gold_ids_with_default_refinement(shared_data: Path, photo: str) -> None:
    dictionary, gold = _gold(shared_data, photo)
    found = MarkerDetector(dictionary).detect(read_gray(shared_data / "aruco/opencv-tutorial" / photo))
    assert sorted(found.ids) == sorted(gold)


def test_unknown_dictionary() -> None:
    with pytest.raises(InputError, match="unknown ArUco dictionary 'DICT_9X9_1'"):
        load_dictionary("DICT_9X9_1")


# --- a dictionary YAML file: built from its bits, every bad file one line ------------------------------------------

def _dictionary_text(markers: int = 3, bits: int = 4) -> str:
    """The first markers of DICT_4X4_50 as OpenCV's writeDictionary lays them out."""
    source = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50)
    lines = ["%YAML:1.0", f"nmarkers: {markers}", f"markersize: {bits}", "maxCorrectionBits: 1"]
    for i in range(markers):
        code = cv2.aruco.Dictionary.getBitsFromByteList(source.bytesList[i:i + 1], bits)
        lines.append(f'marker_{i}: "{"".join(str(b) for b in code.reshape(-1))}"')
    return "\n".join(lines) + "\n"


def test_dictionary_file_matches_opencv(shared_data: Path) -> None:
    path = shared_data / "aruco/opencv-tutorial/tutorial_dict.yml"
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    theirs = cv2.aruco.Dictionary()
    assert theirs.readDictionary(fs.root())  # OpenCV's own reader, on a valid file
    ours = load_dictionary(str(path))
    np.testing.assert_array_equal(ours.bytesList, theirs.bytesList)
    assert (ours.markerSize, ours.maxCorrectionBits) == (theirs.markerSize, theirs.maxCorrectionBits)


def test_dictionary_file_written_here(tmp_path: Path) -> None:
    path = tmp_path / "dict.yml"
    path.write_text(_dictionary_text())
    d = load_dictionary(str(path))
    np.testing.assert_array_equal(d.bytesList, cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50).bytesList[:3])
    assert d.maxCorrectionBits == 1


@pytest.mark.parametrize(("old", "new", "message"), [
    # OpenCV's readDictionary writes past its buffer on a long string (a crash) and reads a short one as garbage
    ('marker_1: "', 'marker_1: "0101', "marker_1: '01010000111110011010' has 20 characters (expected a quoted"),
    ('marker_1: "0000', 'marker_1: "', "marker_1: '111110011010' has 12 characters"),
    ('marker_1: "0000111110011010"', "marker_1: 1111", "marker_1: not a string"),
    ('marker_1: "0000', 'marker_1: "x000', "marker_1: 'x000111110011010' holds other characters"),
    ('marker_1: "0000', 'marker_1: "\\é000', "marker_1: not readable text"),  # OpenCV unescapes it into invalid UTF-8
    ("nmarkers: 3", "nmarkers: 4", "marker_3: missing"),
    ("nmarkers: 3", "nmarkers: -1", "nmarkers: -1.0 is not an integer from 1 to 100000"),
    ("nmarkers: 3", "nmarkers: many", "nmarkers: not a number"),
    ("markersize: 4", "markersize: 100000", "markersize: 100000.0 is not an integer from 2 to 16"),
    ("maxCorrectionBits: 1", "maxCorrectionBits: .nan", "maxCorrectionBits: nan is not an integer"),
    ("%YAML:1.0\n", "", "marker_0"),  # no header: still read; only the bad field named
])
def test_bad_dictionary_file_names_the_field(tmp_path: Path, old: str, new: str, message: str) -> None:
    text = _dictionary_text()
    assert old in text
    path = tmp_path / "dict.yml"
    path.write_text(text.replace(old, new))
    if message == "marker_0":  # the control case: a file without the %YAML header loads
        assert load_dictionary(str(path)).bytesList.shape[0] == 3
        return
    with pytest.raises(InputError) as info:
        load_dictionary(str(path))
    assert str(info.value).startswith(f"{path}: ") and message in str(info.value)
    assert len(str(info.value).splitlines()) == 1


@pytest.mark.parametrize(("content", "message"), [
    (b"", "is empty (expected a dictionary YAML file)"),
    (b"\x00\x00\x89PNG", "is binary, not text"),
    (b"just words", "not OpenCV FileStorage YAML"),
    (b"%YAML:1.0\nnmarkers: [1, 2", "not OpenCV FileStorage YAML (line 2"),
])
def test_not_a_dictionary_file(tmp_path: Path, content: bytes, message: str) -> None:
    path = tmp_path / "dict.yml"
    path.write_bytes(content)
    with pytest.raises(InputError, match=re.escape(message)) as info:
        load_dictionary(str(path))
    assert str(info.value).startswith(str(path)) and len(str(info.value).splitlines()) == 1
    with pytest.raises(InputError, match="is a folder"):
        load_dictionary(str(tmp_path))
    with pytest.raises(InputError, match="dictionary file not found"):
        load_dictionary(str(tmp_path / "nope.yml"))


@pytest.mark.parametrize("black, white", [(20, 235), (110, 150)])
def test_noise_does_not_shrink_a_big_marker(monkeypatch: pytest.MonkeyPatch, black: int, white: int) -> None:
    """Markers whose cells are wide enough for the rain pass, in noise of 3 grey levels at full and at fogged contrast
    (40 levels): their scale stays within 0.6 ‰ of the truth. Fitted on the whole grey opening they read 0.9 ‰ and
    4.5 ‰ small (the opening's minimum-then-maximum pulls a noisy edge inward)."""
    import tests.synthetic as syn
    from tracking.camera import CameraModel

    monkeypatch.setattr(syn, "BLACK", black)
    monkeypatch.setattr(syn, "WHITE", white)
    camera = CameraModel(syn.PAPER_K, np.zeros(5), *syn.PAPER_SIZE)
    detector = MarkerDetector("DICT_6X6_250", camera=camera)
    errors = []
    for k in range(20):
        T = np.eye(4)
        T[:3, :3] = np.diag([1.0, -1.0, -1.0]) @ cv2.Rodrigues(np.array([0.2, 0.3, 0.05 + 0.01 * k]))[0]
        T[:3, 3] = [0.1 + 0.003 * k, 0.05, 20.0]
        marker = syn.PlacedMarker(7, T, 1.0)
        image = syn.render(syn.PAPER_K, np.zeros(5), syn.PAPER_SIZE, [marker], noise=3.0, seed=k,
                           background=(black + white) / 2)
        found = detector.detect(image).markers
        assert [m.id for m in found] == [7]
        errors.append(syn.scale_error(found[0].corners.reshape(4, 2), syn.true_corners(syn.PAPER_K, np.zeros(5),
                                                                                          marker)))
    assert abs(np.mean(errors)) < 6e-4
