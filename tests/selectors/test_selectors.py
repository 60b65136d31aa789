"""Context selectors: the protocol, determinism, checkpoints, the bandit's rule and choices, bad input."""

from __future__ import annotations

import json
import math

import gymnasium as gym
import numpy as np
import pytest
from helpers import SPHERE

from creps_gym.errors import RunDirError
from creps_gym.runner import RunConfig, RunDir, Runner, resume, run
from creps_gym.runner.rundir.checkpoint import FINGERPRINT_FIELDS, config_fingerprint
from creps_gym.selectors import (
    SELECTORS,
    ContextSelector,
    FixedSelector,
    LearningProgressBandit,
    UniformSelector,
    cell_index,
    ducb_index,
    make_selector,
    selector_names,
)
from creps_gym.wrappers import HideContext

LOW, HIGH = np.array([0.0, -1.0]), np.array([3.0, 1.0])
OPTIONS = {"fixed": {"contexts": [[0.5, 0.0], [2.5, 0.5], [1.0, -1.0]]}}
SPHERE_2D = {"dim": 4, "context_dim": 2}


def _selector(name: str):
    selector = make_selector(name, OPTIONS.get(name, {}))
    selector.bind(LOW.copy(), HIGH.copy(), lambda rng, n: LOW + (HIGH - LOW) * rng.random((n, 2)))
    return selector


def _feed(selector, seed: int, iterations: int, n: int = 10) -> list[np.ndarray]:
    """Select, then tell returns that depend on the context and the iteration; the contexts chosen."""
    rng, chosen = np.random.default_rng(seed), []
    for t in range(iterations):
        contexts = selector.select(rng, n)
        chosen.append(contexts)
        returns = -np.abs(contexts[:, 0] - 2.0) * (1.0 + 0.5 * t) - 0.1 * contexts[:, 1]
        selector.tell(contexts, returns, {"sigma": 0.5})
    return chosen


@pytest.mark.parametrize("name", selector_names())
def test_every_selector_keeps_the_protocol_inside_the_box_with_json_state(name):
    selector = _selector(name)
    assert isinstance(selector, ContextSelector)
    for contexts in _feed(selector, 0, 8):
        assert contexts.shape == (10, 2) and contexts.dtype == np.float64
        assert (contexts >= LOW).all() and (contexts <= HIGH).all()
    state = selector.state_dict()
    assert json.loads(json.dumps(state, allow_nan=False)) == state  # JSON data, exactly


@pytest.mark.parametrize("name", selector_names())
def test_same_seed_same_contexts_and_a_restored_state_continues_exactly(name):
    first, second = _selector(name), _selector(name)
    assert all((a == b).all() for a, b in zip(_feed(first, 3, 7), _feed(second, 3, 7), strict=True))
    restored = _selector(name)
    restored.load_state_dict(json.loads(json.dumps(first.state_dict())))
    rng_a, rng_b = np.random.default_rng(9), np.random.default_rng(9)
    assert (first.select(rng_a, 12) == restored.select(rng_b, 12)).all()
    if name in ("uniform", "arcsine", "beta", "env", "bandit", "progress", "active"):  # random: seeds matter
        assert not (_feed(_selector(name), 4, 1)[0] == _feed(_selector(name), 5, 1)[0]).all()


def _toy_utility(chosen: list[np.ndarray]):
    """A model's ``context_utility`` stand-in: larger far from every context chosen so far and pending."""

    def utility(candidates, targets, pending):
        seen = np.concatenate([*chosen, np.zeros((0, 2)) if pending is None else pending])
        if not len(seen):
            return np.zeros(len(candidates))
        return np.min(((candidates[:, None, :] - seen[None, :, :]) ** 2).sum(axis=2), axis=1)

    return utility


@pytest.mark.parametrize(
    "name", [n for n in selector_names() if getattr(SELECTORS[n], "uses_context_utility", 0)]
)
def test_selectors_that_use_the_models_utility_keep_the_protocol_with_it(name):
    runs = []
    for _ in range(2):
        selector, chosen, rng = _selector(name), [], np.random.default_rng(6)
        for _ in range(4):
            contexts = selector.select(rng, 5, context_utility=_toy_utility(chosen))
            assert contexts.shape == (5, 2) and (contexts >= LOW).all() and (contexts <= HIGH).all()
            chosen.append(contexts)
            selector.tell(contexts, -contexts[:, 0], {"sigma": 0.5})
        runs.append(np.concatenate(chosen))
        restored = _selector(name)
        restored.load_state_dict(json.loads(json.dumps(selector.state_dict())))
        utility = _toy_utility(chosen)
        a, b = np.random.default_rng(1), np.random.default_rng(1)
        assert (
            selector.select(a, 3, context_utility=utility) == restored.select(b, 3, context_utility=utility)
        ).all()
    assert (runs[0] == runs[1]).all()  # the same seed and utility: the same contexts


