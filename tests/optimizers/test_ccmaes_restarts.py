"""Contextual CMA-ES's restart portfolio (C11, ``restart_baseline_loss``): the searches after a restart fit
the context baseline with another loss; the first search (every run that never restarts) is unchanged."""

from __future__ import annotations

import numpy as np
import pytest

from creps_gym.errors import ConfigError
from creps_gym.optimizers import CCMAES
from creps_gym.runner import run


def _tell_sphere(optimizer: CCMAES, contexts: np.ndarray) -> None:
    """Ask and tell a batch of a contextual sphere (θ*(s) = s·1) with one outlying return, which Huber's fit
    discounts."""
    params = optimizer.ask(contexts)
    returns = -((params - contexts) ** 2).sum(axis=1)
    returns[0] -= 1e3
    optimizer.tell(contexts, params, returns)


def _contexts(rng: np.random.Generator) -> np.ndarray:
    return rng.uniform(0.0, 1.0, (16, 1))


def _until_restart(**options) -> tuple[CCMAES, np.random.Generator]:
    """The sphere until tolx = 1e-2 restarts the search once."""
    optimizer = CCMAES(4, 1, initial_mean=3.0, initial_cov=1.0, tolx=1e-2, restarts=1, seed=5, **options)
    rng = np.random.default_rng(6)
    while optimizer.restarts_done == 0:
        _tell_sphere(optimizer, _contexts(rng))
        assert optimizer.iteration < 400
    return optimizer, rng


def _same_state(a: CCMAES, b: CCMAES) -> bool:
    one, two = a.state_dict(), b.state_dict()
    if set(one) != set(two):
        return False
    for key in one:
        if key == "config":
            continue
        if isinstance(one[key], np.ndarray) and not np.array_equal(one[key], two[key]):
            return False
        if not isinstance(one[key], np.ndarray) and one[key] != two[key]:
            return False
    return True


def test_the_option_is_validated():
    with pytest.raises(ValueError, match=r"restart_baseline_loss: expected one of .*'other'.*got 'l1'"):
        CCMAES(3, 1, restart_baseline_loss="l1")
    with pytest.raises(ValueError, match="restart_baseline_loss"):
        CCMAES(3, 1, restart_baseline_loss=["huber"])
    with pytest.raises(ValueError, match="restart_baseline_loss"):  # the local baseline has no loss
        CCMAES(3, 1, baseline_bandwidth=0.5, restart_baseline_loss="huber")
    assert CCMAES(3, 1, baseline_bandwidth=0.5).config.restart_baseline_loss == "other"  # the default: kept


@pytest.mark.parametrize(
    ("baseline_loss", "restart_baseline_loss", "expected"),
    [
        ("squared", "other", "huber"),
        ("huber", "other", "squared"),
        ("huber", None, "huber"),
        ("squared", None, "squared"),
        ("huber", "huber", "huber"),
        ("squared", "huber", "huber"),
    ],
)
def test_the_restart_loss_of_each_setting(baseline_loss, restart_baseline_loss, expected):
    """C11: ``"other"`` (the default) alternates the two losses, None keeps ``baseline_loss``."""
    config = CCMAES(3, 1, baseline_loss=baseline_loss, restart_baseline_loss=restart_baseline_loss).config
    assert config.restart_loss() == expected
    assert (
        CCMAES(3, 1).config.restart_baseline_loss == "other" and CCMAES(3, 1).config.restart_loss() == "huber"
    )


def test_the_default_restarts_with_huber():
    """The default portfolio is bit-identical to ``restart_baseline_loss="huber"`` after a restart."""
    default, rng = _until_restart()
    huber, _ = _until_restart(restart_baseline_loss="huber")
    for _ in range(3):
        contexts = _contexts(rng)
        _tell_sphere(default, contexts)
        _tell_sphere(huber, contexts)
    assert _same_state(default, huber)


def test_a_run_is_bit_identical_until_its_first_restart():
    """The twin check: the first search does not depend on the option, up to and including the restart."""
    plain, _ = _until_restart(restart_baseline_loss=None)
    portfolio, _ = _until_restart(restart_baseline_loss="huber")
    assert plain.iteration == portfolio.iteration and _same_state(plain, portfolio)
    never = [CCMAES(4, 1, seed=3, restart_baseline_loss=loss) for loss in (None, "huber")]
    rng = np.random.default_rng(4)
    for _ in range(30):
        contexts = _contexts(rng)
        for optimizer in never:
            _tell_sphere(optimizer, contexts)
    assert never[0].restarts_done == 0 and _same_state(*never)


