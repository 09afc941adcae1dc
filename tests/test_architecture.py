"""The code's shape, so a newcomer finds where a number is computed in a minute: small modules of short functions in
tracking/ and viewer/ (the layering itself is pyproject.toml's import contracts, checked by lint-imports)."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PACKAGES = ("tracking", "viewer")
MAX_MODULE_LINES = 600  # one concept per module: beyond this it holds two
MAX_FUNCTION_LINES = 60  # a function a reader holds in view at once, docstring included


def _modules() -> list[Path]:
    return sorted(p for package in PACKAGES for p in (REPO / package).rglob("*.py"))


@pytest.mark.parametrize("path", _modules(), ids=lambda p: str(p.relative_to(REPO)))
def test_module_is_small(path: Path) -> None:
    source = path.read_text()
    assert source.count("\n") <= MAX_MODULE_LINES, f"{path.relative_to(REPO)}: split it by concept"
    long = [f"{node.name} ({node.end_lineno - node.lineno + 1} lines)" for node in ast.walk(ast.parse(source))
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef)
            and node.end_lineno - node.lineno + 1 > MAX_FUNCTION_LINES]
    assert not long, f"{path.relative_to(REPO)}: {', '.join(long)}"


def test_the_limits_can_fail() -> None:
    """The walk above sees functions at all: this module's own are found and measured."""
    tree = ast.parse(Path(__file__).read_text())
    names = {n.name for n in ast.walk(tree) if isinstance(n, ast.FunctionDef)}
    assert {"test_module_is_small", "_modules"} <= names
    assert len(_modules()) > 50
