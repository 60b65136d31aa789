"""c-bo's refit data before and after 2026-11-30 (benchmarks/low_budget/refit_data.py): a run is the study's
column without its pin, it shares the study run's values until the first refit past 256 episodes, and the
committed tables are the renderings of the committed JSON."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from helpers import EXTRAS, skip_unless_stack_of

from benchmarks.low_budget import refit_data
from benchmarks.low_budget.columns import method_by_name, unpinned
from benchmarks.study_options import CBO_FIT_PIN, CBO_KEPT_PINS
from creps_gym.optimizers import make_optimizer

RESULTS = Path(__file__).resolve().parents[2] / "benchmarks" / "low_budget" / "results"
#: The committed measurements: the robot tasks, functions, and two more c-bo columns on the v2 kicks.
NAMES = ["refit_data", "refit_data_functions", "refit_data_columns"]


def test_unpinned_is_the_column_with_c_bos_own_refit_defaults_and_the_former_log_scale_and_floor():
    ucb = unpinned(method_by_name("c-bo-ucb"))
    assert ucb.options == (("acquisition", "ucb"), *CBO_KEPT_PINS) and ucb.name == "c-bo-ucb"
    config = make_optimizer("c-bo", 2, 1, 0, **dict(unpinned(method_by_name("c-bo")).options)).config
    assert (config.fit_points, config.fit_subset) != tuple(dict(CBO_FIT_PIN).values())  # not the pin's
    with pytest.raises(ValueError, match=r"method: expected a c-bo column pinned to .* got 'creps'"):
        unpinned(method_by_name("creps"))
    with pytest.raises(ValueError, match="got 'c-bo-ucb'"):
        unpinned(ucb)  # no pin left to remove


@pytest.mark.slow
@EXTRAS  # bit for bit only on the stack that computed the study's run (the full environment), not the lowest
def test_a_run_is_the_study_runs_column_without_the_pin_and_shares_its_first_episodes():
    """Sphere p = 2, z = 1, seed 0, to 50 episodes: no refit has seen more than 256 episodes, so the value
    is the committed study run's at 50 bit for bit; the run records c-bo's own refit defaults (no options
    but the kept pins)."""
    study = refit_data.study_document("Sphere-p2-z1", "c-bo", 0, 4)
    skip_unless_stack_of(study["provenance"])
    run = refit_data.one("Sphere-p2-z1", "c-bo", 0, 50)
    assert run["options"] == dict(CBO_KEPT_PINS) and run["budgets"] == [50] and run["samples"] == 4
    assert run["values"] == study["values"][:1]
    assert refit_data.study_document("Sphere-p2-z1", "c-bo", 99, 4) is None


def _document(task: str, seed: int, values: list[float]) -> dict:
    return {"spec": {"task": task, "method": "c-bo", "seed": seed}, "task": task, "values": values}


def test_worse_later_compares_the_medians_at_500_and_300_in_each_metrics_direction(tmp_path):
    """A regret that rises from 300 to 500 and a distance that falls are worse; a falling regret is not;
    another column's runs are not counted."""
    flexibility = "KickFlexibilityLowDim-v2"
    documents = {
        "Sphere-p2-z1-c-bo-s0-b500-n4": _document("Sphere-p2-z1", 0, [9, 8, 7, 1.0, 2.0]),
        "Sphere-p2-z1-c-bo-s1-b500-n4": _document("Sphere-p2-z1", 1, [9, 8, 7, 1.0, 3.0]),
        "Rosenbrock-p2-z1-c-bo-s0-b500-n4": _document("Rosenbrock-p2-z1", 0, [9, 8, 7, 2.0, 1.0]),
        f"{flexibility}-c-bo-s0-b500-n4": _document(flexibility, 0, [1, 2, 3, 6.0, 5.0]),
        "Sphere-p4-z1-c-bo-sklearn-s0-b500-n4": _document("Sphere-p4-z1", 0, [1, 1, 1, 1.0, 9.0]),
    }
    documents["Sphere-p4-z1-c-bo-sklearn-s0-b500-n4"]["spec"]["method"] = "c-bo-sklearn"  # the glob finds it
    for name, document in documents.items():
        (tmp_path / f"{name}.json").write_text(json.dumps(document))
    assert refit_data.worse_later("c-bo", tmp_path) == (["KickFlexibilityLowDim-v2", "Sphere-p2-z1"], 3)


@pytest.mark.parametrize("name", NAMES)
def test_the_committed_table_is_the_rendering_of_the_committed_results(tmp_path, name):
    copy = tmp_path / f"{name}.json"
    shutil.copy(RESULTS / f"{name}.json", copy)
    assert refit_data.render(copy) == (RESULTS / f"{name}.md").read_text(encoding="utf-8")


@pytest.mark.parametrize("name", NAMES)
def test_every_committed_run_shares_the_study_runs_first_episodes_and_uses_the_new_default(name):
    """10 seeds per task and column, each with c-bo's own refit defaults, each agreeing with the study's
    committed document of its task, column and seed at 50, 100 and 200 episodes bit for bit. The runs were
    measured before c-bo's log scale and MES's floor changed (2026-11-30), so their options do not name
    the pins that the unpinned column now carries: they ran with them."""
    document = json.loads((RESULTS / f"{name}.json").read_text(encoding="utf-8"))
    assert document["provenance"]["recorded"] is True
    runs = document["runs"]
    for run in runs:
        study = refit_data.study_document(run["task"], run["method"], run["seed"], run["samples"])
        column = dict(unpinned(method_by_name(run["method"])).options)
        assert {**dict(CBO_KEPT_PINS), **run["options"]} == column and run["values"][:3] == study["values"][
            :3
        ]
    for cell in {(run["task"], run["method"]) for run in runs}:
        assert sorted(run["seed"] for run in runs if (run["task"], run["method"]) == cell) == list(range(10))