def test_the_samplers_are_adapted_not_copied():
    rng_a, rng_b = np.random.default_rng(1), np.random.default_rng(1)
    from creps_gym.wrappers.samplers import BetaContexts, UniformContexts

    assert (_selector("uniform").select(rng_a, 5) == UniformContexts(LOW, HIGH)(rng_b, 5)).all()
    assert (_selector("arcsine").select(rng_a, 5) == BetaContexts(LOW, HIGH, 0.5)(rng_b, 5)).all()
    cycle = _selector("fixed")
    got = np.concatenate([cycle.select(rng_a, 2), cycle.select(rng_a, 2)])  # one cycle over the run
    assert (got == np.array(OPTIONS["fixed"]["contexts"])[[0, 1, 2, 0]]).all()


# -- the bandit's exploration rule ------------------------------------------------------------------------
def test_the_ducb_index_is_the_stated_formula():
    sums, counts = np.array([1.0, 2.0, 0.0]), np.array([4.0, 4.0, 0.0])
    index = ducb_index(sums, counts, 0.5)
    bonus = math.sqrt(0.5 * math.log(8.0) / 4.0)
    assert index[0] == pytest.approx(0.25 + bonus) and index[1] == pytest.approx(0.5 + bonus)
    assert index[2] == math.inf  # an arm never rewarded is tried
    few = ducb_index(np.array([0.6, 0.05]), np.array([20.0, 1.0]), 0.5)
    assert few[1] > few[0]  # the confidence term: a rarely tried arm beats a better-looking one
    assert (ducb_index(np.array([0.6, 0.05]), np.array([20.0, 1.0]), 0.0) == [0.03, 0.05]).all()


def test_the_bandit_rewards_learning_progress_and_discounts_the_past():
    bandit = make_selector("bandit", {"cells": 2, "discount": 0.5, "uniform_share": 0.0})
    bandit.bind(np.zeros(1), np.ones(1), None)
    contexts = np.array([[0.25], [0.75]])
    bandit.tell(contexts, np.array([0.0, 0.0]), {})  # first visits: means, no reward, no count
    assert bandit.counts.tolist() == [0.0, 0.0] and bandit.last_mean == [0.0, 0.0]
    bandit.tell(contexts, np.array([4.0, 1.0]), {})  # progress 4 and 1: rewards 1 and 1/4
    assert bandit.counts.tolist() == [1.0, 1.0] and bandit.sums.tolist() == [1.0, 0.25]
    bandit.tell(contexts[:1], np.array([4.0]), {})  # no progress in cell 0; cell 1 not visited
    assert bandit.counts.tolist() == [1.5, 0.5] and bandit.sums.tolist() == [0.5, 0.125]
    assert cell_index(np.array([[0.0], [0.5], [1.0]]), np.zeros(1), np.ones(1), (2,)).tolist() == [0, 1, 1]


def _practise(selector, iterations: int = 60, n: int = 16) -> np.ndarray:
    """A simulated learner on [0, 1] with 4 cells: cells 0-2 are learnt in ~30 episodes each, cell 3 (the
    hard region, s > 0.75) in ~600. An episode's return is minus the cell's remaining error (competence
    grows with the episodes practised there) plus tiny noise. Returns the cell of every episode, (T, n)."""
    selector.bind(np.zeros(1), np.ones(1), None)
    rng, noise, practised = np.random.default_rng(0), np.random.default_rng(1), np.zeros(4)
    scale = np.array([10.0, 10.0, 10.0, 200.0])
    cells = []
    for _ in range(iterations):
        contexts = selector.select(rng, n)
        where = cell_index(contexts, np.zeros(1), np.ones(1), (4,))
        returns = -np.exp(-practised[where] / scale[where]) + 1e-4 * noise.standard_normal(n)
        np.add.at(practised, where, 1.0)
        selector.tell(contexts, returns, {})
        cells.append(where)
    return np.array(cells)


def test_the_bandit_practises_the_hard_region_once_the_easy_part_is_learnt():
    bandit = _practise(LearningProgressBandit(cells=4, uniform_share=0.25))
    uniform = _practise(UniformSelector())
    late = slice(20, None)  # the easy cells are learnt after ~30 episodes each, i.e. by iteration ~8
    hard_share = (bandit[late] == 3).mean()
    assert hard_share > 0.6 and (uniform[late] == 3).mean() < 0.3  # uniform: a quarter
    early = (bandit[:3] != 3).mean()  # at first every cell progresses: the bandit tries them all
    assert early > 0.5 and set(np.unique(bandit[:3])) == {0, 1, 2, 3}
    kernel = _practise(make_selector("progress", {"uniform_share": 0.25}))  # no partition, finds it too
    assert (kernel[late] == 3).mean() > 0.35


