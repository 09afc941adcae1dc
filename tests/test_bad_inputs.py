"""Every command with bad input, through the real CLI's entry point (in this process; a case of each kind in a
subprocess too): exit 2, one line on stderr naming the file or option, no traceback, every input byte-identical
afterwards, and no output (temporary or not) left behind."""

from __future__ import annotations

import hashlib
import importlib.util
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
import yaml

from tests.cli_runs import run_topside
from tests.conftest import FPS, FRAMES, T0, motion
from tests.streams import mpegts_copy, serving
from tracking.cli.common import PROGRESS_INTERVAL_ENV
from tracking.parallel import RAY_CONNECT_TIMEOUT_ENV

TOPSIDE = [sys.executable, "-m", "tracking.cli"]
PNG = b"\x89PNG\r\n\x1a\n" + bytes(range(256)) * 4
BINARY = bytes(range(256)) * 16


@dataclass(frozen=True)
class Case:
    """One bad input: how to prepare the folder, the command line, and what the one line must name."""

    name: str
    args: list[str]
    names: tuple[str, ...]  # fragments the error line must hold (the file, the field or option)
    prepare: Callable[[Path], None] | None = None
    marks: tuple = ()  # pytest marks (a case that holds only when a package is not installed)


def edit_rig(change: Callable[[dict], None], to: str = "bad-rig.yaml") -> Callable[[Path], None]:
    """A preparation writing a changed copy of the rig."""

    def prepare(folder: Path) -> None:
        rig = yaml.safe_load((folder / "rig.yaml").read_text())
        change(rig)
        (folder / to).write_text(yaml.safe_dump(rig, sort_keys=False))

    return prepare


def write(name: str, data: bytes | str) -> Callable[[Path], None]:
    """A preparation writing one file."""

    def prepare(folder: Path) -> None:
        path = folder / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(data if isinstance(data, bytes) else data.encode())

    return prepare


def recording(name: str) -> Callable[[Path], None]:
    """A preparation writing a small real Rerun recording (capture times 0-4 s), in its own process."""

    def prepare(folder: Path) -> None:
        script = ("import rerun as rr, sys\nrr.init('t')\nrr.save(sys.argv[1])\n"
                  "for i in range(5):\n    rr.set_time('capture', timestamp=float(i))\n"
                  "    rr.log('x', rr.Scalars(float(i)))\n")
        subprocess.run([sys.executable, "-c", script, str(folder / name)], check=True, timeout=60)

    return prepare


def both(*steps: Callable[[Path], None]) -> Callable[[Path], None]:
    """Several preparations in order."""

    def prepare(folder: Path) -> None:
        for step in steps:
            step(folder)

    return prepare


def offsets_csv(shift_s: float = 0.0, cone: str = "A") -> str:
    """A small offsets CSV as `topside track` writes it, at the installation's capture times (+ shift)."""
    rows = ["time,cone,dx,dy,dz,cameras,sdx,sdy,sdz"]
    for t in T0 + np.arange(FRAMES) / FPS:
        d = motion(t)
        rows.append(f"{t + shift_s:.6f},{cone},{d[0]:.5f},{d[1]:.5f},{d[2]:.5f},cam-ahead,0.01,0.01,0.01")
    return "\n".join(rows) + "\n"


def chessboard_photos(folder: Path, copies: int) -> None:
    """One photo of a 9x6 chessboard (inner corners), tilted, as p0.png .. p{copies-1}.png."""
    import cv2

    square = 40
    board = np.kron((np.indices((7, 10)).sum(axis=0) % 2), np.ones((square, square)))
    board = np.pad(255 * board, square, constant_values=255).astype(np.uint8)
    h, w = board.shape
    corners = np.float32([[0, 0], [w, 0], [w, h], [0, h]])
    seen = np.float32([[60, 40], [560, 70], [540, 430], [80, 450]])
    photo = cv2.warpPerspective(board, cv2.getPerspectiveTransform(corners, seen), (640, 480), borderValue=128)
    for i in range(copies):
        cv2.imwrite(str(folder / f"p{i}.png"), photo)


def private_key(path: Path) -> None:
    """An ed25519 private key in PEM, as `openssl genpkey -algorithm ed25519` writes it."""
    from cryptography.hazmat.primitives import serialization
    from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey

    path.write_bytes(Ed25519PrivateKey.generate().private_bytes(
        serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8, serialization.NoEncryption()))


def warning_rig(change: Callable[[dict], None] | None = None) -> Callable[[Path], None]:
    """A preparation writing w.yaml: the rig with cameras[0].mount left out (a warning at every load), changed."""

    def edit(rig: dict) -> None:
        del rig["cameras"][0]["mount"]
        if change is not None:
            change(rig)

    return edit_rig(edit, to="w.yaml")


def nan_centre(rig: dict) -> None:
    rig["markers"][0]["center"][1] = float("nan")


def calibration_with(name: str, old: str, new: str) -> Callable[[Path], None]:
    """A copy of cam-ahead's calibration with one text replaced."""

    def prepare(folder: Path) -> None:
        text = (folder / "calibration/cam-ahead.yaml").read_text()
        assert old in text
        (folder / name).write_text(text.replace(old, new, 1))

    return prepare


def use_calibration(name: str) -> Callable[[Path], None]:
    return edit_rig(lambda rig: rig["cameras"][0].update(calibration=name))


def use_source(name: str) -> Callable[[Path], None]:
    return edit_rig(lambda rig: rig["cameras"][0].update(source=name))


