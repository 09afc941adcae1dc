"""`topside export` and `topside verify`: MCAP audit archives written from a recording and checked; and what
`track --mcap` writes its archive with (the signing key, the metadata, the frame format)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from tracking.cli.common import console
from tracking.cli.options import KeyOption, OperatorOption, VesselOption, VideoFormat, VideoOption
from tracking.errors import InputError
from tracking.outputs import atomic_path, check_outputs

if TYPE_CHECKING:
    import pandas as pd
    from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey

    from tracking.rig import Rig
    from viewer.archive import ArchiveSink
    from viewer.archive.audit import Report

MAX_FINDINGS = 50  # printed by `verify`; the rest are counted


@dataclass(frozen=True)
class ArchiveSettings:
    """What an archive is written with: its signing key (None: unsigned), the metadata's vessel and operator, and how
    frames without H.264 of their own are stored."""

    private: Ed25519PrivateKey | None
    vessel: str
    operator: str
    video: VideoFormat

    @classmethod
    def read(cls, key: Path | None, vessel: str, operator: str, video: VideoFormat) -> ArchiveSettings:
        """The settings, the signing key read now (before any work starts: a bad key is found at once)."""
        from viewer.archive.manifest import load_private_key

        return cls(load_private_key(key) if key is not None else None, vessel, operator, video)

    @classmethod
    def for_track(cls, mcap: Path | None, key: Path | None, vessel: str, operator: str, video: VideoFormat
                  ) -> ArchiveSettings | None:
        """`track`'s settings: None without --mcap; a one-line InputError for a --key with no archive to sign."""
        if mcap is None and key is not None:
            raise InputError("--key", f"{key} signs the MCAP archive, and no --mcap is given (give --mcap FILE to "
                                      "write a signed archive, or leave out --key)")
        return cls.read(key, vessel, operator, video) if mcap is not None else None

    @property
    def metadata(self) -> dict[str, str]:
        return {"vessel": self.vessel, "operator": self.operator}


def archive_sink(rig: Rig, path: Path, options: dict[str, str], truth_df: pd.DataFrame | None,
                 settings: ArchiveSettings, offsets_csv: Path | None) -> ArchiveSink:
    """The MCAP archive writer for `track --mcap` (it attaches the offsets CSV when it closes)."""
    from viewer.archive import ArchiveSink

    return ArchiveSink(rig, path, options, settings.metadata, truth_df, settings.private, offsets_csv,
                       video=settings.video.value)


def export(
    recording: Annotated[Path, typer.Argument(help="A recording (.rrd) written by `topside track --rrd`.")],
    mcap: Annotated[Path, typer.Option(help="MCAP archive to write.")],
    offsets: Annotated[Path | None, typer.Option(help="Offsets CSV of the same run, to attach.")] = None,
    key: KeyOption = None,
    vessel: VesselOption = "",
    operator: OperatorOption = "",
    video: VideoOption = VideoFormat.JPEG,
) -> None:
    """Write the MCAP audit archive of a recording: the same content `track --mcap` writes."""
    from viewer.archive.export import export_recording

    check_outputs({"--mcap": mcap}, [recording, offsets, key])
    settings = ArchiveSettings.read(key, vessel, operator, video)
    if offsets is not None and not offsets.is_file():
        raise InputError(offsets, "offsets CSV not found", "--offsets")
    if offsets is not None:  # what is signed into the archive as offsets.csv must be one
        from tracking.evaluate import read_offsets

        read_offsets(offsets)
    with atomic_path(mcap) as partial:
        n = export_recording(recording, partial, settings.metadata, settings.private,
                             offsets.read_bytes() if offsets else None, settings.video.value)
    console.print(f"wrote {mcap}: {n} messages (check it with: topside verify {mcap})")


def verify(
    archive: Annotated[Path, typer.Argument(help="An MCAP archive written by topside.")],
    key: Annotated[Path | None, typer.Option(help="ed25519 public key (PEM) the archive must be signed with.")
                   ] = None,
    recover: Annotated[bool, typer.Option("--recover", help="Rebuild a valid file from a damaged or killed "
                                                            "writer's, then check that.")] = False,
    out: Annotated[Path | None, typer.Option("-o", "--out", help="Where --recover writes (default: "
                                                                 "NAME.recovered.mcap).")] = None,
) -> None:
    """Check an archive: CRCs, indexes, every channel non-empty, the manifest's SHA-256 digests, the signature."""
    from viewer.archive.audit import verify as verify_file
    from viewer.archive.manifest import load_public_key

    public = load_public_key(key) if key is not None else None
    if recover:
        archive = _recover(archive, out or archive.with_name(f"{archive.stem}.recovered.mcap"), key)
    report = verify_file(archive, public)
    _print_verification(archive, report)
    if not report.ok:
        raise typer.Exit(1)


def _recover(archive: Path, target: Path, key: Path | None) -> Path:
    """`verify --recover`: the file to check, target rebuilt from a damaged or killed writer's archive, or the
    archive itself when it is intact (nothing written)."""
    from viewer.archive.audit import is_intact
    from viewer.archive.audit import recover as recover_file
    from viewer.archive.manifest import time_text

    check_outputs({"--out": target}, [archive, key])
    if is_intact(archive):
        console.print(f"{archive} is intact (a finished writer's summary, indexes and manifest all check): "
                      "nothing to recover, nothing written", markup=False, soft_wrap=True)
        return archive
    with atomic_path(target) as partial:
        r = recover_file(archive, partial)
    console.print(f"recovered {r.messages} messages in {r.chunks} chunks up to "
                  f"{time_text(r.last_ns) if r.last_ns is not None else '-'}; {r.chunks_damaged} damaged "
                  f"chunks and {r.bytes_dropped} trailing bytes dropped", soft_wrap=True)
    if r.manifest_was_missing:
        console.print("the manifest was missing (the writer did not close); the recovered file carries its "
                      "own, marked 'recovered'", style="yellow")
    console.print(f"wrote {target}")
    return target


def _print_verification(archive: Path, report: Report) -> None:
    """The check's notes, its first MAX_FINDINGS failures (the rest counted) and its one-line verdict."""
    for note in report.notes:
        console.print(f"note: {note}", markup=False, soft_wrap=True)
    for err in report.errors[:MAX_FINDINGS]:
        console.print(f"FAIL: {err}", markup=False, soft_wrap=True)
    if len(report.errors) > MAX_FINDINGS:
        console.print(f"FAIL: ... and {len(report.errors) - MAX_FINDINGS} more", soft_wrap=True)
    sig = {"valid": "signature valid", "invalid": "signature INVALID", "absent": "not signed",
           "unchecked": "signed (not checked: no --key)"}[report.signature]
    state = "OK" if report.ok else f"{len(report.errors)} problems"
    console.print(f"{archive}: {state}; {report.messages} messages on {report.channels} channels; {sig}; "
                  f"{report.size / 1e6:.1f} MB checked at {report.mb_per_s:.0f} MB/s", markup=False, soft_wrap=True)