# -- in the runner -----------------------------------------------------------------------------------------
def test_runs_without_a_selector_keep_their_stream_checkpoint_and_fingerprint(tmp_path):
    plain = run("creps-cma-old", SPHERE, 4, 16, 2, env_kwargs=SPHERE_2D)
    assert plain.equals(run("creps-cma-old", SPHERE, 4, 16, 2, env_kwargs=SPHERE_2D, context_selector=None))
    assert not plain.equals(
        run("creps-cma-old", SPHERE, 4, 16, 2, env_kwargs=SPHERE_2D, context_selector="env")
    )
    run("creps-cma-old", SPHERE, 4, 16, 2, env_kwargs=SPHERE_2D, run_dir=tmp_path, checkpoint_every=2)
    config = RunDir.open(tmp_path).config()
    data = config.to_dict()
    old = {"format": "creps_gym.run/3", **{name: data[name] for name in FINGERPRINT_FIELDS}}
    import hashlib

    digest = hashlib.sha256(json.dumps(old, sort_keys=True, allow_nan=False).encode()).hexdigest()
    assert config_fingerprint(config) == digest  # what checkpoints written before the field hold
    assert "selector" not in RunDir.open(tmp_path).load_checkpoint()[0]
    document = json.loads((tmp_path / RunDir.CONFIG).read_text())  # an old folder: no selector fields
    for key in ("context_selector", "context_selector_options"):
        del document["config"][key]
    (tmp_path / RunDir.CONFIG).write_text(json.dumps(document))
    assert RunDir.open(tmp_path).config().context_selector is None
    assert resume(tmp_path).equals(plain)


def test_evaluation_stays_on_the_envs_own_test_contexts():
    fixed = {"contexts": [[1.5, 1.5]]}
    base = RunConfig(SPHERE, "creps-cma-old", 3, 16, 7, env_kwargs=SPHERE_2D)
    chosen = RunConfig(**{**base.to_dict(), "context_selector": "fixed", "context_selector_options": fixed})
    plain, selected = Runner(base), Runner(chosen)
    assert (plain.test_contexts == selected.test_contexts).all()  # from the evaluation seed only
    assert len(np.unique(selected.test_contexts, axis=0)) == base.eval_contexts
    seen = []
    selected.optimizer.tell = lambda contexts, params, returns: seen.append(contexts.copy())
    selected.run()
    assert all((contexts == 1.5).all() for contexts in seen) and len(seen) == 3


def test_bad_selectors_and_options_are_refused_with_named_errors():
    with pytest.raises(ValueError, match=r"context_selector: expected one of \['env'"):
        make_selector("curiosity")
    with pytest.raises(ValueError, match=r"context_selector_options: expected options of 'bandit' from \["):
        make_selector("bandit", {"arms": 3})
    for name, options, error, match in [
        ("bandit", {"discount": 0.0}, ValueError, "discount: expected a finite value in"),
        ("bandit", {"cells": 0}, ValueError, "cells: expected an integer >= 1"),
        ("bandit", {"cells": "4"}, TypeError, "cells: expected an int or a non-empty list"),
        ("bandit", {"uniform_share": 2}, ValueError, "uniform_share"),
        ("progress", {"bandwidth": 0}, ValueError, "bandwidth"),
        ("progress", {"window": 1.5}, TypeError, "window: expected an integer"),
        ("beta", {"a": -1}, ValueError, "a: expected a finite value > 0"),
        ("fixed", {"contexts": [[0.0, 1.0]], "order": "zigzag"}, ValueError, "order"),
        ("bandit", {"cells": float("nan")}, ValueError, "context_selector_options.cells: expected a finite"),
        ("bandit", {"cells": object()}, TypeError, "context_selector_options.cells: expected JSON data"),
    ]:
        with pytest.raises(error, match=match):
            make_selector(name, options)
    with pytest.raises(ValueError, match="1 to 3 dimensions, got 4"):
        LearningProgressBandit().bind(np.zeros(4), np.ones(4), None)
    with pytest.raises(ValueError, match="cells: expected an int or 2 ints"):
        LearningProgressBandit(cells=[2, 2, 2]).bind(np.zeros(2), np.ones(2), None)
    with pytest.raises(ValueError, match="context box is finite"):
        UniformSelector().bind(np.zeros(1), np.full(1, np.inf), None)
    with pytest.raises(ValueError, match="contexts: expected values in the context box"):
        FixedSelector([[5.0, 0.0]]).bind(LOW, HIGH, None)


