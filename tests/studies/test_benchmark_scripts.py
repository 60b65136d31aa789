"""Smoke tests of the paper-reproduction studies (``benchmarks/functions``, ``benchmarks/scaling``).

The scripts run as users run them (a subprocess, by path or with ``python -m``, once per study and mode; the
other calls in this process, ``helpers.study_in_process``) on tiny configurations into a temporary
directory; the tests check that the tables and figures appear, that the tables are computed from the cached
run results, and that cached runs are not recomputed (the studies resume). The committed renderings under
``docs/results/`` must be what ``--render-only`` draws from the committed run caches.
"""

from __future__ import annotations

import dataclasses
import functools
import importlib
import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from helpers import no_figure, study_in_process

pytest.importorskip("matplotlib")
pytest.importorskip("cma")

# The repository root is on sys.path (pyproject.toml: pytest's `pythonpath`), as for `python -m pytest`.
from benchmarks import baselines, study_cli, study_report, study_runner, study_tools

REPO = Path(__file__).resolve().parents[2]
BENCHMARKS = REPO / "benchmarks"
with_baselines = functools.partial(study_tools.execute, baselines=baselines.BASELINES)


def _script(study: str, *args: str, as_module: bool = False) -> str:
    """Run a study's script from the repository root, by path or as ``python -m benchmarks.<study>.run``."""
    command = ["-m", f"benchmarks.{study}.run"] if as_module else [str(BENCHMARKS / study / "run.py")]
    return _python(*command, *args)


def _python(*args: str, timeout: float = 120) -> str:
    """Run ``python ARGS`` from the repository root; its standard output (it must succeed)."""
    result = subprocess.run(
        [sys.executable, *args], capture_output=True, text=True, timeout=timeout, check=False, cwd=REPO
    )
    assert result.returncode == 0, result.stderr
    return result.stdout


def _documents(cache: Path) -> dict[str, dict]:
    return {p.stem: json.loads(p.read_text()) for p in sorted(cache.glob("*.json"))}


