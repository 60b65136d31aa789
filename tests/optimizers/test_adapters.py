"""The pycma, nevergrad and optuna adapters, the optimiser registry and the adapter-writing guide."""

from __future__ import annotations

import json
import shlex
import subprocess
import sys
import threading
from pathlib import Path

import gymnasium
import numpy as np
import pytest
from helpers import EXTRAS, marked, python_blocks, run_argv

from creps_gym import cli
from creps_gym.envs.evaluation import evaluate_policy, test_contexts
from creps_gym.optimizers import registry
from creps_gym.optimizers.adapters import CMAAdapter, MinimizerAdapter, NevergradAdapter, OptunaAdapter
from creps_gym.optimizers.base import load_state, save_state
from creps_gym.runner import default_initial_distribution, run, split_seed
from creps_gym.runner.config import RunConfig
from creps_gym.runner.loop import Runner

ADAPTERS = {"cma": CMAAdapter, "nevergrad": NevergradAdapter, "optuna": OptunaAdapter}
GUIDE = Path(__file__).resolve().parents[2] / "docs" / "writing_an_adapter.md"


def _drive(optimizer, iterations, n=8, z=1, seed=0):
    """A quadratic with maximum at 0.3 in every coordinate; contexts are random and irrelevant."""
    rng = np.random.default_rng(seed)
    asked = []
    for _ in range(iterations):
        contexts = rng.uniform(size=(n, z))
        params = optimizer.ask(contexts)
        asked.append(params)
        optimizer.tell(contexts, params, -np.sum((params - 0.3) ** 2, axis=1))
    return asked


def test_registry_lists_every_adapter_with_a_one_line_description():
    described = registry.describe_optimizers()
    assert set(ADAPTERS) | {"creps", "creps-cma-old", "creps-cma-current"} <= set(described)
    assert all(text and "\n" not in text for text in described.values())
    for name, cls in ADAPTERS.items():
        assert registry.optimizer_class(name) is cls


# Every registered optimiser's shape and checkpoint (pending batch included):
# tests/optimizers/test_contract_checkpoint.py.


def test_make_optimizer_names_the_valid_choices_and_fixed_options():
    with pytest.raises(ValueError, match=r"optimizer: expected one of \[.*'cma'.*\], got 'nope'"):
        registry.make_optimizer("nope", 2, 1, 0)
    with pytest.raises(ValueError, match="variant"):
        registry.make_optimizer("creps-cma-old", 2, 1, 0, variant="current")


@EXTRAS
@pytest.mark.parametrize("name", sorted(ADAPTERS))
@pytest.mark.slow
def test_adapter_learns_on_a_function_env(name):
    history = run(name, "creps_gym/Sphere-v0", 20, 12, 3, env_kwargs={"dim": 3}, eval_every=19)
    regrets = history.column("eval_regret")
    assert np.isnan(regrets[0]) and np.isfinite(regrets[[18, 19]]).all()
    env = gymnasium.make("creps_gym/Sphere-v0", dim=3)
    contexts = test_contexts(env, 16, split_seed(3)[2])  # the runner's test contexts for seed 3
    centre = default_initial_distribution(env.action_space)[0]  # the runner's initial mean
    start = evaluate_policy(env, centre, contexts).mean_regret
    # On the sphere the regret is |theta - theta*(s)|^2, so no constant policy beats the mean of theta*(s).
    best_constant = evaluate_policy(env, env.unwrapped.optimal_params(contexts).mean(axis=0), contexts)
    assert best_constant.mean_regret <= regrets[-1] < 0.9 * start  # maximising the return lowers the regret


@EXTRAS
@pytest.mark.parametrize("name", sorted(ADAPTERS))
def test_sign_convention_library_minimises_the_negated_return(name):
    adapter = ADAPTERS[name](2, 1, initial_mean=0.0, initial_cov=1.0, seed=5)
    contexts = np.zeros((6, 1))
    params = adapter.ask(contexts)
    returns = np.arange(6.0)
    adapter.tell(contexts, params, returns)
    recorded = adapter.state_dict()["told_losses"]
    assert np.array_equal(recorded, -returns)
    assert adapter.diagnostics["best_return"] == 5.0


