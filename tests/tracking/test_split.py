"""The fusion split over time (tracking.split): after a segment's lead-in its shown offsets are the one pass's within
0.5σ and shown where the one pass shows them, in worker processes as in place; `track` splits a run longer than
--fusion-segment and --one-pass-fusion keeps one pass; `batch` runs installations at once as one after another."""

from __future__ import annotations

import dataclasses
import subprocess
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from tests.tracking.test_fusion import camera_rig, observations
from tests.tracking.test_parallel import TOPSIDE, canon, clip, mcap_content, one_worker, rrd_rows, track  # noqa: F401
from tracking.estimator import ESTIMATORS, FilterReport
from tracking.parallel import InPlace, LocalPool
from tracking.rig import Rig, load_rig, save_rig
from tracking.split import SplitInfo, split_estimates

SECONDS = 16.0  # three cameras at 15 FPS, unsynchronised: 720 frames
SEGMENT_S = 4.0  # four segments
LEAD_IN_S = 8.0  # what it takes here (a vessel camera ahead, two drones): 5 s leaves offsets 1σ off


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Rig, list]:
    """The synthetic three-camera rig, written to a file (the workers read it), and its observations."""
    path = tmp_path_factory.mktemp("split") / "rig.yaml"
    save_rig(path, camera_rig("vessel"))
    rig = load_rig(path)
    return rig, observations(rig, SECONDS)


def agreement(one: list, split: list) -> tuple[int, int, int, float]:
    """Rows shown by the split where the one pass withholds, rows the one pass shows that the split withholds, rows
    shown by both, and the largest difference of a shown offset in the one pass's σ."""
    assert [(e.time, e.cone) for e in split] == [(e.time, e.cone) for e in one]  # a row wherever the one pass has one
    extra = missing = both = 0
    worst = 0.0
    for s, o in zip(split, one, strict=True):
        shown, one_shown = np.isfinite(s.offset).all(), np.isfinite(o.offset).all()
        extra += shown and not one_shown
        missing += one_shown and not shown
        if shown and one_shown:
            both += 1
            worst = max(worst, float((np.abs(s.offset - o.offset) / np.sqrt(np.diag(o.covariance))).max()))
    return extra, missing, both, worst


@pytest.mark.parametrize("mode", ["fused", "smoothed"])
def test_split_agrees_with_one_pass_after_its_lead_in(run: tuple[Rig, list], mode: str) -> None:
    rig, obs = run
    one = list(ESTIMATORS[mode](rig, iter(obs)))
    info, report = SplitInfo(), FilterReport()
    split = list(split_estimates(rig, obs, mode, InPlace(), SEGMENT_S, LEAD_IN_S, report=report, info=info))
    assert info.segments == 4 and len(info.results) == 3
    extra, missing, both, worst = agreement(one, split)
    assert extra == 0 and missing == 0 and both > 1000
    assert worst <= 0.5
    assert any(np.abs(s.offset - o.offset).max() > 1e-6 for s, o in zip(split, one, strict=True)
               if np.isfinite(s.offset).all())  # the segments were fused apart from the run before them
    assert report.unplaced == {} and report.below == (0, 0.0)
    short = list(split_estimates(rig, obs, mode, InPlace(), SEGMENT_S, 1.0))  # a lead-in too short to settle
    extra, missing, _, worst = agreement(one, short)
    assert extra == 0 and missing > 100 and worst > 0.5  # it withholds, and what it shows is off


def test_segments_fused_by_workers_are_fused_in_place(run: tuple[Rig, list]) -> None:
    rig, obs = run
    pool = LocalPool(2)
    try:
        info = SplitInfo()
        by_workers = [list(split_estimates(rig, obs, "fused", pool, SEGMENT_S, LEAD_IN_S, poses=poses, info=info))
                      for poses in (True, False)]  # without the cameras' poses the estimates travel as columns
    finally:
        pool.close()
    assert len(info.results) == 6 and all(r.worker for r in info.results)
    in_place = list(split_estimates(rig, obs, "fused", InPlace(), SEGMENT_S, LEAD_IN_S))
    assert canon(by_workers[0]) == canon(in_place) and all(e.T_jacket_cameras for e in in_place)
    assert any(e.T_jacket_cameras is None for e in by_workers[1])
    assert canon([dataclasses.replace(e, T_jacket_cameras=None) for e in by_workers[1]]) == \
        canon([dataclasses.replace(e, T_jacket_cameras=None) for e in in_place])


