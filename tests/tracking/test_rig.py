import re
from pathlib import Path

import numpy as np
import pytest
import yaml

from tracking.errors import InputError
from tracking.rig import face_rotation, load_rig

RIG = {
    "dictionary": "DICT_6X6_250",
    "marker_size": 1.0,
    "cones": {"A": [-10.0, -10.0, 0.0]},
    "markers": [
        {"id": 1, "body": "jacket", "cone": "A", "face": "ahead", "center": [-10.0, -11.5, -1.2]},
        {"id": 2, "body": "topside", "cone": "A", "face": "ahead", "center": [-10.0, -11.5, 0.6]},
    ],
    "pairs": [{"cone": "A", "face": "ahead", "jacket": 1, "topside": 2, "mated": [0, 0, 1.8]}],
    "cameras": [{"name": "stern-1", "calibration": "cam.yaml", "source": "stern-1.mp4"}],
}


def _write(tmp_path: Path, data: dict) -> Path:
    path = tmp_path / "rig.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def test_loads_and_derives(tmp_path: Path) -> None:
    rig = load_rig(_write(tmp_path, RIG))
    assert rig.resolve("cam.yaml") == tmp_path / "cam.yaml"
    T = rig.T_W_S_mated(rig.pairs[0])
    np.testing.assert_allclose(T[:3, 3], [0, 1.8, 0])  # straight up the jacket marker's y axis
    np.testing.assert_allclose(T[:3, :3], np.eye(3))
    assert rig.cameras[0].mount == "drone"  # the loosest motion prior unless the rig says otherwise


def test_face_rotation_is_right_handed_and_looks_out() -> None:
    for face in ("port", "starboard", "astern", "ahead", "port-ahead"):
        R = face_rotation(face)
        assert np.linalg.det(R) == pytest.approx(1.0)
        assert R[2, 1] == pytest.approx(1.0)  # marker y is up
    np.testing.assert_allclose(face_rotation("astern")[:, 2], [0, 1, 0])


@pytest.mark.parametrize(("change", "message"), [
    (lambda d: d["markers"].append(dict(d["markers"][0])), "duplicate marker id 1"),
    (lambda d: d.update(dictionary="DICT_NOPE"), "dictionary: unknown ArUco dictionary 'DICT_NOPE'"),
    (lambda d: d.update(marker_size=-1), "marker_size: Input should be greater than 0"),
    (lambda d: d["markers"][0].update(body="deck"), "markers[0].body: got 'deck'"),
    (lambda d: d["pairs"][0].update(topside=9), "pairs[0].topside: marker id 9 is not in markers"),
    (lambda d: d["pairs"][0].update(mated=[0, 0, 2.5]),
     "pairs[0].mated: [0.0, 0.0, 2.5] disagrees with the marker centres"),
    (lambda d: d["cameras"][0].pop("source"), "cameras[0].source: Field required"),
    (lambda d: d["cameras"][0].update(mount="boat"), "cameras[0].mount: got 'boat'"),
])
def test_bad_rig_names_the_field(tmp_path: Path, change, message: str) -> None:
    import copy

    data = copy.deepcopy(RIG)
    change(data)
    with pytest.raises(InputError, match=re.escape(message)) as info:
        load_rig(_write(tmp_path, data))
    assert str(tmp_path / "rig.yaml") in str(info.value)
    assert "\n" not in str(info.value)
