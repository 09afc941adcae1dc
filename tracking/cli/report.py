"""`topside report`: the installation report of a recording or an archive, one self-contained HTML page."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from tracking.cli.common import console
from tracking.outputs import check_outputs, write_bytes, write_text


def report(
    record: Annotated[Path, typer.Argument(help="A recording (.rrd) or an MCAP archive (.mcap) of one installation.")],
    out: Annotated[Path, typer.Option("-o", "--out", help="The report to write (HTML).")] = Path("report.html"),
    key: Annotated[Path | None, typer.Option(help="ed25519 public key (PEM) an archive's signature is checked "
                                                  "against (without it a signature is reported unchecked).")] = None,
    pdf: Annotated[Path | None, typer.Option("--pdf", help="Also write the page as PDF (A4, laid out by WeasyPrint: "
                                                          "pip install 'topside[pdf]').")] = None,
) -> None:
    """Write an installation's report: per cone whether and when it landed within the tolerance and how sure, its
    offsets over time with NO DATA and why, the cameras' timeline, the rig's clocks and survey, the events with the
    command that opens the record there, and what it summarises (software, digests, the archive's check)."""
    check_outputs({"--out": out, "--pdf": pdf}, [record, key])  # before the reader's imports (3 s)
    from viewer.installation_record import read_record
    from viewer.report import write_report

    summary = write_report(read_record(record, key), out, write_text, pdf, write_bytes)
    for c in summary.cones:
        console.print(f"cone {c.cone}: {c.headline}", markup=False, soft_wrap=True)
    console.print(f"{summary.verdict}; wrote {out}" + (f" and {pdf}" if pdf is not None else ""), markup=False,
                  soft_wrap=True)
