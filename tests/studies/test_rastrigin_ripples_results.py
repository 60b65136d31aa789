"""Where c-bo's recommendations land on Rastrigin (benchmarks/low_budget/rastrigin_ripples.py): the split of
the regret is Rastrigin's, a replayed run is the replay it is compared with bit for bit, and the committed
table is the rendering of the committed JSON."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from helpers import EXTRAS, skip_unless_stack_of

from benchmarks.low_budget import rastrigin_ripples
from creps_gym.envs.functions.definitions import rastrigin

RESULTS = Path(__file__).resolve().parents[2] / "benchmarks" / "low_budget" / "results"
NAME = "rastrigin_ripples"


def test_landing_splits_rastrigins_regret_into_the_basin_and_the_ripple():
    """At the optimum nothing; at another lattice point the bowl only, outside the optimum's basin; at a
    ripple's rim 20 per coordinate; at uniformly random phases 10 per coordinate on average."""
    at = rastrigin_ripples.landing(np.array([[0.0, 0.0], [1.0, -2.0], [0.5, 0.0]]))
    assert at["regret"] == pytest.approx((0 + 5 + 20.25) / 3)
    assert at["lattice_regret"] == pytest.approx((0 + 5 + 0) / 3)  # 0.5 rounds to its even neighbour, 0
    assert at["basin_share"] == pytest.approx(1 / 3)
    assert at["ripple_per_coordinate"] == pytest.approx(20 / 6)
    phases = np.random.default_rng(0).uniform(-3, 3, size=(20_000, 4))
    random = rastrigin_ripples.landing(phases)
    assert random["ripple_per_coordinate"] == pytest.approx(10, abs=0.2)
    assert random["regret"] == pytest.approx(np.mean(rastrigin(phases)))  # the env's formula, x* = 0


def test_only_rastrigin_tasks_are_replayed():
    with pytest.raises(ValueError, match=r"task_name: expected a Rastrigin task of the study, got 'Sphere"):
        rastrigin_ripples.one_run("Sphere-p2-z1", "c-bo", 0, 50)


@pytest.mark.slow
@EXTRAS  # bit for bit only on the stack that computed the compared replay (the full environment)
def test_a_replayed_run_is_the_compared_replays_run_and_records_the_model():
    """Rastrigin p = 2, z = 1, seed 0, to 50 episodes with c-bo's current defaults: the value at 50 is the
    log-scale replay's bit for bit; the lengthscales are the p = 2 θ coordinates' and the noise share a
    share."""
    against = json.loads((RESULTS / "recommenders_log_quantile.json").read_text(encoding="utf-8"))
    skip_unless_stack_of(against["provenance"])
    theirs = next(r for r in against["runs"] if r["task"] == "Rastrigin-p2-z1" and r["seed"] == 0)
    run = rastrigin_ripples.one_run("Rastrigin-p2-z1", "c-bo", 0, 50, True, {"log_quantile": 0.25})
    (record,) = run["records"]
    assert record["value"] == theirs["values"]["trust_region"][0] and record["episodes"] == 50
    assert len(record["lengthscale_periods"]) == 2 and 0 < record["noise_share"] < 1


def test_the_committed_table_is_the_rendering_of_the_committed_results(tmp_path):
    copy = tmp_path / f"{NAME}.json"
    shutil.copy(RESULTS / f"{NAME}.json", copy)
    assert rastrigin_ripples.render(copy) == (RESULTS / f"{NAME}.md").read_text(encoding="utf-8")


def test_every_committed_run_agrees_with_the_compared_replay_on_ten_seeds_of_every_rastrigin_cell():
    document = json.loads((RESULTS / f"{NAME}.json").read_text(encoding="utf-8"))
    assert document["provenance"]["recorded"] is True
    runs = document["runs"]
    assert sorted((r["task"], r["seed"]) for r in runs) == sorted(
        (task, seed) for task in rastrigin_ripples.TASKS for seed in range(10)
    )
    assert "bit for bit in 60 of 60 runs" in (RESULTS / f"{NAME}.md").read_text(encoding="utf-8")
