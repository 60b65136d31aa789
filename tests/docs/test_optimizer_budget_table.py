"""docs/optimizers.md's budget table quotes the target study's rendered tables cell for cell."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
DOC = ROOT / "docs" / "optimizers.md"
RESULTS = ROOT / "docs" / "results" / "ccmaes" / "full" / "results.md"


def _table_after(text: str, heading: str) -> list[dict[str, str]]:
    """The rows of the first Markdown table after ``heading``, as dicts keyed by the header's cells."""
    lines = text[text.index(heading) :].splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("|"))
    rows = []
    for line in lines[start:]:
        if not line.startswith("|"):
            break
        rows.append([cell.strip() for cell in line.strip().strip("|").split("|")])
    header, body = rows[0], rows[2:]
    return [dict(zip(header, row, strict=True)) for row in body]


def _median(cell: str) -> str:
    """The median of a study cell such as ``4,850 (20/20)`` or ``3,912 (20/20), N = 24``."""
    match = re.match(r"([\d,]+) \(\d+/\d+\)", cell)
    if match is None:
        raise ValueError(f"not a study cell: {cell!r}")
    return match.group(1)


def study_cells() -> dict[tuple[str, str], list[str]]:
    """(function, z) -> [surrogate, c-cma-es, creps-cma-old, pycma one context] at N = 50."""
    text = RESULTS.read_text(encoding="utf-8")
    targets = {(r["function"], r["z"]): r for r in _table_after(text, "## Issue 12's targets")}
    surrogate = {(r["function"], r["z"]): r for r in _table_after(text, "## The surrogate") if r["N"] == "50"}
    cells = {}
    for key, row in surrogate.items():
        plain = targets[key]
        cells[key] = [
            _median(row["C-CMA-ES + surrogate"]),
            _median(plain["C-CMA-ES, N = 50"]),
            _median(plain["CREPS-CMA-old, N = 50"]),
            _median(plain["pycma, 1 context, default N"]),
        ]
    return cells


def doc_cells() -> dict[tuple[str, str], list[str]]:
    text = DOC.read_text(encoding="utf-8")
    block = text[text.index("<!-- budget-table:start -->") : text.index("<!-- budget-table:end -->")]
    return {(r["function"], r["z"]): list(r.values())[2:] for r in _table_after(block, "budget-table")}


def test_the_budget_table_quotes_the_target_study():
    documented, study = doc_cells(), study_cells()
    assert set(documented) == set(study) and len(study) == 4
    assert documented == study


LOW_BUDGET = ROOT / "docs" / "results" / "low_budget" / "full" / "results.md"


def test_the_low_budget_table_quotes_the_low_budget_study_row_for_row():
    """docs/optimizers.md's 50–500-episode rows are rows of the low-budget study's rendered tables at 200
    and 300 episodes, cell for cell."""
    text = DOC.read_text(encoding="utf-8")
    block = text[text.index("<!-- low-budget-table:start -->") : text.index("<!-- low-budget-table:end -->")]
    study = LOW_BUDGET.read_text(encoding="utf-8")
    for episodes in (200, 300):
        heading = f"c-bo against the best other method at {episodes} episodes"
        rendered = {row["task"]: row for row in _table_after(study, "## " + heading)}
        documented = _table_after(block, heading)
        assert len(documented) >= 5
        for row in documented:
            assert row == rendered[row["task"]]