def test_bad_runs_with_selectors_are_refused_with_named_errors():
    with pytest.raises(ValueError, match="context_selector_options: expected none without"):
        RunConfig(SPHERE, "creps-cma-old", 3, 12, 0, context_selector_options={"cells": 2})
    with pytest.raises(ValueError, match="context_draws: expected 'batch' with a context_selector"):
        RunConfig(SPHERE, "creps-cma-old", 3, 12, 0, context_selector="bandit", context_draws="reset")
    with pytest.raises(ValueError, match="no selector can choose it"):
        run("creps-cma-old", HideContext(gym.make(SPHERE)), 2, 12, 0, context_selector=UniformSelector())
    with pytest.raises(TypeError, match="not both"):
        Runner(
            RunConfig(SPHERE, "creps-cma-old", 3, 12, 0, context_selector="uniform"),
            context_selector=UniformSelector(),
        )
    with pytest.raises(TypeError, match="expected an object with bind, select, tell"):
        run("creps-cma-old", SPHERE, 2, 12, 0, context_selector=object())

    class Outside(UniformSelector):
        def select(self, rng, n):
            return np.full((n, 1), 99.0)

    with pytest.raises(ValueError, match="chose contexts outside the context box"):
        run("creps-cma-old", SPHERE, 2, 12, 0, context_selector=Outside())


@pytest.mark.parametrize(
    ("name", "state", "match"),
    [
        ("bandit", {"counts": [1.0] * 8, "sums": [2.0] * 8, "last_mean": [None] * 8}, "sums <= counts"),
        ("bandit", {"counts": [1.0] * 8, "sums": [0.0] * 8, "last_mean": [None] * 3}, "a list of 8"),
        ("bandit", {"counts": [1.0] * 8}, "expected keys"),
        ("progress", {"iteration": 2, "contexts": [[0.0]], "returns": [1.0], "ages": [9]}, "ages"),
        ("fixed", {"position": 3}, "expected < 1"),
        ("uniform", {"x": 1}, "expected keys"),
    ],
)
def test_a_damaged_selector_state_is_refused(name, state, match):
    selector = make_selector(name, {"contexts": [[0.5]]} if name == "fixed" else {})
    selector.bind(np.zeros(1), np.ones(1), None)
    before = json.dumps(selector.state_dict())
    with pytest.raises((ValueError, TypeError), match=match):
        selector.load_state_dict(state)
    assert json.dumps(selector.state_dict()) == before  # a rejected call changes nothing


def test_a_run_directory_may_name_only_registered_selectors_and_data_options(tmp_path):
    run("creps-cma-old", SPHERE, 2, 12, 0, run_dir=tmp_path, context_selector="bandit")
    path = tmp_path / RunDir.CONFIG
    document = json.loads(path.read_text())
    for change in ({"context_selector": "os:system"}, {"context_selector_options": {"cells": "evil:mod"}}):
        path.write_text(json.dumps({**document, "config": {**document["config"], **change}}))
        with pytest.raises(RunDirError):
            RunDir.open(tmp_path).config()
    assert sorted(SELECTORS) == sorted(selector_names())


def test_the_command_line_names_the_selector_and_refuses_bad_ones(tmp_path):
    from helpers import cli_in_process

    base = ["run", "--env", SPHERE, "--optimizer", "creps-cma-old", "--iterations", 2, "--samples", 12]
    base += ["--seed", 0, "--no-plot"]
    done = cli_in_process(
        *base, "--out", tmp_path / "a", "--context-selector", "bandit", "--selector-opt", "cells=3"
    )
    assert done.returncode == 0, done.stderr
    config = json.loads((tmp_path / "a" / RunDir.CONFIG).read_text())["config"]
    assert config["context_selector"] == "bandit" and config["context_selector_options"] == {"cells": 3}
    for extra, match in [
        (["--context-selector", "bandt"], "argument --context-selector: expected one of"),
        (
            ["--context-selector", "bandit", "--selector-opt", "discount=2"],
            "argument --selector-opt: discount",
        ),
        (["--selector-opt", "cells=3"], "argument --selector-opt: expected none without a context_selector"),
    ]:
        bad = cli_in_process(*base, "--out", tmp_path / "b", *extra)
        assert bad.returncode == 2 and match in bad.stderr and "Traceback" not in bad.stderr, bad.stderr
