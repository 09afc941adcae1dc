"""Detection on OpenCV's tutorial photos against the corners OpenCV's own test asserts."""

import json
from pathlib import Path

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
