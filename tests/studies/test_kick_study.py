"""The kick study (``benchmarks/kick``): runs resume bit-identically, oracles cache, and the committed summary
is exactly what the committed code renders from the committed ``results.json``."""

from __future__ import annotations

import copy
import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("mujoco")
pytest.importorskip("cma")

from benchmarks import provenance
from benchmarks.kick import oracle, report, run, selector_table, study
from creps_gym.errors import RunDirError
from creps_gym.wrappers import BetaContexts

pytestmark = pytest.mark.extras
FULL = Path(run.__file__).resolve().parent / "results" / "full"


@pytest.fixture(scope="module")
def precision_env() -> study.OffsetParams:
    return study.make_env("precision", threads=1)


@pytest.fixture(scope="module")
def trained(precision_env, tmp_path_factory: pytest.TempPathFactory):
    """``train(spec, trial, seed, folder)``: ``study.train_run(spec, precision_env, trial, seed, folder,
    checkpoint_every=1)``. A run is trained once per module, into a folder of its own: each call copies that
    folder's files into ``folder`` and returns a copy of the result (runs several tests share)."""
    runs: dict[str, tuple[Path, dict]] = {}

    def train(spec: study.RunSpec, trial: int, seed: int, folder: Path) -> dict:
        key = f"{spec!r} {trial} {seed}"
        if key not in runs:
            computed = tmp_path_factory.mktemp("trained")
            result = study.train_run(spec, precision_env, trial, seed, computed, checkpoint_every=1)
            runs[key] = computed, result
        computed, result = runs[key]
        shutil.copytree(computed, folder, dirs_exist_ok=True)
        return copy.deepcopy(result)

    return train


@pytest.fixture(scope="module")
def _oracle_at_3_once(precision_env, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict]:
    folder = tmp_path_factory.mktemp("oracle")
    return folder, oracle.oracle_point(precision_env, "precision", 3, episodes=26, seed=0, folder=folder)


@pytest.fixture
def oracle_at_3(_oracle_at_3_once, tmp_path: Path) -> tuple[Path, dict]:
    """The precision oracle at target 3 (26 episodes, seed 0), computed once per module: a copy of the
    folder it was cached in (``tmp_path / "oracle"``) and a copy of the result it returned."""
    folder, result = _oracle_at_3_once
    shutil.copytree(folder, tmp_path / "oracle")
    return tmp_path / "oracle", copy.deepcopy(result)


@pytest.mark.parametrize("name", ["c-cma-es", "creps-cma-old"])
@pytest.mark.slow
def test_an_interrupted_run_resumes_bit_identically(
    name: str, precision_env, trained, tmp_path: Path
) -> None:
    spec = study.RunSpec("precision", name, samples=6, iterations=4, options={"ridge": 1e-2})
    straight = trained(spec, 0, 7, tmp_path / "straight")
    half = study.RunSpec("precision", name, samples=6, iterations=2, options={"ridge": 1e-2})
    study.train_run(half, precision_env, 0, 7, tmp_path / "resumed", checkpoint_every=1)
    resumed = study.train_run(spec, precision_env, 0, 7, tmp_path / "resumed", checkpoint_every=1)
    assert resumed["iterations"] == straight["iterations"] == 4
    assert resumed["values"] == straight["values"]
    assert resumed["history"] == straight["history"]


@pytest.mark.slow
def test_a_finished_run_is_read_back_and_the_seed_changes_it(precision_env, trained, tmp_path: Path) -> None:
    spec = study.RunSpec("precision", "creps", samples=6, iterations=2)
    first = trained(spec, 0, 0, tmp_path)
    path = tmp_path / "creps-trial0.json"
    document = json.loads(path.read_text())
    document["values"] = [-1.0] * 10  # a cached result is returned as it is, without training again
    path.write_text(json.dumps(document))
    assert study.train_run(spec, precision_env, 0, 0, tmp_path)["values"] == [-1.0] * 10
    changed = study.RunSpec("precision", "creps", samples=6, iterations=2, options={"ridge": 1e-3})
    recomputed = study.train_run(changed, precision_env, 0, 0, tmp_path, checkpoint_every=1)
    assert recomputed["values"] != [-1.0] * 10 and recomputed["setting"]["options"] == {"ridge": 1e-3}
    other = study.train_run(spec, precision_env, 1, 0, tmp_path / "trial1", checkpoint_every=1)
    assert other["history"]["batch"] != first["history"]["batch"]


