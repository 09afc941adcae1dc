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


# --- non-finite numbers, sizes, device indices, warnings, atomic writes -------------------------------------------

@pytest.mark.parametrize(("change", "message"), [
    (lambda d: d["markers"][1]["center"].__setitem__(1, float("nan")), "markers[1].center[1]: Input should be a"),
    (lambda d: d["cones"]["A"].__setitem__(2, float("inf")), "cones.A[2]: Input should be a finite number"),
    (lambda d: d["markers"][0].update(normal=[0.0, float("-inf"), 0.0]), "markers[0].normal[1]: Input should be a"),
    (lambda d: d["pairs"][0].update(mated=[0, float("nan"), 1.8]), "pairs[0].mated[1]: Input should be a finite"),
    (lambda d: d["cameras"][0].update(time_offset=float("nan")), "cameras[0].time_offset: Input should be a finite"),
    (lambda d: d.update(marker_size=float("nan")), "marker_size: Input should be a finite number"),
    (lambda d: d.update(marker_size=0), "marker_size: Input should be greater than 0"),
    (lambda d: d.update(marker_size=True), "marker_size: expected a number, got true"),
    (lambda d: d["markers"][0]["center"].__setitem__(0, 1e300), "markers[0].center[0]: Input should be less than"),
    (lambda d: d["markers"][0].update(id=250), "markers[0].id: 250 is not in DICT_6X6_250 (expected 0 to 249)"),
    (lambda d: d["cameras"][0].update(source=-1), "cameras[0].source: device index -1 is negative"),
    (lambda d: d["cameras"][0].update(source=""), "cameras[0].source: String should have at least 1 character"),
    (lambda d: d.update(warnings=["x"]), "warnings: not a rig field"),
    (lambda d: d["cones"].update({"B\nC": [0, 0, float("nan")]}), "cones['B\\nC'][2]: Input should be a finite"),
])
def test_non_finite_and_bad_sizes_name_the_field(tmp_path: Path, change, message: str) -> None:
    import copy

    data = copy.deepcopy(RIG)
    change(data)
    with pytest.raises(InputError) as info:
        load_rig(_write(tmp_path, data))
    assert message in str(info.value)
    assert str(info.value).startswith(str(tmp_path / "rig.yaml"))
    assert len(str(info.value).splitlines()) == 1


def test_yaml_nan_is_refused(tmp_path: Path) -> None:
    text = yaml.safe_dump(RIG).replace("- -11.5\n", "- .nan\n", 1)
    path = tmp_path / "rig.yaml"
    path.write_text(text)
    with pytest.raises(InputError, match=r"markers\[0\]\.center\[1\]: Input should be a finite number"):
        load_rig(path)


@pytest.mark.parametrize(("content", "message"), [
    (b"", "is empty (expected a rig file)"),
    (b"\x00\x01\x02rig", "is binary, not text (expected a rig file)"),
    (b"name: \xff\xfe", "is binary, not text"),
    (b"a: [1, 2", "line 1: not valid YAML"),
    (b"a: 2001-02-30", "not valid YAML (day is out of range for month)"),
    (b"[" * 2000, "nested too deeply"),
    (b"- 1\n- 2\n", "expected a mapping"),
])
def test_unreadable_rig_file_is_one_line(tmp_path: Path, content: bytes, message: str) -> None:
    path = tmp_path / "rig.yaml"
    path.write_bytes(content)
    with pytest.raises(InputError, match=re.escape(message)) as info:
        load_rig(path)
    assert str(info.value).startswith(str(path)) and len(str(info.value).splitlines()) == 1


def test_rig_folder_is_one_line(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="is a folder"):
        load_rig(tmp_path)


def test_device_index_source(tmp_path: Path) -> None:
    data = {**RIG, "cameras": [{**RIG["cameras"][0], "source": 0, "mount": "fixed"}]}
    rig = load_rig(_write(tmp_path, data))
    assert rig.cameras[0].source == "0"
    assert rig.warnings == ()


def test_warnings_for_defaults_that_change_the_numbers(tmp_path: Path) -> None:
    data = {**RIG, "cameras": [RIG["cameras"][0], {**RIG["cameras"][0], "name": "drone-1", "mount": "drone"}]}
    data.pop("cones")
    path = _write(tmp_path, data)
    rig = load_rig(path)
    assert len(rig.warnings) == 2
    mount, cones = rig.warnings
    assert mount.startswith(f"{path}: cameras[0].mount: not given; stern-1 is treated as a drone")
    assert cones.startswith(f"{path}: cones: not given; each cone's offset is reported at its topside marker")
    assert [c.mount for c in rig.cameras] == ["drone", "drone"]  # the warning changes nothing
    assert "warnings" not in rig.model_dump() and "warnings" not in rig.model_dump(mode="json")