RIG = ["--rig", "rig.yaml"]
CASES = [
    # track: outputs that are inputs, each other, folders, unwritable
    Case("track -o the rig", ["track", *RIG, "-o", "rig.yaml"], ("rig.yaml", "--out", "input")),
    Case("track --rrd a video", ["track", *RIG, "--rrd", "cam-ahead.mp4"], ("cam-ahead.mp4", "--rrd")),
    Case("track --mcap a calibration", ["track", *RIG, "--mcap", "calibration/cam-port.yaml"],
         ("cam-port.yaml", "--mcap")),
    Case("track -o the truth", ["track", *RIG, "--truth", "truth.csv", "-o", "truth.csv"], ("truth.csv", "--out")),
    Case("track -o a link to the rig", ["track", *RIG, "-o", "link.csv"], ("link.csv", "--out"),
         lambda f: (f / "link.csv").symlink_to(f / "rig.yaml")),
    Case("track -o and --rrd the same", ["track", *RIG, "-o", "x.csv", "--rrd", "x.csv"], ("x.csv", "--rrd")),
    Case("track -o a folder", ["track", *RIG, "-o", "calibration"], ("calibration", "directory")),
    Case("track -o under a file", ["track", *RIG, "-o", "truth.csv/offsets.csv"], ("offsets.csv", "not a folder")),
    Case("track --mode unknown", ["track", *RIG, "--mode", "best"], ("--mode", "best")),
    Case("track --video unknown", ["track", *RIG, "--mcap", "a.mcap", "--video", "gif"], ("--video", "gif")),
    Case("track --key not a key", ["track", *RIG, "--mcap", "a.mcap", "--key", "truth.csv"], ("truth.csv",)),
    Case("track --key without --mcap", ["track", *RIG, "--key", "k.pem"], ("--key", "k.pem", "--mcap"),
         write("k.pem", "not read: there is no archive to sign\n")),
    # track: bad rigs and what they point to
    Case("rig with a NaN centre", ["track", "--rig", "bad-rig.yaml"], ("bad-rig.yaml", "center"),
         edit_rig(nan_centre)),
    Case("rig with a negative marker size", ["track", "--rig", "bad-rig.yaml"], ("bad-rig.yaml", "marker_size"),
         edit_rig(lambda rig: rig.update(marker_size=-1.0))),
    Case("rig with an infinite time offset", ["track", "--rig", "bad-rig.yaml"], ("bad-rig.yaml", "time_offset"),
         edit_rig(lambda rig: rig["cameras"][1].update(time_offset=float("inf")))),
    Case("rig with a key given twice", ["track", "--rig", "bad-rig.yaml"],
         ("bad-rig.yaml", "line 70", "duplicate key 'marker_size', first given on line 3"),
         lambda f: (f / "bad-rig.yaml").write_text((f / "rig.yaml").read_text() + "marker_size: 0.5\n")),
    Case("rig with a negative survey_sigma", ["track", "--rig", "bad-rig.yaml"],
         ("bad-rig.yaml", "survey_sigma.position_m", "expected a σ from 0 to 1 m, or three", "got [-0.01"),
         edit_rig(lambda rig: rig.update(survey_sigma={"position_m": [-0.01, 0.01, 0.01], "tilt_deg": 1.0}))),
    Case("rig with a survey_sigma that is a number", ["track", "--rig", "bad-rig.yaml"],
         ("bad-rig.yaml", "survey_sigma", "expected a mapping with position_m (m) and tilt_deg (degrees)"),
         edit_rig(lambda rig: rig.update(survey_sigma=-0.01))),
    Case("rig that is binary", ["track", "--rig", "bin.yaml"], ("bin.yaml",), write("bin.yaml", BINARY)),
    Case("rig that is empty", ["track", "--rig", "empty.yaml"], ("empty.yaml",), write("empty.yaml", "")),
    Case("rig that is a folder", ["track", "--rig", "calibration"], ("calibration",)),
    Case("rig with an unknown mount", ["track", "--rig", "bad-rig.yaml"], ("bad-rig.yaml", "mount"),
         edit_rig(lambda rig: rig["cameras"][0].update(mount="crane"))),
    Case("calibration that is binary", ["track", "--rig", "bad-rig.yaml"], ("junk.yaml",),
         both(write("junk.yaml", BINARY), use_calibration("junk.yaml"))),
    Case("calibration that is not YAML", ["track", "--rig", "bad-rig.yaml"], ("junk.yaml",),
         both(write("junk.yaml", "{{{ not: [yaml"), use_calibration("junk.yaml"))),
    Case("calibration with a NaN focal length", ["track", "--rig", "bad-rig.yaml"], ("nan-cam.yaml", "camera_matrix"),
         both(calibration_with("nan-cam.yaml", "data: [ ", "data: [ .Nan, "), use_calibration("nan-cam.yaml"))),
    Case("video that is missing", ["track", "--rig", "bad-rig.yaml"], ("gone.mp4",), use_source("gone.mp4")),
    Case("video that is a PNG", ["track", "--rig", "bad-rig.yaml", "--rrd", "r.rrd", "--mcap", "r.mcap"],
         ("png.mp4",), both(write("png.mp4", PNG), use_source("png.mp4"))),
    # detect
    Case("detect --marker-size -1", ["detect", "cam-ahead.mp4", "--marker-size", "-1"], ("--marker-size",)),
    Case("detect --marker-size nan", ["detect", "cam-ahead.mp4", "--marker-size", "nan"], ("--marker-size",)),
    Case("detect --camera binary", ["detect", "cam-ahead.mp4", "--camera", "junk.yaml"], ("junk.yaml",),
         write("junk.yaml", BINARY)),
    Case("detect --dictionary binary", ["detect", "cam-ahead.mp4", "--dictionary", "dict.yaml"], ("dict.yaml",),
         write("dict.yaml", BINARY)),
    Case("detect an image that is missing", ["detect", "nothing.png"], ("nothing.png",)),
    Case("detect a stream nobody serves", ["detect", "rtsp://127.0.0.1:1/stream1"],
         ("rtsp://127.0.0.1:1/stream1: cannot be opened as a video",)),  # the URL as given, not rtsp:/127...
    Case("detect a device that is not there", ["detect", "63"], ("device 63", "cannot be opened")),
    # calibrate
    Case("calibrate -o a folder", ["calibrate", "a.png", "--board", "chessboard:9x6:0.025", "-o", "calibration"],
         ("calibration", "directory"), write("a.png", PNG)),
    Case("calibrate -o a photo", ["calibrate", "a.png", "--board", "chessboard:9x6:0.025", "-o", "a.png"],
         ("a.png", "--out"), write("a.png", PNG)),
    Case("calibrate --board nonsense", ["calibrate", "a.png", "--board", "chess:9", "-o", "c.yaml"], ("--board",),
         write("a.png", PNG)),
    Case("calibrate from one photo five times",
         ["calibrate", *(f"p{i}.png" for i in range(5)), "--board", "chessboard:9x6:0.025", "-o", "c.yaml"],
         ("p0.png", "the board is in 5 photos but at only 1 distinct pose", "p1.png, p2.png, p3.png, p4.png repeat "
          "p0.png's view", "need at least 3 distinct views"), lambda f: chessboard_photos(f, 5)),
    Case("calibrate --subpix-window 0", ["calibrate", "a.png", "--board", "chessboard:9x6:0.025", "-o", "c.yaml",
                                         "--subpix-window", "0"], ("--subpix-window",), write("a.png", PNG)),
    # export
    Case("export --mcap the recording", ["export", "run.rrd", "--mcap", "run.rrd"], ("run.rrd", "--mcap"),
         write("run.rrd", BINARY)),
    Case("export a PNG", ["export", "png.rrd", "--mcap", "out.mcap"], ("png.rrd",), write("png.rrd", PNG)),
    Case("export --offsets missing", ["export", "run.rrd", "--mcap", "out.mcap", "--offsets", "no.csv"],
         ("no.csv",), write("run.rrd", BINARY)),
    # verify
    Case("verify --recover a PNG", ["verify", "png.mcap", "--recover"], ("png.mcap", "MCAP"),
         write("png.mcap", PNG)),
    Case("verify --recover -o the archive", ["verify", "a.mcap", "--recover", "-o", "a.mcap"], ("a.mcap", "--out"),
         write("a.mcap", BINARY)),
    Case("verify a missing archive", ["verify", "none.mcap"], ("none.mcap",)),
    Case("verify --key not a key", ["verify", "a.mcap", "--key", "rig.yaml"], ("rig.yaml",),
         write("a.mcap", BINARY)),
    Case("verify --key a private key", ["verify", "a.mcap", "--key", "private.pem"],
         ("private.pem", "is a private key", "openssl pkey -in private.pem -pubout -out public.pem"),
         both(write("a.mcap", BINARY), lambda f: private_key(f / "private.pem"))),
    # report
    Case("report a missing file", ["report", "none.rrd", "-o", "r.html"], ("none.rrd", "not found")),
    Case("report a PNG", ["report", "png.rrd", "-o", "r.html"], ("png.rrd", "not a Rerun recording or an MCAP"),
         write("png.rrd", PNG)),
    Case("report a truncated recording", ["report", "cut.rrd", "-o", "r.html"], ("cut.rrd", "Rerun recording"),
         write("cut.rrd", b"RRF2" + BINARY)),
    Case("report a recording not of topside", ["report", "other.rrd", "-o", "r.html"],
         ("other.rrd", "archive/inputs"), recording("other.rrd")),
    Case("report -o the recording", ["report", "run.rrd", "-o", "run.rrd"], ("run.rrd", "--out"),
         write("run.rrd", BINARY)),
    # view
    Case("view a missing recording", ["view", "none.rrd", "--web"], ("none.rrd",)),
    Case("view a PNG", ["view", "png.rrd", "--web"], ("png.rrd",), write("png.rrd", PNG)),
    Case("view --to before --from", ["view", "png.rrd", "--from", "5", "--to", "1"], ("--to",),
         write("png.rrd", PNG)),
    Case("view --from nan", ["view", "r.rrd", "--web", "--from", "nan"], ("--from", "not a finite number"),
         recording("r.rrd")),
    Case("view --to nan", ["view", "r.rrd", "--web", "--to", "nan"], ("--to", "not a finite number"),
         recording("r.rrd")),
    Case("view --from inf", ["view", "r.rrd", "--web", "--from", "inf"], ("--from", "not a finite number"),
         recording("r.rrd")),
    # track --ray
    Case("track --ray ray:// without ray[client]", ["track", *RIG, "--ray", "ray://HOST:10001"],
         ("--ray", "ray://HOST:10001", "pip install 'ray[client]'"),
         marks=(pytest.mark.skipif(importlib.util.find_spec("grpc") is not None, reason="ray[client] is installed"),)),
    Case("track --ray malformed", ["track", *RIG, "--ray", "ray://host:port"], ("--ray", "ray://host:port",
                                                                               "expected ray://HOST:PORT")),
    Case("track --ray no port", ["track", *RIG, "--ray", "nonsense"], ("--ray", "nonsense", "not a Ray address")),
    Case("track --ray a port nobody listens on", ["track", *RIG, "--ray", "127.0.0.1:1"],
         ("--ray", "127.0.0.1:1 does not answer", "expected a Ray cluster's head")),
    # markers
    Case("markers -o a file", ["markers", *RIG, "-o", "truth.csv"], ("truth.csv", "--out", "is a file")),
    Case("markers --dpi 0", ["markers", *RIG, "-o", "sheets", "--format", "png", "--dpi", "0"], ("--dpi",)),
    Case("markers --format gif", ["markers", *RIG, "-o", "sheets", "--format", "gif"], ("--format", "gif")),
    Case("markers --dpi too fine for a 1 m marker", ["markers", *RIG, "-o", "sheets", "--format", "png", "--dpi",
                                                     "1200"], ("--dpi", "Mpx", "--format pdf")),
    Case("markers onto the rig", ["markers", "--rig", "marker-1-jacket-A-ahead.pdf", "-o", "."],
         ("marker-1-jacket-A-ahead.pdf", "input"),
         lambda f: shutil.copy(f / "rig.yaml", f / "marker-1-jacket-A-ahead.pdf")),
    # batch
    Case("batch with a name given twice", ["batch", "m.yaml"],
         ("m.yaml", "installations[1].name", "'A' is also installations[0]'s name"),
         write("m.yaml", "- {rig: rig.yaml, out: one, name: A}\n- {rig: rig.yaml, out: two, name: A}\n")),
    # evaluate
    Case("evaluate without truth", ["evaluate", "offsets.csv"], ("offsets.csv",),
         write("offsets.csv", offsets_csv())),
    Case("evaluate an empty CSV", ["evaluate", "empty.csv", "truth.csv"], ("empty.csv",), write("empty.csv", "")),
    Case("evaluate a binary CSV", ["evaluate", "bin.csv", "truth.csv"], ("bin.csv",), write("bin.csv", BINARY)),
    Case("evaluate truth with no shared time", ["evaluate", "offsets.csv", "truth.csv"], ("offsets.csv", "truth.csv"),
         write("offsets.csv", offsets_csv(shift_s=1000.0))),
    Case("evaluate truth with no shared cone", ["evaluate", "offsets.csv", "truth.csv"], ("offsets.csv", "truth.csv"),
         write("offsets.csv", offsets_csv(cone="Z"))),
    Case("evaluate --markdown the offsets", ["evaluate", "offsets.csv", "truth.csv", "--markdown", "offsets.csv"],
         ("offsets.csv", "--markdown"), write("offsets.csv", offsets_csv())),
    Case("evaluate --markdown a folder", ["evaluate", "offsets.csv", "truth.csv", "--markdown", "calibration"],
         ("calibration", "--markdown"), write("offsets.csv", offsets_csv())),
    # simulate
    Case("simulate an unknown scenario", ["simulate", "no-such-scenario", "-o", "sim"], ("no-such-scenario",)),
    Case("simulate -o a file", ["simulate", "config1-procedure1", "-o", "rig.yaml"], ("rig.yaml", "--out")),
    Case("simulate -o a folder of other files", ["simulate", "config1-procedure1", "-o", "."], ("--out",)),
    Case("simulate --duration -1", ["simulate", "config1-procedure1", "-o", "sim", "--duration", "-1"],
         ("--duration",)),
    # live
    Case("live -o the rig", ["live", *RIG, "-o", "rig.yaml"], ("rig.yaml", "--out")),
    Case("live --speed 0", ["live", *RIG, "--speed", "0"], ("--speed",)),
    Case("live --stale nan", ["live", *RIG, "--stale", "nan"], ("--stale",)),
    Case("live over an earlier session", ["live", *RIG, "--rrd", "s.rrd", "-o", "s.csv"], ("s.csv", "earlier"),
         write("s.csv", "time,cone\n")),
    Case("export --offsets empty", ["export", "run.rrd", "--mcap", "a.mcap", "--offsets", "e.csv"], ("e.csv",),
         write("e.csv", "")),
    Case("export --offsets binary", ["export", "run.rrd", "--mcap", "a.mcap", "--offsets", "b.csv"], ("b.csv",),
         write("b.csv", BINARY)),
    Case("export --offsets wrong columns", ["export", "run.rrd", "--mcap", "a.mcap", "--offsets", "w.csv"],
         ("w.csv", "time"), write("w.csv", "a,b\n1,2\n")),
    Case("live with a missing video", ["live", "--rig", "bad-rig.yaml"], ("nope.mp4", "not found"),
         use_source("nope.mp4")),
    Case("live with a video that is not one", ["live", "--rig", "bad-rig.yaml"], ("truth.csv", "video"),
         use_source("truth.csv")),
    Case("live mixing files and a device", ["live", "--rig", "bad-rig.yaml"], ("bad-rig.yaml", "mixes"),
         use_source("0")),
    # sync, survey
    Case("sync -o the rig", ["sync", *RIG, "-o", "rig.yaml"], ("rig.yaml", "--out")),
    Case("sync --reference unknown", ["sync", *RIG, "-o", "s.yaml", "--reference", "nope"], ("nope", "--reference")),
    Case("survey --to before --from", ["survey", *RIG, "-o", "s.yaml", "--from", "4", "--to", "2"], ("--to",)),
    Case("survey --from nan", ["survey", *RIG, "-o", "s.yaml", "--from", "nan"], ("--from", "not a finite number")),
    Case("survey --to nan", ["survey", *RIG, "-o", "s.yaml", "--to", "nan"], ("--to", "not a finite number")),
    Case("survey --to inf", ["survey", *RIG, "-o", "s.yaml", "--to", "inf"], ("--to", "not a finite number")),
    Case("survey without survey_sigma", ["survey", *RIG, "-o", "s.yaml"], ("rig.yaml", "survey_sigma")),
    # a rig that warns (a camera without its mount): the error alone, the warnings never before it
    Case("survey without survey_sigma, a rig that warns", ["survey", "--rig", "w.yaml", "-o", "s.yaml"],
         ("w.yaml", "survey_sigma", "no marker to survey"), warning_rig()),
    Case("sync --reference unknown, a rig that warns", ["sync", "--rig", "w.yaml", "-o", "s.yaml", "--reference",
                                                         "nope"], ("nope", "--reference"), warning_rig()),
    Case("check --rrd the rig, a rig that warns", ["check", "--rig", "w.yaml", "--rrd", "w.yaml"], ("w.yaml", "--rrd"),
         warning_rig()),
    Case("track with a missing video, a rig that warns", ["track", "--rig", "w.yaml"], ("gone.mp4",),
         warning_rig(lambda rig: rig["cameras"][1].update(source="gone.mp4"))),
    Case("track -o the rig, a rig that warns", ["track", "--rig", "w.yaml", "-o", "w.yaml"], ("w.yaml", "--out"),
         warning_rig()),
    Case("live --rrd beside an earlier session, a rig that warns", ["live", "--rig", "w.yaml", "--rrd", "s.rrd"],
         ("s-offsets.csv", "earlier"), both(warning_rig(), write("s-offsets.csv", "time,cone\n"))),
    Case("detect --dictionary not the rig's, a rig that warns", ["detect", "cam-ahead.mp4", "--rig", "w.yaml",
                                                                  "--dictionary", "DICT_4X4_50"], ("--dictionary",),
         warning_rig()),
]