@EXTRAS
@pytest.mark.parametrize("name", sorted(ADAPTERS))
def test_contexts_are_ignored_and_asks_are_seeded(name):
    a = ADAPTERS[name](3, 2, seed=9)
    b = ADAPTERS[name](3, 2, seed=9)
    c = ADAPTERS[name](3, 2, seed=10)
    np.random.seed(0)  # noqa: NPY002 (global state must not matter)
    first = _drive(a, 4, z=2, seed=1)
    np.random.seed(123)  # noqa: NPY002
    second = _drive(b, 4, z=2, seed=2)  # other context values, same batch sizes
    assert all(np.array_equal(x, y) for x, y in zip(first, second, strict=True))
    assert not np.array_equal(_drive(c, 1, z=2)[0], first[0])
    rec = a.recommend(np.array([[0.0, 0.0], [3.0, -1.0]]))
    assert np.array_equal(rec[0], rec[1])


@EXTRAS
@pytest.mark.parametrize("name", sorted(ADAPTERS))
def test_replay_reproduces_every_recorded_ask_bit_for_bit(name, tmp_path):
    adapter = ADAPTERS[name](
        4, 1, initial_mean=[1.0, 0.0, -1.0, 2.0], initial_cov=[0.5, 1.0, 2.0, 0.1], seed=3
    )
    asked = _drive(adapter, 6)
    path = save_state(adapter.state_dict(), tmp_path / "adapter.npz")
    state = load_state(path)
    replayed = ADAPTERS[name].from_state_dict(state)
    assert np.array_equal(
        np.concatenate(asked), replayed.initial_mean + replayed.initial_std * state["asked"]
    )
    assert np.array_equal(_drive(replayed, 2, seed=9)[1], _drive(adapter, 2, seed=9)[1])
    tampered = dict(state, asked=state["asked"] + 1e-12)
    with pytest.raises(RuntimeError, match="diverged at event 0"):
        ADAPTERS[name].from_state_dict(tampered)


@EXTRAS
@pytest.mark.parametrize("name", sorted(ADAPTERS))
def test_rejected_tells_leave_the_adapter_unchanged(name):
    adapter = ADAPTERS[name](2, 1, seed=1)
    contexts = np.zeros((5, 1))
    params = adapter.ask(contexts)
    before = adapter.state_dict()
    with pytest.raises(RuntimeError, match="external samples"):
        adapter.tell(contexts, params + 1.0, np.zeros(5), allow_external=True)
    with pytest.raises(ValueError, match="returns: expected finite"):
        adapter.tell(contexts, params, np.array([0.0, 1.0, np.nan, 0.0, 0.0]))
    after = adapter.state_dict()
    assert after["adapter"] == before["adapter"] and np.array_equal(after["asked"], before["asked"])
    adapter.tell(contexts, params, np.zeros(5))  # the pending batch is still accepted


@EXTRAS
def test_cma_needs_whole_populations_of_a_fixed_size():
    adapter = CMAAdapter(2, 1, seed=0)
    params = adapter.ask(np.zeros((6, 1)))
    with pytest.raises(ValueError, match="expected all 6 asked samples"):
        adapter.tell(np.zeros((4, 1)), params[:4], np.zeros(4))
    adapter.tell(np.zeros((6, 1)), params, -np.sum(params**2, axis=1))
    with pytest.raises(ValueError, match="contexts: expected 6 rows"):
        adapter.ask(np.zeros((5, 1)))


@EXTRAS
def test_subsets_are_fine_for_nevergrad_and_optuna():
    for cls in (NevergradAdapter, OptunaAdapter):
        adapter = cls(2, 1, seed=0)
        params = adapter.ask(np.zeros((6, 1)))
        adapter.tell(np.zeros((3, 1)), params[[4, 0, 2]], np.array([1.0, 2.0, 3.0]))
        assert np.array_equal(adapter.state_dict()["told_index"], [4, 0, 2])


@EXTRAS
def test_nevergrad_optimisers_that_run_one_candidate_at_a_time_are_refused():
    for name in ("Powell", "Cobyla"):
        with pytest.raises(
            ValueError, match=f"optimizer: expected a nevergrad optimiser that evaluates batches.*{name}"
        ):
            NevergradAdapter(2, 0, seed=0, optimizer=name)


