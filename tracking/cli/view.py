"""`topside view`: a recording, or a window of it, opened in Rerun's viewer (native, or served to a browser)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated

import typer

from tracking.cli.options import WEB_PORT_DEFAULT, WebPortOption, finite
from tracking.errors import InputError


def view(
    recording: Annotated[Path, typer.Argument(help="A Rerun recording (.rrd), or a segmented one (its .rrd name "
                                                   "or its .segments.csv).")],
    start: Annotated[float | None, typer.Option("--from", help="Open from this capture time, s.",
                                                callback=finite(-math.inf))] = None,
    end: Annotated[float | None, typer.Option("--to", help="Open up to this capture time, s.",
                                              callback=finite(-math.inf))] = None,
    web: Annotated[bool, typer.Option("--web", help="Serve the web viewer instead of opening the native one.")] = False,
    bind: Annotated[str, typer.Option(help="Address (or host name) of this machine the viewer's servers listen on.")
                    ] = "127.0.0.1",
    web_port: WebPortOption = WEB_PORT_DEFAULT,
    grpc_port: Annotated[int | None, typer.Option(help="Port of the viewer's gRPC server (default: 9876 with --web, "
                                                       "a free one for the native viewer).", min=1, max=65535)] = None,
) -> None:
    """Open a recording in Rerun's viewer (native, or web with --web); --from/--to open a window of it.

    With --web, prints the URL to open; Ctrl-C (or SIGTERM) stops the server and removes its temporary files.
    """
    from viewer.playback import view_recording

    if start is not None and end is not None and end <= start:
        raise InputError("--to", f"{end} is not after --from {start}")
    view_recording(recording, start, end, web=web, bind=bind, grpc_port=grpc_port, web_port=web_port)
