"""Hostile input on the state behind the policy surfaces (issue 42, items 16, 17, 18 and 20): sizes set by a
policy file or a flag, kept policies bound to their run, counters and generator states range-checked,
crashes that had the wrong exit code, and state fields refused without their name.

Forgeries edit a checkpoint as an adversary would (recomputing the loop state's plain CRC-32).
"""

from __future__ import annotations

import io
import json
import shutil
import subprocess
import tracemalloc
import zipfile
from pathlib import Path

import numpy as np
import pytest
from helpers import EXTRAS, SPHERE, cli_command, crash_at, forge, run_argv

import creps_gym
from creps_gym.cli import main
from creps_gym.errors import RunDirError
from creps_gym.optimizers import Policy, load_state, restore_optimizer, save_state
from creps_gym.optimizers.features import make_features
from creps_gym.runner import RunDir, resume, run
from creps_gym.selectors.progress import KernelProgressSelector


def policy_bytes(document: dict, arrays: dict) -> bytes:
    """A policy file's bytes as :meth:`Policy.save` writes them, for any ``document``."""
    buffer = io.BytesIO()
    entries = {**arrays, "__policy__.json": np.frombuffer(json.dumps(document).encode(), dtype=np.uint8)}
    with zipfile.ZipFile(buffer, "w") as archive:
        for name, array in entries.items():
            npy = io.BytesIO()
            np.lib.format.write_array(npy, np.ascontiguousarray(array), allow_pickle=False)
            archive.writestr(f"{name}.npy", npy.getvalue())
    return buffer.getvalue()


def _unfinished(path: Path, optimizer: str = "c-cma-es", **options) -> Path:
    """A run of 6 iterations whose last checkpoint is iteration 4 (evaluated at every iteration)."""
    with pytest.raises(RuntimeError, match="crash"):
        run(
            optimizer,
            SPHERE,
            6,
            None,
            0,
            env_kwargs={"dim": 2},
            run_dir=path,
            checkpoint_every=1,
            callbacks=[crash_at(5)],
            **options,
        )
    return path


@pytest.fixture(scope="module")
def unfinished(tmp_path_factory) -> Path:
    return _unfinished(tmp_path_factory.mktemp("runs") / "unfinished")


@pytest.fixture
def copy(tmp_path, unfinished) -> Path:
    shutil.copytree(unfinished, tmp_path / "run")
    return tmp_path / "run"


def _limited(gigabytes: float):
    def limit():  # a missing guard fails with MemoryError instead of hurting the machine
        import resource

        resource.setrlimit(resource.RLIMIT_AS, (int(gigabytes * 2**30),) * 2)

    return limit


def _cli(*args: object) -> subprocess.CompletedProcess:
    return subprocess.run(
        cli_command(*args), capture_output=True, text=True, timeout=300, preexec_fn=_limited(6)
    )


# -- item 16: sizes that a file or a flag sets are checked against memory first -----------------------------
def _rbf_policy(k: int, p: int = 1) -> Policy:
    # The map from an array of centres: a spec of k nested lists would be walked item by item.
    features = make_features({"name": "rbf", "centres": np.zeros((k, 1)), "bandwidth": 1.0}, context_dim=1)
    return Policy(features, np.zeros((k, p)), env=SPHERE, env_kwargs={"dim": p})


@pytest.mark.slow
def test_a_compressed_policy_file_that_declares_many_rbf_centres_is_refused(tmp_path):
    policy = _rbf_policy(1_500_000)
    entries = zipfile.ZipFile(io.BytesIO(policy_bytes(policy.to_dict(arrays=False), policy.arrays())))
    with zipfile.ZipFile(tmp_path / "small.npz", "w", compression=zipfile.ZIP_DEFLATED) as archive:
        for info in entries.infolist():
            archive.writestr(info.filename, entries.read(info), compress_type=zipfile.ZIP_DEFLATED)
    assert (tmp_path / "small.npz").stat().st_size < 200_000  # 1.5 M centres in ~100 kB
    result = _cli("evaluate", tmp_path / "small.npz")
    assert result.returncode == 3, result.stderr
    assert "expected an uncompressed array" in result.stderr and "small.npz" in result.stderr


def test_contexts_whose_policy_features_exceed_memory_are_refused_before_allocating():
    policy = _rbf_policy(200_000)
    with pytest.raises(
        ValueError, match=r"contexts: expected a size whose arrays fit in memory .*k = 200000"
    ):
        policy(np.zeros((100_000, 1)))  # 100 k x 200 k x 3 floats: 480 GB


RUN_ARGS = run_argv("NEW")


