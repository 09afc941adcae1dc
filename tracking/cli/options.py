"""The command line's shared options: typer option types several commands take, the callback refusing numbers that
are not finite or out of range, and the choices typer validates itself.

A choice is an enum.StrEnum: typer lists its values in --help and refuses any other value as a usage error, which
`topside` prints as one line (topside: error: ...) with exit status 2, as every bad input. Each mirrors a tuple of the
module that takes the value (not imported here: the command line starts fast); tests/test_cli.py checks they agree.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from enum import StrEnum
from pathlib import Path
from typing import Annotated

import typer

from tracking.detection import Refinement


class Mode(StrEnum):
    """How `track` estimates the offsets: tracking.estimator.ESTIMATORS' keys (tracking.batch.MODES), in their order."""

    FUSED = "fused"
    SMOOTHED = "smoothed"
    PAPER = "paper"
    RAW = "raw"


class VideoFormat(StrEnum):
    """How an archive stores frames without H.264 of their own: viewer.archive.VIDEO_FORMATS."""

    JPEG = "jpeg"
    H264 = "h264"


class Layout(StrEnum):
    """The layout a live recording opens with: viewer.session.Recorder's layout."""

    SUPERINTENDENT = "superintendent"
    ANALYSIS = "analysis"


class ViewerScope(StrEnum):
    """What a live viewer of the superintendent's layout is sent: viewer.session.VIEWER_SCOPES."""

    SUPERINTENDENT = "superintendent"
    ALL = "all"


class SheetFormat(StrEnum):
    """The file format of `topside markers`' sheets: tracking.marker_sheets.FORMATS."""

    PDF = "pdf"
    PNG = "png"


RefineOption = Annotated[Refinement, typer.Option(help="Corner refinement.")]

# Options shared by `track --mcap` and `export`.
KeyOption = Annotated[Path | None, typer.Option(help="ed25519 private key (PEM) to sign the archive.")]
VesselOption = Annotated[str, typer.Option(help="Crane vessel, for the archive's metadata.")]
OperatorOption = Annotated[str, typer.Option(help="Operator, for the archive's metadata.")]
VideoOption = Annotated[VideoFormat, typer.Option(help="Frames that have no H.264 of their own (stills, raw sources): "
                                                       "jpeg (CompressedImage) or h264 (re-encoded, CompressedVideo). "
                                                       "The cameras' own H.264 always passes through.")]

# Options shared by `track` and `batch`: where the chunks of the videos are tracked.
CHUNK_FRAMES_DEFAULT = 150  # tracking.parallel.CHUNK_FRAMES (not imported here: the CLI starts fast)
WorkersOption = Annotated[int | None, typer.Option(min=1, help="Worker processes that decode and detect (default: "
                                                             "every core; 1: in this process).")]
RayOption = Annotated[str | None, typer.Option(metavar="[ADDRESS]", help="Run the chunks as Ray tasks: on the "
                                               "cluster at ADDRESS (ray://HOST:10001 or auto), or, without ADDRESS, "
                                               "on a Ray started here with --workers CPUs. Needs topside[cluster].")]
ChunkOption = Annotated[int, typer.Option(min=1, help="A chunk of a video starts at the first keyframe this many "
                                                      "frames after the previous chunk's start.")]
# Options shared by `view` and `live`: the web viewer.
WEB_PORT_DEFAULT = 9090  # viewer.playback.WEB_PORT
VIEW_IMAGE_RATE_DEFAULT = 2.0  # viewer.session.VIEW_IMAGE_RATE_HZ (not imported: the CLI starts without rerun)
VIEW_IMAGE_WIDTH_DEFAULT = 640  # viewer.session.VIEW_IMAGE_WIDTH_PX
WebPortOption = Annotated[int, typer.Option(help="Port of the web viewer's page (with --web).", min=1, max=65535)]


def finite(low: float, low_open: bool = True, high: float = math.inf, allow_inf: bool = False
           ) -> Callable[[float | None], float | None]:
    """A typer callback refusing NaN, infinities (unless allow_inf) and values outside (low, high] (or [low, high]);
    low=-math.inf: any finite number up to high (a capture time)."""

    def check(value: float | None) -> float | None:
        if value is None:
            return value
        inside = (value > low if low_open else value >= low) and value <= high
        if math.isnan(value) or (math.isinf(value) and not allow_inf) or not inside:
            bounds = [f"{'>' if low_open else '≥'} {low:g}"] if math.isfinite(low) else []
            bounds += [f"≤ {high:g}"] if math.isfinite(high) else []
            raise typer.BadParameter(" ".join([f"{value} is not a finite number", " and ".join(bounds)]).strip())
        return value

    return check


# Options shared by `track` and `batch`: the fusion split over time (tracking.split).
FUSION_SEGMENT_DEFAULT = 300.0  # tracking.split.SEGMENT_S
OnePassOption = Annotated[bool, typer.Option("--one-pass-fusion", help="Fuse the whole run in one pass on this "
                                             "process, in capture-time order (default: a run longer than "
                                             "--fusion-segment is cut into segments fused by the workers).")]
FusionSegmentOption = Annotated[float, typer.Option(help="Seconds of capture per segment of the fusion split over "
                                                         "time (each read from 20 s before its start).",
                                                    callback=finite(0.0))]
