"""Every run folder and output file that the README, the docs (benchmark READMEs too), the examples and the
notebooks write is their own: running one snippet after another (or the example from the repository root)
overwrites nothing."""

from __future__ import annotations

import re
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SOURCES = [
    ROOT / "README.md",
    *sorted((ROOT / "docs").rglob("*.md")),
    *sorted((ROOT / "benchmarks").rglob("README.md")),
    *sorted((ROOT / "examples").glob("*.py")),
    ROOT / "notebooks" / "make_notebooks.py",
]
# what writes a folder or a file: CLI options, the runner's run_dir, a save call, an example's default
_WRITERS = [
    r"(?:--out|-o|--save|--video|--cache)[ =]([^\s`\\\]|]+)",
    r"run_dir=[\"']([^\"']+)[\"']",
    r"\.save\([\"']([^\"']+)[\"']\)",
    r"default=Path\([\"']([^\"']+)[\"']\)",
]


def _placeholder(path: str) -> bool:
    """A metavariable (DIR, FILE.png, RUN/log.jsonl), not a path a snippet writes."""
    return re.fullmatch(r"[A-Z_]+(?:/[\w.]+|\.\w+)?", path) is not None


def written_paths() -> dict[str, list[str]]:
    """Path written -> where (file:line), over every source."""
    places: dict[str, list[str]] = defaultdict(list)
    for source in SOURCES:
        for number, line in enumerate(source.read_text(encoding="utf-8").splitlines(), 1):
            for pattern in _WRITERS:
                for path in re.findall(pattern, line):
                    if not _placeholder(path):
                        places[path.rstrip("/")].append(f"{source.relative_to(ROOT)}:{number}")
    return places


def test_the_collector_finds_the_known_writers():
    places = written_paths()
    assert places["runs/quickstart"] == ["README.md:8"]
    assert "examples/quickstart.py" in " ".join(places["runs/example-quickstart"])
    assert len(places) >= 10, sorted(places)


def test_every_snippet_writes_its_own_folder_and_files():
    shared = {path: where for path, where in written_paths().items() if len(where) > 1}
    assert not shared, f"written by more than one snippet: {shared}"
