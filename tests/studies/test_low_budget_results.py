"""The quick low-budget measurements of issue 44 (benchmarks/low_budget/results/): every committed table is
rendered from its committed JSON by the committed code."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from benchmarks.low_budget import compare, gp_backends

RESULTS = Path(__file__).resolve().parents[2] / "benchmarks" / "low_budget" / "results"


@pytest.mark.parametrize(("name", "module"), [("quick", compare), ("gp_backends", gp_backends)])
def test_the_committed_table_is_the_rendering_of_the_committed_results(name, module, tmp_path):
    copy = tmp_path / f"{name}.json"
    shutil.copy(RESULTS / f"{name}.json", copy)
    assert module.render(copy) == (RESULTS / f"{name}.md").read_text()


def test_the_quick_results_have_every_method_and_seed_and_their_provenance():
    import json

    document = json.loads((RESULTS / "quick.json").read_text())
    assert document["provenance"]["recorded"] is True
    cells = {(run["function"], run["method"]) for run in document["runs"]}
    assert ("Rosenbrock", "c-bo") in cells and ("Sphere", "creps-cma-old") in cells
    assert all(sum((r["function"], r["method"]) == cell for r in document["runs"]) == 3 for cell in cells)