def snapshot(folder: Path) -> dict[str, str]:
    """Every file under folder (links as their target's name) and its SHA-256."""
    out = {}
    for path in sorted(folder.rglob("*")):
        key = str(path.relative_to(folder))
        if path.is_symlink():
            out[key] = f"-> {path.readlink()}"
        elif path.is_file():
            out[key] = hashlib.sha256(path.read_bytes()).hexdigest()
        else:
            out[key] = "folder"
    return out


def test_at_least_forty_cases_cover_every_command() -> None:
    assert len(CASES) >= 40
    assert {c.args[0] for c in CASES} >= {"track", "detect", "calibrate", "export", "verify", "view", "evaluate",
                                         "simulate", "live", "report"}
    assert len({c.name for c in CASES}) == len(CASES)


@pytest.mark.parametrize("case", [pytest.param(c, id=c.name, marks=c.marks) for c in CASES])
def test_bad_input(case: Case, installation: Path, tmp_path: Path, capfd: pytest.CaptureFixture[str],
                   monkeypatch: pytest.MonkeyPatch) -> None:
    """Run in this process (the same entry point, without an interpreter's start-up per case)."""
    folder = tmp_path / "work"
    shutil.copytree(installation, folder)
    if case.prepare is not None:
        case.prepare(folder)
    before = snapshot(folder)
    code, out, err = run_topside(case.args, folder, capfd, monkeypatch)
    assert_one_line_error(case, code, out, err)
    assert snapshot(folder) == before  # inputs unchanged, nothing written, nothing half-written


