"""A recording session: the tracker's stream of results in, a Rerun recording out (file, live viewer, or both)."""

from __future__ import annotations

import csv
import io
import os
import subprocess
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import rerun as rr
import rerun.blueprint as rrb

from tracking.camera import CameraModel, load_camera
from tracking.errors import InputError
from tracking.estimate import ConeEstimate
from tracking.estimator import cone_points
from tracking.evaluate import truth_at
from tracking.images import Frame
from tracking.live import STALE_S, LiveUpdate
from tracking.outputs import partial_path, write_text
from tracking.pipeline import FrameResult, Sink
from tracking.rig import Rig
from viewer.archive import ArchiveInputs
from viewer.blueprint import LayoutSender, analysis_blueprint
from viewer.feed import ViewerFeed
from viewer.installation import log_concentricity, log_installation, log_true_topside, true_topside_poses
from viewer.playback import rerun_binary, rerun_env
from viewer.recording import (
    APP_ID,
    FILTER_CAMERAS,
    JPEG_QUALITY,
    StatusBoard,
    log_archive_inputs,
    log_camera_poses,
    log_camera_state,
    log_estimate_records,
    log_estimates,
    log_frame,
    log_frame_ages,
    log_frame_image,
    log_frustum,
    log_health,
    log_image,
    log_plot_key,
    log_rig,
    log_series_styles,
    log_topside_poses,
    log_true_cameras,
    log_truth,
    log_video_codec,
    set_capture_time,
    topside_pose,
    view_camera,
)
from viewer.superintendent import (
    ConeReading,
    cone_reading,
    log_camera_health,
    log_cone_reading,
    log_target_circle,
    marked_cones,
    superintendent_blueprint,
)

BATCH_TICK_S = 0.5  # rows are gathered into chunks this long: a chunk's schema costs ~2.5 kB, a frame's rows less
BATCH_BYTES = 8 << 20
FLUSH_S = 0.5  # estimates are sent in columns covering this much capture time (one call per series)
AGES_PERIOD_S = 0.2  # camera frame ages are logged this often
BOARD_PERIOD_S = 0.2  # the superintendent's figures refresh this often (capture time)
BLUEPRINT_MIN_PERIOD_S = 30.0  # a changed camera-per-cone choice re-sends the live layout at most this often
BACKLOG_PERIOD_S = 2.0  # every this much capture time the logger waits for its file (memory stays bounded)
BACKLOG_TIMEOUT_S = 0.5  # ... but at most this long: a slow disk must not stall the live loop
CLOSE_TIMEOUT_S = 10.0  # at the end, a live viewer is offered what is left for this long at most
BACKLOG_MAX_PERIOD_S = 60.0  # after timeouts the period doubles up to this (a slow disk costs < 1 % of the time)
VIEWER_SCOPES = ("superintendent", "all")  # what a live viewer of the superintendent's layout is sent
VIEW_IMAGE_RATE_HZ = 2.0  # live: the superintendent's scope sends each shown camera's picture this often, as a JPEG
VIEW_IMAGE_WIDTH_PX = 640  # ... at most this wide: a 920x600 stream of 2.6 Mbit/s becomes 0.3 Mbit/s (20 kB a picture)
# that a tablet on the vessel's Wi-Fi keeps up with; the figures keep their own rate, the recording every frame
VIEW_PICTURE_BYTES = 25_000  # a VIEW_IMAGE_WIDTH_PX wide JPEG of a marker scene at JPEG_QUALITY, with margin
# (the demo's 920x600 drone_A: 20 kB measured)


def view_bytes_per_s(video_bytes_per_s: float, rate: float, width: int) -> float:
    """A camera's bytes a second in the viewer's own stream: its pictures at rate (Hz) and width (px), else
    (rate 0) its video."""
    scaled = rate * VIEW_PICTURE_BYTES * (width / VIEW_IMAGE_WIDTH_PX) ** 2  # a picture's bytes go with its area
    return video_bytes_per_s if rate <= 0 else min(video_bytes_per_s, scaled)


