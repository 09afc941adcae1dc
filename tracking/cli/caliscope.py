"""`import-caliscope`: a rig of a caliscope session (webcams filming a hand-held ChArUco board), to try the tracker on
real cameras at a desk (tracking/caliscope.py reads the session)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from tracking.cli.common import console, warn_lines
from tracking.errors import InputError
from tracking.outputs import check_outputs

MAX_IDS = 100_000  # ids in one range of --topside: more than any dictionary holds


def import_caliscope(
    session: Annotated[Path, typer.Argument(help="caliscope session folder (charuco.toml, camera_array.toml).")],
    out: Annotated[Path, typer.Option("-o", "--out", help="Folder for rig.yaml, calibration/, times/, truth.csv.")],
    videos: Annotated[Path | None, typer.Option(help="Folder of the videos and their times file (default: the "
                                                     "session's calibration/extrinsic).")] = None,
    topside: Annotated[str | None, typer.Option(help="Marker ids on the \"topside\", e.g. 0-4,7 (default: the "
                                                     "board's first half by id).")] = None,
) -> None:
    """Make a rig of a caliscope session (webcams filming a hand-held ChArUco board): the board split into a "topside"
    and a "jacket" mated at cone A, every camera's calibration and capture times, and truth.csv (the offset is zero:
    the board is rigid). Then: topside track --rig OUT/rig.yaml -o offsets.csv; topside evaluate offsets.csv
    OUT/truth.csv."""
    from tracking.caliscope import read_session, write_session

    the_session = read_session(session, videos)
    ids = _id_set(topside, "--topside") if topside is not None else None
    board_ids = {m.id for m in the_session.board.markers()}
    if ids is not None and (not ids < board_ids or not ids):
        raise InputError("--topside", f"expected some but not all of the board's ids {min(board_ids)}-"
                                      f"{max(board_ids)}, got {topside}")
    names = [f"cam_{c.number}" for c in the_session.cameras]
    inputs = [c.video for c in the_session.cameras]
    check_outputs({"--out (rig.yaml)": out / "rig.yaml", "--out (truth.csv)": out / "truth.csv",
                   **{f"--out ({n}.yaml)": out / "calibration" / f"{n}.yaml" for n in names},
                   **{f"--out ({n}.csv)": out / "times" / f"{n}.csv" for n in names}}, inputs)
    warn_lines(f"{line}: left out" for line in the_session.left_out)
    warn_lines(the_session.notes)
    rig_path = write_session(the_session, out, ids)
    board = the_session.board
    console.print(f"wrote {rig_path}: {board.columns} × {board.rows} board of {board.dictionary}, markers "
                  f"{board.marker_m * 1000:.1f} mm, {len(names)} cameras ({', '.join(names)}), truth "
                  f"{out / 'truth.csv'}", markup=False)


def _id_set(text: str, option: str) -> set[int]:
    """Marker ids written as 0-4,7."""
    ids: set[int] = set()
    try:
        for part in text.split(","):
            first, _, last = part.strip().partition("-")
            low, high = int(first), int(last or first)
            if high - low > MAX_IDS:
                raise ValueError
            ids.update(range(low, high + 1))
    except ValueError:
        raise InputError(option, f"expected ids such as 0-4,7, got {text!r}") from None
    return ids
