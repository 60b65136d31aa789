"""The order the test files run in (``tests/conftest.py`` calls these).

The two workers take whole files (``--dist loadfile``); the longest files go first, so that no long file is
left to run alone at the end while the other worker idles. ``durations.json`` holds each file's seconds
from a whole run (``python -m pytest --store-durations`` writes it again). A file it does not list runs
last; a stale entry only changes the order, never a result. (``--no-loadscope-reorder`` keeps this order:
pytest-xdist would otherwise order the files by their number of tests.)
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

DURATIONS = Path(__file__).with_name("durations.json")


def file_of(nodeid: str) -> str:
    """The file part of a test's node id."""
    return nodeid.split("::", 1)[0]


def order_by_durations(items: list[Any], durations: Path = DURATIONS) -> None:
    """Sort ``items`` (with ``.nodeid``) in place, longest file first by ``durations`` (absent: no change).

    The sort is stable, so a file's tests keep their order and stay in one piece.
    """
    seconds = json.loads(durations.read_text(encoding="utf-8")) if durations.is_file() else {}
    items.sort(key=lambda item: -seconds.get(file_of(item.nodeid), 0.0))


def write_durations(seconds: Mapping[str, float], durations: Path = DURATIONS) -> None:
    """Write each file's seconds, longest first (0.1 s)."""
    ordered = dict(sorted(seconds.items(), key=lambda item: (-item[1], item[0])))
    text = json.dumps({name: round(value, 1) for name, value in ordered.items()}, indent=1)
    durations.write_text(text + "\n", encoding="utf-8")
