"""The contextual BBO study (benchmarks/contextual_bbo/): its functions against their formulas, a run's
document, and the committed renderings against the committed run documents."""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("matplotlib")  # the study renders its figures with it (extra 'plot')

from benchmarks.contextual_bbo import floor_probe, problems, protocol, report, run
from benchmarks.contextual_bbo.problems import PROBLEMS, draw_run
from benchmarks.study_tools import load_document

STUDY = Path(run.__file__).resolve().parent


def _scalar(name: str, x: list[float]) -> float:
    """Each function's textbook formula, one point at a time (an independent check of the kernels)."""
    p = len(x)
    if name == "Sphere":
        return sum(v * v for v in x)
    if name == "Rosenbrock":
        return sum(100 * (x[i + 1] - x[i] ** 2) ** 2 + (1 - x[i]) ** 2 for i in range(p - 1))
    if name == "Ellipsoidal":
        return sum(10 ** (6 * i / (p - 1)) * x[i] ** 2 for i in range(p))
    if name == "Discus":
        return 1e6 * x[0] ** 2 + sum(v * v for v in x[1:])
    if name == "DifferentPowers":
        return math.sqrt(sum(abs(x[i]) ** (2 + 4 * i / (p - 1)) for i in range(p)))
    mean_square = sum(v * v for v in x) / p
    waves = sum(math.cos(2 * math.pi * v) for v in x) / p
    return -20 * math.exp(-0.2 * math.sqrt(mean_square)) - math.exp(waves) + 20 + math.e


@pytest.mark.parametrize("name", sorted(PROBLEMS))
def test_each_function_matches_its_formula_and_is_zero_at_the_contextual_optimum(name):
    problem = PROBLEMS[name]
    rng = np.random.default_rng(0)
    points = rng.normal(0.0, 1.5, (4, problems.N_PARAMS))
    for row, value in zip(points, problem.kernel(points), strict=True):
        assert value == pytest.approx(_scalar(name, row.tolist()), rel=1e-12)
    draw = draw_run(problem, seed=3)
    contexts = draw.contexts(5)
    optimum = problem.optimum - contexts @ draw.shift.T  # θ*(s) = x* − G s
    assert np.all(np.abs(draw.regret(contexts, optimum)) < 1e-12)
    assert np.all(draw.regret(contexts, optimum + 0.1) > 1e-4)


def test_the_draw_follows_the_protocol():
    draw = draw_run(PROBLEMS["Sphere"], seed=0)
    assert draw.shift.shape == (20, 2) and draw.initial_mean.shape == (20,)
    contexts = draw.contexts(1000)
    assert contexts.min() >= 1.0 and contexts.max() < 2.0
    assert draw_run(PROBLEMS["Sphere"], seed=0).shift.tolist() == draw.shift.tolist()
    assert PROBLEMS["Ackley"].sigma0 == 14.5 and PROBLEMS["Ackley"].bound == 32.5
    with pytest.raises(ValueError, match="function: expected one of"):
        protocol.ProtocolSpec("Rastrigin", "c-cma-es", 0)


def test_a_run_counts_true_episodes_and_records_its_stack(monkeypatch):
    monkeypatch.setitem(PROBLEMS, "Sphere", problems.Problem("Sphere", 2, 12))
    document = protocol.run_protocol(protocol.ProtocolSpec("Sphere", "c-cma-es", 0))
    assert document["total_episodes"] == 12 * 50 and document["generations_run"] == 12
    assert document["curve"]["generation"][-1] == 12 and document["stop_reason"] == "budget"
    assert document["protocol_last"] == document["curve"]["average_return"][-1] < 0
    assert {"numpy", "scipy", "python", "cpu", "creps_gym"} <= set(document["environment"])


def test_the_protocol_passes_its_budget_and_grows_the_batch_the_optimiser_wants(monkeypatch):
    """C12: the optimiser gets the protocol's budget unless the spec sets it; C13: the batch after each
    restart is the optimiser's wanted one, the curves stay per 50 episodes and the budget is never passed."""
    monkeypatch.setitem(PROBLEMS, "Sphere", problems.Problem("Sphere", 2, 12))
    draw = draw_run(PROBLEMS["Sphere"], 0)
    assert protocol._make(protocol.ProtocolSpec("Sphere", "c-cma-es", 0), draw).config.budget == 600
    unknown = protocol.ProtocolSpec("Sphere", "c-cma-es", 0, (("budget", None),), "today")
    assert protocol._make(unknown, draw).config.budget is None
    options = (("max_condition", 1.0001), ("restart_population_factor", 2.0))  # a stop after every batch
    document = protocol.run_protocol(protocol.ProtocolSpec("Sphere", "c-cma-es", 0, options, "ipop"))
    # batches of 50, 100, 200: after 350 episodes the 250 left cannot carry 2 × 200, so no third restart
    assert document["restarts"] == 2 and document["total_episodes"] == 350
    assert document["generations_run"] == 3 and document["stop_reason"] == "optimizer: max_condition"
    average = document["curve"]["average_return"]
    assert len(average) == 12 and average[0] == average[1] != average[2] and average[6] == average[-1]


