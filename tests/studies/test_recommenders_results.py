"""c-bo's recommendation rules on the same runs (benchmarks/low_budget/recommenders.py): a run is the
low-budget study's run bit for bit, every rule is measured on it without changing it, and the committed
table is the rendering of the committed JSON, whose every run agrees with the study's documents."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from helpers import EXTRAS, driven_cbo, skip_unless_stack_of

from benchmarks.low_budget import recommenders, replay_results_path
from benchmarks.low_budget.columns import method_by_name
from benchmarks.study_options import CBO_KEPT_PINS, CBO_PINS

RESULTS = Path(__file__).resolve().parents[2] / "benchmarks" / "low_budget" / "results"
#: The committed measurements: the v1 kicks, with the quadratic prior mean, the functions, the v2 kicks (on
#: the study's runs), and the v2 and v1 kicks with c-bo's own defaults (``--unpinned``).
STUDY_NAMES = [
    "recommenders",
    "recommenders_quadratic",
    "recommenders_functions",
    "recommenders_v2",
    "recommenders_v2_defaults",
    "recommenders_defaults",
]
MIRROR = {"symmetric_contexts": [1], "mean_features": "quadratic"}
SCALE = {"log_quantile": 0.25}
#: The replays with options added (``--options``), by name: (their options, those of the replay they are
#: compared with (``--against``; None: none), their budgets). The flexibility kicks with the mirror
#: symmetry against the replay without it (the v2 kick on the study's seeds and on seeds 10-19, the v1
#: kick); c-bo's log scale of 2026-11-30 on the functions (to 300 episodes), and on the v2 kicks against the
#: former scale, with and without the mirror.
OPTION_NAMES = {
    "recommenders_v2_mirror": (MIRROR, {}, (50, 100, 200, 300, 500)),
    "recommenders_v2_mirror_heldout": (MIRROR, {}, (50, 100, 200, 300, 500)),
    "recommenders_mirror": (MIRROR, {}, (50, 100, 200, 300, 500)),
    "recommenders_log_quantile": (SCALE, None, (50, 100, 200, 300)),
    "recommenders_v2_log_quantile": (SCALE, {}, (50, 100, 200, 300, 500)),
    "recommenders_v2_mirror_log_quantile": ({**MIRROR, **SCALE}, MIRROR, (50, 100, 200, 300, 500)),
}
NAMES = STUDY_NAMES + list(OPTION_NAMES) + ["recommenders_v2_defaults_heldout"]


@pytest.mark.slow
@EXTRAS  # bit for bit only on the stack that computed the study's run (the full environment), not the lowest
def test_a_run_is_the_study_run_and_every_rule_is_measured_on_it():
    """Rosenbrock p = 2, z = 1, seed 0, to 50 episodes: the default rule's value is the committed study
    run's at 50 bit for bit (so measuring the other rules changed nothing before it), and the other rules
    give their own finite values; off the kicks there are no falls to count."""
    study_run = json.loads((recommenders.RUNS / "Rosenbrock-p2-z1-c-bo-s0-b500-n4.json").read_text())
    skip_unless_stack_of(study_run["provenance"])
    run = recommenders.one_run("Rosenbrock-p2-z1", "c-bo", 0, 50)
    assert run["budgets"] == [50] and run["key"] == "Rosenbrock-p2-z1-c-bo-s0-b50-n4"
    assert recommenders.check_against_study(run) is True
    trust, observed = run["values"]["trust_region"][0], run["values"]["observed"][0]
    assert trust != observed and observed > 0.0 and run["values"]["neighbours"][0] > 0.0
    assert run["falls"] == {"trust_region": [None], "observed": [None], "neighbours": [None]}
    tampered = {**run, "values": {**run["values"], "trust_region": [trust * (1 + 1e-15)]}}
    assert recommenders.check_against_study(tampered) is False


def test_a_run_needs_a_c_bo_column_and_leaves_the_optimisers_rule_as_it_was():
    with pytest.raises(ValueError, match=r"method: expected a c-bo column, got 'creps' \(creps\)"):
        recommenders.one_run("Rosenbrock-p2-z1", "creps", 0, 50)
    assert recommenders.check_against_study({"key": "Nothing-c-bo-s0-b50-n4"}) is None
    optimizer = driven_cbo()
    config, test = optimizer.config, np.linspace(0, 1, 3)[:, None]
    default = optimizer.recommend(test)
    observed = recommenders.recommend_with(optimizer, "observed", test)
    assert optimizer.config is config and optimizer.recommend(test).tobytes() == default.tobytes()
    assert all((optimizer.params == row).all(axis=1).any() for row in observed)


def test_an_unpinned_run_must_agree_with_the_study_only_where_both_fitted_on_the_same_episodes(tmp_path):
    """c-bo's defaults and the study's pin (the 256 most recent episodes) see the same data up to 256
    episodes: an ``unpinned`` run agrees if its values at 50, 100 and 200 are the study's, whatever they are
    at 300 and 500; a pinned run must agree at every budget. The table says which it is."""
    study = json.loads((recommenders.RUNS / "Rosenbrock-p2-z1-c-bo-s0-b500-n4.json").read_text())
    values = [*study["values"][:3], study["values"][3] * 0.5, study["values"][4] * 0.5]
    run = {"key": "Rosenbrock-p2-z1-c-bo-s0-b500-n4", "budgets": study["budgets"]}
    run |= {"values": {"trust_region": values, "observed": values}, "falls": {"trust_region": [None] * 5}}
    assert recommenders.check_against_study(run) is False
    unpinned = {**run, "unpinned": True}
    assert recommenders.check_against_study(unpinned) is True
    changed = [values[0] * 2, *values[1:]]
    assert recommenders.check_against_study({**unpinned, "values": {"trust_region": changed}}) is False
    runs = [{**unpinned, "task": "Rosenbrock-p2-z1", "method": "c-bo", "seed": 0, "test_contexts": 100}]
    runs[0]["falls"] = {"trust_region": [None] * 5, "observed": [None] * 5}
    path = tmp_path / "unpinned.json"
    path.write_text(json.dumps({"command": ["recommenders.py", "--unpinned"], "runs": runs}))
    text = recommenders.render(path)
    assert (
        "c-bo's defaults (`--unpinned`)" in text and "up to 256 episodes" in text and "in 1 of 1 runs" in text
    )


def test_unpinned_and_options_reach_the_run_as_the_column_they_describe(monkeypatch, tmp_path):
    """``--first-seed`` shifts the seeds; ``--unpinned`` and ``--options`` give each job a fifth and a sixth
    element, and ``one_run`` then starts the study's run with the column's options less the refit pin (the
    log pin stays: the unpinned runs were measured before the log scale's default changed), plus the added
    ones (with neither: the study's column, None)."""
    jobs = []
    monkeypatch.setattr("benchmarks.low_budget.run_and_write", lambda job, todo, *rest: jobs.extend(todo))
    out = ["--out", str(tmp_path / "r.json"), "--seeds", "1", "--tasks", "Sphere-p2-z1"]
    recommenders.main(["--unpinned", *out])
    recommenders.main(out)
    against = ["--against", "benchmarks/low_budget/results/recommenders_v2_defaults.json"]
    recommenders.main(["--options", '{"symmetric_contexts": [0]}', "--first-seed", "10", *against, *out])
    assert jobs == [
        ("Sphere-p2-z1", "c-bo", 0, 500, True, {}),
        ("Sphere-p2-z1", "c-bo", 0, 500, False, {}),
        ("Sphere-p2-z1", "c-bo", 10, 500, False, {"symmetric_contexts": [0]}),
    ]
    for bad in (["--options", "[1]"], ["--against", "benchmarks/low_budget/results/missing.json"]):
        with pytest.raises(SystemExit):  # argparse names the argument, before anything runs
            recommenders.main([*bad, *out])
    assert len(jobs) == 3
    started = []

    def spy(spec, method=None):
        started.append(method)
        raise RuntimeError("stop here")

    monkeypatch.setattr(recommenders, "start_run", spy)
    for flag, options in ((True, None), (False, None), (True, {"symmetric_contexts": [1]})):
        with pytest.raises(RuntimeError, match="stop here"):
            recommenders.one_run("Sphere-p2-z1", "c-bo", 0, 50, flag, options)
    assert started[1] is None and dict(started[0].options) == dict(CBO_KEPT_PINS)
    assert dict(started[2].options) == {**dict(CBO_KEPT_PINS), "symmetric_contexts": (1,)}
    assert dict(method_by_name("c-bo").options) == dict(CBO_PINS)


@pytest.mark.parametrize("name", NAMES)
def test_the_committed_table_is_the_rendering_of_the_committed_results(tmp_path, name):
    copy = tmp_path / f"{name}.json"
    shutil.copy(RESULTS / f"{name}.json", copy)
    assert recommenders.render(copy) == (RESULTS / f"{name}.md").read_text(encoding="utf-8")


@pytest.mark.parametrize("name", STUDY_NAMES)
def test_every_committed_run_is_the_study_run_of_its_task_column_and_seed(name):
    """Each run's default-rule values equal the study's committed document bit for bit, at every budget,
    for 10 seeds of each task, and the kicks count their falls."""
    document = json.loads((RESULTS / f"{name}.json").read_text(encoding="utf-8"))
    assert document["provenance"]["recorded"] is True
    runs = document["runs"]
    assert all(recommenders.check_against_study(run) is True for run in runs)
    for task in {run["task"] for run in runs}:
        assert sorted(run["seed"] for run in runs if run["task"] == task) == list(range(10))
    assert all(None not in run["falls"]["observed"] for run in runs if run["task"].startswith("Kick"))


@pytest.mark.parametrize("name", OPTION_NAMES)
def test_a_replay_with_added_options_names_them_and_its_baseline_has_the_same_seeds(name):
    """Every run of the replay carries the added options and ten consecutive seeds per task; the replay it
    is compared with (``--against``) is committed, with its own options, on the same tasks and seeds."""
    options, baseline_options, budgets = OPTION_NAMES[name]
    document = json.loads((RESULTS / f"{name}.json").read_text(encoding="utf-8"))
    runs = document["runs"]
    assert all(run["options"] == options and run["unpinned"] for run in runs)
    assert {tuple(run["budgets"]) for run in runs} == {budgets}
    if baseline_options is None:
        assert "against" not in document
        baseline = runs
    else:
        baseline = json.loads(replay_results_path(document["against"]).read_text(encoding="utf-8"))["runs"]
        assert all(run.get("options", {}) == baseline_options and run["unpinned"] for run in baseline)
        assert {tuple(run["budgets"]) for run in baseline} == {(50, 100, 200, 300, 500)}
    for task in {run["task"] for run in runs}:
        seeds = sorted(run["seed"] for run in runs if run["task"] == task)
        assert seeds == list(range(seeds[0], seeds[0] + 10))
        assert seeds == sorted(run["seed"] for run in baseline if run["task"] == task)


def test_targets_sets_the_runs_beside_the_studys_c_bo_and_best_other_column_at_200(tmp_path):
    """The ratio to the best column that is not c-bo's (here ``creps``; ``c-bo-ucb`` is c-bo's), the
    study's ``c-bo`` ratio, the seeds where the runs beat the study's ``c-bo`` run of the same seed, and
    the count of tasks where ≤ 0.5 holds; robot tasks and runs without the budget are left out."""
    task = "Rosenbrock-p2-z1"
    study = {"c-bo": [4.0, 2.0, 3.0], "c-bo-ucb": [0.1, 0.1, 0.1], "creps": [10.0, 8.0, 6.0]}
    for method, values in study.items():
        for seed, value in enumerate(values):
            spec = {"task": task, "method": method, "seed": seed}
            document = {"spec": spec, "budgets": [100, 200], "values": [99.0, value]}
            (tmp_path / f"{task}-{method}-s{seed}-b500-n4.json").write_text(json.dumps(document))

    def run(seed, value, name=task, budgets=(100, 200)):
        values = {rule: [99.0, value] for rule in recommenders.RULES}
        key = f"{name}-c-bo-s{seed}-b500-n4"
        cell = {"task": name, "method": "c-bo", "seed": seed, "key": key}
        return {**cell, "budgets": list(budgets), "values": values}

    runs = [run(0, 1.0), run(1, 3.0), run(2, 2.0), run(0, 0.3, "KickPrecisionLowDim-v2")]
    text = recommenders.targets(runs, study=tmp_path)
    assert f"| {task} | 2 | 3 | 8 (`creps`) | 0.25 | 0.375 | 2 of 3 |" in text.splitlines()
    assert "holds on 1 of 1 tasks for these runs and on 1 for the study's `c-bo`" in text
    assert "KickPrecision" not in text
    assert recommenders.targets([run(0, 1.0, budgets=(50, 100))], study=tmp_path) == ""
    elsewhere = recommenders.targets([run(0, 1.0, "Sphere-p2-z1")], study=tmp_path)  # no study runs there
    assert "| Sphere-p2-z1 | 1 | — | — | — | — | 0 of 0 |" in elsewhere.splitlines()


def test_versus_counts_the_seeds_where_the_runs_beat_their_baseline():
    """Medians over the seeds both replays have, task by task, and the wins by the task's direction (the
    flexibility's distance: larger is better; the precision's error: smaller)."""

    def run(seed, value, task="KickFlexibilityLowDim-v2"):
        values = {rule: [value, value + 1.0] for rule in recommenders.RULES}
        return {"task": task, "method": "c-bo", "seed": seed, "budgets": [50, 100], "values": values}

    runs = [run(0, 6.0), run(1, 5.0), run(2, 7.0), run(3, 1.0)]  # seed 3: not in the baseline
    baseline = [run(0, 5.0), run(1, 5.5), run(2, 6.0)]
    precision = "KickPrecisionLowDim-v2"  # a second task's runs pair with its own baseline alone
    runs += [run(0, 0.2, precision), run(1, 0.4, precision)]
    baseline += [run(0, 0.3, precision), run(1, 0.3, precision)]
    table = recommenders.versus(runs, baseline).splitlines()
    assert "| KickFlexibilityLowDim-v2 | c-bo | 50 | trust_region | 6 | 5.5 | 2 of 3 |" in table
    assert "| KickFlexibilityLowDim-v2 | c-bo | 100 | neighbours | 7 | 6.5 | 2 of 3 |" in table
    assert "| KickPrecisionLowDim-v2 | c-bo | 50 | trust_region | 0.3 | 0.3 | 1 of 2 |" in table
    assert len(table) == 2 + 4 * len(recommenders.RULES)


def test_the_side_studies_parse_their_runs_arguments_and_render_only_when_asked(tmp_path, capsys):
    """``--seeds`` (each script's default), ``--workers`` and ``--out``; ``--render-only`` prints the table
    rendered from ``--out`` and computes nothing."""
    import argparse

    from benchmarks.low_budget import parse_runs_arguments

    out = tmp_path / "results.json"
    args = parse_runs_arguments(argparse.ArgumentParser(), ["--out", str(out)], 10, lambda path: "never")
    assert (args.seeds, args.workers, args.out, args.render_only) == (10, 1, out, False)
    shutil.copy(RESULTS / "recommenders.json", out)
    argv = ["--out", str(out), "--render-only", "--seeds", "3"]
    assert parse_runs_arguments(argparse.ArgumentParser(), argv, 10, recommenders.render) is None
    assert capsys.readouterr().out == (RESULTS / "recommenders.md").read_text(encoding="utf-8") + "\n"