SUBPROCESS_CASES = ("track -o the rig", "report a truncated recording", "export --offsets binary",
                    "verify --key a private key", "view --from nan")


@pytest.mark.parametrize("name", SUBPROCESS_CASES)
def test_bad_input_in_its_own_process(name: str, installation: Path, tmp_path: Path) -> None:
    """A case of each kind through a real `topside` process: the exit status and stderr the shell sees."""
    case = next(c for c in CASES if c.name == name)
    folder = tmp_path / "work"
    shutil.copytree(installation, folder)
    if case.prepare is not None:
        case.prepare(folder)
    before = snapshot(folder)
    proc = subprocess.run([*TOPSIDE, *case.args], cwd=folder, capture_output=True, text=True, timeout=120)
    assert "Traceback" not in proc.stderr
    assert_one_line_error(case, proc.returncode, proc.stdout, proc.stderr)
    assert snapshot(folder) == before


def assert_one_line_error(case: Case, code: int, out: str, err: str) -> None:
    """Exit 2 and one line on stderr, `topside: error: ` and the fragments the case names."""
    assert code == 2, out + err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("topside: error: ")
    for fragment in case.names:
        assert fragment in lines[0], lines[0]


@pytest.mark.parametrize(("pairs", "does"), [(True, "marker 4 is tracked for cone A, as pairs says"),
                                             (False, "marker 4 is in no pair, so it gives no offset")])
