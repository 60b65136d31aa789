"""c-bo's log transform scale, Eq. (G6) of :mod:`creps_gym.optimizers.gp_trend`: c is the ``log_quantile``
of the gaps to the best return (the lower quartile; the median until 2026-11-30)."""

import copy

import numpy as np
import pytest

from creps_gym.optimizers import make_optimizer
from creps_gym.optimizers.cbo import ContextualBO
from creps_gym.optimizers.gp_model import transformed_returns
from creps_gym.optimizers.gp_trend import LOG_QUANTILE, chosen_transform, log_transform


def _long_tail(rng: np.random.Generator) -> np.ndarray:
    """Ten good returns in [−1, 0] and thirty bad ones down to −1e6, as a run's early asks on a steep task."""
    return np.concatenate([-rng.uniform(0.0, 1.0, 10), -(10.0 ** rng.uniform(3.0, 6.0, 30))])


@pytest.mark.parametrize("n", [7, 8, 40])
def test_the_scale_is_the_quantile_of_the_gaps_and_the_median_is_numpys_bit_for_bit(n):
    returns = _long_tail(np.random.default_rng(n))[:n]
    gaps = returns.max() - returns
    for q in (0.1, 0.25, 1.0):
        values, scale = log_transform(returns, q)
        assert scale == np.quantile(gaps, q)
        np.testing.assert_array_equal(values, -np.log1p(gaps / scale))
    assert log_transform(returns, 0.5)[1] == np.median(gaps)  # the former default's runs stay as they were
    assert LOG_QUANTILE == 0.25 and log_transform(returns)[1] == np.quantile(gaps, 0.25)


def test_a_lower_quantile_resolves_the_best_returns_under_a_long_tail():
    """Near linear below c, logarithmic above: with c at the median of a tail of bad returns the ten good
    ones differ by under a thousandth of the targets' spread, with c at the lower quartile by far more."""
    returns = _long_tail(np.random.default_rng(0))
    spreads = {}
    for q in (0.5, 0.25):
        targets = transformed_returns(returns, "log", "mean", q)
        spreads[q] = np.ptp(targets[:10]) / np.ptp(targets)
        assert (np.argsort(targets, kind="stable") == np.argsort(returns, kind="stable")).all()  # the order
    assert spreads[0.5] < 1e-3 and spreads[0.25] > 10 * spreads[0.5]


def test_the_option_sets_the_targets_and_autos_choice():
    rng = np.random.default_rng(1)
    contexts, params = rng.uniform(0, 1, (40, 1)), rng.uniform(-1, 1, (40, 2))
    returns = _long_tail(rng)
    for q in (0.5, 0.1):
        optimizer = make_optimizer("c-bo", 2, 1, 0, log_quantile=q, transform="auto", trend="quadratic")
        optimizer.tell(contexts, params, returns, allow_external=True)
        expected = transformed_returns(returns, optimizer._transform, "min", q)
        np.testing.assert_array_equal(optimizer._targets(returns), expected)
        inputs = optimizer._inputs(contexts, params)
        assert optimizer._transform == chosen_transform(inputs, returns, True, q)


@pytest.mark.parametrize("value", [0, 0.0, -0.1, 1.5, float("nan"), float("inf"), True, "0.25", None])
def test_a_quantile_outside_zero_to_one_is_refused_naming_it_in_options_and_in_a_checkpoint(value):
    error = TypeError if isinstance(value, (bool, str)) or value is None else ValueError
    with pytest.raises(error, match="log_quantile: expected"):
        make_optimizer("c-bo", 2, 1, 0, log_quantile=value)
    state = make_optimizer("c-bo", 2, 1, 0).state_dict()
    state["config"] = {**state["config"], "log_quantile": value}
    with pytest.raises(error, match="log_quantile: expected"):
        ContextualBO.from_state_dict(state)


def _taught(**options) -> ContextualBO:
    optimizer = make_optimizer("c-bo", 2, 1, 3, **options)
    rng = np.random.default_rng(4)
    for _ in range(6):
        contexts = rng.uniform(0, 1, (4, 1))
        params = optimizer.ask(contexts)
        optimizer.tell(contexts, params, -(((params - contexts) * [1.0, 30.0]) ** 4).sum(axis=1))
    return optimizer


@pytest.mark.slow
@pytest.mark.parametrize("written", [{"log_quantile": 0.1}, {}])
def test_a_checkpoint_resumes_bit_for_bit_and_one_written_before_the_option_with_the_median(written):
    """A checkpoint keeps the option; one that names none (written before 2026-11-30) resumes with the
    median, the scale its run used, bit for bit past the next refit."""
    optimizer = _taught(log_quantile=written.get("log_quantile", 0.5))
    state = copy.deepcopy(optimizer.state_dict())
    if not written:
        del state["config"]["log_quantile"]
    restored = ContextualBO.from_state_dict(state)
    assert restored.config.log_quantile == written.get("log_quantile", 0.5)
    contexts = np.array([[0.1], [0.5], [0.8], [0.3]])
    for one in (optimizer, restored):
        for _ in range(2):
            params = one.ask(contexts)
            one.tell(contexts, params, -((params - contexts) ** 2).sum(axis=1))
    assert restored.state_dict()["log_hyper"].tobytes() == optimizer.state_dict()["log_hyper"].tobytes()
    assert restored.ask(contexts).tobytes() == optimizer.ask(contexts).tobytes()