@pytest.mark.slow
def test_functions_study_writes_table_and_figures_from_its_cached_runs(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    cache, out = tmp_path / "cache", tmp_path / "out"
    args = ["--functions", "Sphere", "Plane", "--context-dims", "1", "--seeds", "1", "--dim", "4"]
    args += ["--methods", "creps", "creps-cma-old", "creps-cma-current"]
    args += ["cma-fixed", "cma-fixed-batch", "cma-regression"]  # not issue 12's, which may be registered
    args += ["--budget", "3000", "--workers", "1", "--cache", str(cache), "--out", str(out)]
    log = _script("functions", *args)
    assert "0 runs cached" in log
    documents = _documents(cache)
    assert len(documents) == 2 * 6  # 2 functions x 6 methods (3 paper methods + 3 baselines)
    assert (out / "Sphere.png").stat().st_size > 10_000 and (out / "Plane.png").stat().st_size > 10_000
    table = (out / "results.md").read_text()
    fixed = documents["Sphere-p4-z1-cma-fixed-s0-b3000-n50"]
    assert fixed["hit"] is not None  # pycma solves a 4-D sphere at one context within 3000 episodes
    assert f"{fixed['hit']:,} (1/1)" in table
    # Tamper with a cached result: a rerun must read it (no recomputation) and the table must show it.
    key = "Sphere-p4-z1-creps-cma-old-s0-b3000-n50"
    tampered = dict(documents[key], hit=1234567, final=1e-9)
    (cache / f"{key}.json").write_text(json.dumps(tampered))
    with monkeypatch.context() as patch:  # this rerun's check is the table: it draws no figure
        patch.setattr(importlib.import_module("benchmarks.functions.run"), "plot_function", no_figure)
        log = study_in_process("functions", *args)
    assert "12 runs cached" in log and "0 to compute" in log
    assert "1,234,567 (1/1)" in (out / "results.md").read_text()
    # A partial study renders what has finished, computing nothing.
    (cache / f"{key}.json").unlink()
    study_in_process("functions", *args, "--render-only")
    assert len(list(cache.glob("*.json"))) == 11
    assert "Partial: 11 of 12 runs have finished." in (out / "results.md").read_text()


@pytest.mark.slow
def test_scaling_study_writes_heatmaps_and_marks_censored_cells(tmp_path: Path) -> None:
    cache, out = tmp_path / "cache", tmp_path / "out"
    args = ["--functions", "Sphere", "Rosenbrock", "--dims", "2", "4", "--context-dims", "1", "2"]
    args += ["--seeds", "1", "--budget", "1500", "--workers", "1", "--cache", str(cache), "--out", str(out)]
    args += ["--baselines", "cma-fixed", "cma-regression", "--baseline-dims", "2", "--extra-methods"]
    _script("scaling", *args, as_module=True)
    documents = _documents(cache)
    assert len(documents) == 2 * 2 * 2 + 2 * 2 * 2  # the grid + 2 baselines x 2 functions x 2 z at p = 2
    assert (out / "heatmaps.png").stat().st_size > 10_000 and (out / "baselines.png").stat().st_size > 10_000
    table = (out / "results.md").read_text()
    baselines_table = table[table.index("## Baselines") :]
    for document in documents.values():
        spec = document["spec"]
        if spec["method"] != "creps-cma-old":
            label = "pycma" if spec["method"] == "cma-fixed" else "independent"
            header = f"### {study_tools.function_spec(spec['function']).title}: {label}"
            section = baselines_table[baselines_table.index(header) :]
            row = next(line for line in section.splitlines() if line.startswith("| 2 |"))
            text = row.split(" | ")[spec["context_dim"]].strip(" |")
            if spec["method"] == "cma-regression":
                assert text.endswith(
                    f"{document['total_episodes']:,} ep., regret {document['final']:.2g} ("
                    + ("1/1)" if document["hit"] else "0/1)")
                )
            elif document["hit"] is not None:
                assert text == f"{document['hit']:,}"
            continue
        if document["hit"] is not None:
            expected = f"{document['hit']:,}"
        else:  # missed: censored by the budget, or stopped early by the optimiser's own criteria
            stopped = str(document["stop_reason"]).startswith("optimizer")
            expected = ("stopped" if stopped else ">1,500") + f", regret {document['final']:.2g}"
        section = table[table.index("### " + study_tools.function_spec(spec["function"]).title) :]
        row = next(line for line in section.splitlines() if line.startswith(f"| {spec['dim']} |"))
        assert row.split(" | ")[spec["context_dim"]].strip(" |") == expected
    assert any(d["hit"] is None for d in documents.values())  # Rosenbrock p=4 needs more than 1500
    assert any(d["hit"] is not None for d in documents.values())


@pytest.mark.slow
def test_runs_are_deterministic_for_a_seed() -> None:
    spec = study_tools.RunSpec("Sphere", 3, 1, "creps-cma-old", 7, 1000)
    first, second = study_tools.execute(spec), study_tools.execute(spec)
    first.pop("seconds"), second.pop("seconds")
    assert first == second
    other = study_tools.execute(study_tools.RunSpec("Sphere", 3, 1, "creps-cma-old", 8, 1000))
    assert other["values"] != first["values"]


def test_result_document_finds_the_first_episode_at_the_target() -> None:
    spec = study_tools.RunSpec("Sphere", 3, 1, "creps", 0, 500)
    document = study_tools.result_document(spec, [50, 100, 150, 200], [1.0, 2e-5, 9e-6, 1e-7], "x", 0.0)
    assert document["hit"] == 150 and document["final"] == 1e-7 and document["total_episodes"] == 200
    unbounded = study_tools.RunSpec("Plane", 3, 1, "creps", 0, 500)
    document = study_tools.result_document(unbounded, [50, 100], [-10.0, -2e4], "x", 0.0)
    assert document["metric"] == "f" and document["hit"] == 100


def test_curve_indices_thin_long_curves_but_keep_both_ends() -> None:
    np.testing.assert_array_equal(study_tools.curve_indices(5, 300), np.arange(5))
    indices = study_tools.curve_indices(10_000, 100)
    assert len(indices) <= 102 and indices[0] == 0 and indices[-1] == 9999
    assert np.all(np.diff(indices) > 0)


def test_update_block_replaces_only_its_block(tmp_path: Path) -> None:
    path = tmp_path / "README.md"
    path.write_text("# Results\n\nkept\n")
    study_report.update_block(path, "a", "first")
    study_report.update_block(path, "b", "other")
    study_report.update_block(path, "a", "second")
    text = path.read_text()
    assert text.startswith("# Results\n\nkept\n")
    assert "second" in text and "first" not in text and "other" in text
    assert text.count("<!-- a -->") == 1


def test_regression_baseline_training_contexts_span_the_box() -> None:
    one = baselines.training_contexts(1)
    np.testing.assert_allclose(one[:, 0], [0.0, 0.75, 1.5, 2.25, 3.0])
    three = baselines.training_contexts(3)
    assert three.shape == (9, 3) and {0.0, 3.0} == set(np.unique(three[:8]))
    np.testing.assert_allclose(three[8], [1.5, 1.5, 1.5])


def test_unknown_function_or_baseline_is_rejected() -> None:
    with pytest.raises(ValueError, match="function: expected one of"):
        study_tools.function_spec("Nope")
    with pytest.raises(ValueError, match="method: expected a name of letters"):
        study_tools.RunSpec("Sphere", 3, 1, "cma/nope", 0, 100)
    unknown = study_tools.RunSpec("Sphere", 3, 1, "cma-nope", 0, 100)
    with pytest.raises(ValueError, match=r"method: expected a registered optimiser .* or a baseline"):
        study_tools.execute(unknown, baselines=baselines.BASELINES)
    assert study_runner.available_methods(["creps", "cma-nope", "cma-fixed"], baselines.BASELINES, str) == [
        "creps",
        "cma-fixed",
    ]
    with pytest.raises(ValueError, match="budget: expected an integer >= 50"):
        study_tools.RunSpec("Sphere", 3, 1, "creps", 0, 10)
    with pytest.raises(ValueError, match="dim: expected an integer >= 2"):
        study_tools.RunSpec("Sphere", 1, 1, "creps", 0, 100)
    with pytest.raises(ValueError, match="workers: expected"):
        study_runner.run_all([], "/tmp/unused", workers=0)


def test_stalled_runs_are_those_that_missed_the_target_and_stopped_improving() -> None:
    from benchmarks.functions import report

    spec = study_tools.RunSpec("Sphere", 3, 1, "creps-cma-current", 0, 1000)
    episodes = [100, 200, 300, 400]
    flat = study_tools.result_document(spec, episodes, [50.0, 8.0, 7.9, 7.8], "max_episodes", 0.0)
    falling = study_tools.result_document(spec, episodes, [50.0, 8.0, 1.0, 0.1], "max_episodes", 0.0)
    solved = study_tools.result_document(spec, [100, 200], [1.0, 1e-6], "target_regret", 0.0)
    assert report.stalled(flat) and not report.stalled(falling) and not report.stalled(solved)
    plane = study_tools.RunSpec("Plane", 3, 1, "creps-cma-current", 0, 1000)
    stuck = study_tools.result_document(plane, [100, 200, 300], [-100.0, -240.0, -250.0], "x", 0.0)
    assert report.stalled(stuck)


def _count_calls(calls: list):
    def worker(spec, checkpoint_dir):
        calls.append(spec.key)
        return study_tools.execute(spec, checkpoint_dir)

    return worker


@pytest.mark.slow
def test_a_larger_budget_recomputes_only_the_censored_runs(tmp_path: Path) -> None:
    hit = study_tools.RunSpec("Sphere", 3, 1, "creps-cma-old", 0, 3000)
    censored = study_tools.RunSpec("Rosenbrock", 4, 1, "creps-cma-old", 0, 500)
    calls: list[str] = []
    first = study_runner.run_all([hit, censored], tmp_path, workers=1, worker=_count_calls(calls), log=str)
    assert study_tools.ended_early(first[0]) and not study_tools.ended_early(first[1])
    larger = [
        study_tools.RunSpec(s.function, 3 if s is hit else 4, 1, s.method, 0, 6000) for s in (hit, censored)
    ]
    calls.clear()
    second = study_runner.run_all(larger, tmp_path, workers=1, worker=_count_calls(calls), log=str)
    assert calls == [larger[1].key]  # the run that met its target is the same run under any larger budget
    assert second[0] is not None and second[0]["hit"] == first[0]["hit"]
    # ... and the rerun of a run that met its target under the larger budget is the cached document.
    rerun = study_tools.execute(larger[0])
    assert rerun["values"] == first[0]["values"] and rerun["episodes"] == first[0]["episodes"]


@pytest.mark.slow
def test_an_interrupted_run_continues_from_its_checkpoint(tmp_path: Path, monkeypatch) -> None:
    from creps_gym.runner.loop import Runner

    spec = study_tools.RunSpec("Sphere", 5, 2, "creps-cma-old", 1, 20_000)
    reference = study_tools.execute(spec)
    monkeypatch.setattr(study_tools, "CHECKPOINT_EVERY", 10)
    step, calls = Runner.step, []

    def interrupted_step(self, backend):
        calls.append(1)
        if len(calls) == 25:
            raise KeyboardInterrupt  # as if the study were stopped during iteration 25
        return step(self, backend)

    monkeypatch.setattr(Runner, "step", interrupted_step)
    with pytest.raises(KeyboardInterrupt):
        study_runner.run_all([spec], tmp_path, workers=1, log=str)
    partial = tmp_path / "partial" / spec.key
    assert (partial / "checkpoint.npz").exists() and not (tmp_path / f"{spec.key}.json").exists()
    calls.clear()

    def counted_step(self, backend):
        calls.append(1)
        return step(self, backend)

    monkeypatch.setattr(Runner, "step", counted_step)
    (document,) = study_runner.run_all([spec], tmp_path, workers=1, log=str)
    assert len(calls) == reference["total_episodes"] // 50 - 20  # continued after the checkpoint at 20
    assert not partial.exists()  # removed once the document is stored
    assert document["values"] == reference["values"] and document["hit"] == reference["hit"]


def test_a_cap_that_cannot_bind_is_the_uncapped_run() -> None:
    capped = study_tools.RunSpec("Sphere", 16, 1, "creps-cma-old", 0, 1000, max_interpolation=0.2)
    assert capped.key == study_tools.RunSpec("Sphere", 16, 1, "creps-cma-old", 0, 1000).key  # 50/256 < 0.2
    binding = study_tools.RunSpec("Sphere", 4, 1, "creps-cma-old", 0, 1000, max_interpolation=0.2)
    assert binding.key == "Sphere-p4-z1-creps-cma-old-cap0.2-s0-b1000-n50"
    no_z = dataclasses.replace(binding, divide_by_z=False)
    assert no_z.key == "Sphere-p4-z1-creps-cma-old-cap0.2-noz-s0-b1000-n50"
    with pytest.raises(ValueError, match="divide_by_z: expected True for method 'cma-fixed'"):
        study_tools.RunSpec("Sphere", 4, 1, "cma-fixed", 0, 1000, divide_by_z=False)
    with pytest.raises(ValueError, match="max_interpolation: expected 1 for method 'creps'"):
        study_tools.RunSpec("Sphere", 4, 1, "creps", 0, 1000, max_interpolation=0.2)
    # The cap reaches the optimiser: at p = 4, λ = 1 without it, so the runs differ from the first update.
    uncapped = study_tools.execute(study_tools.RunSpec("Sphere", 4, 1, "creps-cma-old", 0, 500))
    capped = study_tools.execute(dataclasses.replace(binding, budget=500))
    assert capped["values"][0] == uncapped["values"][0] and capped["values"][1:] != uncapped["values"][1:]
    without_z = study_tools.execute(
        dataclasses.replace(binding, budget=500, max_interpolation=1.0, divide_by_z=False)
    )
    assert (
        without_z["values"][0] == uncapped["values"][0] and without_z["values"][1:] != uncapped["values"][1:]
    )


def test_a_regression_baseline_is_never_reused_for_another_budget(tmp_path: Path) -> None:
    small = study_tools.RunSpec("Sphere", 2, 1, "cma-regression", 0, 2000)
    (document,) = study_runner.run_all([small], tmp_path, workers=1, worker=with_baselines, log=str)
    assert document["hit"] is not None and not study_tools.ended_early(document)
    assert study_tools.cached_result(tmp_path, dataclasses.replace(small, budget=4000)) is None


def test_scaling_cells_say_why_every_seed_missed() -> None:
    from benchmarks.scaling import report as scaling
    from benchmarks.scaling.run import parse_args

    def document(reason: str, final: float) -> dict:
        spec = {"function": "Sphere", "method": "creps-cma-old", "dim": 4, "context_dim": 1}
        return {"spec": spec, "hit": None, "final": final, "total_episodes": 10, "stop_reason": reason}

    runs = [document("optimizer: max_std_growth", 1e9), document("optimizer: max_condition", 2.0)]
    runs.append(document("iterations", 3.0))
    kinds = [scaling.missed_kind(d) for d in runs]
    assert kinds == ["diverged", "stopped", "censored"]
    args = parse_args(["--quick", "--dims", "4", "--context-dims", "1"])
    (row,) = scaling.grid(runs, "Sphere", args)
    assert scaling.cell_text(row[0], 1000) == ">1,000 1 / diverged 1 / stopped 1, regret 3"
    (row,) = scaling.grid(runs[:1], "Sphere", args)
    assert scaling.cell_text(row[0], 1000) == "diverged, regret 1e+09"


def test_run_all_keeps_the_checkpoints_of_the_same_run_under_a_budget_it_is_still_computing(tmp_path):
    """Two budgets of one run in one call (a recomputation): storing the first must not remove the other's
    checkpoints, which a second worker may be writing."""
    small = study_tools.RunSpec("Sphere", 2, 1, "c-cma-es", 0, 100, 10)
    large = dataclasses.replace(small, budget=200)
    seen = []

    def worker(spec, checkpoint_dir):
        if spec == small:  # the large run has checkpointed meanwhile, in another worker
            (checkpoint_dir.parent / large.key).mkdir(parents=True)
        seen.append((spec.budget, (checkpoint_dir.parent / large.key).exists()))
        return study_tools.result_document(spec, [10], [1.0], None, 0.0)

    study_runner.run_all([small, large], tmp_path, workers=1, worker=worker, log=str)
    assert seen == [(100, True), (200, True)]
    assert not (tmp_path / "partial" / large.key).exists()  # removed once its own document is stored


def test_a_render_of_a_larger_study_runners_it_partial(tmp_path: Path) -> None:
    computed = study_report.invocation_timing(tmp_path, wall=3.0, computed=5, total=5)
    assert "Partial" not in study_report.timing_text(computed, [{"seconds": 1.0}] * 5)
    rendered = study_report.invocation_timing(tmp_path, wall=0.1, computed=0, total=10)  # the study grew
    text = study_report.timing_text(rendered, [{"seconds": 1.0}] * 8)
    assert "3 s wall" in text and "**Partial: 8 of 10 runs have finished.**" in text


@pytest.mark.slow
def test_the_study_tools_import_no_baseline() -> None:
    """The import circle baselines <-> study_tools is gone: the baselines are passed in as a mapping."""
    code = "import sys, benchmarks.study_tools; print('benchmarks.baselines' in sys.modules)"
    result = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, check=True
    )
    assert result.stdout.strip() == "False"
    assert set(baselines.BASELINES) >= {"cma-fixed", "cma-fixed-batch", "cma-regression"}
    spec = study_tools.RunSpec("Sphere", 2, 1, "cma-fixed", 0, 500)
    with pytest.raises(ValueError, match="method: expected a registered optimiser"):
        study_tools.execute(spec)  # without the mapping, study_tools knows no baseline
    assert study_tools.execute(spec, baselines=baselines.BASELINES)["spec"]["method"] == "cma-fixed"


