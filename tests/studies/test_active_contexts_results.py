"""The committed comparison of active context choice with uniform draws (benchmarks/low_budget/
active_contexts.py): its table is the rendering of its committed JSON, which holds every run and its
provenance."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from benchmarks.low_budget import active_contexts

RESULTS = Path(__file__).resolve().parents[2] / "benchmarks" / "low_budget" / "results"


NAMES = ("active_contexts", "active_steep")


@pytest.mark.parametrize("name", NAMES)
def test_the_committed_table_is_the_rendering_of_the_committed_results(tmp_path, name):
    copy = tmp_path / f"{name}.json"
    shutil.copy(RESULTS / f"{name}.json", copy)
    assert active_contexts.render(copy) == (RESULTS / f"{name}.md").read_text()


@pytest.mark.parametrize("name", NAMES)
def test_every_task_has_both_selectors_on_the_same_seeds_at_least_five_and_provenance(name):
    document = json.loads((RESULTS / f"{name}.json").read_text())
    assert document["provenance"]["recorded"] is True
    tasks = {(r["function"], r["p"], r["z"]) for r in document["runs"]}
    for task in tasks:
        runs = [r for r in document["runs"] if (r["function"], r["p"], r["z"]) == task]
        seeds = {n: sorted(r["seed"] for r in runs if r["selector"] == n) for n in active_contexts.SELECTORS}
        assert seeds["uniform"] == seeds["active"] and len(seeds["active"]) >= 5