@EXTRAS
def test_pycma_options_given_as_numpy_scalars_are_saved_as_numbers(tmp_path):
    adapter = CMAAdapter(2, 0, seed=1, CMA_elitist=np.bool_(True), popsize=np.int64(4))
    contexts = np.zeros((4, 0))
    params = adapter.ask(contexts)
    adapter.tell(contexts, params, -(params**2).sum(axis=1))
    restored = CMAAdapter.load(adapter.save(tmp_path / "cma.npz"))
    assert restored.options["CMA_elitist"] is True and restored.options["popsize"] == 4
    np.testing.assert_array_equal(restored.ask(contexts), adapter.ask(contexts))


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        ({"initial_cov": [[1.0, 0.5], [0.5, 1.0]]}, ValueError, "off-diagonal"),
        ({"initial_cov": -1.0}, ValueError, "initial_cov: expected positive variances"),
        ({"initial_mean": np.zeros((2, 2))}, ValueError, r"initial_mean: expected a scalar or shape \(2,\)"),
        ({"seed": 1.5}, TypeError, r"seed: expected an int in \[0, 2\*\*32\) or None, got float"),
        ({"seed": 2**32}, ValueError, r"seed: expected an int in \[0, 2\*\*32\) or None, got 4294967296"),
        ({"bogus": 1}, TypeError, "bogus"),
    ],
)
@pytest.mark.parametrize("name", marked(sorted(ADAPTERS)))
def test_bad_arguments_are_named(name, kwargs, error, match):
    with pytest.raises(error, match=match):
        ADAPTERS[name](2, 1, **kwargs)


@EXTRAS
def test_library_specific_options_are_checked():
    with pytest.raises(
        ValueError, match=r"options: expected none of \[.*\] \(set by the adapter\), got \['seed'\]"
    ):
        CMAAdapter(2, 1, seed=0, cma_options={"seed": 4})
    with pytest.raises(TypeError, match=r"expected pycma option names .*got unknown \['popsiz'\]"):
        CMAAdapter(2, 1, popsiz=4)
    with pytest.raises(ValueError, match=r"got \['tolfun'\] flat and in cma_options"):
        CMAAdapter(2, 1, tolfun=1.0, cma_options={"tolfun": 2.0})
    adapter = CMAAdapter(2, 1, popsize=4)
    with pytest.raises(ValueError, match=r"popsize: expected the batch size 6 .*, got 4"):
        adapter.ask(np.zeros((6, 1)))
    assert adapter.state_dict()["adapter"]["events"] == []  # the rejected ask left it unchanged
    with pytest.raises(ValueError, match="optimizer: expected a name in nevergrad"):
        NevergradAdapter(2, 1, optimizer="NoSuchOptimizer")
    with pytest.raises(ValueError, match=r"sampler: expected one of \['tpe', 'random'\], got 'grid'"):
        OptunaAdapter(2, 1, sampler="grid")
    with pytest.raises(ValueError, match="bound_stds"):
        OptunaAdapter(2, 1, bound_stds=0)


@EXTRAS
def test_optuna_searches_inside_the_documented_box():
    adapter = OptunaAdapter(
        3, 1, initial_mean=[1.0, 2.0, 3.0], initial_cov=0.25, sampler="random", bound_stds=2.0
    )
    params = adapter.ask(np.zeros((50, 1)))
    assert np.all(np.abs(params - [1.0, 2.0, 3.0]) <= 1.0) and np.ptp(params, axis=0).min() > 0.5


@EXTRAS
@pytest.mark.parametrize("nested", [False, True])
def test_cma_takes_pycma_options_flat_and_reports_its_own_stop_criteria(nested):
    options = {"tolfun": 1e3, "tolfunhist": 1e3, "popsize": 6}
    adapter = CMAAdapter(2, 1, seed=0, **({"cma_options": options} if nested else options))
    assert adapter.options == options and adapter.stop() == {}
    _drive(adapter, 12, n=6)
    assert adapter.stop()  # the huge tolerances are met once the history is long enough
    assert adapter._lib.popsize == 6