def test_warning_for_a_cone_without_a_tip(tmp_path: Path) -> None:
    data = yaml.safe_load(yaml.safe_dump(RIG))
    data["cameras"][0]["mount"] = "vessel"
    data["markers"] += [{"id": 3, "body": "jacket", "cone": "B", "face": "port", "center": [10.0, -10.0, -1.2]},
                        {"id": 4, "body": "topside", "cone": "B", "face": "port", "center": [10.0, -10.0, 0.6]}]
    data["pairs"].append({"cone": "B", "face": "port", "jacket": 3, "topside": 4})
    rig = load_rig(_write(tmp_path, data))
    assert rig.warnings == (f"{tmp_path / 'rig.yaml'}: cones: no tip for B; reported at the topside marker's centre, "
                            "not at the cone tip",)


def test_warnings_for_clocks_and_surveys_that_widen_the_sigma(tmp_path: Path) -> None:
    data = yaml.safe_load(yaml.safe_dump(RIG))
    data["cameras"][0].update(mount="vessel", time_offset_sigma=0.29)
    data["survey_sigma"] = {"position_m": 0.02, "tilt_deg": 1.0}
    path = _write(tmp_path, data)
    clocks, survey = load_rig(path).warnings
    assert clocks == (f"{path}: cameras[].time_offset_sigma: stern-1 state clocks known to ±0.29 s; the offsets' σ "
                      "grows by the topside's motion over that time (at 0.25 m/s, 72 mm), so moving cones may be "
                      "withheld: measure them with topside sync")
    assert survey.startswith(f"{path}: survey_sigma: markers known to 20 mm and 1° (1σ);")
    assert survey.endswith("refine them with topside survey, or survey the markers better")
    data["cameras"][0]["time_offset_sigma"] = 0.005  # a synced clock, a good survey: nothing to say
    data["survey_sigma"] = {"position_m": 0.003, "tilt_deg": [0.1, 0.1, 0.2]}
    assert load_rig(_write(tmp_path, data)).warnings == ()


def test_save_rig_is_atomic(tmp_path: Path) -> None:
    from tracking.rig import save_rig

    rig = load_rig(_write(tmp_path, RIG))
    out = tmp_path / "out" / "saved.yaml"
    save_rig(out, rig)
    assert load_rig(out).model_dump() == rig.model_dump()
    assert sorted(p.name for p in out.parent.iterdir()) == ["saved.yaml"]  # no temporary file left


# --- markers turned about their normal, or given a full orientation ------------------------------------------------

def _with_marker(tmp_path: Path, **fields) -> Path:
    import copy

    data = copy.deepcopy(RIG)
    data["markers"][0].update(fields)
    return _write(tmp_path, data)


def test_rotation_deg_turns_the_marker_about_its_normal(tmp_path: Path) -> None:
    from tracking.rig import turned

    upright = face_rotation("ahead")
    for angle in (90.0, 37.0, -123.5):
        R = load_rig(_with_marker(tmp_path, rotation_deg=angle)).markers[0].T_body_marker[:3, :3]
        np.testing.assert_allclose(R[:, 2], upright[:, 2], atol=1e-12)  # the normal stays
        a = np.deg2rad(angle)  # counter-clockwise as seen facing it: x turns towards y
        np.testing.assert_allclose(R[:, 0], np.cos(a) * upright[:, 0] + np.sin(a) * upright[:, 1], atol=1e-12)
        np.testing.assert_allclose(R, turned(upright, angle), atol=1e-12)
    R90 = load_rig(_with_marker(tmp_path, rotation_deg=90)).markers[0].T_body_marker[:3, :3]
    np.testing.assert_allclose(R90[:, 0], [0, 0, 1], atol=1e-12)  # printed top to the left: x points up


def test_R_and_quaternion_give_the_same_orientation(tmp_path: Path) -> None:
    turned37 = load_rig(_with_marker(tmp_path, rotation_deg=37)).markers[0].T_body_marker[:3, :3]
    typed = np.round(turned37, 4).tolist()  # as a person types it: four decimals
    by_matrix = load_rig(_with_marker(tmp_path, R=typed)).markers[0].T_body_marker[:3, :3]
    np.testing.assert_allclose(by_matrix, turned37, atol=1e-4)
    np.testing.assert_allclose(by_matrix.T @ by_matrix, np.eye(3), atol=1e-12)  # made exactly orthonormal
    w = np.sqrt(1 + np.trace(turned37)) / 2
    q = [w, (turned37[2, 1] - turned37[1, 2]) / (4 * w), (turned37[0, 2] - turned37[2, 0]) / (4 * w),
         (turned37[1, 0] - turned37[0, 1]) / (4 * w)]
    by_quaternion = load_rig(_with_marker(tmp_path, quaternion=np.round(q, 5).tolist())).markers[0]
    np.testing.assert_allclose(by_quaternion.T_body_marker[:3, :3], turned37, atol=1e-4)
    labelled = load_rig(_with_marker(tmp_path, face="plate-7", R=typed)).markers[0]  # any label with R
    assert labelled.face == "plate-7"


