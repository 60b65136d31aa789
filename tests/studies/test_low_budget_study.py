"""The low-budget study (``benchmarks/low_budget/run.py``, issue 44 item 5): its runs, its cache, its report,
and the committed renderings, which must be what ``--render-only`` draws from the committed runs."""

from __future__ import annotations

import dataclasses
import json
import shutil
from pathlib import Path

import pytest
from helpers import EXTRAS, no_figure, skip_unless_stack_of

pytest.importorskip("matplotlib")

from benchmarks.low_budget import columns, study
from benchmarks.low_budget import run as study_run
from benchmarks.low_budget.report import ANCHORS

TINY = ["--functions", "Sphere", "--robots", "--methods", "creps", "c-bo", "--workers", "1"]


def _tiny(tmp_path: Path, *flags: str) -> Path:
    out = tmp_path / "out"
    argv = ["--quick", *TINY, "--cache", str(tmp_path / "runs"), "--out", str(out), *flags]
    assert study_run.main(argv) == 0
    return out / "results.md"


@pytest.mark.slow
def test_quick_mode_writes_runs_with_their_curve_timing_and_provenance(tmp_path: Path) -> None:
    table = _tiny(tmp_path, "--seeds", "1", "--budget", "24").read_text()
    documents = {p.stem: json.loads(p.read_text()) for p in (tmp_path / "runs").glob("*.json")}
    assert sorted(documents) == ["Sphere-p2-z1-c-bo-s0-b24-n4", "Sphere-p2-z1-creps-s0-b24-n12"]
    for document in documents.values():
        assert document["budgets"] == [24] and document["episodes"] == [24]
        assert document["provenance"]["recorded"] is True and document["values"][0] >= 0
        assert "cma" in document["provenance"]["packages"]  # as every study's; no kick here: no MuJoCo
        assert "mujoco" not in document["provenance"]["packages"]
        assert document["optimizer_seconds"][0] > 0 and document["last_batch_seconds_per_episode"][0] > 0
        assert document["optimizer_cpu_seconds"][0] > 0 and document["cpu_seconds"] > 0
    assert "| `c-bo` | 4 |" in table and "Sphere-p2-z1" in table
    assert all(anchor in table for anchor in ANCHORS) and "not computed here" in table
    # A second invocation with more seeds marks the cells whose seeds have not all finished.
    partial = _tiny(tmp_path, "--seeds", "2", "--budget", "24", "--render-only").read_text()
    assert "[1/2]" in partial and "Partial: 2 of 4 runs" in partial


def test_a_runs_provenance_records_what_its_task_and_column_use() -> None:
    """A library column's run records its library's version, a kick's MuJoCo's, and no run another's."""
    spec = study.LowBudgetSpec
    assert study_run.run_packages(spec("Rosenbrock-p2-z1", "c-bo-sklearn", 0, 500)) == ("cma", "scikit-learn")
    assert study_run.run_packages(spec("KickPrecisionLowDim-v2", "c-bo", 0, 500)) == ("cma", "mujoco")
    botorch = study_run.run_packages(spec("KickFlexibilityLowDim-v2", "c-bo-botorch", 0, 500))
    assert botorch == ("cma", "mujoco", "torch", "botorch", "gpytorch")
    assert study_run.run_packages(spec("PlanarReacherLowDim", "creps", 0, 500)) == ("cma",)  # numpy alone


def test_a_run_is_deterministic_and_its_budgets_come_from_one_run() -> None:
    spec = study.LowBudgetSpec("Rosenbrock-p2-z1", "creps", 3, 100)
    first, second = study.one_run(spec), study.one_run(spec)
    assert first["values"] == second["values"] and spec.budgets == (50, 100)
    assert first["episodes"] == [48, 96] and first["budgets"] == [50, 100]  # whole batches of 12
    shorter = study.one_run(dataclasses.replace(spec, budget=50))
    assert shorter["values"] == first["values"][:1]  # the curve's first point is the 50-episode run's end
    assert spec.key == "Rosenbrock-p2-z1-creps-s3-b100-n12"


@EXTRAS  # bit for bit only on the stack that computed it (the full environment), not the lowest versions
@pytest.mark.slow
def test_a_committed_c_bo_run_is_what_the_code_computes() -> None:
    """The c-bo columns are the code's: a committed quick run (the reacher's, 100 episodes) computed again
    gives its curve and test contexts bit for bit (the GP's solves call LAPACK directly: the same bits)."""
    path = Path(study_run.__file__).parent / "runs" / "quick" / "PlanarReacherLowDim-c-bo-s0-b100-n4.json"
    committed = json.loads(path.read_text(encoding="utf-8"))
    skip_unless_stack_of(committed["provenance"])
    computed = study.one_run(study.LowBudgetSpec("PlanarReacherLowDim", "c-bo", 0, 100))
    for field in ("values", "episodes", "test_contexts", "final", "stop_reason"):
        assert computed[field] == committed[field], field