@EXTRAS
@pytest.mark.slow
def test_the_runner_gives_nevergrad_its_budget_and_ngopt_runs_on_this_numpy():
    # NGOpt picks its meta-model here, which calls float() on a one-element array (a TypeError on numpy 2.4)
    history = run(
        "nevergrad",
        "creps_gym/Sphere-v0",
        6,
        10,
        0,
        env_kwargs={"dim": 3},
        optimizer_options={"optimizer": "NGOpt"},
        run_dir=None,
    )
    assert np.isfinite(history.column("eval_regret")).all()
    runner_budgets = {}
    for max_episodes, expected in ((None, 60), (35, 35)):
        config = RunConfig("creps_gym/Sphere-v0", "nevergrad", 6, 10, 0, max_episodes=max_episodes)
        runner_budgets[max_episodes] = Runner(config).optimizer.options["budget"]
        assert runner_budgets[max_episodes] == expected
    given = RunConfig("creps_gym/Sphere-v0", "nevergrad", 6, 10, 0, optimizer_options={"budget": 7})
    assert Runner(given).optimizer.options["budget"] == 7  # the user's budget wins


@EXTRAS
def test_nevergrad_threads_are_stopped_by_close_and_by_the_runner():
    baseline = threading.active_count()
    with NevergradAdapter(
        3, 1, seed=0, optimizer="Carola3", budget=100
    ) as adapter:  # runs Cobyla in a thread
        _drive(adapter, 3, n=4)
        assert threading.active_count() > baseline
    assert threading.active_count() == baseline
    history = run(
        "nevergrad",
        "creps_gym/Sphere-v0",
        3,
        4,
        0,
        env_kwargs={"dim": 3},
        optimizer_options={"optimizer": "Carola3"},
    )
    assert len(history) == 3 and threading.active_count() == baseline


@EXTRAS
@pytest.mark.slow
def test_a_script_that_keeps_its_runner_exits(tmp_path):
    script = tmp_path / "keeps_runner.py"  # the runner, a global, holds the adapter until after exit's join
    script.write_text(
        "from creps_gym.runner.config import RunConfig\n"
        "from creps_gym.runner.loop import Runner\n"
        "config = RunConfig('creps_gym/Sphere-v0', 'nevergrad', 3, 4, 0, env_kwargs={'dim': 3},\n"
        "                   optimizer_options={'optimizer': 'Carola3'})\n"
        "runner = Runner(config)\n"
        "print(len(runner.run()))\n"
    )
    result = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=60)
    assert result.returncode == 0 and result.stdout.strip() == "3", result.stderr


def test_the_adapter_guide_examples_run(monkeypatch, capsys):
    monkeypatch.setattr(registry, "_REGISTRY", dict(registry._REGISTRY))
    blocks = python_blocks(GUIDE)
    assert len(blocks) >= 2
    namespace: dict = {"__name__": "writing_an_adapter"}
    for block in blocks:
        exec(compile(block, str(GUIDE), "exec"), namespace)
    assert issubclass(namespace["RandomSearchAdapter"], MinimizerAdapter)
    assert "random-search" in registry.optimizer_names()
    assert "mean regret of the recommended policy" in capsys.readouterr().out


RUNNER_GUIDE = GUIDE.parent / "runner.md"


@EXTRAS
@pytest.mark.parametrize("index", range(3))
@pytest.mark.slow
def test_the_documented_adapter_commands_run(index, tmp_path, capsys):
    section = RUNNER_GUIDE.read_text().split("## Adapters", 1)[1].split("\n## ", 1)[0]
    commands = [line for line in section.splitlines() if line.startswith("creps-gym run ")]
    assert len(commands) == 3
    argv = shlex.split(commands[index])[1:]
    argv[argv.index("--out") + 1] = str(tmp_path / "run")
    assert cli.main([*argv, "--no-plot"]) == 0
    assert "stop: iterations" in capsys.readouterr().out


