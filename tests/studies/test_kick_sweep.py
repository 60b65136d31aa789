"""The kick study's sweep of optimiser options (issue 45, ``run.py --opt``): the options are parsed and
checked by the optimiser, their runs go to their own folder and record them, a screening budget resumes bit
for bit to a longer one, and the study's summary renders the sweep beside the study's own runs."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("mujoco")

from benchmarks.kick import report, run, spread, study, sweep_table
from creps_gym.optimizers.registry import make_optimizer
from creps_gym.optimizers.state_files import save_state

pytestmark = pytest.mark.extras
PRECISION = ["--full", "--only", "precision", "--methods", "creps-cma-old"]


def test_opt_values_are_json_merged_over_the_methods_options_and_name_the_folder() -> None:
    args = run.parse_args(
        [*PRECISION, "--opt", "epsilon=1.0", "--opt", "step_size=csa", "--opt", "x=[1]"][:-2]
    )
    assert args.options == {"epsilon": 1.0, "step_size": "csa"}  # JSON, or a plain string
    ((spec, trials),) = run.run_specs(args)
    assert spec.options == {**run.RBF, "epsilon": 1.0, "step_size": "csa"} and trials == 3
    assert args.out == run.RESULTS / "full-opt-epsilon-1.0+step_size-csa"
    args = run.parse_args(
        [*PRECISION, "--opt", "divide_by_z=false", "--features", "affine", "--iterations", "7"]
    )
    assert args.out == run.RESULTS / "full-features-affine-opt-divide_by_z-false"
    assert run.run_specs(args)[0][0].iterations == 7  # a screening budget
    assert run.parse_args(PRECISION).options == {} and run.parse_args(PRECISION).out == run.RESULTS / "full"


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--opt", "epsilon"], "argument --opt: expected KEY=VALUE"),
        (
            ["--opt", "epsilon=1", "--opt", "epsilon=2"],
            "expected each KEY once, got ['epsilon'] more than once",
        ),
        (["--opt", "bogus=1"], "argument --opt: creps-cma-old: options: expected names in"),
        (["--opt", "epsilon=3.5"], "argument --opt: creps-cma-old: epsilon: expected < log(N) = 2.9957"),
        (["--opt", "step_size=cma"], "argument --opt: creps-cma-old: step_size: expected one of"),
        (["--opt", f"tolstagnation={'9' * 120}"], "expected a folder slug of at most 100 characters"),
        (["--iterations", "0"], "--iterations: expected an int >= 1, got 0"),
    ],
)
def test_a_bad_option_is_a_usage_error_naming_it(argv: list[str], message: str, capsys) -> None:
    with pytest.raises(SystemExit):
        run.parse_args([*PRECISION, *argv])
    assert message in capsys.readouterr().err


def test_the_folder_slug_keeps_only_safe_characters_in_key_order() -> None:
    assert study.options_slug({"step_size": "csa", "epsilon": 2}) == "epsilon-2+step_size-csa"
    assert study.options_slug({"a/b": "../x y"}) == "a_b-.._x_y"  # no separator, no space
    assert (
        study.results_folder("full", "bandit", "rbf", {"epsilon": 1.0})
        == "full-bandit-features-rbf-opt-epsilon-1.0"
    )
    assert study.results_folder("full", None, None, {}) == "full"


def _compute(out: Path, *argv: str) -> None:
    run.compute(run.parse_args([*PRECISION, "--trials", "1", "--threads", "1", "--out", str(out), *argv]))


@pytest.mark.slow
def test_an_opt_run_records_its_options_resumes_bit_identically_and_joins_the_sweep(tmp_path: Path) -> None:
    full, sweep = tmp_path / "full", tmp_path / "full-opt-epsilon-1.0"
    _compute(tmp_path / "straight", "--iterations", "2", "--opt", "epsilon=1.0")
    _compute(sweep, "--iterations", "1", "--opt", "epsilon=1.0", "--checkpoint-every", "1")  # screening
    _compute(sweep, "--iterations", "2", "--opt", "epsilon=1.0", "--checkpoint-every", "1")  # resumed
    name = "runs/precision/creps-cma-old-trial0.json"
    straight, resumed = (json.loads((folder / name).read_text()) for folder in (tmp_path / "straight", sweep))
    assert resumed["setting"]["options"] == {**run.RBF, "epsilon": 1.0} == resumed["options"]
    assert resumed["iterations"] == 2 and resumed["values"] == straight["values"]
    assert resumed["history"] == straight["history"]
    full.mkdir()  # the study's folder, with no run of its own here
    assert sweep_table.sweep_folders(full) == [sweep] and sweep_table.sweep_folders(sweep) == []
    document = json.loads(json.dumps(report.collect(full, "full", run.MODES["full"])))
    ((row,),) = [document["sweep"]["precision"]["rows"]]
    assert (row["folder"], row["options"]) == (sweep.name, {**run.RBF, "epsilon": 1.0})  # no study run
    assert row["iterations"] == [2] and row["finals"] == [float(np.mean(resumed["values"]))]
    assert row["study_same"] == [None]
    assert row["final_ess"] == [spread.final_ess(sweep / "runs/precision/creps-cma-old-trial0.npz", 2)]
    assert 1.0 <= row["final_ess"][0] < 20.0
    text = report.summary_text(document)
    assert f"## {sweep_table.SWEEP_SECTION}" in text
    assert "| `results/full-opt-epsilon-1.0` | 1 | 2–2 of 2 |" in text


def test_a_sweep_row_compares_with_the_study_s_same_trial_and_lists_runs_in_progress(tmp_path: Path) -> None:
    def finished(folder: Path, trial: int, options: dict, iterations: int, curve: list) -> None:
        document = {
            "experiment": "precision",
            "name": "creps-cma-old",
            "features": "rbf",
            "options": options,
            "trial": trial,
            "samples": 20,
            "budget_iterations": iterations,
            "iterations": iterations,
            "episodes": 20 * iterations,
            "stopped": [],
            "values": [0.5] * 9 + [2.0],
            "setting": {"env": study.ENV_IDS["precision"], "contexts": "arcsine"},
            "history": {"batch": [[-1.0, 0.25]] * iterations, "evaluations": curve},
        }
        runs = folder / "runs" / "precision"
        runs.mkdir(parents=True, exist_ok=True)
        (runs / f"creps-cma-old-trial{trial}.json").write_text(json.dumps(document))
        state = {"cov": 4.0 * np.eye(2), "iteration": iterations, "diagnostics": {"ess": 3.0 + trial}}
        save_state(state, runs / f"creps-cma-old-trial{trial}.npz")

    full, sweep = tmp_path / "full", tmp_path / "full-opt-epsilon-2.0"
    for trial in (0, 1):
        finished(full, trial, {"ridge": 0.01}, 100, [[50, [1.0] * 10], [100, [2.0 + trial] * 10]])
    finished(sweep, 1, {"ridge": 0.01, "epsilon": 2.0}, 50, [[50, [0.25] * 10]])
    (sweep / "runs" / "precision" / "creps-cma-old-trial0.history.json").write_text(
        json.dumps({"setting": {}, "batch": [[0.0, 0.0]] * 30})
    )
    document = report.collect(full, "full", run.MODES["full"])
    own, row = document["sweep"]["precision"]["rows"]
    assert own["final_ess"] == [3.0, 4.0] and own["final_spread"] == [2.0, 2.0]
    assert (row["options"], row["study_same"], row["far_target"]) == ({"epsilon": 2.0}, [1.0], [2.0])
    assert document["sweep"]["precision"]["in_progress"] == {sweep.name: {"creps-cma-old-trial0": 30}}
    text = "\n".join(sweep_table.sweep_section(json.loads(json.dumps(document["sweep"]))))
    assert (
        "| 0.65 ± 0.00 m | 0.65 | 2.00 | 1.00 | 0.25 (50) | 0.25 ± 0.00 | 2.00 ± 0.00 | 4.0 ± 0.0 |" in text
    )
    assert "| 2.50 (100) |" not in text and "| 1.00 (50) |" in text  # the study's best mean evaluation
    line = (
        "- `epsilon=2.0` (`results/full-opt-epsilon-2.0`, 1 trial, 50 of 50 iterations): final 0.65 m "
        "(per trial 0.65; far point 2.00); the study's same trials at the same iteration 1.00 m; falls "
        "0.25, final spread 2.00, ESS 4.0"
    )
    assert sweep_table.row_line(row) == line and f"\n{line}\n" in text
    assert "- the study's own options (`results/full`, 2 trials, 100 of 100 iterations): final 0.65 m" in text
    assert (
        "In progress in `results/full-opt-epsilon-2.0` (checkpoint, no result yet): creps-cma-old-trial0"
        in text
    )


def test_final_ess_reads_the_checkpoint_s_diagnostics(tmp_path: Path) -> None:
    path = tmp_path / "creps-cma-old-trial0.npz"
    save_state({"cov": np.eye(2), "iteration": 5, "diagnostics": {"ess": 7.5}}, path)
    assert spread.final_ess(path, 5) == 7.5 and spread.final_ess(path, 6) is None
    save_state({"cov": np.eye(2), "iteration": 5}, path)
    assert spread.final_ess(path, 5) is None  # an optimiser that records none
    save_state({"cov": np.eye(2), "iteration": 5, "diagnostics": {"ess": float("nan")}}, path)
    with pytest.raises(ValueError, match=f"checkpoint {path}: expected a finite positive 'ess'"):
        spread.final_ess(path, 5)
    link = tmp_path / "link.npz"
    link.symlink_to(path)
    with pytest.raises(ValueError, match="checkpoint: expected a regular file"):
        spread.final_ess(link, 5)


def test_the_readme_s_sweep_quotes_the_rendered_rows() -> None:
    readme = (Path(run.__file__).resolve().parent / "README.md").read_text(encoding="utf-8")
    section = readme.split("\n### The sweep\n", 1)[1].split("\n## ", 1)[0]
    quotes = [line for line in section.splitlines() if line.startswith("- ") and "(`results/" in line]
    summary = (run.RESULTS / "full" / "summary.md").read_text(encoding="utf-8").splitlines()
    assert quotes and all(line in summary for line in quotes), [q for q in quotes if q not in summary]


@pytest.mark.slow
@pytest.mark.parametrize("divide_by_z", [True, False])
def test_without_selection_the_z_divisor_alone_grows_the_old_mean_covariance(divide_by_z: bool) -> None:
    """README, "The sweep": with returns that say nothing about θ, E[S] = Σ/Z around the old mean, so each
    update multiplies Σ by 1 − λ + λ/Z = 1 + ESS/(p²(ESS − 1)) > 1 + 1/p² (Eqs. 14–16); without Z by 1."""
    p = 25
    optimizer = make_optimizer("creps-cma-old", p, 1, seed=0, divide_by_z=divide_by_z, epsilon=2.0)
    rng = np.random.default_rng(1)
    log_factor = 0.0
    for _ in range(100):
        contexts = rng.uniform(3.0, 12.0, size=(20, 1))
        optimizer.tell(contexts, optimizer.ask(contexts), rng.normal(size=20))  # returns independent of θ
        ess, interpolation = optimizer.diagnostics["ess"], optimizer.diagnostics["interpolation"]
        assert interpolation == pytest.approx(ess / p**2)  # λ of Eq. (14): far below any cap ≥ N/p²
        if divide_by_z:
            log_factor += np.log1p(interpolation / (ess - 1.0))  # λ(1/Z − 1) with Z = 1 − 1/ESS
            assert np.log1p(interpolation / (ess - 1.0)) > np.log1p(1.0 / p**2)
    variance = float(np.mean(np.diag(optimizer.policy.covariance)))
    assert variance == pytest.approx(np.exp(log_factor), rel=0.05)
    assert (variance > 1.2) == divide_by_z
    readme = (Path(run.__file__).resolve().parent / "README.md").read_text(encoding="utf-8")
    bound = f"(1 + 1/{p**2})^500 = {(1 + 1 / p**2) ** 500:.2f}"  # the standard deviation after 1000 updates
    assert bound in readme
