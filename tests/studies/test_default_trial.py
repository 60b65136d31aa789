"""``benchmarks/default_trial.py``: a candidate default of ``c-cma-es`` run on a study's specs and compared
with the default column seed by seed; the committed comparisons are rendered from the committed runs."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from benchmarks import default_trial
from benchmarks.study_runner import run_all
from benchmarks.study_tools import RunSpec, store_document

COMMITTED = sorted(default_trial.OUT.glob("*.json"))


def _stored(folder: Path, spec: RunSpec, hit: int | None, final: float) -> dict:
    document = {"spec": {**spec.__dict__, "options": [list(p) for p in spec.options]}, "hit": hit}
    document.update(final=final, values=[final], provenance={"cpu": "test"})
    store_document(folder / f"{spec.key}.json", document)
    return document


def test_only_a_run_that_missed_or_hit_after_half_its_budget_can_change_under_c12():
    spec = {"budget": 1000}
    assert not default_trial.stale({"spec": spec, "hit": 500})
    assert default_trial.stale({"spec": spec, "hit": 501})
    assert default_trial.stale({"spec": spec, "hit": None})


def test_a_trial_spec_adds_its_options_and_they_are_checked():
    spec = RunSpec("Sphere", 3, 1, "c-cma-es", 2, 1000)
    trial = default_trial.trial_spec({**spec.__dict__, "options": []}, {"ridge_centre": "old"})
    assert trial.options == (("ridge_centre", "old"),)
    assert trial.key == "Sphere-p3-z1-c-cma-es-ridge_centre=old-s2-b1000-n50"
    with pytest.raises(ValueError, match="options: expected distinct"):
        default_trial.trial_spec({**spec.__dict__, "options": []}, {"no_such_option": 1})
    with pytest.raises(ValueError, match="options: expected at least one option"):
        default_trial.label_of({})
    assert default_trial.label_of({"b": 1, "a": "x"}) == "a=x-b=1"


def test_cells_pair_each_default_run_with_its_trial_and_rank_hits_before_final_values(tmp_path):
    options = {"ridge_centre": "old"}
    specs = [RunSpec("Sphere", 3, 1, "c-cma-es", seed, 1000) for seed in range(4)]
    outcomes = [((100, 1e-6), (50, 1e-6)), ((None, 1e-3), (900, 1e-6)), ((None, 1e-3), (None, 1e-2))]
    for spec, (base, trial) in zip(specs, outcomes, strict=False):
        _stored(tmp_path, spec, *base)
        _stored(tmp_path, default_trial.trial_spec({**spec.__dict__, "options": []}, options), *trial)
    _stored(tmp_path, specs[3], 10, 1e-6)  # no trial yet: left out
    _stored(tmp_path, RunSpec("Sphere", 3, 1, "creps", 0, 1000), 10, 1e-6)  # another column
    (tmp_path / "link.json").symlink_to(tmp_path / f"{specs[0].key}.json")  # a link is not read
    rows, provenance = default_trial.cells(tmp_path, options)
    assert len(rows) == 1 and provenance == [{"cpu": "test"}]
    row = rows[0]
    assert (row["runs"], row["hits"], row["better"], row["worse"]) == (3, [1, 2], 2, 1)
    assert row["median_episodes"] == [None, 900.0] and row["median_final"] == [1e-3, 1e-6]
    assert row["both_hit"] == 1 and math.isclose(row["log_ratio_sum"], math.log(0.5))
    text = default_trial.render_markdown({"study": "x", "options": options, "label": "l", "cells": rows})
    assert "| Sphere | 3 | 1 | 50 | 1,000 | centre | 3 | 1, 2 | > 1,000 | 900 |" in text
    assert "ranks better in 2 and worse in 1" in text and "geometric mean" in text and "is 0.500." in text


@pytest.mark.slow
def test_a_trial_of_the_defaults_own_value_is_the_default_run_and_a_same_run_keeps_its_file(tmp_path):
    """Twin check of the machinery: the trial of ``ridge_centre="old"`` (the default since issue 45) computes
    the default column's run again, bit for bit; a refreshed run that comes out the same keeps its committed
    file."""
    spec = RunSpec("Sphere", 3, 1, "c-cma-es", 0, 400)
    (default,) = run_all([spec], tmp_path, workers=1, log=lambda line: None)
    committed = json.loads((tmp_path / f"{spec.key}.json").read_text())
    committed["provenance"] = {"marker": "as committed"}
    store_document(tmp_path / f"{spec.key}.json", committed)
    assert default_trial.stale(default)  # 400 episodes never reach the target: refreshed
    assert default_trial.run_trial(tmp_path, {"ridge_centre": "old"}) == 0
    assert json.loads((tmp_path / f"{spec.key}.json").read_text())["provenance"] == {"marker": "as committed"}
    trial = json.loads((tmp_path / "Sphere-p3-z1-c-cma-es-ridge_centre=old-s0-b400-n50.json").read_text())
    assert (trial["values"], trial["final"]) == (default["values"], default["final"])
    (row,), _ = default_trial.cells(tmp_path, {"ridge_centre": "old"})
    assert (row["better"], row["worse"]) == (0, 0)


@pytest.mark.parametrize("path", COMMITTED, ids=lambda path: path.stem)
def test_the_committed_comparisons_are_rendered_from_the_committed_runs(path):
    summary = json.loads(path.read_text(encoding="utf-8"))
    folder, base = default_trial.HERE / summary["study"] / "runs", summary["base"]
    rows, provenance = default_trial.cells(folder, summary["options"], base)
    assert rows == summary["cells"] and provenance == summary["provenance"]
    assert summary["base_runs"] == len(default_trial.default_documents(folder, base))
    assert path.with_suffix(".md").read_text(encoding="utf-8") == default_trial.render_markdown(summary)


def test_a_base_column_is_chosen_by_its_options_and_the_trial_keeps_them(tmp_path):
    base = {"keep_best": False}
    spec = RunSpec("Sphere", 3, 1, "c-cma-es", 0, 1000, options=tuple(base.items()))
    _stored(tmp_path, RunSpec("Sphere", 3, 1, "c-cma-es", 0, 1000), 10, 1e-6)  # the default column
    _stored(tmp_path, spec, 20, 1e-6)
    trial = default_trial.trial_spec(
        {**spec.__dict__, "options": [["keep_best", False]]}, {"ridge_centre": "old"}
    )
    assert trial.options == (("keep_best", False), ("ridge_centre", "old"))
    _stored(tmp_path, trial, 10, 1e-6)
    assert [path.name for path, _ in default_trial.default_documents(tmp_path, base)] == [f"{spec.key}.json"]
    assert default_trial.default_documents(tmp_path, base, match="^Rosenbrock-") == []
    (row,), _ = default_trial.cells(tmp_path, {"ridge_centre": "old"}, base)
    assert (row["median_episodes"], row["better"]) == ([20.0, 10.0], 1)
    assert default_trial.cells(tmp_path, {"ridge_centre": "old"}) == ([], [])  # the default has no trial
    with pytest.raises(SystemExit):
        default_trial.main(["render", "--study", "functions", "--options", "{}"])