def test_track_splits_a_long_run_and_one_pass_fusion_keeps_one_pass(clip: Path, one_worker: Path,  # noqa: F811
                                                                   tmp_path: Path) -> None:
    """Segments of 1 s of the 2.5 s clip, each read from its default lead-in (20 s) before it: from the run's start,
    so the same outputs as one pass, recording and archive included (the recording's values at their capture times:
    an estimate now comes after more frames than in one pass, and is logged beside their frame numbers; the status
    panel, logged with the estimates, counts the frames seen by then; the archive's messages are written in another
    order)."""
    split = track(clip, tmp_path, "split", "--workers", "2", "--fusion-segment", "1")  # the one pass: one_worker's
    assert split.returncode == 0, split.stderr
    assert "fused in 3 segments of 1 s" in split.stdout and "segments" not in (one_worker / "one.txt").read_text()
    csv = (one_worker / "one.csv").read_bytes()
    assert csv.count(b"\n") > 100 and (tmp_path / "split.csv").read_bytes() == csv
    rrd, split_rrd = (Counter({k: n for k, n in rrd_rows(path, frame_timelines=False).items()
                               if not k.startswith("('/status'")})
                      for path in (one_worker / "one.rrd", tmp_path / "split.rrd"))
    assert sum(rrd.values()) > 1000 and split_rrd == rrd
    (messages, meta), (split_messages, split_meta) = (mcap_content(p) for p in (one_worker / "one.mcap",
                                                                                 tmp_path / "split.mcap"))
    assert split_messages == messages and split_meta.pop("topside.checkpoint") != meta.pop("topside.checkpoint")
    assert split_meta == meta  # the checkpoint's hash chains the messages in the order written
    verified = subprocess.run([*TOPSIDE, "verify", str(tmp_path / "split.mcap")], capture_output=True, text=True,
                              timeout=120)
    assert verified.returncode == 0, verified.stdout + verified.stderr


def test_batch_at_once_writes_what_one_after_another_writes(installation: Path, tmp_path: Path) -> None:
    manifest = tmp_path / "manifest.yaml"
    manifest.write_text(  # two small installations: each camera's chunks spread over the workers one after another
        f"- {{rig: {installation / 'rig.yaml'}, out: smoothed, truth: {installation / 'truth.csv'}, mode: smoothed}}\n"
        f"- {{rig: {installation / 'rig.yaml'}, out: cone-a, truth: {installation / 'truth.csv'}}}\n")
    outputs = {}
    for workers, how in (("2", "2 at once, each on one worker"), ("3", "one after another, each on 3 workers")):
        proc = subprocess.run([*TOPSIDE, "batch", str(manifest), "--workers", workers, "--chunk-frames", "20"],
                              capture_output=True, text=True, timeout=600)
        assert proc.returncode == 0, proc.stderr
        assert f"installations tracked {how}" in proc.stdout
        outputs[workers] = {p.relative_to(tmp_path): p.read_bytes() for p in sorted(tmp_path.glob("*/*"))}
        for p in tmp_path.glob("*/*"):
            p.unlink()
    assert len(outputs["2"]) == 4 and outputs["2"] == outputs["3"]
    assert outputs["2"][Path("smoothed/offsets.csv")].count(b"\n") > 20
    assert outputs["2"][Path("smoothed/offsets.csv")] != outputs["2"][Path("cone-a/offsets.csv")]  # its mode kept


def test_the_cli_default_segment_is_the_splits() -> None:
    from tracking.cli.options import FUSION_SEGMENT_DEFAULT
    from tracking.split import SEGMENT_S as DEFAULT

    assert FUSION_SEGMENT_DEFAULT == DEFAULT
