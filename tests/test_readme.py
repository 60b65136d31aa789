"""Every ```python block of the README runs, in order, so the examples cannot rot."""

from __future__ import annotations

from pathlib import Path

import pytest
from helpers import python_blocks

README = Path(__file__).resolve().parent.parent / "README.md"
BLOCKS = python_blocks(README)


def test_readme_has_python_examples():
    assert BLOCKS, "the README lost its Python examples"


@pytest.mark.parametrize("index", range(len(BLOCKS)))
def test_readme_python_block_runs(index, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    namespace: dict = {"__name__": "__readme__"}
    for block in BLOCKS[: index + 1]:  # later blocks may use names defined earlier
        exec(compile(block, f"README.md block {index}", "exec"), namespace)
