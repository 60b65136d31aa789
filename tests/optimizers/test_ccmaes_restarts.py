"""Contextual CMA-ES's restart portfolio (C11, ``restart_baseline_loss``): the searches after a restart fit
the context baseline with another loss; the first search (every run that never restarts) is unchanged."""

from __future__ import annotations

import numpy as np
import pytest

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