UPRIGHT_AHEAD = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]  # face ahead's R: x to port, y up, z ahead


@pytest.mark.parametrize(("fields", "message"), [
    ({"R": [[1, 0, 0], [0, 0.5, -1], [0, 1, 0]]}, "markers[0].R: not orthonormal (|RᵀR - I| reaches"),
    ({"R": [[-1, 0, 0], [0, 0, -1], [0, 1, 0]]}, "markers[0].R: a reflection (determinant -1"),
    ({"R": [[1, 0, 0], [0, 0, 1], [0, -1, 0]]}, "markers[0].R: its z axis (the outward normal) [0.0, 1.0, 0.0] is "
                                                "180° from face ahead's normal"),
    ({"R": [[1, 0, 0], [0, 0, -1]]}, "markers[0].R: List should have at least 3 items"),
    ({"R": [[1, 0, 0], [0, 0, float("nan")], [0, 1, 0]]}, "markers[0].R[1][2]: Input should be a finite number"),
    ({"quaternion": [1, 1, 0, 0]}, "markers[0].quaternion: norm 1.41421 is not 1 (expected a unit quaternion"),
    ({"quaternion": [1, 0, 0]}, "markers[0].quaternion: List should have at least 4 items"),
    ({"quaternion": [0.7071, 0.7071, 0, 0], "R": UPRIGHT_AHEAD}, "markers[0].quaternion: give R or quaternion, not "
                                                                 "both"),
    ({"R": UPRIGHT_AHEAD, "rotation_deg": 10}, "markers[0].rotation_deg: not with R (exactly one way"),
    ({"quaternion": [0.7071, 0.7071, 0, 0], "normal": [0, -1, 0]}, "markers[0].normal: not with quaternion"),
    ({"rotation_deg": 400}, "markers[0].rotation_deg: Input should be less than or equal to 360"),
    ({"rotation_deg": True}, "markers[0].rotation_deg: expected a number, got true"),
    ({"rotation_deg": float("inf")}, "markers[0].rotation_deg: Input should be a finite number"),
    ({"face": "plate-7"}, "markers[0].face: unknown face 'plate-7' (expected one of port"),
])
def test_bad_orientation_names_the_field(tmp_path: Path, fields: dict, message: str) -> None:
    with pytest.raises(InputError) as info:
        load_rig(_with_marker(tmp_path, **fields))
    assert message in str(info.value)
    assert str(info.value).startswith(str(tmp_path / "rig.yaml")) and len(str(info.value).splitlines()) == 1


def test_a_surveyed_camera_position(tmp_path: Path) -> None:
    data = {**RIG, "cameras": [{**RIG["cameras"][0], "mount": "fixed", "position": [-10.0, -40.0, 2.0],
                                "position_sigma": 0.05}]}
    cam = load_rig(_write(tmp_path, data)).cameras[0]
    assert cam.position == [-10.0, -40.0, 2.0] and cam.position_sigma == 0.05


@pytest.mark.parametrize(("fields", "message"), [
    ({"position": [1.0, 2.0, 3.0]}, "cameras[0].position_sigma: missing (expected the survey's σ in m with position)"),
    ({"position_sigma": 0.1}, "cameras[0].position: missing (expected the surveyed [x, y, z]"),
    ({"position": [1.0, 2.0, 3.0], "position_sigma": 0}, "cameras[0].position_sigma: Input should be greater than 0"),
    ({"position": [1.0, 2.0, 3.0], "position_sigma": 1000}, "cameras[0].position_sigma: Input should be less than"),
    ({"position": [1.0, float("nan"), 3.0], "position_sigma": 0.1}, "cameras[0].position[1]: Input should be a finite"),
    ({"position": [1.0, 2.0], "position_sigma": 0.1}, "cameras[0].position: List should have at least 3 items"),
])
def test_bad_camera_survey_names_the_field(tmp_path: Path, fields: dict, message: str) -> None:
    data = {**RIG, "cameras": [{**RIG["cameras"][0], **fields}]}
    with pytest.raises(InputError) as info:
        load_rig(_write(tmp_path, data))
    assert message in str(info.value) and len(str(info.value).splitlines()) == 1
