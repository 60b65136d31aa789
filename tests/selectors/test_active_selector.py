"""The ``active`` context selector and c-bo's ``context_utility``: the maths of Eq. (C1), the choice of an
unexplored region, the fallback without a model, bad input, and runs that resume bit for bit."""

from __future__ import annotations

import json

import numpy as np
import pytest
from helpers import SPHERE

from creps_gym.optimizers import make_optimizer
from creps_gym.optimizers.context_value import (
    _gains,
    context_information,
    plausible_maximisers,
    posterior_covariance,
)
from creps_gym.optimizers.gp_model import fit_gp
from creps_gym.runner import RunDir, resume, run
from creps_gym.selectors import ActiveContextSelector, UniformSelector, make_selector

SPHERE_1D = {"dim": 2, "context_dim": 1}


def _model(seed: int = 0, n: int = 30, d: int = 3):
    """A GP on n random inputs in the unit box (d dimensions) with a smooth target."""
    rng = np.random.default_rng(seed)
    x = rng.uniform(size=(n, d))
    y = np.sin(3.0 * x[:, 0]) - (x[:, 1:] ** 2).sum(axis=1)
    return fit_gp(x, (y - y.mean()) / y.std(), np.array([np.log(0.4)] * d + [0.0, np.log(1e-3)]))


def _half_explored(seed: int = 0):
    """c-bo on the context box [0, 1] told 40 episodes, all at contexts below 0.4 (θ* = s: -(θ - s)²)."""
    box = {"context_low": 0.0, "context_high": 1.0, "param_low": -1.0, "param_high": 2.0}
    optimizer = make_optimizer("c-bo", 1, 1, seed, **box)
    rng = np.random.default_rng(seed)
    contexts = rng.uniform(0.0, 0.4, size=(40, 1))
    params = rng.uniform(-1.0, 2.0, size=(40, 1))
    optimizer.tell(contexts, params, -((params - contexts) ** 2)[:, 0], allow_external=True)
    return optimizer


def test_the_gain_is_the_variance_one_more_observation_removes():
    model = _model()
    rng = np.random.default_rng(1)
    queries, representers = rng.uniform(size=(5, 3)), rng.uniform(size=(7, 3))
    before = model.predict(representers)[1]
    for query, gain in zip(queries, _gains(model, queries, representers), strict=True):
        after = model.condition(query, 0.0).predict(representers)[1]  # the variance ignores the value
        assert gain == pytest.approx((before - after).sum() / (model.signal * 7), rel=1e-6, abs=1e-12)
    covariance = posterior_covariance(model, queries, queries)
    assert np.diag(covariance) == pytest.approx(model.predict(queries)[1], rel=1e-9, abs=1e-12)


def test_plausible_maximisers_are_the_largest_upper_bounds():
    model = _model()
    contexts, thetas = np.array([[0.2], [0.8]]), np.random.default_rng(2).uniform(size=(50, 2))
    chosen = plausible_maximisers(model, contexts, thetas, 4, 4.0)
    assert chosen.shape == (2, 4, 3)
    for context, rows in zip(contexts, chosen, strict=True):
        inputs = np.hstack([np.repeat(context[None, :], 50, axis=0), thetas])
        mean, variance = model.predict(inputs)
        bound = mean + 2.0 * np.sqrt(variance)
        assert rows[:, 1:] == pytest.approx(thetas[np.argsort(-bound)[:4]])


def test_many_contexts_are_scored_in_blocks_with_the_same_choice(monkeypatch):
    from creps_gym.optimizers import context_value

    model = _model()
    contexts, thetas = (
        np.random.default_rng(4).uniform(size=(9, 1)),
        np.random.default_rng(5).uniform(size=(20, 2)),
    )
    whole = plausible_maximisers(model, contexts, thetas, 3, 4.0)
    monkeypatch.setattr(context_value, "BLOCK", 20 * 30 * 2)  # two contexts per block
    assert plausible_maximisers(model, contexts, thetas, 3, 4.0) == pytest.approx(whole, abs=0)


def test_the_utility_is_highest_where_the_optimum_is_least_known():
    optimizer = _half_explored()
    candidates = np.array([[0.1], [0.2], [0.3], [0.7], [0.8], [0.9]])
    targets = np.linspace(0.0, 1.0, 11)[:, None]
    utility = optimizer.context_utility(candidates, targets)
    assert utility.shape == (6,) and ((utility >= 0) & (utility <= 1)).all()
    assert utility[3:].min() > 2.0 * utility[:3].max()  # the unexplored half teaches more
    assert (optimizer.context_utility(candidates, targets) == utility).all()  # deterministic
    pending = optimizer.context_utility(candidates, targets, np.array([[0.8]]))
    assert pending[4] < utility[4]  # an episode already planned there leaves less to learn


