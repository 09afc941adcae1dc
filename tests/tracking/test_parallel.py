"""Offline tracking in chunks (tracking.parallel): the same output with one worker, two, and Ray in local mode, read
back through the CSV, rerun's own reader and the MCAP reader; chunks at keyframes; errors and a missing Ray as one
line."""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
from collections import Counter
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import pytest

from tests.synthetic import made_once, simulated_once
from tracking.images import VideoHealth, frames
from tracking.parallel import InPlace, LocalPool, plan_rig, track_chunks
from tracking.pipeline import TrackStats, track_rig
from tracking.rig import load_rig

SCENARIO = "config2-procedure5-weather"  # four cameras in fog and rain: the rain pass finds markers too
DURATION_S = 2.5
CHUNK = 20  # frames: every camera's 75 frames cut into 2-4 chunks at their keyframes
TOPSIDE = [sys.executable, "-m", "tracking.cli"]
VOLATILE = ("software_commit", "written_utc")  # which software and when it wrote: not the data


@pytest.fixture(scope="session")
def clip(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Every test here shares one simulated clip."""
    return simulated_once(tmp_path_factory, SCENARIO, DURATION_S)


def canon(o: object) -> object:
    """A value as nested tuples compared exactly (arrays by their bytes); a video's health without the packets read
    before its end (how many the decoder had taken when a frame came out depends on its threads)."""
    if isinstance(o, VideoHealth):
        fields = {f.name: getattr(o, f.name) for f in dataclasses.fields(VideoHealth)}
        if not o.ended:
            fields.pop("packets")
        return canon(fields)
    if dataclasses.is_dataclass(o):
        return type(o).__name__, tuple((f.name, canon(getattr(o, f.name))) for f in dataclasses.fields(o))
    if isinstance(o, np.ndarray):
        return o.dtype.str, o.shape, o.tobytes()
    if isinstance(o, Mapping):  # dicts, and the filter's camera poses (taken when read)
        return tuple(sorted((repr(k), canon(v)) for k, v in o.items()))
    if isinstance(o, list | tuple):
        return tuple(canon(x) for x in o)
    return repr(o)


def results(stream) -> list:
    return [canon(dataclasses.replace(r, frame=dataclasses.replace(r.frame, gray=None, bgr=None))) for r in stream]


def test_chunks_start_at_keyframes_and_cover_every_packet(clip: Path) -> None:
    import av

    rig = load_rig(clip / "rig.yaml")
    for plan in plan_rig(rig, chunk_frames=CHUNK):
        assert len(plan.chunks) >= 2, plan.camera
        with av.open(str(rig.resolve(next(c.source for c in rig.cameras if c.name == plan.camera)))) as container:
            stream = container.streams.video[0]
            keys = [p.pts for p in container.demux(stream) if p.size and p.is_keyframe]
        assert [c.start_pts for c in plan.chunks[1:]] == [k for k in keys if k in {c.start_pts for c in plan.chunks}]
        assert all(c.packets >= CHUNK for c in plan.chunks[:-1])
        assert sum(c.packets or plan.frames - c.packets_before for c in plan.chunks) == plan.frames
        assert [c.packets_before for c in plan.chunks[1:]] == list(np.cumsum([c.packets for c in plan.chunks[:-1]]))


def test_chunked_frames_are_one_pass_frames(clip: Path) -> None:
    """Every frame's detections, poses, offsets, body observation, number, time, packet and video health, in the
    same order as track_rig gives them, from two worker processes (and ROI tracking's, in this process too)."""
    rig = load_rig(clip / "rig.yaml")
    one_stats, chunk_stats = TrackStats(), TrackStats()
    one_pass = results(track_rig(rig, packets=True, stats=one_stats))
    pool = LocalPool(2)
    try:
        assert one_pass == results(track_chunks(rig, pool, packets=True, stats=chunk_stats, chunk_frames=CHUNK))
        assert canon(one_stats.videos) == canon(chunk_stats.videos)
        roi = results(track_chunks(rig, pool, roi_tracking=True, packets=True, chunk_frames=CHUNK))  # a detector
        assert roi == results(track_chunks(rig, InPlace(), roi_tracking=True, packets=True, chunk_frames=CHUNK))
        assert roi != one_pass  # with state, afresh per chunk: its own frames, the same in workers as in place
    finally:
        pool.close()


def rrd_rows(path: Path, frame_timelines: bool = True) -> Counter:
    """Every logged value of a recording, read back with rerun's own reader: (entity, component, times, value) rows
    (log time and tick, the recording's start time and the software's commit left out; frame_timelines=False: the
    capture time alone, not the frame numbers current when a value was logged)."""
    import rerun as rr

    rows: Counter = Counter()
    for chunk in rr.chunk.RrdReader(path).store().stream().to_chunks():
        batch = chunk.to_record_batch()
        cols = {n: batch.column(i).to_pylist() for i, n in enumerate(batch.schema.names)}
        times = [n for n in cols if n == "capture_time" or (frame_timelines and n.startswith("frame_"))]
        if not frame_timelines:
            cols = {n: v for n, v in cols.items() if not n.startswith("frame_")}
        values = [n for n in cols if n not in times and n not in ("log_time", "log_tick", "RecordingInfo:start_time")
                  and not n.startswith("rerun.")]
        for r in range(batch.num_rows):
            t = tuple((n, cols[n][r]) for n in times)
            for c in values:
                value = cols[c][r]
                if c == "TextDocument:text" and chunk.entity_path == "/archive/inputs":
                    doc = json.loads(value[0])
                    value = sorted((k, v) for k, v in doc.items() if k not in VOLATILE)
                if value is not None:
                    rows[repr((chunk.entity_path, c, t, value))] += 1
    return rows


def mcap_content(path: Path) -> tuple[Counter, dict]:
    """An archive's messages (topic, log and publish time, data) and its metadata but when and by which commit."""
    from mcap.reader import make_reader

    messages: Counter = Counter()
    with path.open("rb") as f:
        reader = make_reader(f)
        for _, channel, m in reader.iter_messages(log_time_order=True):
            messages[(channel.topic, m.log_time, m.publish_time, m.data)] += 1
        meta = {md.name: {k: v for k, v in md.metadata.items() if k not in VOLATILE} for md in reader.iter_metadata()}
    return messages, meta


def track(clip: Path, out: Path, name: str, *args: str) -> subprocess.CompletedProcess:
    """`track` with every output, its detector searching around the last markers (--roi, afresh at each chunk, so
    the same frames whatever runs the chunks: test_chunked_frames_are_one_pass_frames) at 2.4x less CPU."""
    return subprocess.run([*TOPSIDE, "track", "--rig", str(clip / "rig.yaml"), "-o", str(out / f"{name}.csv"),
                           "--rrd", str(out / f"{name}.rrd"), "--mcap", str(out / f"{name}.mcap"),
                           "--chunk-frames", str(CHUNK), "--roi", *args], capture_output=True, text=True,
                          timeout=600)


@pytest.fixture(scope="session")
def one_worker(clip: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """`track` on one worker, fused in one pass: one.csv, one.rrd, one.mcap and its stdout (one.txt), made once for
    the tests that compare what other ways of running write with it."""

    def make(folder: Path) -> None:
        folder.mkdir()
        proc = track(clip, folder, "one", "--workers", "1", "--one-pass-fusion")
        assert proc.returncode == 0, proc.stderr
        (folder / "one.txt").write_text(proc.stdout)

    return made_once(tmp_path_factory, "track-one-worker", make)


def test_workers_and_ray_write_the_same_outputs(clip: Path, one_worker: Path, tmp_path: Path) -> None:
    # Ray with two local workers (local worker processes: test_chunked_frames_are_one_pass_frames; fused in
    # segments: test_split); the outputs are written here whatever ran the chunks
    proc = track(clip, tmp_path, "ray", "--ray", "--workers", "2", "--one-pass-fusion")
    assert proc.returncode == 0, proc.stderr
    assert "wrote" in proc.stdout and "wrote" in (one_worker / "one.txt").read_text()
    csv = (one_worker / "one.csv").read_bytes()
    assert csv.count(b"\n") > 100
    rrd, mcap = rrd_rows(one_worker / "one.rrd"), mcap_content(one_worker / "one.mcap")
    assert sum(rrd.values()) > 1000 and sum(mcap[0].values()) > 1000
    assert (tmp_path / "ray.csv").read_bytes() == csv
    assert rrd_rows(tmp_path / "ray.rrd") == rrd
    assert mcap_content(tmp_path / "ray.mcap") == mcap


def test_a_workers_error_is_one_line(clip: Path, tmp_path: Path) -> None:
    """A calibration of another image size: met in a worker, reported as one line, exit status 2, nothing written."""
    import yaml

    data = yaml.safe_load((clip / "rig.yaml").read_text())
    cam = data["cameras"][1]
    text = (clip / cam["calibration"]).read_text()
    (tmp_path / "small.yaml").write_text(text.replace("image_width: 920", "image_width: 640"))
    for c in data["cameras"]:
        c["source"], c["calibration"] = str(clip / c["source"]), str(clip / c["calibration"])
    cam["calibration"] = str(tmp_path / "small.yaml")
    (tmp_path / "rig.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
    proc = subprocess.run([*TOPSIDE, "track", "--rig", str(tmp_path / "rig.yaml"), "-o", str(tmp_path / "o.csv"),
                           "--workers", "2", "--chunk-frames", str(CHUNK)], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "image size" in lines[0] and "Traceback" not in proc.stderr, proc.stderr
    assert not list(tmp_path.glob("o*.csv"))


def test_ray_missing_says_how_to_install_it(clip: Path, tmp_path: Path) -> None:
    code = ("import sys; sys.modules['ray'] = None; from tracking.cli import main; "
            f"sys.argv = ['topside', 'track', '--rig', {str(clip / 'rig.yaml')!r}, '-o', "
            f"{str(tmp_path / 'o.csv')!r}, '--ray']; main()")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert proc.stderr.strip() == ("topside: error: --ray: needs Ray, which is not installed (install it with: pip "
                                   "install 'topside[cluster]')")
    assert not list(tmp_path.glob("o*.csv"))


def test_rain_pass_runs_where_rain_is(clip: Path, installation: Path) -> None:
    """The second (rain-filtered) detection pass runs on frames with rain and is skipped on clear ones, where the
    markers found are those both passes find."""
    from tracking.detection import MarkerDetector, detections
    from tracking.images import frames

    rig = load_rig(clip / "rig.yaml")
    rainy = next(iter(frames(rig.resolve(rig.cameras[0].source)))).gray
    clear_rig = load_rig(installation / "rig.yaml")
    detector = MarkerDetector(clear_rig.dictionary)
    assert detector.rainy(rainy, detector.opening(rainy))
    for frame in frames(clear_rig.resolve(clear_rig.cameras[0].source)):
        opened = detector.opening(frame.gray)
        assert not detector.rainy(frame.gray, opened)
        quads, ids, _ = detector.find(frame.gray, opened)
        both = detections(detector.refine(frame.gray, opened, quads)[0], ids, [])
        found = detector.detect(frame.gray)
        assert found.ids == both.ids and len(found.ids) >= 2
        assert all(np.array_equal(a.corners, b.corners) for a, b in zip(found.markers, both.markers, strict=True))


def test_the_cli_default_chunk_is_the_trackers() -> None:
    from tracking.cli.options import CHUNK_FRAMES_DEFAULT
    from tracking.parallel import CHUNK_FRAMES

    assert CHUNK_FRAMES_DEFAULT == CHUNK_FRAMES


def test_input_errors_cross_processes() -> None:
    """An InputError raised in a worker process or a Ray task arrives whole (pickled as its three parts)."""
    import pickle

    from tracking.errors import InputError

    for err in (InputError("rig.yaml", "bad (expected good)", "cameras[0].source"), InputError("a.mp4", "damaged")):
        back = pickle.loads(pickle.dumps(err))
        assert (back.source, back.message, back.field, str(back)) == (err.source, err.message, err.field, str(err))


def test_a_times_file_stamps_every_frame_in_chunks_as_in_one_pass(clip: Path, tmp_path: Path) -> None:
    """Cameras with times files (jittered capture times, one frame unlisted): one pass and chunks at keyframes give
    every frame the file's time plus the camera's time_offset, and both drop the unlisted frame and say so."""
    import yaml

    rig_data = yaml.safe_load((clip / "rig.yaml").read_text())
    rig_data["cameras"] = rig_data["cameras"][:2]  # two cameras' frames interleave as four would, at half the cost
    rng = np.random.default_rng(7)
    sidecar: dict[str, np.ndarray] = {}
    for cam in rig_data["cameras"]:
        n = sum(1 for _ in frames(clip / cam["source"]))  # decoded only: counting needs no tracking
        times = 50.0 + np.cumsum(rng.uniform(0.04, 0.09, n))  # not the nominal 1/15 s
        numbers = np.arange(n)
        keep = numbers != 30  # frame 30 unlisted
        path = tmp_path / f"{cam['name']}.times.csv"
        pd_frame = np.column_stack([numbers[keep], times[keep]])
        path.write_text("frame,time\n" + "".join(f"{int(f)},{t:.6f}\n" for f, t in pd_frame))
        cam["times"], cam["time_offset"] = str(path), 0.25
        cam["calibration"] = str(clip / cam["calibration"])
        cam["source"] = str(clip / cam["source"])
        sidecar[cam["name"]] = np.where(keep, times + 0.25, np.nan)
    (tmp_path / "rig.yaml").write_text(yaml.safe_dump(rig_data))
    rig = load_rig(tmp_path / "rig.yaml")
    one_stats, chunk_stats = TrackStats(), TrackStats()
    one_pass = list(track_rig(rig, stats=one_stats))
    chunked = list(track_chunks(rig, InPlace(), stats=chunk_stats, chunk_frames=CHUNK))
    for run in (one_pass, chunked):
        got = {(r.camera, r.frame.index): r.time for r in run}
        assert all(np.isclose(t, sidecar[c][i]) for (c, i), t in got.items())
        assert not any(i == 30 for _, i in got)
        assert len(got) == sum(np.isfinite(t).sum() for t in sidecar.values())
    assert [r.time for r in one_pass] == [r.time for r in chunked]
    for stats in (one_stats, chunk_stats):
        assert all(v.unlisted == 1 for v in stats.videos.values())
        assert all("without a time in the times file" in line for line in stats.warnings())


def test_workers_end_when_track_is_killed(clip: Path, tmp_path: Path) -> None:
    """`kill -9` of `track --workers 2` leaves no process behind: the workers (and the resource tracker they hold
    open) see their parent gone and end."""
    import os
    import signal
    import time

    proc = subprocess.Popen([*TOPSIDE, "track", "--rig", str(clip / "rig.yaml"), "-o", str(tmp_path / "o.csv"),
                             "--workers", "2"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)

    def children() -> list[int]:
        out = subprocess.run(["pgrep", "-P", str(proc.pid)], capture_output=True, text=True).stdout
        return [int(p) for p in out.split()]

    deadline = time.monotonic() + 30
    while len(children()) < 3 and time.monotonic() < deadline and proc.poll() is None:  # tracker and two workers
        time.sleep(0.1)
    kids = children()
    assert len(kids) >= 3 and proc.poll() is None
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=10)

    def alive(pid: int) -> bool:
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return False
        return not open(f"/proc/{pid}/stat").read().split(")")[-1].split()[0] == "Z"

    deadline = time.monotonic() + 15
    while any(alive(p) for p in kids) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert not [p for p in kids if alive(p)]
