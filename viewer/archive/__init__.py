"""MCAP audit archives: the tracker's stream of results in, one MCAP file out that Foxglove and Rerun open.

messages.py builds the messages, frames.py a frame's image and annotations, file.py the MCAP file (chunks, metadata,
attachments, checkpoints), writer.py the Archive and its sink for `track`; manifest.py the manifest, its digests and
signature, audit.py `topside verify`, export.py `topside export` (a recording to an archive).

Channels (Foxglove schemas in protobuf encoding, log time = capture time):
    /cameras/<camera>/image          foxglove.CompressedImage (JPEG), frame_id <camera>
    /cameras/<camera>/calibration    foxglove.CameraCalibration, at the first frame and every STATIC_PERIOD_S
    /cameras/<camera>/detections     foxglove.ImageAnnotations: marker outlines, ids, reprojected axes
    /cameras/<camera>/health         topside.CameraHealth: markers, reprojection error, frame interval
    /frames/markers                  foxglove.FrameTransforms jacket -> marker_<id>, topside -> marker_<id>
    /frames/cameras                  foxglove.FrameTransforms jacket -> <camera> as the markers place it
    /frames/topside                  foxglove.FrameTransforms jacket -> topside (fitted to the cone offsets)
    /frames/filter_cameras           foxglove.FrameTransforms jacket -> filter_<camera>: where the fused filter has
                                     each camera (live mode), once per estimate time
    /offsets/<cone>                  topside.ConeOffset: dx dy dz, 1σ, covariance (3x3, m²), status, cameras
    /truth/<cone>                    topside.ConeOffset: the simulator's truth, when known
    /log                             foxglove.Log: events (start, first frame, markers lost/found, cone state)
Metadata records `topside` (installation, vessel, operator, software, configuration hash), `time_span`, and a
`topside.checkpoint` after every flushed chunk (the running SHA-256 of all messages so far, signed with a key);
attachments: the rig file, every calibration file, the offsets CSV, the manifest (viewer/archive/manifest.py) and its
ed25519 signature. Chunks (zstd) are flushed to disk every FLUSH_PERIOD_S of capture time, so a killed writer
leaves every chunk before the last flush readable (`topside verify --recover`).
"""

from viewer.archive.file import ArchiveFile, software_commit, software_version, time_span
from viewer.archive.frames import VIDEO_FORMATS, FrameView, VideoEncoder, annotations_message, frame_view
from viewer.archive.messages import CameraHealth, ConeOffset, calibration_message, capture_ns, log_message
from viewer.archive.writer import Archive, ArchiveInputs, ArchiveSink

__all__ = [
    "VIDEO_FORMATS",
    "Archive",
    "ArchiveFile",
    "ArchiveInputs",
    "ArchiveSink",
    "CameraHealth",
    "ConeOffset",
    "FrameView",
    "VideoEncoder",
    "annotations_message",
    "calibration_message",
    "capture_ns",
    "frame_view",
    "log_message",
    "software_commit",
    "software_version",
    "time_span",
]