def test_mes_against_ucb_is_counted_seed_by_seed_with_an_exact_sign_test() -> None:
    from benchmarks.low_budget.report import paired_table, sign_test

    assert sign_test(5, 10) == 1.0 and sign_test(0, 0) == 1.0
    assert sign_test(10, 10) == pytest.approx(2 / 1024) and sign_test(1, 10) == pytest.approx(22 / 1024)

    def run(method, seed, value):
        spec = {"task": "KickFlexibilityLowDim", "method": method, "seed": seed}
        return {"spec": spec, "budgets": [200], "values": [value]}

    grouped = {  # distance: higher is better; seed 2 ties, seed 3 has no UCB run
        ("KickFlexibilityLowDim", "c-bo"): [run("c-bo", s, v) for s, v in enumerate([3.0, 1.0, 2.0, 5.0])],
        ("KickFlexibilityLowDim", "c-bo-ucb"): [run("c-bo-ucb", s, v) for s, v in enumerate([2.0, 4.0, 2.0])],
    }
    table = paired_table(grouped, ["KickFlexibilityLowDim", "Sphere-p2-z1"], [200], "c-bo", "c-bo-ucb")
    assert "| KickFlexibilityLowDim | 1/2 (p 1) |" in table and "Sphere" not in table


def test_the_library_columns_are_set_beside_c_bo_seed_by_seed() -> None:
    from benchmarks.low_budget.report import library_table

    def run(method, seed, values):
        spec = {"task": "Sphere-p2-z1", "method": method, "seed": seed}
        return {"spec": spec, "budgets": [50, 100], "values": values}

    grouped = {  # regret: lower is better; at 100 sklearn beats c-bo on seeds 0 and 1, ties on 2
        ("Sphere-p2-z1", "c-bo"): [run("c-bo", s, [9.0, v]) for s, v in enumerate([3.0, 2.0, 1.0])],
        ("Sphere-p2-z1", "c-bo-sklearn"): [
            run("c-bo-sklearn", s, [8.0, v]) for s, v in enumerate([1.0, 1.0, 1.0])
        ],
        ("Rosenbrock-p2-z1", "c-bo"): [run("c-bo", 0, [1.0, 1.0])],  # no library run: no row
    }
    table = library_table(grouped, ["Sphere-p2-z1", "Rosenbrock-p2-z1"], 4, [50, 100])
    assert "| Sphere-p2-z1 | `c-bo` | 9 [3/4] | 2 [3/4] |  |" in table
    assert "| Sphere-p2-z1 | `c-bo-sklearn` | 8 [3/4] | 1 [3/4] | 2/2 (p 0.5) |" in table
    assert "| Sphere-p2-z1 | `c-bo-botorch` | — | — | — |" in table and "Rosenbrock" not in table


def test_every_method_starts_from_the_same_distribution(monkeypatch: pytest.MonkeyPatch) -> None:
    seen = []

    def spy(name, p, z, seed, **options):
        seen.append((name, options["initial_mean"].tolist(), options["initial_cov"].tolist()))
        raise RuntimeError("stop here")

    monkeypatch.setattr(columns, "make_optimizer", spy)
    for method in ("c-bo", "c-cma-es"):
        with pytest.raises(RuntimeError):
            study.one_run(study.LowBudgetSpec("Sphere-p4-z1", method, 0, 50))
    assert seen == [(m, [0.0] * 4, [4.0] * 4) for m in ("c-bo", "c-cma-es")]


def test_a_selector_variant_is_one_more_method_entry(monkeypatch: pytest.MonkeyPatch) -> None:
    variant = columns.Method("creps+arcsine", "creps", (("epsilon", 1.0),), selector="arcsine")
    monkeypatch.setattr(columns, "METHODS", (*columns.METHODS, variant))
    document = study.one_run(study.LowBudgetSpec("Sphere-p2-z1", "creps+arcsine", 0, 50))
    assert document["method"]["selector"] == "arcsine" and document["stop_reason"] == "budget"
    plain = study.one_run(study.LowBudgetSpec("Sphere-p2-z1", "creps", 0, 50))
    assert document["values"] != plain["values"]  # the selector's contexts, not the env's draws


def test_unknown_tasks_methods_and_bad_budgets_are_rejected() -> None:
    with pytest.raises(ValueError, match="task"):
        study.LowBudgetSpec("Sphere-p4", "creps", 0)
    with pytest.raises(ValueError, match="task"):
        study.LowBudgetSpec("Plane-p4-z1", "creps", 0)
    with pytest.raises(ValueError, match="method"):
        study.LowBudgetSpec("Sphere-p4-z1", "cma", 0)
    with pytest.raises(ValueError, match="budget"):
        study.LowBudgetSpec("Sphere-p4-z1", "creps", 0, 0)


