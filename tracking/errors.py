"""The one error type the CLI turns into a one-line message and exit status 2."""

from __future__ import annotations

from pathlib import Path

EXIT_BAD_INPUT = 2


class InputError(Exception):
    """Bad input: names the file, the field and what was expected."""

    def __init__(self, source: str | Path, message: str, field: str | None = None) -> None:
        self.source = str(source)
        self.field = field
        self.message = message
        where = f"{self.source}: {field}: " if field else f"{self.source}: "
        super().__init__(where + message)
