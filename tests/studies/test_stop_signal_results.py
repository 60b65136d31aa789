"""c-bo's ``no_signal`` stop measured (benchmarks/low_budget/stop_signal.py): the first statistic is the one
``stop()`` reports, the leave-one-out errors are what their closed form claims, and the committed tables are
the renderings of the committed JSON."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from benchmarks.low_budget import stop_signal
from creps_gym.optimizers import make_optimizer
from creps_gym.optimizers.gp_model import fit_gp

RESULTS = Path(__file__).resolve().parents[2] / "benchmarks" / "low_budget" / "results"
NAMES = ["stop_signal", "stop_signal_noise"]


def test_the_held_out_errors_are_the_leave_one_out_refits_errors():
    """Each episode left out in turn, the GP with the same hyperparameters on the others predicts it: its
    error is r_i, the others' mean's is c_i, to rounding."""
    rng = np.random.default_rng(3)
    inputs = rng.uniform(0, 1, (30, 3))
    targets = np.sin(4 * inputs[:, 0]) + inputs[:, 1] ** 2 + 0.1 * rng.standard_normal(30)
    log_hyper = np.log([0.4, 0.7, 2.0, 1.5, 0.02])
    errors, others = stop_signal.held_out_errors(fit_gp(inputs, targets, log_hyper))
    for i in range(30):
        kept = np.arange(30) != i
        mean = fit_gp(inputs[kept], targets[kept], log_hyper).predict(inputs[i : i + 1])[0][0]
        assert errors[i] == pytest.approx(targets[i] - mean, rel=1e-8, abs=1e-10)
        assert others[i] == pytest.approx(targets[i] - targets[kept].mean(), rel=1e-12)


def test_the_first_statistic_is_the_one_stop_reports():
    """Four (s, θ) told 15 times each with standard normal returns: ``stop()`` reports its noise share,
    and the leave-one-out statistics see noise too."""
    optimizer = make_optimizer("c-bo", 2, 1, 0)
    rng = np.random.default_rng(0)
    contexts, params = rng.uniform(0, 3, (4, 1)), rng.uniform(-3, 3, (4, 2))
    for _ in range(15):
        optimizer.tell(contexts, params, rng.standard_normal(4), allow_external=True)
    found = stop_signal.statistics(optimizer)
    assert optimizer.stop() == {"no_signal": found[0]}
    assert min(found[1:]) >= 0.95


def test_a_noise_run_records_every_look_from_50_episodes():
    run = stop_signal.one_run("Sphere-p2-z1", "c-bo", 0, 60, noise=True)
    assert [record[0] for record in run["records"]] == [52, 56, 60] and run["noise"] is True
    assert all(len(record) == 4 and min(record[1:]) >= 0 for record in run["records"])


@pytest.mark.parametrize("name", NAMES)
def test_the_committed_table_is_the_rendering_of_the_committed_results(tmp_path, name):
    copy = tmp_path / f"{name}.json"
    shutil.copy(RESULTS / f"{name}.json", copy)
    assert stop_signal.render(copy) == (RESULTS / f"{name}.md").read_text(encoding="utf-8")


def test_the_committed_measurement_covers_every_task_and_stop_never_ends_a_task_run():
    document = json.loads((RESULTS / "stop_signal.json").read_text(encoding="utf-8"))
    assert document["provenance"]["recorded"] is True
    runs = document["runs"]
    cells = sorted((r["task"], r["method"], r["seed"]) for r in runs)
    assert cells == sorted(
        (t, m, s) for t in stop_signal.TASKS for m in ("c-bo", "c-bo+quadratic") for s in range(3)
    )
    assert max(record[1] for run in runs for record in run["records"]) < stop_signal.THRESHOLD