@pytest.mark.parametrize(
    ("args", "expected"),
    [
        (
            ["evaluate", "RUN", "--contexts", str(10**12)],
            "argument --contexts: expected a size whose arrays fit",
        ),
        (
            [*RUN_ARGS, "--context-selector", "progress", "--selector-opt", f"candidates={10**12}"],
            "argument --selector-opt: candidates: expected a size whose arrays fit in memory",
        ),
    ],
    ids=["evaluate-contexts", "selector-candidates"],
)
@pytest.mark.slow
def test_sizes_set_by_a_flag_are_refused_with_one_line(tmp_path, unfinished, args, expected):
    args = [str(unfinished) if a == "RUN" else str(tmp_path / "new") if a == "NEW" else a for a in args]
    result = _cli(*args)
    assert result.returncode == 2 and expected in result.stderr, result.stderr
    assert "Traceback" not in result.stderr and not (tmp_path / "new").exists()


@pytest.mark.slow
def test_selector_candidates_from_a_run_folder_are_refused_before_allocating(tmp_path):
    _unfinished(tmp_path / "run", context_selector="progress")
    document = json.loads((tmp_path / "run" / RunDir.CONFIG).read_text())
    document["config"]["context_selector_options"] = {"candidates": 10**12}
    (tmp_path / "run" / RunDir.CONFIG).write_text(json.dumps(document))
    result = _cli("resume", tmp_path / "run")
    assert result.returncode == 3 and "candidates: expected a size whose arrays fit" in result.stderr