@pytest.mark.parametrize("name", marked(registry.optimizer_names()))
def test_every_registered_optimizer_rejects_returns_whose_spread_overflows(name):
    """Returns near ±1e308 are finite but their differences are not: a clear error, state unchanged."""
    optimizer = registry.make_optimizer(name, 3, 1, 5)
    contexts = np.linspace(0.0, 1.0, 8)[:, None]
    params = optimizer.ask(contexts)
    before = optimizer.state_dict()
    returns = np.where(np.arange(8) % 2, 1e308, -1e308)
    with pytest.raises(ValueError, match=r"returns: expected a finite spread max - min .* got returns from"):
        optimizer.tell(contexts, params, returns)
    after = optimizer.state_dict()
    assert after.keys() == before.keys()
    assert all(np.array_equal(after[key], value) for key, value in before.items())
    optimizer.tell(contexts, params, -np.sum(params**2, axis=1))  # the pending ask still stands
    assert optimizer.iteration == 1


def _played(name):
    adapter = registry.make_optimizer(name, 2, 0, 3)
    contexts = np.zeros((6, 0))
    for _ in range(3):
        params = adapter.ask(contexts)
        adapter.tell(contexts, params, -(params**2).sum(axis=1))
    return adapter.state_dict()


def _truncate_events(state):
    state["adapter"] = {**state["adapter"], "events": state["adapter"]["events"][:2]}


def _negative_index(state):
    state["told_index"] = state["told_index"].copy()
    state["told_index"][0] = -1


def _nan_loss(state):
    state["told_losses"] = state["told_losses"].copy()
    state["told_losses"][1] = np.nan


def _zero_event(state):
    state["adapter"] = {**state["adapter"], "events": [0, *state["adapter"]["events"]]}


@pytest.mark.parametrize("name", marked(sorted(ADAPTERS)))
@pytest.mark.parametrize(
    ("tamper", "match"),
    [
        (_truncate_events, r"state\['adapter'\]\['events'\]: expected asks and tells of 18 and 18 rows"),
        (_negative_index, r"state\['told_index'\]: expected rows of the last ask \(0 to 5\)"),
        (_nan_loss, r"state\['told_losses'\]: expected finite values"),
        (_zero_event, r"state\['adapter'\]\['events'\]: expected a list of non-zero ints"),
    ],
)
def test_a_tampered_adapter_record_is_refused_before_replay(name, tamper, match):
    state = _played(name)
    tamper(state)
    with pytest.raises(ValueError, match=match):
        registry.restore_optimizer(name, state)


# -- options are data (issue 30, items 5 and 12) -------------------------------------------------------------
@EXTRAS
@pytest.mark.parametrize(
    "value", ["9**9**9", "abc", "1e-12", "__import__('os')", {"a": 1}, [1, "x"], [[[[1]]]]]
)
def test_cma_options_that_pycma_would_evaluate_are_refused_naming_the_option(value):
    with pytest.raises(
        ValueError, match=r"tolfun: expected a number, a boolean, None or a list of them .* got "
    ):
        CMAAdapter(2, 1, seed=0, tolfun=value)
    with pytest.raises(ValueError, match=r"tolfun: expected a number"):
        CMAAdapter(2, 1, seed=0, cma_options={"tolfun": value})


@EXTRAS
def test_cma_options_that_are_data_still_reach_pycma():
    options = {
        "tolfun": 1e3,
        "CMA_elitist": True,
        "bounds": [[-1, None], [1, 2.0]],
        "BoundaryHandler": "BoundTransform",
    }
    adapter = CMAAdapter(2, 1, seed=0, **options)
    adapter.ask(np.zeros((6, 1)))
    assert adapter._lib.opts["tolfun"] == 1e3 and adapter._lib.opts["bounds"] == [[-1, None], [1, 2.0]]


@EXTRAS
def test_the_cli_refuses_a_cma_option_that_is_not_data_with_exit_2_before_writing(tmp_path, capsys):
    """Before: ``--opt tolfun=abc`` failed with exit 1 after writing the run folder."""
    argv = run_argv(
        tmp_path / "run",
        "--no-progress",
        "--no-plot",
        "--opt",
        "tolfun=abc",
        env_kwargs=("dim=2",),
        optimizer="cma",
    )
    assert cli.main(argv) == 2
    err = capsys.readouterr().err
    assert "argument --opt: tolfun: expected a number, a boolean, None or a list of them" in err
    assert "got str 'abc'" in err and not (tmp_path / "run").exists()