def test_after_a_restart_the_baseline_is_fitted_with_the_restart_loss():
    """After the restart, the portfolio's update is the plain update with ``baseline_loss`` set to Huber's."""
    portfolio, rng = _until_restart(restart_baseline_loss="huber")
    plain, _ = _until_restart(restart_baseline_loss=None)
    state = portfolio.state_dict()
    state["config"] = dict(state["config"], baseline_loss="huber", restart_baseline_loss=None)
    huber = CCMAES.from_state_dict(state)
    contexts = _contexts(rng)
    for optimizer in (portfolio, plain, huber):
        _tell_sphere(optimizer, contexts)
    assert np.array_equal(portfolio.coefficients, huber.coefficients)
    assert np.array_equal(portfolio.cov, huber.cov) and portfolio.step_size == huber.step_size
    assert not np.array_equal(portfolio.coefficients, plain.coefficients)


def test_the_portfolio_survives_a_checkpoint_bit_identically(tmp_path):
    optimizer, rng = _until_restart(restart_baseline_loss="huber")
    restored = CCMAES.load(optimizer.save(tmp_path / "c.npz"))
    assert restored.config.restart_baseline_loss == "huber" and restored.restarts_done == 1
    for _ in range(3):
        contexts = _contexts(rng)
        _tell_sphere(optimizer, contexts)
        _tell_sphere(restored, contexts)
    assert _same_state(optimizer, restored)


@pytest.mark.slow
def test_different_powers_at_z3_is_solved_after_a_restart_with_huber():
    """Different Powers at z = 3 with the function study's settings (p = 15, N = 50, seed 2): the first search
    diverges and stops; the restart with the squared baseline fails again, the default one with Huber's solves
    it."""

    def regrets(**options):
        history = run(
            "c-cma-es",
            "creps_gym/DifferentPowers-v0",
            iterations=900,
            samples_per_iteration=50,
            seed=2,
            env_kwargs={"dim": 15, "context_dim": 3},
            optimizer_options=options,
            target_regret=1e-5,
            eval_every=1,
            eval_contexts=16,
            backend="vector",
            vector_mode="native",
            context_draws="reset",
            divergence=None,
        )
        return history.column("eval_regret"), history.column("diag.restarts")

    huber, restarts = regrets()  # the default portfolio
    assert huber[-1] <= 1e-5 and restarts[-1] == 1
    squared, restarts = regrets(restart_baseline_loss=None)
    assert squared.min() > 1e-5 and restarts[-1] >= 1


# -- C12 (a restart only when it can pay off) and C13 (IPOP's population growth) ----------------------------
def _tell_clean(optimizer: CCMAES, contexts: np.ndarray) -> None:
    """Ask and tell a batch of the contextual sphere θ*(s) = s·1 (no outlier: the search converges)."""
    params = optimizer.ask(contexts)
    optimizer.tell(contexts, params, -((params - contexts) ** 2).sum(axis=1))


def _first_stop(**options) -> tuple[CCMAES, np.random.Generator]:
    """The sphere until tolx = 1e-3 fires in the first search (83 batches of 16), restarted or not."""
    optimizer = CCMAES(4, 1, initial_mean=3.0, initial_cov=1.0, tolx=1e-3, restarts=1, seed=5, **options)
    rng = np.random.default_rng(6)
    while optimizer.restarts_done == 0 and not optimizer.stop():
        _tell_clean(optimizer, _contexts(rng))
        assert optimizer.iteration < 400
    return optimizer, rng


@pytest.fixture(scope="module")
def first_search_episodes() -> int:
    """The episodes the first search takes to its stop (the same with every budget: C12 decides after it)."""
    optimizer, _ = _first_stop()
    assert optimizer.restarts_done == 1 and optimizer.search_start == optimizer.evaluations
    return optimizer.evaluations


def test_the_new_options_are_validated():
    for bad, error in (
        (0, ValueError),
        (-5, ValueError),
        (1.5, TypeError),
        (True, TypeError),
        ("9", TypeError),
    ):
        with pytest.raises(error, match=r"budget: expected an integer >= 1"):
            CCMAES(3, 1, budget=bad)
    for bad, error in ((0.5, ValueError), (101.0, ValueError), (float("nan"), ValueError), ("2", TypeError)):
        with pytest.raises(error, match=r"restart_population_factor: expected"):
            CCMAES(3, 1, restart_population_factor=bad)
    config = CCMAES(3, 1, budget=np.int64(100), restart_population_factor=2).config
    assert (config.budget, config.restart_population_factor) == (100, 2.0)
    assert (CCMAES(3, 1).config.budget, CCMAES(3, 1).config.restart_population_factor) == (None, 1.0)
    with pytest.raises(ValueError, match="base: expected an integer >= 1"):
        CCMAES(3, 1).wanted_batch_size(0)


