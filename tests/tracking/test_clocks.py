"""topside sync's solver on synthetic pair offsets: clocks off by known amounts, a topside moving or still."""

from __future__ import annotations

import numpy as np
import pytest

from tests.synthetic import rig_dict
from tracking.clocks import UNKNOWN_SIGMA_S, synced_rig, synchronise
from tracking.offsets import PairOffset
from tracking.pose import Choice
from tracking.rig import Rig, SurveySigma

FPS = 15.0
NOISE_M = 0.003  # σ of each offset axis
SEEN = {"cam-ahead": [("ahead", 1, 2)], "cam-port": [("port", 3, 4)], "drone": [("ahead", 1, 2), ("port", 3, 4)]}
TRUE_ERROR_S = {"cam-ahead": 0.0, "cam-port": 0.237, "drone": -0.412}  # true clock minus the rig's


def moving(t: np.ndarray) -> np.ndarray:
    """(N, 3) a topside swinging and creeping: up to 0.14 m/s."""
    return np.stack([0.3 * np.sin(2 * np.pi * t / 14), 0.1 * t - 3.0, 0.05 * np.sin(2 * np.pi * t / 8 + 1)], axis=1)


def still(t: np.ndarray) -> np.ndarray:
    """(N, 3) a topside hanging still (2 mm of drift a minute)."""
    return np.stack([0.2 + 0.002 * t / 60, np.full_like(t, -1.0), np.full_like(t, 2.0)], axis=1)


def rig() -> Rig:
    cams = [{"name": n, "calibration": f"{n}.yaml", "source": f"{n}.mp4", "time_offset": 0.1 * k,
             "mount": "drone"} for k, n in enumerate(SEEN)]
    return Rig.model_validate(rig_dict(cams))


def offsets(the_rig: Rig, motion, seconds: float = 60.0, seed: int = 0) -> list[PairOffset]:
    """Every camera's pair offsets at its frames' times on the rig's clocks: the motion at the true time, a constant
    bias per camera and pair (its survey and view errors), white noise."""
    rng = np.random.default_rng(seed)
    out = []
    for cam in the_rig.cameras:
        t_rig = cam.time_offset + np.arange(0.0, seconds, 1 / FPS)
        truth = motion(t_rig + TRUE_ERROR_S[cam.name])
        for face, j, s in SEEN[cam.name]:
            bias = rng.normal(0.0, 0.01, 3)
            noisy = truth + bias + rng.normal(0.0, NOISE_M, truth.shape)
            out += [PairOffset(float(t), cam.name, "A", face, j, s, np.eye(4), o, NOISE_M**2 * np.eye(3),
                               Choice.UNIQUE) for t, o in zip(t_rig, noisy, strict=True)]
    return sorted(out, key=lambda o: o.time)


def test_clocks_off_by_known_amounts_are_measured_within_their_sigma() -> None:
    the_rig = rig()
    clocks = synchronise(the_rig, offsets(the_rig, moving))
    ref = next(c for c in clocks if c.reference)
    for c in clocks:
        assert c.known, c.note
        true = TRUE_ERROR_S[c.camera] - TRUE_ERROR_S[ref.camera]
        assert c.sigma is not None and c.sigma < 0.005  # 900 frames at 0.14 m/s and 3 mm: a few ms
        assert abs(c.change - true) < max(3 * c.sigma, 1e-3), (c.camera, c.change, true, c.sigma)
        assert abs(c.change - true) < 0.010  # the target
    synced = synced_rig(the_rig, clocks)
    for cam, c in zip(synced.cameras, clocks, strict=True):
        assert cam.time_offset == pytest.approx(c.offset, abs=1e-6)
        assert cam.time_offset_sigma == pytest.approx(c.sigma, abs=1e-6)


def test_a_named_reference_keeps_its_offset() -> None:
    the_rig = rig()
    clocks = synchronise(the_rig, offsets(the_rig, moving, seed=1), reference="cam-port")
    by_name = {c.camera: c for c in clocks}
    assert by_name["cam-port"].reference and by_name["cam-port"].change == 0.0
    true = TRUE_ERROR_S["drone"] - TRUE_ERROR_S["cam-port"]
    assert abs(by_name["drone"].change - true) < 0.010


def test_a_still_topside_says_it_cannot_tell_rather_than_guess() -> None:
    the_rig = rig()
    clocks = synchronise(the_rig, offsets(the_rig, still))
    unknown = [c for c in clocks if not c.reference]
    assert unknown and all(not c.known for c in unknown)
    for c in unknown:
        assert c.offset == c.rig_offset and c.sigma is None
        assert "too small" in c.note or "never saw" in c.note
    synced = synced_rig(the_rig, clocks)
    assert [c.time_offset for c in synced.cameras] == [c.time_offset for c in the_rig.cameras]
    ref = next(c for c in clocks if c.reference)
    assert all(c.time_offset_sigma is None for c in synced.cameras if c.name != ref.camera)  # not measured
    assert UNKNOWN_SIGMA_S <= 0.02


def test_a_camera_without_pair_offsets_is_named() -> None:
    the_rig = rig()
    clocks = synchronise(the_rig, [o for o in offsets(the_rig, moving) if o.camera != "cam-port"])
    port = next(c for c in clocks if c.camera == "cam-port")
    assert not port.known and port.frames == 0 and "no marker pair" in port.note


def crossing(t: np.ndarray) -> np.ndarray:
    """(N, 3) a topside brought 20 m astern onto its cones at up to 0.25 m/s, swinging 0.3 m as it goes."""
    s = np.clip(t / 80.0, 0.0, 1.0)
    along = 20.0 * (1.0 - (s - np.sin(2 * np.pi * s) / (2 * np.pi)))  # eases in and out
    return np.stack([0.3 * np.sin(2 * np.pi * t / 14), along, 2.0 + 0.05 * np.sin(2 * np.pi * t / 8)], axis=1)


def test_a_jacket_marker_tilted_within_its_survey_does_not_shift_the_clocks() -> None:
    # cam-port's jacket marker turned 1.5° about z and 1° about x: its offsets, 20 m long at first, swing by up to
    # 0.5 m as the topside comes in: a lag, were the pair's frame taken as surveyed
    the_rig = rig().model_copy(update={"survey_sigma": SurveySigma(position_m=0.02, tilt_deg=1.0)})
    turned = np.array([[1.0, -0.026, 0.0], [0.026, 1.0, -0.017], [0.0, 0.017, 1.0]])
    measured = [PairOffset(o.time, o.camera, o.cone, o.face, o.jacket_id, o.topside_id, o.T_W_S,
                           turned @ o.offset if o.camera == "cam-port" else o.offset, o.covariance, o.choice)
                for o in offsets(the_rig, crossing, seconds=90.0, seed=2)]
    clocks = synchronise(the_rig, measured, reference="cam-ahead")
    port = next(c for c in clocks if c.camera == "cam-port")
    assert port.known, port.note
    assert abs(port.change - TRUE_ERROR_S["cam-port"]) < max(2 * (port.sigma or 0.0), 0.003), (port.change,
                                                                                                  port.sigma)