def test_the_floor_probe_runs_cells_and_measures_the_baseline_against_the_context_effect(
    monkeypatch, tmp_path
):
    monkeypatch.setitem(PROBLEMS, "Discus", problems.Problem("Discus", 1, 8))
    out = tmp_path / "cells.json"
    options = '{"restarts": 0, "ridge_centre": "old"}'
    assert (
        floor_probe.main(
            ["cells", "--functions", "Discus", "--seeds", "2", "--options", options, "--out", str(out)]
        )
        == 0
    )
    document = json.loads(out.read_text())
    assert [row["seed"] for row in document["rows"]] == [0, 1] and document["options"][
        "ridge_centre"
    ] == "old"
    assert document["rows"][0]["generations_run"] == 8 and document["provenance"]["recorded"] is True
    rows = floor_probe.advantage_rows("Discus", 0, {"restarts": 0}, every=4, draws=50)
    assert [row["generation"] for row in rows] == [0, 4, 7]
    first = rows[0]
    assert (
        first["theta_part_std"] > 0
        and first["baseline_error_rms"] >= 0
        and -1 <= first["tau_advantages_theta"] <= 1
    )
    with pytest.raises(SystemExit):
        floor_probe.main(["cells", "--options", "[1, 2]"])


def test_published_json_holds_every_cell_of_the_published_table_with_its_source():
    published = report.load_published()
    methods = published["methods"]
    assert len(methods) == 7 and len(PROBLEMS) == 6
    cells = [(row["function"], row["method"]) for row in published["values"]]
    assert len(cells) == 42 and set(cells) == {(f, m) for f in PROBLEMS for m in methods}
    for row in [*published["values"], *published["hyperparameter_study"]]:
        assert row["source"] in published["sources"] and row["function"] in PROBLEMS
        if row["value"] is None:  # NaN in the table: the published runs diverged
            assert row["printed"] == "NaN"
        else:
            assert row["value"] == float(row["printed"]) < 0
    value = {(row["function"], row["method"]): row["value"] for row in published["values"]}
    assert value["Sphere", "C-ACM-ES+"] == -1.294e-08 and value["DifferentPowers", "aC-ACM-ES"] == -1.284e-14
    assert value["Ackley", "C-ACM-ES+"] is None and value["Discus", "C-ACM-ES"] == -8.877e-12
    tuned = {(row["function"], row["setting"]): row["value"] for row in published["hyperparameter_study"]}
    assert (
        tuned["Rosenbrock", "n_iter = 10000"] == -2.396e-14
        and tuned["Ackley", "n_start = 3000"] == -3.995e-09
    )
    # the rendered table shows every published cell as printed, in its function's row and method's column
    lines = report.protocol_table([], published).splitlines()
    head = [cell.strip() for cell in lines[0].strip("|").split("|")]
    rows = {line.split("|")[1].strip(): [c.strip() for c in line.strip("|").split("|")] for line in lines[2:]}
    for row in published["values"]:
        assert rows[row["function"]][head.index(row["method"])] == row["printed"]
    assert rows["Rosenbrock"][head.index("hyperparameter study: best")].startswith("-2.396e-14")
    best = report.best_table([], published)
    assert (
        "| DifferentPowers | -1.3e-14 | aC-ACM-ES |" in best
        and "| Rosenbrock | -2.4e-14 | C-ACM-ES, n_iter" in best
    )


@pytest.mark.parametrize("mode", ["quick", "full"])
@pytest.mark.slow
def test_the_committed_results_are_rendered_from_the_committed_runs(tmp_path, mode):
    committed = STUDY / "results" / mode
    if not (committed / "results.md").exists():
        pytest.skip(f"no committed {mode} results")
    shutil.copy(committed / "timing.json", tmp_path / "timing.json")
    assert run.main([f"--{mode}", "--render-only", "--out", str(tmp_path)]) == 0
    assert (tmp_path / "results.md").read_text() == (committed / "results.md").read_text()
    assert (tmp_path / "curves.png").stat().st_size > 10_000
    for spec in run.specs_for(mode, list(PROBLEMS)):
        document = load_document(STUDY / "runs" / ("quick" if mode == "quick" else "") / f"{spec.key}.json")
        assert document is not None, spec.key  # every run of the mode is committed
        assert {"numpy", "scipy", "python", "cpu"} <= set(document["environment"])


def test_the_floor_table_of_the_docs_is_rendered_from_the_committed_floor_runs():
    """docs/algorithms.md's floor table (issue 45): each option's row is the mean protocol measure of its
    ``results/floor`` file, as ``floor_probe.floor_table`` renders it."""
    from benchmarks.contextual_bbo.floor_probe import floor_table

    doc = (Path(__file__).resolve().parents[2] / "docs" / "algorithms.md").read_text(encoding="utf-8")
    assert floor_table() in doc


def test_the_restart_tables_of_the_docs_are_rendered_from_the_committed_restart_runs():
    """docs/algorithms.md's restart tables (issue 45 item 3, C12 and C13): each row is the mean protocol
    measure of its ``results/restarts`` file, as ``floor_probe.restart_tables`` renders it."""
    from benchmarks.contextual_bbo.floor_probe import restart_tables

    doc = (Path(__file__).resolve().parents[2] / "docs" / "algorithms.md").read_text(encoding="utf-8")
    for table in restart_tables():
        assert table in doc
