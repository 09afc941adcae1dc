"""Writing a benchmark's results: a markdown file in benchmarks/results/."""

from __future__ import annotations

from pathlib import Path

from tracking.outputs import write_text

RESULTS_DIR = Path(__file__).resolve().parent / "results"


def write_results(name: str, lines: list[str], echo: bool = False, to_file: bool = True) -> Path | None:
    """benchmarks/results/<name>.md from the table's lines (printed too with echo); its path. Without to_file (a run
    on other inputs than the committed results'), printed only."""
    text = "\n".join(lines).rstrip("\n") + "\n"
    if echo or not to_file:
        print(text)
    if not to_file:
        return None
    RESULTS_DIR.mkdir(parents=True, exist_ok=True)
    path = RESULTS_DIR / f"{name}.md"
    write_text(path, text)  # whole or not at all
    print(f"wrote {path}")
    return path