def test_a_marker_on_a_cone_not_in_cones_is_warned_of(pairs: bool, does: str, installation: Path,
                                                      tmp_path: Path) -> None:
    """A marker whose cone is not in `cones` (and no pair's): track says what it did with it, in one warning line."""
    folder = tmp_path / "work"
    shutil.copytree(installation, folder)

    def change(rig: dict) -> None:
        rig["markers"][3]["cone"] = "B"  # marker 4, the port face's topside marker
        if not pairs:
            del rig["pairs"]

    edit_rig(change)(folder)
    proc = subprocess.run([*TOPSIDE, "track", "--rig", "bad-rig.yaml", "--workers", "1"], cwd=folder,
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stderr
    warned = [line for line in proc.stderr.splitlines() if "markers[3].cone" in line]
    assert warned == [f"topside: warning: bad-rig.yaml: markers[3].cone: B is not in cones, and no pair is on it; "
                      f"{does}"], proc.stderr


# --- what a crew reads without a terminal (a log on the vessel, nohup, a pipe) ---------------------------------------

PROGRESS_LINE = re.compile(r"^(\d{4}-\d\d-\d\d \d\d:\d\d:\d\d\.\d{3}) topside: (.+)$")
LONG_NAME = "drone_port_forward_upper_deck_camera_with_a_name_no_one_would_type"  # a table of it passes 80 columns


def piped(args: list[str], folder: Path, interval_s: float) -> tuple[int, str, list[tuple[float, str]]]:
    """A command with stdout and stderr pipes (no terminal, no COLUMNS) and progress every interval_s: its exit
    status, its stdout, and each stderr line with the wall time it arrived."""
    env = {k: v for k, v in os.environ.items() if k not in ("COLUMNS", "LINES")}
    env[PROGRESS_INTERVAL_ENV] = str(interval_s)
    proc = subprocess.Popen([*TOPSIDE, *args], cwd=folder, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=env)
    assert proc.stderr is not None and proc.stdout is not None
    lines = [(time.time(), line.rstrip("\n")) for line in proc.stderr]
    out = proc.stdout.read()
    return proc.wait(timeout=120), out, lines


def test_a_piped_track_prints_timestamped_progress_and_whole_tables(installation: Path, tmp_path: Path) -> None:
    """track with its output piped: a timestamped progress line at least every interval (10 s by default; 0.2 s
    here), the last saying it is done; its table not cut at 80 columns."""
    folder = tmp_path / "work"
    shutil.copytree(installation, folder)
    edit_rig(lambda rig: rig["cameras"][0].update(name=LONG_NAME), to="rig.yaml")(folder)
    interval = 0.2
    started = time.time()
    code, out, lines = piped(["track", "--rig", "rig.yaml", "--workers", "2"], folder, interval)
    assert code == 0, lines
    progress = [(arrived, PROGRESS_LINE.match(line)) for arrived, line in lines if PROGRESS_LINE.match(line)]
    assert len(progress) >= 3, lines
    stamps = [time.mktime(time.strptime(m[1][:19], "%Y-%m-%d %H:%M:%S")) + float(m[1][19:]) for _, m in progress]
    for (arrived, _), stamp in zip(progress, stamps, strict=True):
        assert abs(arrived - stamp) < 1.0  # the stamp is the time the line was written
    assert stamps[0] - started < 10.0  # the first within the default interval of the start (Python's start included)
    gaps = np.diff(stamps)
    assert gaps.min() >= 0 and gaps.max() < interval + 1.5, gaps  # every interval, give or take a loaded machine
    for _, m in progress[:-1]:
        assert re.fullmatch(r"finding the keyframes of 2 videos: \d+ s|tracking 2 cameras: \d+ of 24 frames "
                            r"\(\d+ %\), \d+ s", m[2]), m[2]
    assert re.fullmatch(r"tracking 2 cameras: 24 of 24 frames \(100 %\), done in \d+ s", progress[-1][1][2])
    assert LONG_NAME in out  # the whole name in the table, not 'drone_port_…'


@pytest.mark.parametrize("command", ["check", "sync"])
def test_piped_fieldwork_prints_progress_while_reading_footage(command: str, installation: Path,
                                                               tmp_path: Path) -> None:
    """check and sync with their output piped: progress lines counting the frames read, the last once done."""
    args = {"check": ["check", *RIG], "sync": ["sync", *RIG, "-o", "synced.yaml"]}[command]
    code, _, lines = piped(args, installation if command == "check" else _copy(installation, tmp_path), 0.05)
    assert code in (0, 1), lines
    progress = [m[2] for _, line in lines if (m := PROGRESS_LINE.match(line))]
    assert progress and re.fullmatch(r".*: 24 frames, done in \d+ s", progress[-1]), lines


def _copy(installation: Path, tmp_path: Path) -> Path:
    folder = tmp_path / "work"
    shutil.copytree(installation, folder)
    return folder


def test_help_is_whole_at_80_columns() -> None:
    """Every command's help at 80 columns: nothing cut ('…'), the board's syntax and topside[cluster] whole."""
    from typer.testing import CliRunner

    from tracking.cli import app

    runner = CliRunner()
    names = [c.name or c.callback.__name__.replace("_", "-") for c in app.registered_commands  # typer's names
             if c.callback is not None]
    assert len(names) >= 14
    for name in names:
        result = runner.invoke(app, [name, "--help"], env={"COLUMNS": "80", "TERMINAL_WIDTH": "80"})
        assert result.exit_code == 0, result.output
        assert "…" not in result.output, (name, result.output)
        assert max(len(line) for line in result.output.splitlines()) <= 80, (name, result.output)
    calibrate = runner.invoke(app, ["calibrate", "--help"], env={"COLUMNS": "80"}).output
    assert "chessboard:COLSxROWS:SQUARE" in calibrate and "charuco:COLSxROWS:SQUARE:MARKER:DICT" in calibrate
    assert "Needs topside[cluster]." in " ".join(runner.invoke(app, ["track", "--help"],
                                                              env={"COLUMNS": "80"}).output.split())


def test_version() -> None:
    """topside --version: one line, topside's installed version and what decides its numbers; exit 0."""
    from importlib.metadata import version

    proc = subprocess.run([*TOPSIDE, "--version"], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.count("\n") == 1 and not proc.stderr
    assert proc.stdout.startswith(f"topside {version('topside')} (Python {sys.version.split()[0]}, opencv ")


def test_calibrate_warns_of_a_photo_repeating_another(shared_data: Path, tmp_path: Path) -> None:
    """Three distinct views and a copy of one: calibrated, with one warning naming the copy and the photo it repeats."""
    left = shared_data / "calibration" / "opencv-left"
    photos = [left / f"left0{i}.jpg" for i in (1, 2, 3)]
    shutil.copy(photos[0], tmp_path / "again.jpg")
    proc = subprocess.run([*TOPSIDE, "calibrate", *map(str, photos), str(tmp_path / "again.jpg"), "--board",
                           "chessboard:9x6:0.025", "-o", str(tmp_path / "c.yaml")], capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert [line for line in proc.stderr.splitlines() if "warning" in line] == [
        "topside: warning: again.jpg: the board where left01.jpg has it (the same pose: the view adds nothing)"]
    assert (tmp_path / "c.yaml").is_file()


@pytest.mark.parametrize("scheme", ["ray://", ""], ids=["client", "gcs"])
def test_ray_at_a_port_that_is_no_ray_head_gives_up_in_one_line(scheme: str, installation: Path) -> None:
    """--ray at a port that accepts connections and never answers (Ray's GCS would retry for ever): one line once
    the connection timeout is over (2 s here, 60 s by default), nothing of Ray's retries on stderr, no output."""
    import socket
    import threading

    pytest.importorskip("ray")
    if scheme:
        pytest.importorskip("grpc")  # ray[client]
    with socket.socket() as server:
        server.bind(("127.0.0.1", 0))
        server.listen(8)
        held: list[socket.socket] = []
        threading.Thread(target=lambda: [held.append(server.accept()[0]) for _ in range(8)], daemon=True).start()
        address = f"{scheme}127.0.0.1:{server.getsockname()[1]}"
        env = os.environ | {RAY_CONNECT_TIMEOUT_ENV: "2"}
        started = time.monotonic()
        proc = subprocess.run([*TOPSIDE, "track", "--rig", str(installation / "rig.yaml"), "-o", "o.csv", "--ray",
                               address], cwd=installation.parent, capture_output=True, text=True, timeout=120,
                              env=env)
        took = time.monotonic() - started
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.splitlines() == [f"topside: error: --ray: {address} answers, and no Ray cluster connected "
                                        "within 2 s (expected a Ray cluster's head: ray://HOST:10001 for Ray's client, "
                                        "HOST:6379 for its GCS)"]
    assert took < 30  # Ray's client alone would wait 30 s, its GCS connection for ever
    assert not (installation.parent / "o.csv").exists()


CONES_LINE = re.compile(r"cones: A (GREEN|AMBER|RED) (\d+)±(\d+) mm \(Δx ([+-]\d+) Δy ([+-]\d+) Δz ([+-]\d+)\)")


def test_live_prints_the_cones_in_a_log(installation: Path, tmp_path: Path) -> None:
    """live with its output piped: the cones' line, timestamped, every progress interval (0.2 s here): NO DATA and
    why before the first measurement, then the offsets in mm (the truth: Δz 400 mm throughout)."""
    code, out, lines = piped(["live", *RIG, "--rrd", str(tmp_path / "l.rrd"), "--speed", "0.25"], installation, 0.2)
    assert code == 0, lines
    cones = [m[2] for _, line in lines if (m := PROGRESS_LINE.match(line)) and m[2].startswith("cones: ")]
    assert cones and cones[0] == "cones: A NO DATA (no measurement yet)", lines
    shown = [m for line in cones if (m := CONES_LINE.fullmatch(line))]
    assert len(shown) >= 2, cones
    for m in shown:
        assert abs(int(m[6]) - 400) <= 10 and int(m[3]) < 50
        assert abs(np.hypot(int(m[4]), int(m[5])) - int(m[2])) <= 1.5  # the distance from the target is Δx, Δy's
    assert "wrote 24 rows" in out


def test_a_live_web_replay_keeps_serving_after_its_files_end(installation: Path, tmp_path: Path) -> None:
    """live --web replaying files: when they end, the recording and CSV are final, one line says the viewer keeps
    serving, and it does until SIGTERM (or Ctrl-C), which ends the command with status 0 and the viewer."""
    import socket
    import urllib.request

    def free_port() -> int:
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            return s.getsockname()[1]

    web_port, grpc_port = free_port(), free_port()
    proc = subprocess.Popen([*TOPSIDE, "live", *RIG, "--rrd", str(tmp_path / "l.rrd"), "--speed", "inf", "--web",
                             "--web-port", str(web_port), "--grpc-port", str(grpc_port)], cwd=installation,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert proc.stderr is not None
    try:
        line = ""
        while proc.poll() is None and not line.startswith("the replay has ended"):
            line = proc.stderr.readline()
        assert line.startswith("the replay has ended; the web viewer keeps serving at "
                               f"http://127.0.0.1:{web_port}/") and line.endswith(" until Ctrl-C\n"), line
        assert (tmp_path / "l-offsets.csv").read_text().count("\n") == 25  # final, under its name
        time.sleep(1.0)
        assert proc.poll() is None
        assert b"<html" in urllib.request.urlopen(f"http://127.0.0.1:{web_port}/", timeout=10).read()
    finally:
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=60)
    assert proc.returncode == 0, err
    assert out.count("wrote 24 rows") == 1 and "stopped" not in err
    with pytest.raises(OSError):
        urllib.request.urlopen(f"http://127.0.0.1:{web_port}/", timeout=5)


@pytest.mark.parametrize("inverted", [False, True], ids=["black-on-white", "white-on-black"])
def test_marker_sheets_print_at_scale_and_read_back(inverted: bool, installation: Path, tmp_path: Path) -> None:
    """markers --format png at 200 dpi of a rig with 0.1 m markers: a sheet per marker whose square OpenCV reads as
    that marker, 0.1 m / 25.4 mm × 200 px wide, in a quiet zone, the DPI in the file; the rig untouched."""
    import cv2
    from PIL import Image

    from tracking.cli.options import SheetFormat
    from tracking.detection import MarkerDetector
    from tracking.marker_sheets import FORMATS

    assert tuple(f.value for f in SheetFormat) == FORMATS
    folder = tmp_path / "work"
    shutil.copytree(installation, folder)
    edit_rig(lambda rig: rig.update(marker_size=0.1, inverted=inverted), to="small.yaml")(folder)
    before = (folder / "small.yaml").read_bytes()
    proc = subprocess.run([*TOPSIDE, "markers", "--rig", "small.yaml", "-o", "sheets", "--format", "png", "--dpi",
                           "200"], cwd=folder, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert (folder / "small.yaml").read_bytes() == before
    sheets = sorted((folder / "sheets").iterdir())
    assert [p.name for p in sheets] == ["marker-1-jacket-A-ahead.png", "marker-2-topside-A-ahead.png",
                                        "marker-3-jacket-A-port.png", "marker-4-topside-A-port.png"]
    detector = MarkerDetector("DICT_6X6_250", inverted=inverted)
    side_px = 0.1 / 0.0254 * 200
    for path, marker_id in zip(sheets, (1, 2, 3, 4), strict=True):
        assert Image.open(path).info["dpi"] == pytest.approx((200, 200), abs=0.01)
        gray = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
        assert gray.shape[1] == pytest.approx(1.5 * side_px, abs=1)  # the square and a quiet zone of 2 cells in 8
        [found] = detector.detect(gray).markers
        assert found.id == marker_id
        sides = np.linalg.norm(np.roll(found.corners, -1, axis=0) - found.corners, axis=1)
        assert np.allclose(sides, side_px, atol=2.0), sides  # at print scale, to 2 px of 787
        assert found.corners[0][1] < found.corners[3][1]  # the marker's top at the page's top
        paper = 0 if inverted else 255
        assert np.all(gray[:int(0.2 * side_px)] == paper)  # the quiet zone above the square
    assert "wrote 4 sheets to sheets" in proc.stdout


def test_marker_sheets_as_pdf_pages_of_print_size(installation: Path, tmp_path: Path) -> None:
    """markers (PDF): a page per marker exactly the square (1 m) and its quiet zone wide, in points."""
    proc = subprocess.run([*TOPSIDE, "markers", *RIG, "-o", str(tmp_path)], cwd=installation, capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    pages = sorted(tmp_path.glob("marker-*.pdf"))
    assert len(pages) == 4
    for page in pages:
        box = re.search(rb"/MediaBox \[\s*0 0 ([0-9.]+) ([0-9.]+)\s*\]", page.read_bytes())
        assert box is not None
        assert float(box[1]) == pytest.approx(1.5 / 0.0254 * 72, abs=0.5)  # 1.5 m: 1 m and two 0.25 m zones
        assert float(box[2]) == pytest.approx(1.66 / 0.0254 * 72, abs=0.5)  # and the 0.16 m label band


def test_detect_reads_a_stream_url(installation: Path, tmp_path: Path) -> None:
    """detect http://…/cam.ts --frames 3: a camera tried before the rig exists, through a stream URL (an MPEG-TS copy
    of cam-ahead's video served over HTTP here): its markers every frame, on the wall clock, then it stops."""
    with serving(mpegts_copy(installation / "cam-ahead.mp4", tmp_path / "cam.ts").parent) as url:
        started = time.time()
        proc = subprocess.run([*TOPSIDE, "detect", f"{url}/cam.ts", "--frames", "3", "--json"], capture_output=True,
                              text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    frames = [json.loads(line) for line in proc.stdout.splitlines()]
    assert [f["frame"] for f in frames] == [0, 1, 2]
    assert all(sorted(m["id"] for m in f["markers"]) == [1, 2] for f in frames)
    assert all(started <= f["time"] <= time.time() + 1 for f in frames)  # stamped on the wall clock as they came


def test_sync_keeps_the_rigs_comments(installation: Path, tmp_path: Path) -> None:
    """sync writes the rig it read with its comments and layout: only the measured clock changes."""
    folder = _copy(installation, tmp_path)
    text = "# surveyed 2026-05-01, report S-114\n" + (folder / "rig.yaml").read_text().replace(
        "marker_size: 1.0", "marker_size: 1.0  # the black square")
    (folder / "rig.yaml").write_text(text)
    proc = subprocess.run([*TOPSIDE, "sync", *RIG, "-o", "synced.yaml"], cwd=folder, capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode in (0, 1), proc.stderr
    synced = (folder / "synced.yaml").read_text()
    import difflib

    changed = [line for line in difflib.ndiff(text.splitlines(), synced.splitlines()) if line[:2] in ("- ", "+ ")]
    assert changed and all(line[2:].strip().startswith("time_offset") for line in changed), changed
    assert synced.startswith("# surveyed 2026-05-01, report S-114\n")
    assert "marker_size: 1.0  # the black square" in synced