@pytest.mark.slow
def test_a_forged_progress_state_with_many_kept_episodes_stays_in_bounded_memory():
    selector = KernelProgressSelector(window=1)
    selector.bind(np.zeros(1), np.ones(1), None)
    k = 400_000
    state = {"iteration": 5, "contexts": [[0.5]] * k, "returns": [0.0] * (k // 2) + [1.0] * (k // 2)}
    state["ages"] = [0] * (k // 2) + [1] * (k // 2)
    selector.load_state_dict(state)
    tracemalloc.start()
    try:
        contexts = selector.select(np.random.default_rng(0), 8)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert contexts.shape == (8, 1) and peak < 300 * 2**20  # 256 candidates x 400 k kept: 2.4 GB at once


def test_the_progress_estimate_in_blocks_equals_the_estimate_at_once():
    selector = KernelProgressSelector(window=1)
    selector.bind(np.zeros(2), np.ones(2), None)
    rng = np.random.default_rng(1)
    for _ in range(3):
        selector.tell(rng.random((50, 2)), rng.random(50), {})
    points = rng.random((300, 2))
    whole = selector.progress(points)
    from creps_gym.selectors import progress as module

    block, module.BLOCK = module.BLOCK, 1000  # 10 points per block
    try:
        np.testing.assert_array_equal(selector.progress(points), whole)
    finally:
        module.BLOCK = block


# -- item 17: kept policies are bound to their run; counters are range-checked -----------------------------
def test_a_best_policy_copied_from_another_run_is_refused(tmp_path, capsys):
    for seed in (0, 1):
        run("c-cma-es", SPHERE, 3, None, seed, env_kwargs={"dim": 2}, run_dir=tmp_path / f"s{seed}")
    shutil.copy(tmp_path / "s1" / RunDir.BEST_POLICY, tmp_path / "s0" / RunDir.BEST_POLICY)
    assert main(["evaluate", str(tmp_path / "s0")]) == 3
    err = capsys.readouterr().err
    assert "best_policy.npz" in err and "expected a policy kept by this run (its fingerprint" in err
    with pytest.raises(RunDirError, match="a policy of another run"):
        creps_gym.load_policy(tmp_path / "s0")


@pytest.mark.parametrize(
    ("change", "expected"),
    [
        ({"source.iteration": 999}, "best_policy: expected an iteration in \\[0, 4\\]"),
        ({"source.eval_regret": 0.0}, "expected the evaluation of the history's best iteration"),
        ({"env": "creps_gym/Rosenbrock-v0"}, "expected a policy kept by this run \\(its env"),
        ({"n_params": 3}, "n_params|columns"),
        ({"source.run": "0" * 64}, "its fingerprint"),
    ],
    ids=["iteration-999", "regret-0", "another-env", "another-p", "another-run"],
)
def test_a_best_policy_forged_in_a_checkpoint_is_refused(copy, change, expected):
    flat = load_state(copy / RunDir.CHECKPOINT)
    best = flat["best_policy"]
    for key, value in change.items():
        if key == "n_params":
            best["n_params"] = value
            best["arrays"]["coefficients"] = [0.0] * (2 * value)  # affine features: 2 rows
            best["arrays"]["param_low"], best["arrays"]["param_high"] = ["-inf"] * 3, ["inf"] * 3
        elif key.startswith("source."):
            best["source"][key.removeprefix("source.")] = value
        else:
            best[key] = value
    forge(copy / RunDir.CHECKPOINT, best_policy=best)
    with pytest.raises(RunDirError, match=expected):
        resume(copy)
    assert not (copy / RunDir.BEST_POLICY).exists() or Policy.load(copy / RunDir.BEST_POLICY).env == SPHERE


@pytest.mark.parametrize("value", [10**400, -3, 1e308, 1.5], ids=["10**400", "-3", "1e308", "1.5"])
@pytest.mark.parametrize("key", ["restarts_done", "flat_iterations"])
def test_optimizer_counters_in_a_checkpoint_are_range_checked(copy, capsys, key, value):
    forge(copy / RunDir.CHECKPOINT, **{f"optimizer.{key}": value})
    assert main(["resume", str(copy), "--no-plot"]) == 3
    err = capsys.readouterr().err
    assert f"state['{key}']: expected an integer" in err and "Traceback" not in err, err


@pytest.mark.parametrize("value", [10**400, -3, 1.5], ids=["10**400", "-3", "1.5"])
def test_surrogate_generation_counters_are_range_checked(tmp_path, value):
    path = _unfinished(tmp_path / "run", "c-cma-es-surrogate")
    forge(path / RunDir.CHECKPOINT, **{"optimizer.model_generations_total": value})
    with pytest.raises(RunDirError, match=r"state\['model_generations_total'\]: expected an integer"):
        resume(path)


@pytest.mark.parametrize(
    ("selector", "field", "value", "expected"),
    [
        ("progress", "iteration", 10**400, "iteration: expected an integer of at most"),
        ("progress", "iteration", -3, "iteration: expected an integer >= 0"),
        ("bandit", "counts", 10**400, "counts: expected finite values"),
        ("bandit", "counts", 1e308, "counts: expected a sum <="),
    ],
    ids=["progress-10**400", "progress-negative", "bandit-10**400", "bandit-1e308"],
)
def test_selector_counters_in_a_checkpoint_are_range_checked(tmp_path, selector, field, value, expected):
    path = _unfinished(tmp_path / "run", context_selector=selector)
    state = load_state(path / RunDir.CHECKPOINT)["selector"]
    if field == "counts":
        state["counts"] = [value] * len(state["counts"])
        state["sums"] = [0.0] * len(state["sums"])
    else:
        state[field] = value
    forge(path / RunDir.CHECKPOINT, selector=state)
    with pytest.raises(RunDirError, match=expected):
        resume(path)


# -- item 18: crashes that had the wrong exit code ----------------------------------------------------------
def _policy_file(tmp_path: Path, **document_changes) -> Path:
    policy = Policy.constant([1.0, 2.0], 1, env=SPHERE, env_kwargs={"dim": 2})
    document = {**policy.to_dict(arrays=False), **document_changes}
    (tmp_path / "p.npz").write_bytes(policy_bytes(document, policy.arrays()))
    return tmp_path / "p.npz"


def test_a_policy_file_with_deeply_nested_env_kwargs_is_a_damaged_file(tmp_path, capsys):
    deep: dict = {}
    for _ in range(900):
        deep = {"a": deep}
    path = _policy_file(tmp_path, env_kwargs=deep)
    assert main(["evaluate", str(path)]) == 3 and main(["policy", str(path)]) == 3
    err = capsys.readouterr().err
    assert "expected JSON nested at most 100 levels deep" in err and "RecursionError" not in err


def test_an_npy_header_with_a_bool_in_its_shape_is_a_damaged_file(tmp_path, capsys):
    path = _policy_file(tmp_path)
    entries = zipfile.ZipFile(io.BytesIO(path.read_bytes()))
    with zipfile.ZipFile(tmp_path / "true.npz", "w") as archive:
        for info in entries.infolist():
            raw = entries.read(info)
            if info.filename == "coefficients.npy":  # (1, 2) -> (True, 2), the header's length kept
                raw = raw.replace(b"'shape': (1, 2), }   ", b"'shape': (True, 2), }")
            archive.writestr(info, raw)
    assert main(["policy", str(tmp_path / "true.npz")]) == 3
    assert "expected a shape of non-negative ints" in capsys.readouterr().err


def test_a_bandit_with_a_uniform_share_of_one_runs(tmp_path):
    history = run(
        "c-cma-es",
        SPHERE,
        2,
        None,
        0,
        env_kwargs={"dim": 2},
        run_dir=tmp_path / "run",
        context_selector="bandit",
        context_selector_options={"uniform_share": 1},
    )
    assert len(history) == 2 and (tmp_path / "run" / RunDir.POLICY).exists()


@pytest.mark.parametrize("word", [-1, 2**128, 1.5])
def test_a_bad_generator_state_in_a_checkpoint_is_a_damaged_file(copy, capsys, word):
    flat = load_state(copy / RunDir.CHECKPOINT)
    flat["optimizer.rng"]["state"]["state"] = word
    save_state(flat, copy / RunDir.CHECKPOINT)
    assert main(["policy", str(copy), "--which", "final"]) == 3
    err = capsys.readouterr().err
    assert "checkpoint.npz" in err and "state['rng']: expected a PCG64 state" in err


# -- item 20: optimiser state fields are named and range-checked --------------------------------------------
def _optimizer_state(path: Path) -> dict:
    flat = load_state(path / RunDir.CHECKPOINT)
    return {k.removeprefix("optimizer."): v for k, v in flat.items() if k.startswith("optimizer.")}


@pytest.mark.parametrize(
    ("key", "value", "error", "expected"),
    [
        ("step_size", None, TypeError, r"state\['step_size'\]: expected a real number"),
        ("step_size", 1e-320, ValueError, r"state\['step_size'\]: expected a value >= 1.5e-154"),
        ("dual_eta", "abc", TypeError, r"state\['dual_eta'\]: expected a real number"),
        ("dual_eta", 10**400, ValueError, r"state\['dual_eta'\]: expected a finite number"),
        (
            "flat_iterations",
            10**30,
            ValueError,
            r"state\['flat_iterations'\]: expected an integer of at most",
        ),
        ("flat_iterations", -5, ValueError, r"state\['flat_iterations'\]: expected an integer >= 0"),
        ("flat_iterations", 1.5, TypeError, r"state\['flat_iterations'\]: expected an integer"),
    ],
    ids=["step-None", "step-1e-320", "eta-abc", "eta-10**400", "flat-10**30", "flat-negative", "flat-1.5"],
)
def test_creps_state_fields_are_named_and_range_checked(tmp_path, key, value, error, expected):
    path = tmp_path / "run"
    run("creps", SPHERE, 2, 12, 0, env_kwargs={"dim": 2}, run_dir=path)
    state = _optimizer_state(path)
    state[key] = value
    with pytest.raises(error, match=expected):
        restore_optimizer("creps", state)


def test_an_ask_with_a_row_missing_is_refused_naming_ask_before_any_episode():
    from creps_gym.optimizers.creps import CREPS

    class Short(CREPS):
        def ask(self, contexts):
            return super().ask(contexts)[:-1]

    with pytest.raises(
        ValueError, match=r"optimizer\.ask\(\) output: expected shape \(12, 2\), got \(11, 2\)"
    ):
        run(Short(2, 1, seed=0), SPHERE, 2, 12, 0, env_kwargs={"dim": 2})


@pytest.mark.parametrize("name", ["disable_env_checker", "max_episode_steps"])
def test_an_argument_of_gymnasium_make_is_not_an_env_keyword(tmp_path, capsys, name):
    args = [*RUN_ARGS, "--env-kwarg", f"{name}=1", "--no-plot"]
    assert main([str(tmp_path / "new") if a == "NEW" else a for a in args]) == 2
    err = capsys.readouterr().err
    assert f"argument --env-kwarg: expected keyword arguments of the env, got '{name}'" in err
    assert not (tmp_path / "new").exists()


@pytest.mark.parametrize("name", [RunDir.CONFIG, RunDir.HISTORY_JSON])
def test_a_meta_that_is_not_an_object_is_damage_not_a_crash(tmp_path, capsys, name):
    path = tmp_path / "run"
    run("creps", SPHERE, 2, 12, 0, env_kwargs={"dim": 2}, run_dir=path)
    document = json.loads((path / name).read_text())
    document["meta"] = [1, 2]
    (path / name).write_text(json.dumps(document))
    code = main(["export", str(path), "-o", str(tmp_path / "out.csv")])
    err = capsys.readouterr().err
    if name == RunDir.CONFIG:
        assert code == 3 and "config.json: damaged" in err and "expected a 'meta' object, got list" in err
    else:  # the history is rebuilt from the log, with a warning
        assert code == 0 and "meta: expected a JSON object, got list" in err


@EXTRAS  # `plot` needs matplotlib
@pytest.mark.slow
def test_a_plot_title_with_bad_mathtext_is_a_usage_error(tmp_path, capsys, unfinished):
    args = ["plot", str(unfinished), "-o", str(tmp_path / "p.png"), "--title", r"$\frac{$"]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "argument --title: expected text matplotlib can draw" in err and "ParseSyntaxException" in err
    assert not (tmp_path / "p.png").exists()
    assert main([*args[:-1], r"a $x^2$ and \$5"]) == 0


def test_an_integer_reward_beyond_the_float_range_is_named():
    from creps_gym.runner.backends.episodes import episode_return
    from creps_gym.wrappers.episodic import _real_reward

    with pytest.raises(
        ValueError, match=r"reward: expected a finite real number .* 401 digits .* inner step 3"
    ):
        _real_reward(10**400, 3)
    with pytest.raises(ValueError, match="reward: expected a finite return, got an integer of 401 digits"):
        episode_return(10**400)