def test_a_converged_search_near_the_budgets_end_keeps_sampling(first_search_episodes):
    """C12: with fewer episodes left than the first search took, no restart; ``stop()`` reports its
    criterion (a caller that stops on it stops), and the search goes on sampling its tight distribution."""
    budget = first_search_episodes + 16  # one batch left after the stop
    optimizer, rng = _first_stop(budget=budget)
    assert optimizer.evaluations == first_search_episodes and optimizer.restarts_done == 0
    assert "tolx" in optimizer.stop() and optimizer.diagnostics["restarts"] == 0.0
    for _ in range(3):  # a caller that does not stop on stop() (the budget overrun is the caller's choice)
        contexts = _contexts(rng)
        spread = np.abs(optimizer.ask(contexts) - optimizer.policy.mean(contexts)).max()
        assert spread < 0.01  # the converged distribution (max std 1.1e-3), not the initial one (σ0 = 1)
        _tell_clean(optimizer, contexts)
        assert optimizer.restarts_done == 0  # tolx may fire again or not: it never restarts


def test_early_in_the_budget_it_restarts_as_without_one(first_search_episodes):
    """C12: with at least the first search's episodes left, the restart is today's, bit for bit."""
    today, _ = _first_stop()
    for budget in (2 * first_search_episodes, 10**9):
        early, _ = _first_stop(budget=budget)
        assert early.restarts_done == 1 and early.search_start == first_search_episodes
        assert _same_state_but_config(today, early)
    short, _ = _first_stop(budget=2 * first_search_episodes - 1)
    assert short.restarts_done == 0


def _same_state_but_config(a: CCMAES, b: CCMAES) -> bool:
    return _same_state(a, b) and a.rng.bit_generator.state == b.rng.bit_generator.state


def test_the_population_grows_by_the_factor_after_each_restart(first_search_episodes):
    """C13: N₀ · F^r after r restarts; C12 asks for F times the ended search's episodes; the weights follow
    the batch told."""
    enough = 2 * first_search_episodes
    assert _first_stop(budget=enough, restart_population_factor=2.0)[0].restarts_done == 0  # needs 2×
    optimizer, rng = _first_stop(budget=3 * first_search_episodes, restart_population_factor=2.0)
    assert optimizer.restarts_done == 1 and optimizer.wanted_batch_size(16) == 32
    contexts = rng.uniform(0.0, 1.0, (optimizer.wanted_batch_size(16), 1))
    _tell_clean(optimizer, contexts)
    assert optimizer.diagnostics["mu_eff"] == optimizer.config.constants(32).mu_eff
    assert CCMAES(3, 1).wanted_batch_size(16) == 16  # F = 1: the caller's batch
    grown = CCMAES(3, 1, restart_population_factor=1.5, restarts=2)
    grown.restarts_done = 2
    assert grown.wanted_batch_size(16) == 36  # 16 · 1.5² = 36


def test_the_budget_and_the_factor_survive_a_checkpoint_bit_identically(tmp_path, first_search_episodes):
    options = {"budget": 3 * first_search_episodes, "restart_population_factor": 2.0}
    optimizer, rng = _first_stop(**options)
    restored = CCMAES.load(optimizer.save(tmp_path / "c.npz"))
    assert (restored.config.budget, restored.config.restart_population_factor) == (
        3 * first_search_episodes,
        2.0,
    )
    assert restored.search_start == optimizer.search_start == first_search_episodes
    for _ in range(3):
        contexts = rng.uniform(0.0, 1.0, (optimizer.wanted_batch_size(16), 1))
        _tell_clean(optimizer, contexts)
        _tell_clean(restored, contexts)
    assert _same_state_but_config(optimizer, restored)


def test_a_checkpoint_from_before_c12_loads_with_todays_restarts(first_search_episodes):
    optimizer, _ = _first_stop()
    state = optimizer.state_dict()
    del state["search_start"]
    state["config"] = {
        k: v for k, v in state["config"].items() if k not in ("budget", "restart_population_factor")
    }
    old = CCMAES.from_state_dict(state)
    assert (old.config.budget, old.config.restart_population_factor, old.search_start) == (None, 1.0, 0)
    with pytest.raises(ValueError, match=r"state\['search_start'\]"):
        CCMAES.from_state_dict({**optimizer.state_dict(), "search_start": -1})


def test_the_runner_gives_c_cma_es_its_budget_unless_given_and_refuses_a_growing_batch():
    from creps_gym.runner.config import RunConfig
    from creps_gym.runner.loop import Runner

    for max_episodes, expected in ((None, 120), (50, 50)):
        config = RunConfig("creps_gym/Sphere-v0", "c-cma-es", 6, 20, 0, max_episodes=max_episodes)
        assert Runner(config).optimizer.config.budget == expected  # min(iterations × samples, max_episodes)
    given = RunConfig("creps_gym/Sphere-v0", "c-cma-es", 6, 20, 0, optimizer_options={"budget": None})
    assert Runner(given).optimizer.config.budget is None  # the user's setting wins
    growing = RunConfig(
        "creps_gym/Sphere-v0", "c-cma-es", 6, 20, 0, optimizer_options={"restart_population_factor": 2.0}
    )
    with pytest.raises(
        ConfigError, match=r"restart_population_factor=1 \(the runner's batch stays samples\)"
    ):
        Runner(growing)  # the runner asks a fixed batch: C13 only where the caller grows it (the protocol)