@pytest.mark.slow
def test_study_files_are_read_bounded_and_a_linked_run_file_is_refused(
    precision_env, trained, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    spec = study.RunSpec("precision", "creps", samples=6, iterations=2)
    trained(spec, 0, 0, tmp_path / "real")
    linked = tmp_path / "linked" / "runs" / "precision"
    linked.mkdir(parents=True)
    (linked / "creps-trial0.json").symlink_to(tmp_path / "real" / "creps-trial0.json")
    with pytest.raises(RunDirError, match="symbolic link"):  # the report does not follow it ...
        report.collect(tmp_path / "linked", "full", run.MODES["full"], selectors=False)
    with pytest.raises(RunDirError, match="symbolic link"):  # ... nor does a resumed run
        study.train_run(spec, precision_env, 0, 0, linked, checkpoint_every=1)
    monkeypatch.setattr(study, "MAX_JSON_BYTES", 100)  # a run document is larger than 100 bytes
    with pytest.raises(RunDirError, match="expected at most 100 bytes"):
        study.train_run(spec, precision_env, 0, 0, tmp_path / "real", checkpoint_every=1)


@pytest.mark.slow
def test_training_contexts_follow_the_spec_and_a_change_of_them_is_computed_again(
    precision_env, tmp_path: Path
) -> None:
    uniform = study.RunSpec("precision", "c-cma-es", samples=6, iterations=2, features="affine")
    arcsine = study.RunSpec("precision", "c-cma-es", 6, 2, "affine", contexts="arcsine")
    draws = {
        spec.contexts: study.context_sampler(spec, precision_env)(np.random.default_rng(0), 50_000)
        for spec in (uniform, arcsine)
    }
    np.testing.assert_array_equal(
        draws["arcsine"], BetaContexts([3.0], [12.0], 0.5)(np.random.default_rng(0), 50_000)
    )
    np.testing.assert_array_equal(
        draws["uniform"], precision_env.unwrapped.sample_contexts(np.random.default_rng(0), 50_000)
    )
    far = {name: float(np.mean(s[:, 0] > 11.5)) for name, s in draws.items()}
    assert far["uniform"] == pytest.approx(0.5 / 9, abs=0.005)  # 1 in 18 in the last half metre
    assert far["arcsine"] == pytest.approx(2 / np.pi * np.arcsin(np.sqrt(0.5 / 9)), abs=0.005)  # 15 %
    first = study.train_run(uniform, precision_env, 0, 0, tmp_path, checkpoint_every=1)
    assert first["setting"]["contexts"] == "uniform"
    again = study.train_run(arcsine, precision_env, 0, 0, tmp_path, checkpoint_every=1)
    assert again["setting"]["contexts"] == "arcsine"
    assert again["history"]["batch"] != first["history"]["batch"]  # other contexts, so trained again
    with pytest.raises(ValueError, match="contexts: expected one of"):
        study.RunSpec("precision", "c-cma-es", 6, 2, contexts="sobol")
    specs = run.run_specs(run.parse_args(["--full"]))
    assert {(spec.experiment, spec.contexts) for spec, _ in specs} == {
        ("precision", "arcsine"),
        ("flexibility", "uniform"),
    }


def test_features_choose_the_mean_map_and_the_results_folder(precision_env, tmp_path: Path) -> None:
    spec = study.RunSpec("precision", "c-cma-es", 6, 2, features="quadratic")
    assert spec.mean_features() == "quadratic"
    result = study.train_run(spec, precision_env, 0, 0, tmp_path, checkpoint_every=1)
    assert result["setting"]["features"] == "quadratic"
    assert study.load_run(tmp_path / "c-cma-es-trial0").config.mean_map.n_features == 3  # [1, s, s²]
    with pytest.raises(ValueError, match=r"features: expected one of \['affine', 'quadratic', 'rbf'\]"):
        study.RunSpec("precision", "c-cma-es", 6, 2, features="cubic")
    argv = ["--full", "--only", "flexibility", "--methods", "c-cma-es", "--features", "quadratic"]
    args = run.parse_args(argv)
    ((spec_full, trials),) = run.run_specs(args)
    assert (spec_full.features, spec_full.iterations, trials) == ("quadratic", 700, 3)
    assert spec_full.options == {**run.FULL_BUDGET, "ridge_centre": "zero"}  # only the features change
    assert args.out == run.RESULTS / "full-features-quadratic"
    assert (
        run.parse_args([*argv, "--contexts", "bandit"]).out == run.RESULTS / "full-bandit-features-quadratic"
    )
    default = [features for methods in run.METHODS.values() for _, features, _ in methods]
    assert [s.features for s, _ in run.run_specs(run.parse_args(["--full"]))] == default  # METHODS' own
    with pytest.raises(SystemExit):
        run.parse_args(["--features", "cubic"])


@pytest.mark.slow
def test_the_oracle_learns_one_context_and_caches_it(precision_env, oracle_at_3) -> None:
    folder, result = oracle_at_3  # oracle_point(precision_env, "precision", 3, 26, seed=0, folder=folder)
    assert result["context"] == [6.0] and result["episodes"] == 26 and result["population"] == 13
    assert np.isfinite(result["value"]) and result["value"] >= 0.0
    assert oracle.oracle_point(precision_env, "precision", 3, episodes=26, seed=0, folder=folder) == result


def test_run_files_that_name_no_env_ran_on_the_legacy_one() -> None:
    legacy = {"setting": {"features": "rbf", "options": {}, "samples": 20}}
    assert study.stored_setting(legacy, "precision")["env"] == "creps_gym/KickPrecision-v0"
    assert study.stored_setting(legacy, "precision")["contexts"] == "uniform"
    assert study.ENV_IDS["precision"] == "creps_gym/KickPrecision-v1"  # so v0 runs are computed again
    assert study.stored_setting(legacy, "flexibility")["env"] == "creps_gym/KickFlexibility-v1"
    assert study.ENV_IDS["flexibility"] == "creps_gym/KickFlexibility-v2"  # so v1 runs are computed again
    record = {"budget_episodes": 26, "episodes": 26, "population": 13}
    for experiment in ("precision", "flexibility"):
        assert not oracle._reusable(record, experiment, 26)
        assert oracle._reusable({**record, "env": study.ENV_IDS[experiment]}, experiment, 26)


def test_trial_indices_pick_the_trials_one_process_runs() -> None:
    assert run.trial_numbers(run.parse_args(["--full"]), 3) == [0, 1, 2]
    assert run.trial_numbers(run.parse_args(["--full", "--trial-indices", "2"]), 3) == [2]
    with pytest.raises(SystemExit):
        run.parse_args(["--trial-indices", "-1"])


@pytest.fixture(scope="module")
def flat_flexibility_env() -> study.OffsetParams:
    """v1, whose return is a flat 0 for every kick that misses the ball."""
    return study.OffsetParams(study.gym.make(study.LEGACY_ENV_IDS["flexibility"], num_threads=1))


@pytest.mark.slow
def test_the_oracle_restarts_with_twice_the_population_when_a_start_stops(
    flat_flexibility_env, tmp_path
) -> None:
    # The reference kick never touches a ball at x_B = 0.30 m: flat returns stop pycma within two iterations.
    result = oracle.oracle_point(
        flat_flexibility_env, "flexibility", 24, episodes=130, seed=0, folder=tmp_path
    )
    starts = result["starts"]
    assert [s["population"] for s in starts] == [13, 26, 52]
    assert all(s["stop"] for s in starts[:-1])
    assert result["episodes"] == sum(s["episodes"] for s in starts) <= 130
    assert result["value"] == max(s["value"] for s in starts)


@pytest.mark.slow
def test_an_old_oracle_record_is_reused_only_if_its_start_ran_its_budget(
    precision_env, oracle_at_3, tmp_path
) -> None:
    _, fresh = oracle_at_3  # oracle_point(precision_env, "precision", 3, 26, seed=0, folder=a fresh folder)
    old = {k: v for k, v in fresh.items() if k != "starts"}
    (tmp_path / "old").mkdir()
    (tmp_path / "old" / "oracle-03.json").write_text(json.dumps(old))
    reused = oracle.oracle_point(precision_env, "precision", 3, episodes=26, seed=0, folder=tmp_path / "old")
    assert reused == {**old, "env": study.ENV_IDS["precision"], "starts": [{**fresh["starts"][0]}]}
    stopped_early = {**old, "episodes": 13, "value": 99.0}
    (tmp_path / "old" / "oracle-03.json").write_text(json.dumps(stopped_early))
    recomputed = oracle.oracle_point(precision_env, "precision", 3, 26, seed=0, folder=tmp_path / "old")
    assert recomputed["value"] == fresh["value"] and "starts" in recomputed


def _finished_trial(experiment: str, trial: int, setting: dict, **fields) -> dict:
    """The document of a finished 5-iteration c-cma-es trial (20 samples), with ``fields`` replaced."""
    document = {
        "experiment": experiment,
        "name": "c-cma-es",
        "features": "affine",
        "options": {},
        "trial": trial,
        "samples": 20,
        "budget_iterations": 5,
        "iterations": 5,
        "episodes": 100,
        "stopped": [],
        "setting": setting,
        "values": [],
        "history": {"batch": [], "evaluations": []},
    }
    return {**document, **fields}


def test_results_have_the_issue_shape_and_the_summary_says_what_spreads(tmp_path: Path) -> None:
    runs = tmp_path / "runs"
    for experiment, values in (("precision", [0.5] * 10), ("flexibility", [3.0] * 28)):
        (runs / experiment).mkdir(parents=True)
        for trial, shift in enumerate((0.0, 1.0)):
            document = _finished_trial(experiment, trial, {"env": study.ENV_IDS[experiment]}, features="rbf")
            document.update(
                values=[v + shift for v in values], history={"batch": [], "evaluations": [[5, values]]}
            )
            (runs / experiment / f"c-cma-es-trial{trial}.json").write_text(json.dumps(document))
        stale = {**document, "trial": 2, "setting": {"env": "creps_gym/KickFlexibility-v1"}}
        (runs / experiment / "c-cma-es-trial2.json").write_text(json.dumps(stale))  # another env: ignored
        oracle = {
            "index": 0,
            "env": study.ENV_IDS[experiment],
            "context": [0.15, -0.15],
            "optimizer": "cma",
            "episodes": 13,
            "value": 8.0,
            "best": 9.0,
            "starts": [{"population": 13, "episodes": 13, "value": 8.0, "stop": {}}],
        }
        (runs / experiment / "oracle-00.json").write_text(json.dumps(oracle))
    document = report.collect(tmp_path, "quick", run.MODES["quick"])
    assert "— (oracle incomplete)" in report.summary_text(document)  # no fraction of a partial oracle
    for index in range(1, len(study.grid_contexts())):
        (runs / "flexibility" / f"oracle-{index:02d}.json").write_text(json.dumps(oracle))
    document = report.collect(tmp_path, "quick", run.MODES["quick"])
    assert document["precision"]["c-cma-es"]["trial_errors"] == [0.5, 1.5]
    assert document["flexibility"]["c-cma-es"]["trial_distances"] == [3.0, 4.0]  # the v1 trial is stale
    assert document["flexibility"]["oracle"]["position_distances"] == [8.0] * 28
    text = report.summary_text(document)
    assert "1.00 ± 0.50 m" in text  # precision: mean ± std across the two trials
    assert document["precision"]["c-cma-es"]["training_contexts"] == ["uniform", "uniform"]  # not named
    assert "| c-cma-es | uniform | 5 × 20 | 2 |" in text
    assert "3.50 ± 0.50 m" in text and "| 0.44 |" in text  # flexibility, and 3.5 / 8.0 of the oracle


def test_the_learning_curve_table_averages_the_trials_where_all_were_evaluated() -> None:
    entries = {
        "c-cma-es": {"curves": [[[50, 9.0], [100, 1.0], [200, 0.5]], [[50, 9.0], [100, 2.0], [200, 1.0]]]},
        "creps": {"curves": [[[100, 3.0], [200, 2.0]], [[100, 4.0]]]},  # trial 1 stopped before 200
        "oracle": {"target_errors": [0.1] * 10},
    }
    lines = report._curve_table(entries, "Curves")
    assert lines[2] == "| method | 100 | 200 |"
    assert lines[4:6] == ["| c-cma-es | 1.50 | 0.75 |", "| creps | 3.50 | — |"]
    assert len(lines) == 7 and report._curve_table({"oracle": entries["oracle"]}, "Curves") == []


def test_a_finished_run_being_recomputed_under_another_setting_is_in_progress_not_rendered(
    tmp_path: Path,
) -> None:
    folder = tmp_path / "runs" / "precision"
    folder.mkdir(parents=True)
    old = {"env": study.ENV_IDS["precision"], "features": "affine", "options": {}, "samples": 20}
    for trial in (0, 1):
        document = _finished_trial("precision", trial, old, values=[float(trial)] * 10)
        (folder / f"c-cma-es-trial{trial}.json").write_text(json.dumps(document))
        (folder / f"c-cma-es-trial{trial}.history.json").write_text(json.dumps({"setting": old, "batch": []}))
    new = {**old, "options": {"baseline_loss": "huber"}}  # trial 1 restarted under new options
    (folder / "c-cma-es-trial1.history.json").write_text(json.dumps({"setting": new, "batch": [[0, 0]] * 3}))
    document = report.collect(tmp_path, "quick", run.MODES["quick"])
    assert document["precision"]["c-cma-es"]["trial_errors"] == [0.0]
    assert document["in_progress"] == {"precision/c-cma-es-trial1": 3}


@pytest.mark.slow
def test_the_script_runs_by_path_writes_results_summary_and_figures_and_quick_computes_again(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    pytest.importorskip("matplotlib")
    # The study computes in process on a tiny budget (3 iterations instead of --quick's 40); running the
    # script by path (the repository root put on sys.path by run.py) is checked by the --render-only call.
    monkeypatch.setitem(run.MODES, "quick", {**run.MODES["quick"], "precision": (3, 1)})
    args = ["--quick", "--only", "precision", "--methods", "creps", "--out", str(tmp_path), "--threads", "1"]
    assert run.main(args) == 0
    document = json.loads((tmp_path / "results.json").read_text())
    assert len(document["precision"]["creps"]["trial_errors"]) == 1
    assert (tmp_path / "summary.md").read_text() == report.summary_text(document)
    assert (tmp_path / "precision.png").stat().st_size > 10_000
    (group,) = document["provenance"]
    assert group["runs"] == ["precision/creps-trial0"] and provenance.is_recorded(group["record"])
    assert group["record"]["packages"]["mujoco"] != "not installed"
    path = tmp_path / "runs" / "precision" / "creps-trial0.json"
    written = json.loads(path.read_text())
    path.write_text(json.dumps({**written, "values": [9.0] * 10, "provenance": None}))
    script = [sys.executable, str(Path(run.__file__)), *args, "--render-only"]
    rendered = subprocess.run(script, capture_output=True, text=True, timeout=300, check=False)
    assert rendered.returncode == 0, rendered.stderr[-2000:]
    assert "9.00 ± 0.00 m" in (tmp_path / "summary.md").read_text()  # read back as it is
    assert "1 run: computed before provenance" in (tmp_path / "summary.md").read_text()
    assert run.main(args) == 0
    recomputed = json.loads(path.read_text())  # --quick trains the run again, bit for bit
    assert recomputed["values"] == written["values"] and recomputed["history"] == written["history"]
    assert json.loads((tmp_path / "results.json").read_text())["precision"] == document["precision"]


#: Every committed results folder: the study's (quick, full) and the ``--contexts`` ones beside them.
FOLDERS = sorted({"quick", "full", *(path.parent.name for path in FULL.parent.glob("*/results.json"))})


@pytest.mark.parametrize("name", FOLDERS)
@pytest.mark.slow
def test_the_committed_summary_is_rendered_from_the_committed_results(name: str, tmp_path: Path) -> None:
    folder = FULL.parent / name
    if not (folder / "results.json").exists():
        pytest.skip(f"no committed {name} results yet: python benchmarks/kick/run.py --{name}")
    shutil.copy(folder / "results.json", tmp_path / "results.json")
    document = json.loads((tmp_path / "results.json").read_text())
    mode = document["mode"]
    assert (folder / "summary.md").read_text() == report.summary_text(document)
    # ... with the comparison of training contexts if run.py --contexts wrote a folder beside it (issue 32).
    beside = [path.name for path in selector_table.comparison_folders(folder)]
    assert document.get("selectors", {}).get("folders", [name])[1:] == beside
    if beside:
        section = f"## {selector_table.SECTION}"
        assert section in (folder / "summary.md").read_text()
    # ... it says where every run and oracle was computed, or that it was before provenance was recorded.
    records = [group["record"] for group in document["provenance"] for _ in group["runs"]]
    entries = [entry for x in ("precision", "flexibility") for entry in document[x].values()]
    assert len(records) == sum(len(entry.get("trials", entry.get("contexts", []))) for entry in entries)
    if not all(provenance.is_recorded(record) for record in records):
        assert "recorded before provenance" in (FULL.parents[1] / "README.md").read_text(encoding="utf-8")
    # ... and results.json is what the committed code gathers from the committed run files: a run file
    # that the current code would compute again (another env or setting) cannot stay in it.
    gathered = report.collect(folder, mode, run.MODES[mode])
    assert json.loads(json.dumps(gathered)) == document


@pytest.mark.parametrize("selector", study.SELECTED_CONTEXTS)
@pytest.mark.slow
def test_a_learning_selector_trains_resumes_bit_identically_and_is_wired_to_the_command_line(
    selector: str, precision_env, trained, tmp_path: Path
) -> None:
    spec = study.RunSpec("precision", "creps-cma-old", 6, 4, options={"ridge": 1e-2}, contexts=selector)
    straight = study.train_run(spec, precision_env, 0, 7, tmp_path / "straight", checkpoint_every=1)
    half = study.RunSpec("precision", "creps-cma-old", 6, 2, options={"ridge": 1e-2}, contexts=selector)
    study.train_run(half, precision_env, 0, 7, tmp_path / "resumed", checkpoint_every=1)
    states = json.loads((tmp_path / "resumed" / "creps-cma-old-trial0.selector.json").read_text())
    assert sorted(states, key=int) == ["1", "2"]  # the last two checkpoints' states
    resumed = study.train_run(spec, precision_env, 0, 7, tmp_path / "resumed", checkpoint_every=1)
    assert resumed["history"] == straight["history"] and resumed["values"] == straight["values"]
    assert resumed["setting"]["contexts"] == selector
    final = json.loads((tmp_path / "straight" / "creps-cma-old-trial0.selector.json").read_text())
    assert sorted(final, key=int) == ["3", "4"] and final["4"] != final["3"]  # told every iteration
    if selector == "bandit":  # ("progress" draws uniformly until it has seen two windows of 3 iterations)
        uniform = study.RunSpec("precision", "creps-cma-old", 6, 4, options={"ridge": 1e-2})
        other = trained(uniform, 0, 7, tmp_path / "uniform")
        assert other["history"]["batch"] != straight["history"]["batch"]
    args = run.parse_args(
        ["--full", "--only", "precision", "--methods", "creps-cma-old", "--contexts", selector]
    )
    ((spec_full, trials),) = run.run_specs(args)
    assert spec_full.contexts == selector and spec_full.iterations == 1000 and trials == 3
    assert args.out == run.RESULTS / f"full-{selector}"


def test_the_row_table_averages_each_row_of_balls_over_trials_and_counts_the_positions_at_zero() -> None:
    near_only = np.repeat([8.0, 6.0, 0.0, 0.0], 7)  # x-major: 7 positions per row of x_B
    everywhere = np.repeat([10.0, 4.0, 2.0, 1.0], 7)
    everywhere[-1] = 0.0  # one fall at x_B = 0.30 m
    entries = {"c-cma-es": {"position_distances": [near_only.tolist(), everywhere.tolist()]}, "oracle": {}}
    lines = report._row_table(entries)
    assert (
        lines[2]
        == "| method | x_B = 0.15 m | x_B = 0.20 m | x_B = 0.25 m | x_B = 0.30 m | positions at 0 m |"
    )
    # rows: (8 + 10) / 2, (6 + 4) / 2, (0 + 2) / 2, (0 + 6/7) / 2; zeros: 14 and 1.
    assert lines[4] == "| c-cma-es | 9.00 | 5.00 | 1.00 | 0.43 | 14, 1 |"
    assert len(lines) == 6  # the oracle has no row