def test_the_reported_command_leaves_out_what_does_not_change_the_results() -> None:
    flags = [
        "--full",
        "--workers",
        "4",
        "--no-z",
        "--out=/tmp/x",
        "--render-only",
        "--cache",
        "c",
        "--seeds",
        "2",
    ]
    assert study_cli.command_flags(flags, "full") == "--full --no-z --seeds 2"
    assert study_cli.command_flags(["--render-only"], "quick") == "--quick"
    methods = ["--full", "--compute-methods", "c-cma-es", "creps-cma-csa", "--dims", "64", "--workers", "1"]
    assert study_cli.command_flags(methods, "full") == "--full --dims 64"


def test_a_compute_predicate_computes_only_the_runs_it_accepts(tmp_path: Path) -> None:
    old = study_tools.RunSpec("Sphere", 3, 1, "creps-cma-old", 0, 3000)
    new = study_tools.RunSpec("Sphere", 3, 1, "c-cma-es", 0, 3000)
    calls: list[str] = []
    chosen = study_runner.run_all(
        [old, new], tmp_path, workers=1, worker=_count_calls(calls), log=str, compute=lambda s: s is new
    )
    assert calls == [new.key] and [d["spec"]["method"] for d in chosen] == ["c-cma-es"]
    calls.clear()
    both = study_runner.run_all([old, new], tmp_path, workers=1, worker=_count_calls(calls), log=str)
    assert calls == [old.key] and [d["spec"]["method"] for d in both] == ["creps-cma-old", "c-cma-es"]


