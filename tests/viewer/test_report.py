"""`topside report` on real recordings and archives of the small installation: the recording's report and the
archive's agree; a camera dropout and a withheld period show; an interrupted or damaged archive says so; the page
opens in headless Chromium with every network request refused."""

from __future__ import annotations

import shutil
import subprocess
import sys
from fractions import Fraction
from pathlib import Path

import av
import numpy as np
import pytest

from tests.browser import chromium, open_offline
from tests.conftest import REPO, Archived
from tests.viewer import archive_writer
from tracking.installation_report import CameraSpan, Summary, Verdict, summarise
from viewer.installation_record import InstallationRecord, read_record
from viewer.report import render

TOPSIDE = [sys.executable, "-m", "tracking.cli"]
STRETCH = 4  # the dropout clip's time runs this much slower than the rendered one (its frames 0.27 s apart)
DROPPED = range(3, 9)  # cam-port's frames left out of the dropout clip: 1.9 s of silence


def weasyprint_works() -> bool:
    """Whether `report --pdf` can lay out a PDF here (the pdf extra and its Pango library)."""
    try:
        import weasyprint  # noqa: F401
    except (ImportError, OSError):
        return False
    return True


def summary_of(record: InstallationRecord) -> Summary:
    return summarise(record.estimates, record.frames, *record.span, record.cones, record.cameras, record.stated)


def comparable(s: Summary) -> tuple:
    """What two reports of one run must share: verdicts, moments, NO DATA, camera spans, events (to 1 ms)."""
    def r(v: float) -> float:
        return round(v, 3)

    cones = [(c.cone, c.verdict, c.landed and r(c.landed.time), c.closest and (r(c.closest.time),
              r(c.closest.concentricity)), [(r(p.start), r(p.end), p.what) for p in c.no_data], c.estimates)
             for c in s.cones]
    cameras = {n: [(r(p.start), r(p.end), p.what) for p in spans] for n, spans in s.cameras.items()}
    return cones, cameras, [(r(e.time), e.subject, e.what) for e in s.events], r(s.start), r(s.end)


def test_the_recording_and_its_archive_give_the_same_report(archived: Archived, tmp_path: Path) -> None:
    rrd, mcap = read_record(archived.rrd), read_record(archived.mcap)
    assert comparable(summary_of(rrd)) == comparable(summary_of(mcap))
    np.testing.assert_allclose(rrd.estimates[["dx", "dy", "dz", "sdx", "sdy", "sdz"]].to_numpy(float),
                               mcap.estimates[["dx", "dy", "dz", "sdx", "sdy", "sdz"]].to_numpy(float), atol=1e-9)
    assert rrd.provenance.configuration_sha256 == mcap.provenance.configuration_sha256
    assert rrd.provenance.files == mcap.provenance.files
    assert (mcap.integrity.state, mcap.integrity.signature) == ("whole", "absent")
    summary = summary_of(rrd)
    (cone,) = summary.cones
    assert cone.verdict == Verdict.NOT_LANDED  # the clip hovers 0.4 m above cone A
    assert cone.closest is not None and 0.2 < cone.closest.concentricity < 0.5  # the ramp passes ~0.27 m off, in
    # the frames before cam-ahead (its lone marker seldom settled by IPPE) is compared, and 0.45 m at the first shown
    assert [p.what for p in cone.no_data] == ["σ too large", "warming up", "cameras not yet compared"]  # before
    # the second camera, then under the warm-up's limit, then before the two are compared
    out, pdf = tmp_path / "report.html", tmp_path / "report.pdf"
    proc = subprocess.run([*TOPSIDE, "report", str(archived.mcap), "-o", str(out), "--pdf", str(pdf)],
                          capture_output=True, text=True, timeout=120, cwd=REPO)
    if weasyprint_works():
        assert proc.returncode == 0, proc.stderr
        assert pdf.read_bytes().startswith(b"%PDF") and pdf.stat().st_size > 50_000  # the page and its plots
    else:  # the pdf extra or its Pango library missing: one line naming --pdf, nothing written
        assert proc.returncode == 2 and "--pdf" in proc.stderr and not out.exists()
        proc = subprocess.run([*TOPSIDE, "report", str(archived.mcap), "-o", str(out)], capture_output=True,
                              text=True, timeout=120, cwd=REPO)
        assert proc.returncode == 0, proc.stderr
    assert "cone A: not landed" in proc.stdout
    page = out.read_text()
    assert "Sleipnir" in page and mcap.provenance.configuration_sha256 in page
    assert "http://" not in page and "https://" not in page and "src=\"data:image/png;base64," in page


