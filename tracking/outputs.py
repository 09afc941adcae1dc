"""Where commands write: an output never overwrites an input, and appears under its name only once complete.

Every output is first written to a temporary file beside it, ``<stem>.partial<suffix>`` (``-2``, ``-3``... when that
name is taken, so an earlier run's leftover is never overwritten), and renamed into place when complete. A failure
removes the temporary file; an interrupted recording keeps it, under that name, so nothing recorded is lost.
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Callable, Iterable, Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path

from tracking.errors import InputError

PARTIAL = ".partial"  # infix of a temporary output: offsets.partial.csv, run.partial.rrd
MAX_PARTIALS = 1000


def same_file(a: Path, b: Path) -> bool:
    """True when two paths name one file (symbolic and hard links included)."""
    try:
        return a.resolve() == b.resolve() or (a.exists() and b.exists() and os.path.samefile(a, b))
    except OSError:
        return False


def check_outputs(outputs: Mapping[str, Path | None], inputs: Iterable[Path | str | None] = ()) -> None:
    """A one-line InputError, before any work, when an output is one of the inputs, another output, an existing
    directory, or in a folder that cannot be written (outputs: option name -> path)."""
    given = [(option, Path(p)) for option, p in outputs.items() if p is not None]
    sources = [Path(p) for p in inputs if p is not None and str(p)]
    for i, (option, path) in enumerate(given):
        if path.is_dir():
            raise InputError(path, "is a directory (expected a file name to write)", option)
        for source in sources:
            if same_file(path, source):
                raise InputError(path, f"is an input of this command ({source}); an output never overwrites an "
                                       "input (expected another file name)", option)
        for other_option, other in given[:i]:
            if same_file(path, other):
                raise InputError(path, f"is also given as {other_option} (expected a file name of its own)", option)
        check_writable(path, option)


def check_writable(path: Path, option: str) -> None:
    """A one-line InputError when path's folder cannot be made or written, or path exists and cannot be replaced."""
    folder = path.parent
    existing = folder
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        raise InputError(path, f"cannot be written: {existing} is not a folder", option)
    if not os.access(existing, os.W_OK | os.X_OK):
        raise InputError(path, f"cannot be written: no permission to write in {existing}", option)


def _claim_beside(path: Path, name: str, suffix: str, claim: Callable[[Path], None], what: str) -> Path:
    """The first of <name>.partial<suffix>, <name>.partial-2<suffix>, ... beside path that claim creates anew."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    for n in range(1, MAX_PARTIALS):
        candidate = path.with_name(f"{name}{PARTIAL}{'' if n == 1 else f'-{n}'}{suffix}")
        try:
            claim(candidate)
        except FileExistsError:
            continue
        except OSError as exc:
            raise InputError(path, f"cannot be written ({exc.strerror})") from None
        return candidate
    raise InputError(path, f"cannot be written: {MAX_PARTIALS} temporary {what} beside it already")


def partial_path(path: Path) -> Path:
    """A new, empty temporary file beside path, claimed atomically: <stem>.partial<suffix> or <stem>.partial-N."""
    path = Path(path)
    return _claim_beside(path, path.stem, path.suffix,
                         lambda p: os.close(os.open(p, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)), "files")


def partial_dir(path: Path) -> Path:
    """A new, empty temporary folder beside path: <name>.partial or <name>.partial-N."""
    path = Path(path)
    return _claim_beside(path, path.name, "", Path.mkdir, "folders")


def replace_dir(partial: Path, path: Path) -> Path:
    """Move a complete temporary folder onto path; an earlier folder there (checked replaceable) is removed after."""
    old = None
    if path.exists():
        old = partial_dir(path.with_name(f"{path.name}.old"))
        old.rmdir()
        os.replace(path, old)
    os.replace(partial, path)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)
    return path


def commit(partial: Path, path: Path) -> Path:
    """Rename a complete temporary file onto its final name; returns the final name."""
    try:
        os.replace(partial, path)
    except OSError as exc:
        raise InputError(path, f"cannot be written ({exc.strerror}); the complete output is in {partial}") from None
    return path


def discard(partial: Path) -> None:
    """Remove a temporary file (or folder) that will not be completed."""
    if partial.is_dir():
        shutil.rmtree(partial, ignore_errors=True)
    else:
        partial.unlink(missing_ok=True)


@contextmanager
def atomic_path(path: Path, keep_on_interrupt: bool = False) -> Iterator[Path]:
    """A temporary file beside path to write; renamed onto path when the block completes, removed when it fails.

    keep_on_interrupt: a KeyboardInterrupt keeps the temporary file (a recording stopped by hand keeps what it has).
    """
    path = Path(path)
    partial = partial_path(path)
    try:
        yield partial
    except KeyboardInterrupt:
        if not keep_on_interrupt:
            discard(partial)
        raise
    except BaseException:
        discard(partial)
        raise
    commit(partial, path)


def write_bytes(path: Path, data: bytes) -> Path:
    """Write a whole file atomically."""
    with atomic_path(Path(path)) as partial:
        partial.write_bytes(data)
    return Path(path)


def write_text(path: Path, text: str) -> Path:
    """Write a whole text file atomically."""
    return write_bytes(path, text.encode())


class Outputs:
    """The temporary files of one command's outputs: all renamed into place when the command completes, all removed
    when it fails; an interrupted recording (keep_on_interrupt) keeps them under their temporary names."""

    def __init__(self, keep_on_interrupt: bool = False) -> None:
        self.keep_on_interrupt = keep_on_interrupt
        self.partials: dict[Path, Path] = {}  # final -> temporary
        self.kept: list[Path] = []  # temporary files left after an interruption

    def claim(self, path: Path | None) -> Path | None:
        """The temporary file to write for an output (None stays None)."""
        if path is None:
            return None
        partial = partial_path(Path(path))
        self.partials[Path(path)] = partial
        return partial

    def commit(self) -> None:
        """Rename every temporary file that was written onto its final name."""
        for path, partial in self.partials.items():
            if partial.exists():
                commit(partial, path)
        self.partials = {}

    def discard(self) -> None:
        """Remove every temporary file."""
        for partial in self.partials.values():
            discard(partial)
        self.partials = {}

    def __enter__(self) -> Outputs:
        return self

    def __exit__(self, kind: type[BaseException] | None, exc: BaseException | None, tb: object) -> None:
        if kind is None:
            self.commit()
        elif issubclass(kind, KeyboardInterrupt) and self.keep_on_interrupt:
            self.kept = [p for p in self.partials.values() if p.exists() and p.stat().st_size > 0]
            for partial in self.partials.values():
                if partial not in self.kept:
                    discard(partial)
            self.partials = {}
        else:
            self.discard()