def test_the_full_study_computes_the_issues_target_cells_first() -> None:
    specs = study_run.study_specs(study_run.parse_args(["--full"]))
    methods = len(columns.METHODS)
    assert len(specs) == 37 * methods * 10 and len({s.key for s in specs}) == len(specs)
    first = [s.task for s in specs[: 6 * methods * 10 : methods * 10]]
    targets = ["Rosenbrock-p4-z1", "DifferentPowers-p4-z1", "Rastrigin-p4-z1", "KickPrecisionLowDim"]
    assert first == [*targets, "KickPrecisionLowDim-v1", "KickPrecisionLowDim-v2"]
    robots = study_run.study_specs(
        study_run.parse_args(["--full", "--functions", "--robots", "KickPrecisionLowDim"])
    )
    assert {s.task for s in robots} == {"KickPrecisionLowDim"}  # `--functions` with none: only the robots
    assert [(s.method, s.seed) for s in specs[: methods + 1]][-1] == ("c-bo", 1)  # seed by seed, every method


@pytest.mark.slow
@pytest.mark.parametrize("mode", ["quick", "full"])
def test_committed_renderings_are_drawn_from_the_committed_runs(
    mode: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``--render-only`` on the committed runs reproduces the committed table (the figure, which depends on
    the matplotlib version, is not drawn here)."""
    committed = study_run.parse_args([f"--{mode}"]).out
    if not (committed / "results.md").exists():
        pytest.skip(f"{committed} is not rendered yet: python benchmarks/low_budget/run.py --{mode}")
    monkeypatch.setattr(study_run, "plot_curves", no_figure)
    shutil.copy(committed / "timing.json", tmp_path / "timing.json")
    assert study_run.main([f"--{mode}", "--render-only", "--out", str(tmp_path)]) == 0
    assert (tmp_path / "results.md").read_text() == (committed / "results.md").read_text()


def test_the_cost_estimate_uses_the_finished_runs_of_the_same_method_and_names_what_it_cannot_estimate() -> (
    None
):
    from benchmarks.low_budget.report import cost_text

    documents = [
        {"spec": {"task": "Sphere-p2-z1", "method": "creps", "seed": s}, "cpu_seconds": 1.0 + 2 * s}
        for s in (0, 1)
    ]
    specs = [study.LowBudgetSpec("Sphere-p2-z1", "creps", s) for s in range(3)]
    specs += [
        study.LowBudgetSpec("Rosenbrock-p2-z1", "creps", 0),
        study.LowBudgetSpec("Sphere-p4-z1", "c-bo", 0),
    ]
    text = cost_text(documents, specs)
    assert "2 runs finished, 3 missing" in text and "0.0 h" in text  # 2 s + 2 s (the same p and z)
    assert "not estimated (no finished run): cheap env: c-bo." in text
    assert "| Sphere-p2-z1 | `creps` | 2 | 2 (1–3) |" in text


def test_the_report_says_which_tasks_are_complete_partial_or_not_started() -> None:
    from benchmarks.low_budget.report import completeness_text

    specs = [
        study.LowBudgetSpec(t, "creps", s)
        for t in ("Sphere-p2-z1", "Sphere-p4-z1", "Sphere-p8-z1")
        for s in (0, 1)
    ]
    documents = [{"spec": {"task": "Sphere-p2-z1", "method": "creps", "seed": s}} for s in (0, 1)]
    documents.append({"spec": {"task": "Sphere-p4-z1", "method": "creps", "seed": 1}})
    assert completeness_text(documents, specs) == (
        "Complete tasks: Sphere-p2-z1. Partial: Sphere-p4-z1 (1 of 2 runs). "
        "Not started: 1 task(s) (Sphere-p8-z1).\n"
    )


def test_an_active_column_chooses_its_contexts_with_the_optimisers_model():
    """The active selector gets c-bo's ``context_utility`` in the study's loop (without it every context is a
    uniform draw and the column is c-bo's bit for bit, as the first active runs were): every committed run
    of an active column differs from the run of its optimiser alone."""
    runs = sorted(
        (Path(__file__).resolve().parents[2] / "benchmarks/low_budget/runs").rglob("*+active-s*.json")
    )
    assert runs
    for path in runs:
        alone = path.with_name(path.name.replace("+active", ""))
        assert json.loads(path.read_text())["values"] != json.loads(alone.read_text())["values"], path.name


def test_every_committed_run_records_its_columns_optimiser_options_and_selector():
    """A run's file name holds its column's name, not its options: a column whose options changed (as
    c-bo+quadratic's transform did) must not leave runs of the old options behind under the same name."""
    methods = {method.name: method for method in columns.METHODS}
    runs = Path(__file__).resolve().parents[2] / "benchmarks/low_budget/runs"
    paths = sorted(runs.rglob("*.json"))
    assert len(paths) > 1000
    for path in paths:
        document = json.loads(path.read_text(encoding="utf-8"))
        method = methods[document["spec"]["method"]]
        options = dict(method.options)
        expected = {"optimizer": method.optimizer, "options": options, "selector": method.selector}
        expected |= {} if method.factory is None else {"factory": method.factory}
        assert document["method"] == expected, path.name


def _committed_text(*parts: str) -> str:
    """A committed file of the repository, by its path's parts."""
    return Path(study_run.__file__).resolve().parents[2].joinpath(*parts).read_text(encoding="utf-8")


def _table(results: str, heading: str) -> list[list[str]]:
    """The table under ``heading`` in ``results``: its header and rows as lists of cells."""
    section = results[results.index(heading) :].split("\n## ")[0]
    lines = [line.strip() for line in section.splitlines() if line.startswith("|")]
    return [[c.strip() for c in line.strip("|").split("|")] for line in lines if not line.startswith("|---")]


def test_the_docs_library_comparison_quotes_the_rendered_tables() -> None:
    """docs/optimizers.md's c-bo against c-bo-botorch and c-bo-sklearn: every number from the full results."""
    results = _committed_text("docs", "results", "low_budget", "full", "results.md")
    doc = " ".join(_committed_text("docs", "optimizers.md").split())
    library = {(row[0], row[1].strip("`")): row[2:] for row in _table(results, "## c-bo on its own GP")[1:]}

    def at_500(task: str, method: str) -> str:
        return library[(task, method)][4].split(" [")[0]

    def better(task: str) -> str:  # "k/n (p …)": the seeds where scikit-learn's run ends better than c-bo's
        return library[(task, "c-bo-sklearn")][5].split(" (")[0].replace("/", " of ")

    rb, dp, ra = (f"{f}-p4-z1" for f in ("Rosenbrock", "DifferentPowers", "Rastrigin"))
    pr, fl = "KickPrecisionLowDim-v1", "KickFlexibilityLowDim-v1"
    phrases = [
        f"Rosenbrock (p = 4, z = 1) {at_500(rb, 'c-bo')} against BoTorch's {at_500(rb, 'c-bo-botorch')} "
        f"and scikit-learn's {at_500(rb, 'c-bo-sklearn')}",
        f"Different Powers {at_500(dp, 'c-bo')} against BoTorch's {at_500(dp, 'c-bo-botorch')} and "
        f"scikit-learn's {at_500(dp, 'c-bo-sklearn')}",
        f"Rastrigin {at_500(ra, 'c-bo')} against BoTorch's {at_500(ra, 'c-bo-botorch')} and scikit-learn's "
        f"{at_500(ra, 'c-bo-sklearn')} (each better on {better(ra)} seeds)",
        f"{at_500(pr, 'c-bo-sklearn')} m of precision error against {at_500(pr, 'c-bo')} m and at "
        f"{at_500(fl, 'c-bo-sklearn')} m of flexibility distance against {at_500(fl, 'c-bo')} m "
        f"(better on {better(pr)} seeds in both)",
    ]
    assert better(pr) == better(fl)
    assert library[(ra, "c-bo-botorch")][5].split(" (")[0].replace("/", " of ") == better(ra)
    header, *rows = _table(results, "## The optimiser's own seconds per asked episode")
    timing = {row[0]: row for row in rows}

    def seconds(method: str, tasks: tuple[str, ...]) -> str:
        values = [float(timing[t][header.index(f"`{method}`")].split()[0]) for t in tasks]
        return f"{min(values):.2g}–{max(values):.2g}"

    five = (rb, dp, ra, pr, fl)
    phrases.append(f"{seconds('c-bo-sklearn', five)} against c-bo's {seconds('c-bo', five)}")
    phrases.append(f"BoTorch's {seconds('c-bo-botorch', (rb, dp))}. So c-bo keeps its own GP.")
    for phrase in phrases:
        assert phrase in doc, phrase


def test_the_docs_active_contexts_sentence_quotes_the_rendered_tables() -> None:
    """docs/contexts.md's "at most k of 10 seeds" at 500 episodes: the largest count of both tables of active
    contexts against uniform draws, over the tasks with all 10 seeds."""
    results = _committed_text("docs", "results", "low_budget", "full", "results.md")
    rows = [row for row in _table(results, "## Active contexts against uniform draws") if row[0] != "task"]
    counts = [tuple(map(int, row[-1].split(" (")[0].split("/"))) for row in rows if row[-1] != "—"]
    most = max(wins for wins, seeds in counts if seeds == 10)
    doc = " ".join(_committed_text("docs", "contexts.md").split())
    assert f"at 500 episodes it ends better on at most {most} of 10 seeds of any task" in doc