class Compactor:
    """Rewrites finished recording files with `rerun rrd optimize` in the background (chunks merged: ~25 % smaller).

    The source stays until the compacted copy is complete and renamed onto its final name, so a failure or a kill
    loses nothing; if compaction fails, the source itself is renamed onto the final name.
    """

    def __init__(self) -> None:
        self.running: list[tuple[subprocess.Popen, Path, Path, Path]] = []

    def start(self, source: Path, layout: Path | None = None, final: Path | None = None) -> None:
        """Compact one closed file into final (default: in place); with a layout (.rbl), that blueprint is merged in."""
        final = source if final is None else final
        if not source.is_file():
            return
        tmp = partial_path(final)
        inputs = [str(layout)] if layout is not None and layout.is_file() else []
        proc = subprocess.Popen(["nice", "-n", "10", rerun_binary(), "rrd", "optimize", *inputs, str(source),
                                 "-o", str(tmp)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                env=rerun_env(), start_new_session=True)
        self.running.append((proc, source, tmp, final))

    def poll(self, wait: bool = False) -> None:
        """Rename the files whose compaction has finished (all of them, waiting, with wait=True)."""
        still = []
        for proc, source, tmp, final in self.running:
            code = proc.wait() if wait else proc.poll()
            if code is None:
                still.append((proc, source, tmp, final))
            elif code == 0 and tmp.is_file() and tmp.stat().st_size > 0:
                os.replace(tmp, final)
                if source != final:
                    source.unlink(missing_ok=True)
            else:
                tmp.unlink(missing_ok=True)
                if source != final:
                    os.replace(source, final)
        self.running = still

    def stop(self) -> None:
        """End the compactions still running (the tool is ending); their sources are renamed uncompacted."""
        for proc, *_ in self.running:
            if proc.poll() is None:
                proc.kill()
        self.poll(wait=True)


class Recorder:
    """Logs frames and estimates of one tracked installation into a Rerun recording.

    rrd: file to write; with segment_s, a new file <stem>-NNN.rrd every segment_s of capture time, listed in
    <stem>.segments.csv, with the layout in <stem>.rbl. viewer: the input of a live viewer to stream to as well,
    never waited for (viewer/feed.py: a viewer that cannot keep up is cut loose, the file goes on).
    viewer_scope: with the superintendent's layout, "superintendent" sends the viewer only what that layout shows
    (its figures, and the images of the cameras it shows) through a stream of its own, so a tablet keeps up and opens
    at once; "all" sends it everything the file gets. forward: more sinks (on_frame, on_estimate) that get every
    frame and estimate as they come, unthrottled (the live Foxglove stream, viewer/foxglove_live.py).
    view_image_rate, view_image_width: with the viewer's own stream, its pictures as JPEGs at most this often and this
    wide (a tablet's budget; 0: every frame as the file has it).
    """

    def __init__(self, rig: Rig, rrd: Path | None = None, truth: pd.DataFrame | None = None,
                 show_rejected: bool = False, recording_id: str | None = None,
                 jpeg_quality: int = JPEG_QUALITY, viewer: ViewerFeed | None = None, segment_s: float | None = None,
                 stale_s: float = STALE_S, layout: str = "analysis",
                 options: Mapping[str, str] | None = None, estimate_period_s: float = 0.0,
                 viewer_scope: str = "superintendent", forward: Sequence[Sink] = (), view_image_rate: float = 0.0,
                 view_image_width: int = VIEW_IMAGE_WIDTH_PX) -> None:
        self.rig = rig
        self.view_image_rate = view_image_rate  # Hz; 0: the viewer's own stream gets every frame as recorded
        self.view_image_width = view_image_width
        self._view_image_at: dict[str, float] = {}  # camera -> capture time of its last picture in the viewer's stream
        self.truth = truth
        self.show_rejected = show_rejected
        self.jpeg_quality = jpeg_quality
        self.stale_s = stale_s
        self.forward = list(forward)
        self.estimate_period_s = estimate_period_s  # live: a cone's estimates are recorded at most this often
        self._estimate_logged: dict[str, float] = {}
        self._inputs = ArchiveInputs.from_rig(rig, options or {}).to_json()  # for `topside export`
        self.layout = layout  # the file's stored blueprint: "analysis" (engineers) or "superintendent"
        self.rec = rr.RecordingStream(APP_ID, recording_id=recording_id, batcher_config=rr.ChunkBatcherConfig(
            flush_tick=BATCH_TICK_S, flush_num_bytes=BATCH_BYTES))
        self.cameras: dict[str, CameraModel] = {c.name: load_camera(rig.resolve(c.calibration)) for c in rig.cameras}
        self.marked = marked_cones(rig)  # cones with marker pairs
        self.cones = rig.all_cones()
        self._cone_points = cone_points(rig)  # where each cone's offset applies, as the filter has it
        self.status = StatusBoard()
        self._truth_cones = {c[len("cone_"):-len("_dx")] for c in truth.columns
                             if c.startswith("cone_") and c.endswith("_dx")} if truth is not None else set()
        self._last_time = 0.0
        self._last_capture: dict[str, float] = {}
        self._video: set[str] = set()  # cameras whose codec is declared
        self._gop: dict[str, list[Frame]] = {}  # packets since each camera's newest keyframe: a new segment, and
        # the viewer's own stream when it starts showing a camera, open with them
        self._viewer = viewer
        self._rrd = Path(rrd) if rrd is not None else None
        self._segment_s = segment_s
        self._segments: list[list] = []  # [file, first capture time, last capture time]
        self._compactor = Compactor()
        self._measured: Counter[tuple[str, str]] = Counter()  # (cone, camera) -> pair offsets
        self._cone_cameras: dict[str, str] = {}
        self._blueprint_sent = -np.inf
        self._layouts: list[LayoutSender] = []  # live: the superintendent's layout as cameras per cone change, one
        # sender per stream (each clears the layout its own stream had)
        self._board_logged = -np.inf
        self._last_update: LiveUpdate | None = None
        self._estimates: list[ConeEstimate] = []  # not yet sent
        self._ages_logged = -np.inf
        self._drained = -np.inf
        self._drain_period = BACKLOG_PERIOD_S
        self.backlog_timeouts = 0  # waits for the sinks that ran out of time
        self._layout: Path | None = None  # segmented: the stored blueprint, merged into each segment when compacted
        self._view: rr.RecordingStream | None = None  # the viewer's own stream (superintendent scope), else None
        self._tee: rr.BinaryStream | None = None  # "all" scope: the file's stream, encoded for the viewer too
        self._shown: set[str] = set()  # cameras whose images the viewer's own stream carries
        self._open_sinks(viewer_scope)

    def _open_sinks(self, viewer_scope: str) -> None:
        """The viewer's own stream (superintendent scope) with its target circles, or the file's stream encoded for
        the viewer too ("all"); and the first file. The file's sinks never include a viewer's connection."""
        if self._viewer is not None and self.layout == "superintendent" and viewer_scope == "superintendent":
            self._view = rr.RecordingStream(APP_ID, recording_id=self.rec.get_recording_id(),
                                            batcher_config=rr.ChunkBatcherConfig(flush_tick=BATCH_TICK_S,
                                                                                 flush_num_bytes=BATCH_BYTES))
            self._view.set_sinks(self._viewer.stream(self._view), default_blueprint=self._stored_blueprint())
            for cone in self.cones:
                log_target_circle(self._view, cone, cone in self.marked)
        elif self._viewer is not None:
            self._tee = self._viewer.stream(self.rec)
        if self._rrd is not None:
            self._rrd.parent.mkdir(parents=True, exist_ok=True)
            if self._segment_s:
                self._layout = self._rrd.with_name(f"{self._rrd.stem}.rbl")
                self._stored_blueprint().save(APP_ID, self._layout)
        self._open(self._writing_path(0) if self._segment_s else self._rrd)
        if self._viewer is not None:
            self._viewer.send_now(CLOSE_TIMEOUT_S)  # the layout and static data: the viewer's servers start on them

    def _stored_blueprint(self) -> rrb.Blueprint:
        """The layout a file opens with."""
        return (superintendent_blueprint(self.rig, self.cone_cameras()) if self.layout == "superintendent"
                else analysis_blueprint(self.rig, self.truth is not None))

    def _segment_path(self, index: int) -> Path | None:
        """Final file of the index-th segment."""
        return None if self._rrd is None else self._rrd.with_name(f"{self._rrd.stem}-{index:03d}.rrd")

    def _writing_path(self, index: int) -> Path | None:
        """The file the index-th segment is written to: a temporary name, renamed when the segment is closed."""
        final = self._segment_path(index)
        if final is None:
            return None
        if final.exists():
            raise InputError(final, "exists (an earlier session's recording; a recording is never overwritten): "
                                    "expected another --rrd name", "--rrd")
        return partial_path(final)

    def _open(self, path: Path | None) -> None:
        """Attach the sinks (a file and/or a viewer) and log everything static."""
        # A footer indexes every chunk, held in memory until the file closes (~5 kB a chunk, ~140 chunks/s live):
        # segments are written without one, and the compactor (`rerun rrd optimize`) adds it once closed.
        sinks: list = [rr.FileSink(path, write_footer=not self._segment_s)] if path is not None else []
        if self._tee is not None and self._viewer is not None and self._viewer.alive:
            sinks.append(self._tee)  # in memory, never waiting: viewer/feed.py sends it as the viewer takes it
        if sinks:
            # rerun-sdk 0.41 never frees the stream a blueprint is built in (~0.7-2.4 MB each): over six hours of
            # 1-minute segments that is the main process's whole growth. Only the first segment gets it here; the
            # others get the saved layout (.rbl) when compacted, and a live viewer keeps the one it has.
            first = not self._segments
            self.rec.set_sinks(*sinks, default_blueprint=self._stored_blueprint() if first else None)
        if path is not None:
            self._segments.append([path.name, None, None])
        log_rig(self.rec, self.rig)
        log_installation(self.rec, self.rig)
        log_archive_inputs(self.rec, self._inputs)
        for name, cam in self.cameras.items():
            log_frustum(self.rec, f"world/cameras/{name}", cam)  # where its frames' images and marker poses go
        self._filter_frusta: set[str] = set()  # drawn with a camera's first filtered pose (none in the paper's mode)
        for name in self._video:
            log_video_codec(self.rec, name)
        log_series_styles(self.rec, self.cones, self.truth is not None, self.cameras)
        log_plot_key(self.rec, self.cones, self.cameras, self.truth is not None)
        for cone in self.cones:
            log_target_circle(self.rec, cone, cone in self.marked)
        if self.truth is not None and len(self._segments) <= 1:
            log_truth(self.rec, self.truth, self.cones)
            log_true_cameras(self.rec, self.truth, self.cameras)
            log_true_topside(self.rec, self.rig, *true_topside_poses(self.truth, self._cone_points))

    def _rotate_if_due(self, t: float) -> None:
        """Start the next segment file when this one spans segment_s; it opens with every camera's current GOP."""
        if not self._segment_s or not self._segments:
            return
        seg = self._segments[-1]
        if seg[1] is None or t - seg[1] < self._segment_s:
            return
        self.flush_estimates()
        index = len(self._segments) - 1
        closed = self._rrd.with_name(self._segments[index][0]) if self._rrd is not None else None
        self._open(self._writing_path(len(self._segments)))
        if closed is not None:
            final = self._segment_path(index)
            self._compactor.start(closed, self._layout if len(self._segments) > 2 else None, final)
            self._segments[index][0] = final.name  # the index names it as it will be once renamed
        if self._last_update is not None:  # every segment opens with the superintendent's figures
            self._log_board(self._last_update)
        for camera, frames in self._gop.items():  # the frames a decoder needs before the next keyframe
            for frame in frames:
                set_capture_time(self.rec, frame.time)
                rr.set_time(f"frame_{camera}", sequence=frame.index, recording=self.rec)
                log_image(self.rec, f"world/cameras/{camera}/image", frame, self.jpeg_quality)
        self._write_index()

    def _write_index(self) -> None:
        """<stem>.segments.csv: every segment's file and capture-time span."""
        if self._rrd is None or not self._segment_s:
            return
        text = io.StringIO()
        w = csv.writer(text)
        w.writerow(["file", "start", "end"])
        w.writerows(self._segments)
        write_text(self._rrd.with_name(f"{self._rrd.stem}.segments.csv"), text.getvalue())

    def _note_time(self, t: float) -> None:
        """Extend the current segment's span."""
        if self._segments:
            seg = self._segments[-1]
            seg[1] = t if seg[1] is None else min(seg[1], t)
            seg[2] = t if seg[2] is None else max(seg[2], t)

    def on_frame(self, result: FrameResult) -> None:
        """Log one processed frame."""
        for sink in self.forward:
            sink.on_frame(result)
        self._rotate_if_due(result.time)
        self._note_time(result.time)
        if result.frame.packet is not None and result.camera not in self._video:
            log_video_codec(self.rec, result.camera)
            self._video.add(result.camera)
        if result.frame.packet is not None and (self._segment_s or self._view is not None):
            gop = self._gop.setdefault(result.camera, [])
            if result.frame.keyframe:
                gop.clear()
            gop.append(replace(result.frame, gray=None, bgr=None))  # the packet is all a segment needs
        log_frame(self.rec, self.rig, self.cameras[result.camera], result, self.show_rejected, self.jpeg_quality)
        if self._view is not None and result.camera in self._shown:
            self._view_frame(result)
        self.status.frames[result.camera] = self.status.frames.get(result.camera, 0) + 1
        self.status.markers[result.camera] = self.status.markers.get(result.camera, 0) + len(result.poses)
        self._last_time = max(self._last_time, result.time)
        self._last_capture[result.camera] = result.time
        if result.time - self._ages_logged >= AGES_PERIOD_S:
            log_frame_ages(self.rec, result.time, self._last_capture)
            self._ages_logged = result.time
        if result.tracked:
            log_health(self.rec, result)
        for m in result.offsets:
            self._measured[(m.cone, m.camera)] += 1
        if result.time - self._drained >= self._drain_period:
            self._drain()
            self._drained = result.time

    def _drain(self) -> None:
        """Wait (bounded) until the file has taken what was logged: faster than real time, or with the CPU
        saturated, rerun's writer otherwise falls behind and its queue grows by the whole segment. A file that
        keeps timing out (a slow disk) is waited for ever more rarely, so it cannot slow the tracking."""
        try:
            self.rec.flush(timeout_sec=BACKLOG_TIMEOUT_S)  # the viewer's stream is never waited for (viewer/feed.py)
            self._drain_period = BACKLOG_PERIOD_S
        except RuntimeError:  # "Flush timed out": the data stays queued and goes out with the next one
            self.backlog_timeouts += 1
            self._drain_period = min(2 * self._drain_period, BACKLOG_MAX_PERIOD_S)

    def on_estimate(self, estimate: ConeEstimate) -> None:
        """Take one cone estimate: sent with the others of its FLUSH_S; the status panel when due."""
        for sink in self.forward:
            sink.on_estimate(estimate)
        if estimate.time - self._estimate_logged.get(estimate.cone, -np.inf) >= self.estimate_period_s:
            self._estimate_logged[estimate.cone] = estimate.time
            self._estimates.append(estimate)
            if estimate.time - self._estimates[0].time >= FLUSH_S:
                self.flush_estimates()
        self.status.latest[estimate.cone] = estimate
        self.status.log_if_due(self.rec, estimate.time)

    def flush_estimates(self) -> None:
        """Send the buffered estimates: offsets, σ, errors against the truth, and the topside's translation."""
        batch, self._estimates = self._estimates, []
        if not batch:
            return
        truth = None
        if self.truth is not None:
            truth = np.full((len(batch), 3), np.nan)
            for cone in self._truth_cones & {e.cone for e in batch}:
                rows = [i for i, e in enumerate(batch) if e.cone == cone]
                truth[rows] = truth_at(self.truth, cone, np.array([batch[i].time for i in rows]))
        log_estimates(self.rec, batch, truth)
        log_estimate_records(self.rec, batch)
        log_concentricity(self.rec, self._cone_points, batch)
        full: dict[float, dict[str, np.ndarray]] = {}
        for e in batch:
            if np.all(np.isfinite(e.offset)):
                full.setdefault(e.time, {})[e.cone] = e.offset
        log_topside_poses(self.rec, np.array(list(full)),
                          np.array([topside_pose(self._cone_points, v) for v in full.values()]).reshape(-1, 4, 4))
        poses: dict[str, dict[float, np.ndarray]] = {}  # the estimator's camera poses, once per time
        for e in batch:
            for name, T in (e.T_jacket_cameras or {}).items():
                poses.setdefault(name, {})[e.time] = T
        for name, by_time in poses.items():
            if name not in self._filter_frusta:
                log_frustum(self.rec, f"{FILTER_CAMERAS}/{name}", self.cameras[name])
                self._filter_frusta.add(name)
            log_camera_poses(self.rec, f"{FILTER_CAMERAS}/{name}", np.array(list(by_time)),
                             np.array(list(by_time.values())))

    def on_update(self, update: LiveUpdate) -> None:
        """Log a live update: its frames and estimates in capture-time order (each frame before the estimates it
        gave, so both land in the segment that spans their time), then the superintendent's figures."""
        for item in update.in_capture_order():
            if isinstance(item, ConeEstimate):
                self.on_estimate(item)
            else:
                self.on_frame(item)
        for event in update.events:  # on the live clock: a lost camera's silence is named in the recording
            if update.now > 0:
                log_camera_state(self.rec, update.now, event.camera, str(event.state), event.detail)
        self._last_update = update
        self._compactor.poll()
        if update.now - self._board_logged >= BOARD_PERIOD_S:
            self._log_board(update)
        self._feed_viewer(update.now)

    def readings(self) -> list[ConeReading]:
        """Every cone's reading at the newest update's live time, as the recording's superintendent view has it (none
        before the first update)."""
        update = self._last_update
        if update is None:
            return []
        return [cone_reading(self.status.latest.get(cone), cone, update.now, update.last_measurement, self.stale_s)
                for cone in self.cones]

    def _feed_viewer(self, now: float) -> None:
        """Send the live viewer what it takes now, without waiting; once it is cut loose, nothing more is logged
        for it (its own stream dropped; the file's stream loses its copy for it at the next segment)."""
        if self._viewer is None:
            return
        self._viewer.pump(now)
        if not self._viewer.alive and self._view is not None:
            self._view = None
            self._layouts = self._layouts[:1]  # the file's layout sender only

    def _log_board(self, update: LiveUpdate) -> None:
        """Every cone's reading and the camera table at the update's live time; the estimates waiting FLUSH_S."""
        if self._estimates and update.now - self._estimates[0].time >= FLUSH_S:  # a series per call: fewer chunks
            self.flush_estimates()
        self._board_logged = update.now
        behind = self._viewer.behind(update.now) if self._viewer is not None else 0.0
        for cone in self.cones:
            args = (self.status.latest.get(cone), cone, update.now, update.last_measurement, self.stale_s)
            log_cone_reading(self.rec, cone_reading(*args), update.now, self.stale_s)
            if self._view is not None:  # the viewer's own stream: grey while its input is behind (the file: not)
                log_cone_reading(self._view, cone_reading(*args, behind=behind), update.now, self.stale_s)
        for stream in self._streams():
            log_camera_health(stream, update.cameras, update.now)
        self._send_layout_if_changed(update.now)

    def _streams(self) -> list[rr.RecordingStream]:
        """The file's stream, and the viewer's own when it has one."""
        return [self.rec] if self._view is None else [self.rec, self._view]

    def _view_frame(self, result: FrameResult) -> None:
        """A shown camera's frame into the viewer's own stream: every one, or a scaled JPEG at view_image_rate."""
        camera = self.cameras[result.camera]
        if self.view_image_rate <= 0:
            log_frame_image(self._view, self.rig, camera, result, jpeg_quality=self.jpeg_quality)
        elif result.time - self._view_image_at.get(result.camera, -np.inf) >= 1.0 / self.view_image_rate:
            log_frame_image(self._view, self.rig, camera, result, jpeg_quality=self.jpeg_quality,
                            scale=self._view_scale(result.camera))
            self._view_image_at[result.camera] = result.time

    def _view_scale(self, name: str) -> float:
        """How many times its size a camera's pictures are in the viewer's own stream (at most 1)."""
        width = self.cameras[name].width
        return min(1.0, self.view_image_width / width) if self.view_image_rate > 0 and width else 1.0

    def _show_cameras(self, cameras: set[str]) -> None:
        """The viewer's own stream carries these cameras' images from now on; a newly shown camera's start with the
        packets since its newest keyframe, so its video decodes at once."""
        if self._view is None:
            return
        for name in sorted(cameras - self._shown):
            log_frustum(self._view, f"world/cameras/{name}", view_camera(self.cameras[name], self._view_scale(name)))
            self._view_image_at.pop(name, None)  # its next frame is shown at once
            if self.view_image_rate > 0:
                continue  # pictures of their own: no video to start decoding
            if name in self._video:
                log_video_codec(self._view, name)
            for frame in self._gop.get(name, []):
                set_capture_time(self._view, frame.time)
                rr.set_time(f"frame_{name}", sequence=frame.index, recording=self._view)
                log_image(self._view, f"world/cameras/{name}/image", frame, self.jpeg_quality)
        self._shown = set(cameras)

    def cone_cameras(self) -> dict[str, str]:
        """The camera that measured each cone most often."""
        best: dict[str, tuple[int, str]] = {}
        for (cone, camera), n in self._measured.items():
            if n > best.get(cone, (0, ""))[0]:
                best[cone] = (n, camera)
        return {cone: camera for cone, (_, camera) in best.items()}

    def _send_layout_if_changed(self, now: float) -> None:
        """The superintendent's layout: at once; again at once when a cone gets its first camera (at most once per
        cone); again when the camera that best shows a cone changes, at most every BLUEPRINT_MIN_PERIOD_S."""
        mapping = self.cone_cameras()
        first = self._blueprint_sent == -np.inf
        # The first layout goes out with the first figures, when often one camera has measured one cone: a live
        # replay of config2-procedure5 had cone D's camera at 0.2 s and cone A's within the next second, and cone A
        # said "no camera yet" for the next 30 s.
        gained = mapping.keys() - self._cone_cameras.keys()
        if first or gained or (mapping != self._cone_cameras and now - self._blueprint_sent >= BLUEPRINT_MIN_PERIOD_S):
            self._layouts = self._layouts or [LayoutSender(APP_ID) for _ in self._streams()]
            self._show_cameras(set(mapping.values()))
            layout = superintendent_blueprint(self.rig, mapping)
            for sender, stream in zip(self._layouts, self._streams(), strict=True):
                sender.send(stream, layout)
            self._cone_cameras = mapping
            self._blueprint_sent = now

    def close(self, stopped: str = "") -> None:
        """Final status and flush to disk (stopped: not recorded here; the archive and the command say it)."""
        self.flush_estimates()
        self.status.log_if_due(self.rec, self._last_time, force=True)
        if self._last_update is not None:
            self._log_board(self._last_update)
        self.rec.flush(timeout_sec=1e38)  # the file: no viewer's sink is among its sinks, nothing of it can wait
        if self._viewer is not None:
            self._viewer.close(CLOSE_TIMEOUT_S)
        self.rec.disconnect()
        if self._view is not None:
            self._view.disconnect()
        if self._rrd is None:
            return
        if self._segment_s:
            index = len(self._segments) - 1
            last = self._rrd.with_name(self._segments[index][0])
            self._compactor.start(last, self._layout if len(self._segments) > 1 else None, self._segment_path(index))
            self._segments[index][0] = self._segment_path(index).name
        else:
            self._compactor.start(self._rrd)
        try:
            self._compactor.poll(wait=True)
        except KeyboardInterrupt:  # a second Ctrl-C: files renamed as they are
            self._compactor.stop()
        self._write_index()