@EXTRAS
def test_resume_refuses_cma_options_in_config_json_that_are_not_data(tmp_path, capsys):
    """Before: pycma evaluated ``"9**9"`` from config.json (``"9**9**9"`` computed for ever)."""
    run("cma", "creps_gym/Sphere-v0", 2, 6, 0, env_kwargs={"dim": 2}, run_dir=tmp_path)
    (tmp_path / "checkpoint.npz").unlink()  # a run folder without checkpoint: built from config.json
    document = json.loads((tmp_path / "config.json").read_text())
    document["config"]["optimizer_options"] = {"tolfun": "9**9"}
    (tmp_path / "config.json").write_text(json.dumps(document))
    assert cli.main(["resume", str(tmp_path), "--no-progress", "--no-plot"]) == 3
    err = capsys.readouterr().err
    assert "config.json: optimizer_options: tolfun: expected a number" in err and "got str '9**9'" in err


# -- a restored pending batch is the one the replay asks (issue 30, item 8) --------------------------------
def _pending_state(name):
    adapter = registry.make_optimizer(name, 3, 1, 0)
    _drive(adapter, 2)
    adapter.ask(np.zeros((8, 1)))
    return adapter.state_dict()


@EXTRAS
@pytest.mark.parametrize("name", sorted(ADAPTERS))
def test_a_pending_batch_that_the_replay_does_not_ask_is_refused(name):
    """Before: forged pending rows were restored, and could then be told as if the library asked them."""
    state = _pending_state(name)
    assert np.array_equal(ADAPTERS[name].from_state_dict(state)._pending[1], state["pending_params"])
    shifted = {**state, "pending_params": state["pending_params"] + 1e-9}
    with pytest.raises(ValueError, match=r"state\['pending_params'\]: expected the batch of the last ask"):
        ADAPTERS[name].from_state_dict(shifted)
    fewer = {
        **state,
        "pending_contexts": state["pending_contexts"][:4],
        "pending_params": state["pending_params"][:4],
    }
    with pytest.raises(ValueError, match=r"state\['pending_params'\]: expected .* \(8 rows\), got 4 rows"):
        ADAPTERS[name].from_state_dict(fewer)
    told = registry.make_optimizer(name, 3, 1, 0)
    _drive(told, 2)
    after_tell = {
        **told.state_dict(),
        "pending_contexts": state["pending_contexts"],
        "pending_params": state["pending_params"],
    }
    with pytest.raises(ValueError, match=r"state\['pending_params'\]: expected .* \(0 rows\), got 8 rows"):
        ADAPTERS[name].from_state_dict(after_tell)


@pytest.mark.parametrize("name", marked(registry.optimizer_names()))
@pytest.mark.slow
def test_every_registered_optimizer_answers_restart_and_changes_nothing_when_it_cannot(name):
    """The runner's divergence rule calls ``restart()``: a bool; where it is False, the state is unchanged
    (the run then stops); where it is True, the next ask samples the initial distribution again."""
    optimizer = registry.make_optimizer(name, 3, 1, 5, initial_mean=[0.1, 0.2, 0.3], initial_cov=0.5)
    _drive(optimizer, 3)
    before = optimizer.state_dict()
    restarted = optimizer.restart()
    assert isinstance(restarted, bool)
    if not restarted:
        after = optimizer.state_dict()
        assert after.keys() == before.keys()
        assert all(np.array_equal(after[key], value) for key, value in before.items())
    else:
        fresh = registry.make_optimizer(name, 3, 1, 5, initial_mean=[0.1, 0.2, 0.3], initial_cov=0.5)
        running = getattr(optimizer, "coefficients", None)  # the search's own mean (not a kept best, C10)
        if running is None:
            running, fresh_running = optimizer.mean_policy().coefficients, fresh.mean_policy().coefficients
        else:
            fresh_running = fresh.coefficients
        assert np.array_equal(running, fresh_running)
    _drive(optimizer, 1)  # and it goes on