def test_the_selector_picks_the_unexplored_region():
    optimizer = _half_explored()
    selector = make_selector("active", {"candidates": 64})
    selector.bind(np.zeros(1), np.ones(1), None)
    state = optimizer.rng.bit_generator.state
    chosen = selector.select(np.random.default_rng(0), 3, context_utility=optimizer.context_utility)
    assert chosen.shape == (3, 1) and (chosen > 0.5).all()
    assert len(np.unique(chosen)) == 3  # a chosen candidate leaves the pool
    assert optimizer.rng.bit_generator.state == state  # the optimiser's stream is untouched
    uniform = UniformSelector()
    uniform.bind(np.zeros(1), np.ones(1), None)
    drawn = [uniform.select(np.random.default_rng(s), 3)[:, 0] for s in range(20)]
    assert np.mean([(d > 0.5).mean() for d in drawn]) < 0.75  # uniform draws do not


def test_without_a_model_the_draws_are_uniform_bit_for_bit():
    active, uniform = ActiveContextSelector(), UniformSelector()
    low, high = np.array([0.0, -1.0]), np.array([3.0, 1.0])
    for selector in (active, uniform):
        selector.bind(low, high, None)
    assert (active.select(np.random.default_rng(4), 5) == uniform.select(np.random.default_rng(4), 5)).all()
    rng = np.random.default_rng(5)
    flat = active.select(rng, 2, context_utility=lambda c, t, p: np.zeros(len(c)))  # ties: the first
    replay = np.random.default_rng(5)
    replay.uniform(low, high, size=(16, 2))  # the targets
    assert (flat == replay.uniform(low, high, size=(32, 2))[:2]).all()  # the first candidates, in order
    fresh = make_optimizer("c-bo", 2, 2, 0)
    assert (fresh.context_utility(np.zeros((3, 2)), np.ones((2, 2))) == 0).all()  # no GP yet: zeros


def test_bad_utilities_options_and_states_are_refused_with_named_errors():
    selector = ActiveContextSelector(uniform_share=0.5)
    with pytest.raises(RuntimeError, match="select\\(\\) before bind\\(\\)"):
        selector.select(np.random.default_rng(0), 2)
    selector.bind(np.zeros(1), np.ones(1), None)
    for utility, error, match in [
        (lambda c, t, p: np.zeros(3), ValueError, "expected 32 numbers"),
        (lambda c, t, p: np.full(len(c), np.nan), ValueError, "expected finite values"),
        ("best", TypeError, "context_utility: expected a callable"),
    ]:
        with pytest.raises(error, match=match):
            selector.select(np.random.default_rng(0), 4, context_utility=utility)
    for options, match in [
        ({"candidates": 0}, "candidates: expected an integer >= 1"),
        ({"targets": 5000}, "targets: expected an integer of at most 1024"),
        ({"uniform_share": 1.5}, "uniform_share"),
    ]:
        with pytest.raises(ValueError, match=match):
            make_selector("active", options)
    with pytest.raises(ValueError, match="expected keys"):
        selector.load_state_dict({"x": 1})
    optimizer = _half_explored()
    with pytest.raises(ValueError, match="candidates: expected shape"):
        optimizer.context_utility(np.zeros((3, 2)), np.zeros((2, 1)))
    with pytest.raises(ValueError, match="targets: expected"):
        optimizer.context_utility(np.zeros((3, 1)), np.full((2, 1), np.nan))


def test_context_information_with_pending_contexts_never_swaps_the_points_it_counts():
    model = _model()
    rng = np.random.default_rng(3)
    candidates, targets, thetas = (
        rng.uniform(size=(8, 1)),
        rng.uniform(size=(6, 1)),
        rng.uniform(size=(40, 2)),
    )
    alone = context_information(model, candidates, targets, thetas)
    after = context_information(model, candidates, targets, thetas, candidates[:2])
    assert (after <= alone + 1e-12).all()  # one more planned episode only removes variance


@pytest.mark.slow
def test_a_c_bo_run_with_the_active_selector_resumes_bit_identically(tmp_path):
    kwargs = {"env_kwargs": SPHERE_1D, "context_selector": "active", "checkpoint_every": 2, "eval_every": 3}
    uninterrupted = run("c-bo", SPHERE, 6, 4, 3, **kwargs)

    def crash(record, history):
        if record.iteration == 5:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run("c-bo", SPHERE, 6, 4, 3, run_dir=tmp_path, callbacks=[crash], **kwargs)
    state = RunDir.open(tmp_path).load_checkpoint()[0]
    assert state["iteration"] == 4 and state["selector"] == {}
    assert resume(tmp_path).equals(uninterrupted)
    assert json.loads((tmp_path / RunDir.CONFIG).read_text())["config"]["context_selector"] == "active"
    plain = run("c-bo", SPHERE, 6, 4, 3, env_kwargs=SPHERE_1D, context_selector="uniform", eval_every=3)
    assert not plain.equals(uninterrupted)  # the model chose other contexts than uniform draws


def test_an_optimiser_without_a_model_gets_uniform_draws():
    kwargs = {"env_kwargs": SPHERE_1D, "eval_every": 2}
    active = run("creps-cma-old", SPHERE, 3, 12, 1, context_selector="active", **kwargs)
    assert active.equals(run("creps-cma-old", SPHERE, 3, 12, 1, context_selector="uniform", **kwargs))