#: Every committed rendering under docs/results/ (study, the options that computed it).
COMMITTED_RENDERINGS = [
    ("functions", ["--quick"]),
    ("functions", ["--full"]),
    ("scaling", ["--quick"]),
    ("scaling", ["--full"]),
    ("scaling", ["--full", "--max-interpolation", "0.2", "--baselines"]),
    ("scaling", ["--full", "--no-z", "--max-interpolation", "0.2", "--baselines"]),
    ("ccmaes", ["--quick"]),
    ("ccmaes", ["--full"]),
]


@pytest.mark.parametrize(
    ("study", "flags"), COMMITTED_RENDERINGS, ids=lambda v: v if isinstance(v, str) else " ".join(v)
)
@pytest.mark.slow
def test_committed_renderings_are_drawn_from_the_committed_runs(
    study: str, flags: list[str], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``--render-only`` on the committed run caches reproduces each committed table exactly (the figures,
    which depend on the matplotlib version, are not drawn here)."""
    module = importlib.import_module(f"benchmarks.{study}.run")
    committed = module.parse_args(flags).out
    if not (committed / "results.md").exists():
        pytest.skip(f"{committed} is not rendered yet: python benchmarks/{study}/run.py {' '.join(flags)}")
    for name in [n for n in dir(module) if n.startswith("plot_")]:
        monkeypatch.setattr(module, name, no_figure)
    shutil.copy(committed / "timing.json", tmp_path / "timing.json")  # the computing invocation's timing
    assert module.main([*flags, "--render-only", "--out", str(tmp_path)]) == 0
    assert (tmp_path / "results.md").read_text() == (committed / "results.md").read_text()


@pytest.mark.slow
def test_ccmaes_study_renders_its_targets_from_the_cached_runs(tmp_path: Path) -> None:
    cache, out = tmp_path / "cache", tmp_path / "out"
    args = ["--dim", "4", "--functions", "Sphere", "--context-dims", "1", "--seeds", "1", "--headline-seeds"]
    args += ["2", "--columns", "creps-cma-old", "cma-fixed", "cma-fixed-batch", "--budget", "3000"]
    args += ["--workers", "1", "--cache", str(cache), "--out", str(out)]
    log = _script("ccmaes", *args)
    assert "0 runs cached" in log
    documents = _documents(cache)
    # The headline columns (creps-cma-old, cma-fixed) have 2 seeds, the others 1; every run in the setting.
    assert sorted(documents) == sorted(
        f"Sphere-p4-z1-{method}-e100-uniform5-s{seed}-b3000-n50"
        for method, seeds in (("creps-cma-old", 2), ("cma-fixed", 2), ("cma-fixed-batch", 1))
        for seed in range(seeds)
    )
    assert (out / "curves.png").stat().st_size > 10_000
    # Tamper with the cache: the rerun computes nothing, and the tables (targets too) follow the documents.
    for seed, hit in ((0, 4000), (1, None)):
        key = f"Sphere-p4-z1-creps-cma-old-e100-uniform5-s{seed}-b3000-n50"
        (cache / f"{key}.json").write_text(json.dumps(dict(documents[key], hit=hit)))
    for seed, hit in ((0, 900), (1, 1100)):
        key = f"Sphere-p4-z1-cma-fixed-e100-uniform5-s{seed}-b3000-n50"
        (cache / f"{key}.json").write_text(json.dumps(dict(documents[key], hit=hit)))
    log = _script("ccmaes", *args, as_module=True)
    assert "5 runs cached" in log and "0 to compute" in log
    table = (out / "results.md").read_text()
    row = next(line for line in table.splitlines() if line.startswith("| Sphere | 1 | "))
    # median of (4000, missed) is censored; pycma's median 1000 sets the recommended-N bound at 2,000.
    assert row.split(" | ")[2:9] == [">3,000 (1/2)", "–", "≤ 5,500", "–", "–", "1,000 (2/2)", "≤ 2,000"]


def test_ccmaes_targets_are_computed_from_medians_with_missed_seeds_as_infinite() -> None:
    from benchmarks.ccmaes import report

    def runs(*hits):
        return [{"hit": hit, "spec": {"samples": 50, "seed": i}} for i, hit in enumerate(hits)]

    assert report.median_episodes(runs(5000, None, 6000)) == 6000
    assert report.median_episodes(runs(5000, None, None)) == float("inf")
    assert report.median_episodes([]) is None
    assert report.target_met(runs(5000, 5400, None), 5_500, 0.0) == "met"
    assert report.target_met(runs(5000, 5600, 5700), 5_500, 0.0) == "not met"
    nineteen, eighteen = runs(*[20_000] * 19, None), runs(*[20_000] * 18, None, None)
    assert report.target_met(nineteen, 25_000, 0.95) == "met"
    assert report.target_met(eighteen, 25_000, 0.95) == "not met"  # median fine, but only 18/20 seeds
    cells = {("Sphere", 1, "c-cma-es"): runs(5000, 5200, 6000), ("Sphere", 1, "cma-fixed"): runs(1500, 1600)}
    cells[("Sphere", 1, "c-cma-es-rec")] = runs(3000, 3300)
    row = report.headline_table(cells, [("Sphere", 1)], 200_000).splitlines()[2].split(" | ")
    assert row[2:9] == ["–", "5,200 (3/3)", "≤ 5,500", "met", "3,150 (2/2), N = 50", "1,550 (2/2)", "≤ 3,100"]
    assert row[9] == "not met |"  # 3,150 > 2 x 1,550


def test_ccmaes_surrogate_table_sets_the_surrogate_against_c_cma_es_and_pycma_in_its_cells() -> None:
    from benchmarks.ccmaes import run, surrogate_table

    def runs(samples, *hits):
        return [{"hit": hit, "spec": {"samples": samples, "seed": i}} for i, hit in enumerate(hits)]

    cells = {
        ("Sphere", 1, "c-cma-es-surrogate"): runs(50, 700, 650, 800),
        ("Sphere", 1, "c-cma-es"): runs(50, 5000, 4800, 5200),
        ("Sphere", 1, "c-cma-es-surrogate-rec"): runs(24, 3000, None, None),  # the median seed missed
        ("Sphere", 1, "c-cma-es-rec"): runs(24, 3900, 4000),
        ("Sphere", 1, "cma-fixed"): runs(50, 1500, 1600),
    }
    lines = surrogate_table.surrogate_table(cells, 200_000).splitlines()
    assert len(lines) == 4  # no runs in the other cells: no rows
    assert lines[2].split(" | ")[1:] == [
        "1",
        "50",
        "700 (3/3)",
        "5,000 (3/3)",
        "0.14 (≤ 0.7: met)",
        "1,550 (2/2)",
        "0.45 (≤ 2: met) |",
    ]
    assert lines[3].split(" | ")[3:] == [
        ">200,000 (1/3)",
        "3,950 (2/2)",
        "∞ (≤ 0.7: not met)",
        "1,550 (2/2)",
        "∞ (≤ 2: not met) |",
    ]
    args = run.parse_args(
        ["--full", "--columns", "c-cma-es-surrogate", "--seeds", "1", "--headline-seeds", "2"]
    )
    specs = {(s.function, s.context_dim, s.samples) for _, s in run.column_specs(args)}
    assert specs == {
        ("Sphere", 1, 50),
        ("Sphere", 3, 50),
        ("Rosenbrock", 1, 50),
        ("ShiftedRotatedElliptic", 1, 50),
    }
    assert len(run.column_specs(args)) == 8  # 2 seeds (the headline seeds) in each of issue 33's cells


def test_ccmaes_columns_without_a_recommended_batch_size_are_skipped_with_a_message(monkeypatch) -> None:
    from benchmarks.ccmaes import run

    monkeypatch.setattr(run, "available_methods", lambda methods, baselines, log: list(methods))  # all known
    monkeypatch.setattr(run, "recommended_batch", lambda dim, z: None)
    messages: list[str] = []
    args = run.parse_args(["--quick", "--columns", "cma-fixed", "c-cma-es-rec", "c-cma-es"])
    pairs = run.column_specs(args, messages.append)
    assert {column for column, _ in pairs} == {"cma-fixed", "c-cma-es"}
    assert messages == [
        "skipped column 'c-cma-es-rec': creps_gym.optimizers.ccmaes has no recommended_batch_size"
    ]
    assert all(spec.initial == "uniform5" and spec.eval_contexts == 100 for _, spec in pairs)
    monkeypatch.setattr(run, "recommended_batch", lambda dim, z: 10 + dim + z)
    pairs = run.column_specs(args, messages.append)
    assert {spec.samples for column, spec in pairs if column == "c-cma-es-rec"} == {
        26,
        28,
    }  # p = 15, z = 1, 3


def test_the_initial_distribution_and_test_contexts_of_a_spec_reach_every_method() -> None:
    spec = study_tools.RunSpec("Sphere", 3, 1, "creps-cma-old", 4, 400, initial="uniform5", eval_contexts=100)
    mean, std = study_tools.initial_distribution(spec)
    again, _ = study_tools.initial_distribution(spec)
    other, _ = study_tools.initial_distribution(dataclasses.replace(spec, seed=5))
    assert np.all(np.abs(mean) <= 5.0) and np.array_equal(std, np.ones(3)) and np.array_equal(mean, again)
    assert not np.array_equal(mean, other)
    assert spec.key == "Sphere-p3-z1-creps-cma-old-e100-uniform5-s4-b400-n50"
    with pytest.raises(ValueError, match="action_space: expected the env's action space"):
        study_tools.initial_distribution(dataclasses.replace(spec, initial="centre"))
    with pytest.raises(ValueError, match="initial: expected one of"):
        dataclasses.replace(spec, initial="uniform")
    for method in ("creps-cma-old", "cma-fixed"):
        variants = [
            dataclasses.replace(spec, method=method, initial=initial, eval_contexts=contexts)
            for initial, contexts in (("uniform5", 100), ("centre", 100), ("uniform5", 16))
        ]
        first = [with_baselines(v)["values"][0] for v in variants]
        assert first[0] != first[1], method  # another initial distribution
        # Other test contexts (pycma on one context uses the first of them, the same for 16 and 100)
        assert (first[0] != first[2]) == (method == "creps-cma-old"), method


@pytest.mark.slow
def test_issue_12_optimisers_fill_their_columns_once_registered(tmp_path: Path, monkeypatch) -> None:
    """Stand-ins registered as ``c-cma-es`` and ``creps-cma-csa`` (CREPS-CMA aliases) get their own columns in
    the function study and their own tables and heatmap in the scaling study."""
    from benchmarks.functions import run as functions
    from benchmarks.scaling import run as scaling
    from creps_gym.optimizers import registry

    for name in ("c-cma-es", "creps-cma-csa"):
        alias = registry.OptimizerEntry(name, "stand-in", "creps_gym.optimizers.creps_cma:CREPSCMA")
        monkeypatch.setitem(registry._REGISTRY, name, alias)
    monkeypatch.setattr(scaling, "PINNED", {})  # the stand-ins have no restart options to pin
    monkeypatch.setattr(functions, "pin_c3", lambda method, options=(): tuple(options))  # nor a ridge
    monkeypatch.setattr(functions, "plot_function", no_figure)  # its check is the table's header
    common = ["--context-dims", "1", "--seeds", "1", "--budget", "1000", "--workers", "1"]
    out = tmp_path / "functions"
    args = ["--functions", "Sphere", "--dim", "3", "--methods", "creps-cma-old", "c-cma-es", "creps-cma-csa"]
    assert functions.main([*args, *common, "--cache", str(tmp_path / "c1"), "--out", str(out)]) == 0
    header = next(
        line for line in (out / "results.md").read_text().splitlines() if line.startswith("| function")
    )
    assert header == "| function | CREPS-CMA-old | C-CMA-ES | CREPS-CMA-CSA |"
    out = tmp_path / "scaling"
    args = ["--functions", "Sphere", "--dims", "2", "--baselines", "--extra-methods", "c-cma-es"]
    assert scaling.main([*args, *common, "--cache", str(tmp_path / "c2"), "--out", str(out)]) == 0
    table = (out / "results.md").read_text()
    assert "## C-CMA-ES (`c-cma-es`)" in table and (out / "heatmaps-c-cma-es.png").stat().st_size > 10_000
    assert len(list((tmp_path / "c2").glob("Sphere-p2-z1-c-cma-es-s0-*.json"))) == 1


def test_run_spec_options_are_sorted_validated_and_leave_the_keys_without_them_unchanged() -> None:
    setting = {"eval_contexts": 100, "initial": "uniform5"}
    plain = study_tools.RunSpec("Rosenbrock", 15, 3, "c-cma-es", 0, 100_000, 50, **setting)
    assert plain.key == "Rosenbrock-p15-z3-c-cma-es-e100-uniform5-s0-b100000-n50"  # as before options
    assert "options" not in study_tools.result_document(plain, [50], [1.0], None, 1.0)["spec"]
    given = {"restarts": 0, "baseline_batches": 1}
    spec = dataclasses.replace(plain, options=given)
    assert spec.options == (("baseline_batches", 1), ("restarts", 0))
    assert spec == dataclasses.replace(plain, options=[("restarts", 0), ("baseline_batches", 1)])
    assert spec.key == "Rosenbrock-p15-z3-c-cma-es-e100-uniform5-baseline_batches=1-restarts=0-s0-b100000-n50"
    document = json.loads(json.dumps(study_tools.result_document(spec, [50], [1.0], None, 1.0)))
    assert study_tools.RunSpec(**document["spec"]) == spec  # the cache's documents name their run
    for method, options in [
        ("c-cma-es", {"restart": 0}),  # not an option of c-cma-es
        ("c-cma-es", {"seed": 3}),  # set by the run, not by its options
        ("c-cma-es", {"restarts": [0]}),
        ("cma-fixed", {"restarts": 0}),  # a baseline has no options
    ]:
        with pytest.raises(ValueError, match="options"):
            dataclasses.replace(plain, method=method, options=options)


@pytest.mark.slow
def test_run_spec_divergence_is_validated_ends_the_key_and_reaches_the_runner(tmp_path: Path) -> None:
    plain = study_tools.RunSpec("DifferentPowers", 15, 3, "c-cma-es", 4, 2_000, 50)
    assert "divergence" not in study_tools.result_document(plain, [50], [1.0], None, 1.0)["spec"]
    watched = dataclasses.replace(plain, divergence=1000.0)
    assert watched.key == "DifferentPowers-p15-z3-c-cma-es-div1000-s4-b2000-n50"
    document = json.loads(json.dumps(study_tools.result_document(watched, [50], [1.0], None, 1.0)))
    assert study_tools.RunSpec(**document["spec"]) == watched
    for bad in (0.0, -1.0, float("inf"), True, "1000"):
        with pytest.raises(ValueError, match="divergence: expected None or a positive finite number"):
            dataclasses.replace(plain, divergence=bad)
    study_tools.execute(watched, tmp_path / "run")
    config = json.loads((tmp_path / "run" / "config.json").read_text())["config"]
    assert config["divergence"] == 1000.0


@pytest.mark.slow
def test_run_spec_options_reach_the_optimiser(tmp_path: Path) -> None:
    spec = study_tools.RunSpec("Rosenbrock", 4, 1, "c-cma-es", 0, 600, 20, initial="uniform5")
    reuse = study_tools.execute(spec, tmp_path / "default")
    bare = study_tools.execute(dataclasses.replace(spec, options={"baseline_batches": 1}), tmp_path / "bare")
    config = json.loads((tmp_path / "bare" / "config.json").read_text())["config"]
    assert config["optimizer_options"]["baseline_batches"] == 1
    assert bare["values"][0] == reuse["values"][0]  # the first update: nothing to reuse yet
    assert bare["values"] != reuse["values"]
    assert bare["spec"]["options"] == (("baseline_batches", 1),)  # JSON: [["baseline_batches", 1]]


@pytest.mark.slow
def test_ccmaes_study_sweeps_the_batch_size_on_the_sphere_at_z_1(tmp_path: Path) -> None:
    from benchmarks.ccmaes import columns, report

    cache, out = tmp_path / "cache", tmp_path / "out"
    args = [
        "--columns",
        "c-cma-es-n12",
        "c-cma-es-n16",
        "cma-fixed",
        "--dim",
        "4",
        "--context-dims",
        "1",
        "3",
    ]
    args += ["--seeds", "1", "--headline-seeds", "1", "--budget", "3000", "--workers", "1"]
    log = study_in_process("ccmaes", *args, "--cache", str(cache), "--out", str(out))
    # The sweep runs on the Sphere at z = 1 only; pycma on every function and z.
    sweep = sorted(k for k in _documents(cache) if "c-cma-es" in k)
    assert sweep == [
        "Sphere-p4-z1-c-cma-es-e100-uniform5-ridge_centre=zero-s0-b3000-n12",  # C3: study_options.pin_c3
        "Sphere-p4-z1-c-cma-es-e100-uniform5-ridge_centre=zero-s0-b3000-n16",
    ]
    assert "to compute" in log
    section = (out / "results.md").read_text().split("## Sphere, z = 1: C-CMA-ES's batch size (1 seed(s))")[1]
    header, _, row = section.strip().splitlines()[:3]
    assert header.startswith("| N = 12 | N = 16 | N = 20 |") and header.endswith("| target |")
    assert row.startswith("| ") and " | – | – | – | – | ≤ " in row  # N = 20 .. 40 not run
    assert "**Partial: runs cached of 1 seeds: N = 20: 0; N = 24: 0; N = 32: 0; N = 40: 0.**" in section
    # With every column there, the table names the batch sizes that meet the target.
    runs = {c.name: [{"hit": 100 * c.batch, "spec": {"seed": 0}}] for c in columns.BATCH_SWEEP}
    cells = {("Sphere", 1, name): documents for name, documents in runs.items()}
    cells[("Sphere", 1, "cma-fixed")] = [{"hit": 1000, "spec": {"seed": 0}}]
    text = report.sweep_table(cells, 10_000, 1)
    assert (
        "| 1,200 (1/1) | 1,600 (1/1) | 2,000 (1/1) | 2,400 (1/1) | 3,200 (1/1) | 4,000 (1/1) | ≤ 2,000 |"
        in text
    )
    assert "Batch sizes that meet the target: N = 12, N = 16, N = 20." in text and "Partial" not in text


@pytest.mark.slow
def test_ccmaes_study_renders_the_remedies_from_the_cached_runs(tmp_path: Path) -> None:
    from benchmarks.ccmaes import report

    cache, out = tmp_path / "cache", tmp_path / "out"
    args = ["--remedies", "--dim", "4", "--context-dims", "1", "--seeds", "1", "--headline-seeds", "1"]
    args += ["--budget", "1000", "--workers", "1", "--cache", str(cache), "--out", str(out)]
    log = study_in_process("ccmaes", *args)
    assert "0 runs cached" in log and "7 to compute" in log
    documents = _documents(cache)
    # each with the committed runs' C3 (study_options.pin_c3), sorted by name into the key
    suffixes = ["-baseline_batches=1-restarts=0-ridge_centre=zero", "-restarts=0-ridge_centre=zero"]
    suffixes += ["-baseline_batches=1-ridge_centre=zero", "-ridge_centre=zero"]
    suffixes += ["-ridge_centre=zero-standardise_advantages=True", "-active=False-ridge_centre=zero"]
    suffixes += ["-baseline_degree=3-ridge_centre=zero"]
    assert sorted(documents) == sorted(
        f"Rosenbrock-p4-z1-c-cma-es-e100-uniform5{s}-s0-b1000-n50" for s in suffixes
    )
    table = (out / "results.md").read_text()
    section = table.split("## Rosenbrock: the remedies (1 seed(s), C-CMA-ES, N = 50)")[1].split("## Figures")[
        0
    ]
    row = next(line for line in section.splitlines() if line.startswith("| 1 | "))
    assert len(row.split(" | ")) == 8 and "Partial" not in section  # z and the 7 variants, every run there
    assert (
        "| `baseline_batches=1`, `restarts=0` | `restarts=0` | `baseline_batches=1` | defaults |" in section
    )
    # A missing run is named; a cell shows the median and the seeds that got there.
    runs = [{"hit": 900, "spec": {"seed": 0}}, {"hit": None, "spec": {"seed": 1}}]
    text = report.remedies_table({("Rosenbrock", 3, "c-cma-es"): runs}, [3], 1000, 2)
    assert "| 3 | – | – | – | >1,000 (1/2) | – |" in text
    assert "neither at z = 3: 0" in text and "both (the default) at z = 3" not in text


def test_ccmaes_signal_table_sets_each_signal_beside_the_default_and_counts_the_lower_medians() -> None:
    from benchmarks.ccmaes import report

    def runs(*hits: int | None, samples: int = 50) -> list[dict]:
        return [{"hit": h, "spec": {"seed": i, "samples": samples}} for i, h in enumerate(hits)]

    cells = {
        ("Sphere", 1, "c-cma-es"): runs(400, 600),
        ("Sphere", 1, "c-cma-es-coef"): runs(300, 500),
        ("Sphere", 1, "c-cma-es-rec"): runs(None, 300, samples=24),
        ("Sphere", 1, "c-cma-es-rec-coef"): runs(200, 200, samples=24),
        ("Sphere", 3, "c-cma-es"): runs(700, 700),
        ("Sphere", 3, "c-cma-es-coef"): runs(700, 700),
        ("Rosenbrock", 1, "c-cma-es"): runs(None, None),
        ("Rosenbrock", 1, "c-cma-es-coef"): runs(None, None),
    }
    rows = [("Sphere", 1), ("Sphere", 3), ("Rosenbrock", 1)]
    text = report.signal_table(cells, rows, 1000, 2)
    assert "| Sphere | 1 | 500 (2/2) | 400 (2/2) | >1,000 (1/2), N = 24 | 200 (2/2), N = 24 |" in text
    assert "| Rosenbrock | 1 | >1,000 (0/2) | >1,000 (0/2) | – | – |" in text
    # Lower at both Sphere z = 1 batch sizes (a missed median counts as infinite), a tie at z = 3, and no
    # pair where neither got there: 2 of 3 pairs compared.
    assert "The coefficients' median is lower in 2 of the 3 (cell, batch size) pairs" in text
    assert "**Partial: runs cached of 2 seeds: c-cma-es-rec at Sphere, z = 3: 0;" in text
    missed = report.signal_table({k: v for k, v in cells.items() if k[0] == "Rosenbrock"}, rows[2:], 1000, 2)
    assert "No (cell, batch size) pair has a median that reached the target yet." in missed


def test_ccmaes_bound_table_sets_faster_step_size_variants_against_both_targets() -> None:
    from benchmarks.ccmaes import report

    def runs(*hits: int | None, samples: int = 50, dim: int = 15) -> list[dict]:
        return [{"hit": h, "spec": {"seed": i, "samples": samples, "dim": dim}} for i, h in enumerate(hits)]

    cells = {
        ("Sphere", 1, "cma-fixed"): runs(1000, 1000),
        ("Sphere", 1, "c-cma-es-rec"): runs(2500, 2600, samples=24),  # above the bound 2 × 1,000
        ("Rosenbrock", 3, "c-cma-es"): runs(30_000, 32_000),
        ("Sphere", 1, "c-cma-es-rec-d08"): runs(1900, 1900, samples=24),
        ("Rosenbrock", 3, "c-cma-es-d08"): runs(30_000, None),  # a seed missed: fewer than 95 %
        ("Sphere", 1, "c-cma-es-rec-coef"): runs(1800, 2000, samples=24),
        ("Rosenbrock", 3, "c-cma-es-coef"): runs(20_000, 22_000),
    }
    text = report.bound_table(cells, 100_000, 2)
    assert "| default | defaults | 2,550 (2/2), N = 24 | 31,000 (2/2) |" in text
    assert "| d_σ = 0.8 | `d_sigma=0.8` | 1,900 (2/2), N = 24 | >100,000 (1/2) |" in text
    assert "| target | | ≤ 2,000 (2 × pycma) | ≤ 39,000, ≥ 2/2 seeds |" in text
    assert "Variants that meet both targets: coefficients." in text
    assert "pycma on one context" not in text  # no yardstick runs yet
    assert "**Partial: runs cached of 2 seeds: no sample reuse, Sphere z = 1: 0;" in text
    cells[("Sphere", 1, "cma-fixed-2p")] = runs(2800, 3000, dim=30)
    cells[("Sphere", 1, "cma-fixed-batch-2p")] = runs(4400, 4400, samples=24, dim=30)
    text = report.bound_table(cells, 100_000, 2)
    assert (
        "with 2p = 30 parameters (as many as the affine mean's coefficients at z = 1), from a mean "
        "U[-5, 5]^30 with σ0 = 1: 2,900 (2/2) episodes at its default population, N = 14, and 4,400 (2/2) "
        "at C-CMA-ES's recommended N = 24." in text
    )


def test_ccmaes_restricted_columns_run_only_in_their_cells_with_the_headline_seeds() -> None:
    from benchmarks.ccmaes import columns, run

    names = [c.name for c in columns.BOUND_COLUMNS + columns.YARDSTICK] + ["c-cma-es-n12", "c-cma-es-bare"]
    args = run.parse_args(["--full", "--columns", *names, "--seeds", "1", "--headline-seeds", "2"])
    cells = {}
    for column, spec in run.column_specs(args):
        cells.setdefault(column, set()).add((spec.function, spec.dim, spec.context_dim, spec.samples))
        assert spec.seed < 2
    assert cells["c-cma-es-rec-d08"] == {("Sphere", 15, 1, 24)}
    assert cells["c-cma-es-d08"] == {("Rosenbrock", 15, 3, 50)}
    assert cells["cma-fixed-2p"] == {("Sphere", 30, 1, 50)}  # pycma's own population; N = 50 in the key
    assert cells["cma-fixed-batch-2p"] == {("Sphere", 30, 1, 24)}  # p's recommended N, on 2p parameters
    assert cells["c-cma-es-n12"] == {("Sphere", 15, 1, 12)}
    assert cells["c-cma-es-bare"] == {("Rosenbrock", 15, 1, 50), ("Rosenbrock", 15, 3, 50)}
    assert len(run.column_specs(args)) == 2 * (len(cells) + 1)  # 2 seeds each; the bare column in 2 cells


def test_ccmaes_cells_count_a_run_that_ended_early_under_a_smaller_budget() -> None:
    from benchmarks.ccmaes import run

    spec = study_tools.RunSpec("Rosenbrock", 4, 1, "c-cma-es", 0, 2000, 50, options={"restarts": 0})
    early = study_tools.result_document(
        dataclasses.replace(spec, budget=1000), [50], [1.0], "optimizer: tolx", 1
    )
    assert study_tools.ended_early(early)  # so run_all returns it for the spec with budget 2000
    assert run.group([("c-cma-es-reuse", spec)], [early]) == {("Rosenbrock", 1, "c-cma-es-reuse"): [early]}
    other = dataclasses.replace(spec, options={"restarts": 1})
    assert run.group([("c-cma-es-reuse", other)], [early]) == {}


@pytest.mark.slow
def test_runner_overhead_script_prints_the_ratio_and_the_checkpoint_costs() -> None:
    lines = _python(str(BENCHMARKS / "runner_overhead.py"), "--quick", timeout=300).splitlines()
    first = next(i for i, line in enumerate(lines) if "runner ms" in line) + 1
    ratio = lines[first].split()
    assert ratio[:3] == ["15", "50", "1"] and float(ratio[-1]) > 0
    below = next(i for i, line in enumerate(lines) if "checkpoint ms" in line) + 1
    costs = [line.split() for line in lines[below:]]
    assert [row[0] for row in costs] == ["10", "100"] and all(float(row[1]) > 0 for row in costs)