def restamp(source: Path, out: Path, keep: callable) -> None:
    """A copy of an H.264 clip with its time STRETCH times slower, the frames keep(k) is false for left out."""
    with av.open(str(source)) as src, av.open(str(out), "w") as dst:
        stream = dst.add_stream("libx264", rate=30)
        stream.width, stream.height = src.streams.video[0].width, src.streams.video[0].height
        stream.pix_fmt = "yuv420p"
        stream.options = {"crf": "12", "preset": "ultrafast"}
        stream.codec_context.time_base = Fraction(1, 1000)
        for k, frame in enumerate(src.decode(video=0)):
            if keep(k):
                new = av.VideoFrame.from_ndarray(frame.to_ndarray(format="bgr24"), format="bgr24")
                new.pts = round(float(frame.time) * 1000 * STRETCH)
                new.time_base = stream.codec_context.time_base
                dst.mux(stream.encode(new))
        dst.mux(stream.encode(None))


@pytest.fixture(scope="module")
def dropout(installation: Path, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """The installation four times slower, cam-port silent for 1.9 s in the middle: tracked to .rrd and .mcap."""
    folder = tmp_path_factory.mktemp("dropout")
    shutil.copytree(installation / "calibration", folder / "calibration")
    shutil.copy(installation / "rig.yaml", folder / "rig.yaml")
    restamp(installation / "cam-ahead.mp4", folder / "cam-ahead.mp4", lambda k: True)
    restamp(installation / "cam-port.mp4", folder / "cam-port.mp4", lambda k: k not in DROPPED)
    proc = subprocess.run([*TOPSIDE, "track", "--rig", str(folder / "rig.yaml"), "-o", str(folder / "offsets.csv"),
                           "--rrd", str(folder / "run.rrd"), "--mcap", str(folder / "run.mcap")],
                          capture_output=True, text=True, timeout=120, cwd=REPO)
    assert proc.returncode == 0, proc.stderr
    return folder / "run.rrd", folder / "run.mcap"


def test_a_camera_dropout_and_a_withheld_period_show(dropout: tuple[Path, Path]) -> None:
    rrd, mcap = (read_record(p) for p in dropout)
    summary = summary_of(rrd)
    assert comparable(summary) == comparable(summary_of(mcap))
    port = summary.cameras["cam-port"]
    lost = [p for p in port if p.what == CameraSpan.LOST]
    assert len(lost) == 1
    assert lost[0].duration == pytest.approx(STRETCH * (len(DROPPED) + 1) / 15, abs=0.02)
    assert all(p.what == CameraSpan.LIVE for p in summary.cameras["cam-ahead"])
    (cone,) = summary.cones
    withheld = [p for p in cone.no_data if p.what == "σ too large"]
    assert withheld and withheld[0].start == pytest.approx(summary.start)
    page = render(rrd, summary)
    assert "lost" in page and "σ too large" in page
    events = [e for e in summary.events if e.subject == "cam-port"]
    assert events and events[0].time == pytest.approx(lost[0].start)
    assert f"topside view run.rrd --from {max(summary.start, lost[0].start - 2):.2f}" in page


def test_an_interrupted_archive_says_so(installation: Path, tmp_path: Path) -> None:
    out = tmp_path / "stopped.mcap"
    archive_writer.main(installation / "rig.yaml", out, 2.0, False, None, "stopped by the operator (Ctrl-C)")
    record = read_record(out)
    assert record.integrity.state == "interrupted"
    assert any("stopped by the operator" in line for line in record.integrity.lines)
    page = render(record)
    assert "This record is interrupted" in page and "does not hold the whole installation" in page


def test_a_damaged_archive_reports_what_is_left(dropout: tuple[Path, Path], tmp_path: Path) -> None:
    cut = tmp_path / "cut.mcap"
    data = dropout[1].read_bytes()  # 3 s: a chunk a second
    cut.write_bytes(data[:len(data) * 2 // 3])
    record = read_record(cut)
    assert record.integrity.state == "damaged"
    assert any("truncated" in line for line in record.integrity.lines)
    whole = read_record(dropout[1])
    assert 0 < len(record.estimates) < len(whole.estimates)  # the intact chunks' estimates, not the lost ones
    assert "This record is damaged" in render(record)


@pytest.mark.skipif(chromium() is None, reason="no chromium (apt-get install chromium)")
def test_the_report_opens_offline_in_chromium(dropout: tuple[Path, Path], tmp_path: Path) -> None:
    html = tmp_path / "report.html"
    html.write_text(render(read_record(dropout[1])))
    page = open_offline(html, tmp_path / "report.png")
    assert page.requests == []  # nothing asked of the network
    assert "Verdict per cone" in page.text and "not landed" in page.text and "lost" in page.text
    h, w, _ = page.image.shape
    assert w >= 1000 and h > 1500  # the whole page: verdicts, plots, cameras, events, provenance
    assert page.image.std() > 30  # drawn, not blank
    def pixels(rgb: tuple[int, int, int]) -> int:
        return int(np.all(np.abs(page.image.astype(int) - rgb) < 30, axis=2).sum())

    assert pixels((31, 95, 191)) > 40  # the concentricity line (its parts before and after the dropout)
    assert pixels((230, 40, 40)) > 2000  # the tolerance line, the lost camera's bar


def test_a_live_recording_names_a_cameras_silence_as_the_tracker_stated_it(installation: Path, tmp_path: Path
                                                                           ) -> None:
    """A live session's recording keeps what the live tracker said of a camera (health/<camera>/state); the report
    names the silence it falls in by it: cam-port frozen, cam-ahead (which said nothing) lost."""
    from dataclasses import replace

    import rerun as rr

    from tracking.live import LiveUpdate
    from tracking.pipeline import track_rig
    from tracking.rig import load_rig
    from tracking.sources import CameraState, SourceEvent
    from viewer.session import Recorder

    rr.set_strict_mode(True)
    rig = load_rig(installation / "rig.yaml")
    results = [r for _, r in zip(range(24), track_rig(rig, packets=True), strict=False)]
    before, after = results[:12], [replace(r, frame=replace(r.frame, time=r.time + 2.0)) for r in results[12:]]
    recorder = Recorder(rig, tmp_path / "live.rrd", layout="superintendent")
    recorder.on_update(LiveUpdate(now=before[-1].time, results=before))
    frozen = SourceEvent("cam-port", CameraState.FROZEN, 0.0, "the image does not change")
    recorder.on_update(LiveUpdate(now=before[-1].time + 0.3, events=[frozen]))
    recorder.on_update(LiveUpdate(now=after[-1].time, results=after))
    recorder.close()
    record = read_record(tmp_path / "live.rrd")
    assert list(record.stated[["camera", "state", "detail"]].itertuples(index=False, name=None)) == [
        ("cam-port", "frozen", "the image does not change")]
    spans = summary_of(record).cameras
    assert [p.what for p in spans["cam-port"]] == [CameraSpan.LIVE, CameraSpan.FROZEN, CameraSpan.LIVE]
    assert [p.what for p in spans["cam-ahead"]] == [CameraSpan.LIVE, CameraSpan.LOST, CameraSpan.LIVE]
    assert spans["cam-port"][1].detail == "the image does not change"
