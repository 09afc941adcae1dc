"""The one error type the CLI turns into a one-line message and exit status 2."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

EXIT_BAD_INPUT = 2


class InputError(Exception):
    """Bad input: names the file, the field and what was expected."""

    def __init__(self, source: str | Path, message: str, field: str | None = None) -> None:
        self.source = str(source)
        self.field = field
        self.message = message
        where = f"{self.source}: {field}: " if field else f"{self.source}: "
        super().__init__(where + message)


def read_yaml(path: Path) -> Any:
    """A YAML file's content; a one-line InputError naming the line when it is not valid YAML."""
    try:
        return yaml.safe_load(path.read_text())
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"line {mark.line + 1}" if mark else "YAML"
        raise InputError(path, f"not valid YAML ({getattr(exc, 'problem', exc)})", where) from None
