"""The numbers the docs quote are the code's: scripts/render_doc_numbers.py renders them, this compares."""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

from helpers import EXTRAS

_PATH = Path(__file__).resolve().parents[2] / "scripts" / "render_doc_numbers.py"
_SPEC = importlib.util.spec_from_file_location("render_doc_numbers", _PATH)
render = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(render)


def test_the_readme_main_job_needs_the_iterations_readme_and_runner_doc_quote():
    assert "--target-regret" in render.main_job_argv()
    iterations, episodes = render.main_job()  # the README's command, parsed by the CLI (about 6 s)
    for path, text in render.quickstart_docs(iterations, episodes).items():
        assert path.read_text(encoding="utf-8") == text, f"{path.name}: run scripts/render_doc_numbers.py"
    drifted = render.quickstart_docs(iterations + 100, episodes + 5000)
    assert all(path.read_text(encoding="utf-8") != text for path, text in drifted.items())


def _cells(table: str, row: int) -> list[str]:
    return [cell.strip() for cell in table.splitlines()[row].strip("|").split("|")]


@EXTRAS
def test_the_reacher_table_is_rendered_from_the_documented_example():
    committed = render.committed_reacher_table()
    columns = zip(*(_cells(committed, row)[1:] for row in (0, 2, 3)), strict=True)
    numbers = [(int(i), float(r.replace("−", "-")), float(d)) for i, r, d in columns]
    assert render.reacher_table(numbers) == committed  # the committed table has the script's layout
    first = render.reacher_table(render.reacher_rows(iterations=1))  # column 0: the initial policy, ~1 s
    assert [_cells(first, row)[:2] for row in (0, 2, 3)] == [_cells(committed, row)[:2] for row in (0, 2, 3)]
    assert re.search(r"for it in range\(161\):", render.reacher_block())  # the full run: --check, ~2 min
