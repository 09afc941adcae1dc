"""The one error type the CLI turns into a one-line message and exit status 2, and the readers' shared checks."""

from __future__ import annotations

import codecs
import re
from pathlib import Path
from typing import Any

import yaml

EXIT_BAD_INPUT = 2
MAX_TEXT_BYTES = 16 * 1024 * 1024  # a rig, calibration or dictionary file is kilobytes; a bigger one is not one
SNIFF_BYTES = 64 * 1024  # how much of a (possibly large) CSV is read to tell text from binary
LINE_BREAKS = re.compile(r"[\n\r\v\f\x1c\x1d\x1e\x85\u2028\u2029]+")  # everything str.splitlines() splits on


def one_line(text: str) -> str:
    """text with every line break (as str.splitlines() sees them) replaced by a space."""
    return LINE_BREAKS.sub(" ", text).strip()


class InputError(Exception):
    """Bad input: names the file, the field and what was expected; always one line."""

    def __init__(self, source: str | Path, message: str, field: str | None = None) -> None:
        self.source = one_line(str(source))
        self.field = one_line(field) if field else field
        self.message = one_line(message)
        where = f"{self.source}: {self.field}: " if self.field else f"{self.source}: "
        super().__init__(where + self.message)

    def __reduce__(self) -> tuple:
        """Pickled as its three parts (a worker process or a Ray task raises it, the command reports it)."""
        return type(self), (self.source, self.message, self.field)


def looks_binary(data: bytes, final: bool = True) -> bool:
    """True when data holds a NUL byte or is not UTF-8 (final=False: data may end inside a character)."""
    if b"\x00" in data:
        return True
    try:
        codecs.getincrementaldecoder("utf-8")().decode(data, final=final)
    except UnicodeDecodeError:
        return True
    return False


def a_or_an(noun: str) -> str:
    """noun with its indefinite article: "a rig file", "an offsets file"."""
    return f"{'an' if noun[:1].lower() in 'aeiou' else 'a'} {noun}"


def check_text_file(path: Path, what: str, limit: int | None = SNIFF_BYTES) -> bytes:
    """The first `limit` bytes (None: all) of a text file; a one-line InputError when it is missing, a folder,
    unreadable, empty or binary. what: the kind of file expected, for the message ("rig file")."""
    if path.is_dir():
        raise InputError(path, f"is a folder (expected {a_or_an(what)})")
    if not path.is_file():
        raise InputError(path, f"{what} not found")
    try:
        with path.open("rb") as f:
            data = f.read(limit if limit is not None else -1)
    except OSError as exc:
        raise InputError(path, f"cannot be read ({exc.strerror or exc})") from None
    if not data.strip():
        raise InputError(path, f"is empty (expected {a_or_an(what)})")
    if looks_binary(data, final=limit is None or len(data) < limit):
        raise InputError(path, f"is binary, not text (expected {a_or_an(what)})")
    return data


def read_text(path: Path, what: str) -> str:
    """A whole small text file (at most MAX_TEXT_BYTES), checked by check_text_file."""
    data = check_text_file(path, what, MAX_TEXT_BYTES + 1)
    if len(data) > MAX_TEXT_BYTES:
        raise InputError(path, f"is larger than {MAX_TEXT_BYTES // 2**20} MiB (expected {a_or_an(what)})")
    return data.decode("utf-8")


class UniqueKeyLoader(yaml.SafeLoader):
    """yaml.SafeLoader refusing a mapping that gives a key twice (PyYAML keeps the last, silently): a rig with
    marker_size twice is a typo, not a choice. Merge keys (<<) still merge, and a key given after them overrides."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict[Any, Any]:
        seen: dict[Any, int] = {}
        for key_node, _ in node.value:
            if key_node.tag == "tag:yaml.org,2002:merge":
                continue
            key = self.construct_object(key_node, deep=True)
            try:
                first = seen.get(key)
            except TypeError:  # an unhashable key: SafeLoader's own error names it
                break
            if first is not None:
                raise yaml.constructor.ConstructorError(
                    None, None, f"duplicate key {key!r}, first given on line {first}", key_node.start_mark)
            seen[key] = key_node.start_mark.line + 1
        return super().construct_mapping(node, deep=deep)


def read_yaml(path: Path, what: str = "YAML file") -> Any:
    """A YAML file's content; a one-line InputError naming the line when it is not valid YAML, and naming the file
    when it is missing, a folder, unreadable, empty, binary or too large."""
    text = read_text(Path(path), what)
    try:
        return yaml.load(text, Loader=UniqueKeyLoader)  # a SafeLoader
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"line {mark.line + 1}" if mark else "YAML"
        raise InputError(path, f"not valid YAML ({getattr(exc, 'problem', None) or exc})", where) from None
    except RecursionError:
        raise InputError(path, "nested too deeply (expected a YAML mapping)") from None
    except ValueError as exc:  # a value YAML reads as a date that is none, e.g. 2001-02-30
        raise InputError(path, f"not valid YAML ({exc})") from None
