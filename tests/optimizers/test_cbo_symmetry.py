"""c-bo's ``symmetric_contexts``: the GP models the return over |s_i| in the named context dimensions.

Twin checks (an optimiser told (s, θ) with the option against one told (|s|, θ) without it), the invariance
of every answer under s_i → −s_i, the folded scaling box, the distilled policy, what it gains on an even
task, and its validation from options and from an untrusted checkpoint."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from creps_gym.optimizers import load_state, make_optimizer, save_state
from creps_gym.optimizers.cbo import ContextualBO
from creps_gym.optimizers.cbo_config import CBOConfig, fold_box, fold_contexts


def _even_returns(contexts: np.ndarray, params: np.ndarray) -> np.ndarray:
    """An even task in s_1: the best θ is (|s_1|, s_0)."""
    best = np.stack([np.abs(contexts[:, 1]), contexts[:, 0]], axis=1)
    return -((params - best) ** 2).sum(axis=1)


def _told(optimizer: ContextualBO, contexts: np.ndarray, seen: np.ndarray | None = None) -> None:
    """Ask at ``seen`` (default: ``contexts``) and tell the even task's returns at ``contexts``."""
    params = optimizer.ask(contexts if seen is None else seen)
    optimizer.tell(contexts if seen is None else seen, params, _even_returns(contexts, params))


def _symmetric(seed: int, **options) -> ContextualBO:
    """c-bo with ``symmetric_contexts=(1,)`` (and the quadratic mean features it needs)."""
    return make_optimizer("c-bo", 2, 2, seed, symmetric_contexts=(1,), mean_features="quadratic", **options)


def test_fold_contexts_and_fold_box():
    contexts = np.array([[-1.0, -2.0, 3.0], [1.0, 2.0, -3.0]])
    folded = fold_contexts(contexts, (0, 2))
    np.testing.assert_array_equal(folded, [[1.0, -2.0, 3.0], [1.0, 2.0, 3.0]])
    assert contexts[0, 0] == -1.0  # a copy
    assert fold_contexts(contexts, ()) is contexts
    low, high = fold_box(np.array([-1.0, -3.0, 1.0]), np.array([2.0, -1.0, 4.0]), (0, 1, 2))
    np.testing.assert_array_equal(low, [0.0, 1.0, 1.0])  # holds 0; all negative; all positive
    np.testing.assert_array_equal(high, [2.0, 3.0, 4.0])


def test_told_raw_contexts_it_asks_what_plain_c_bo_told_the_folded_ones_asks():
    """The twin: with the option the optimiser is plain c-bo on (|s_1|, θ), bit for bit."""
    options = {"initial_mean": 0.0, "initial_cov": 1.0, "candidates": 64}
    symmetric = make_optimizer("c-bo", 2, 2, 3, symmetric_contexts=[1], mean_features="quadratic", **options)
    plain = make_optimizer("c-bo", 2, 2, 3, **options)
    rng = np.random.default_rng(0)
    for _ in range(6):
        contexts = rng.uniform(-1.0, 1.0, (4, 2))
        params = symmetric.ask(contexts)
        np.testing.assert_array_equal(params, plain.ask(fold_contexts(contexts, (1,))))
        returns = _even_returns(contexts, params)
        symmetric.tell(contexts, params, returns)
        plain.tell(fold_contexts(contexts, (1,)), params, returns)
    probe = rng.uniform(-1.0, 1.0, (5, 2))
    np.testing.assert_array_equal(symmetric.recommend(probe), plain.recommend(fold_contexts(probe, (1,))))


@pytest.mark.parametrize("rule", ["trust_region", "observed", "neighbours"])
def test_every_answer_is_the_same_at_a_context_and_at_its_mirror_image(rule):
    optimizer = _symmetric(5, recommend_over=rule, candidates=64)
    rng = np.random.default_rng(1)
    for _ in range(6):
        _told(optimizer, rng.uniform(-1.0, 1.0, (4, 2)))
    probe = rng.uniform(-1.0, 1.0, (6, 2))
    mirror = probe * [1.0, -1.0]
    np.testing.assert_array_equal(optimizer.recommend(probe), optimizer.recommend(mirror))
    targets = rng.uniform(-1.0, 1.0, (3, 2))
    np.testing.assert_array_equal(
        optimizer.context_utility(probe, targets), optimizer.context_utility(mirror, targets)
    )
    state = optimizer.rng.bit_generator.state
    asked = optimizer.ask(probe)
    optimizer.rng.bit_generator.state = state
    np.testing.assert_array_equal(asked, optimizer.ask(mirror))


def test_a_configured_context_box_is_folded_for_the_scaling():
    optimizer = _symmetric(0, context_low=[0.0, -0.5], context_high=[1.0, 1.0])
    low, high = optimizer.context_scale
    np.testing.assert_array_equal(low, [0.0, 0.0])
    np.testing.assert_array_equal(high, [1.0, 1.0])
    grid = optimizer.distillation_contexts()  # the policy's grid stays in the contexts' own box
    assert grid[:, 1].min() == -0.5 and grid[:, 1].max() == 1.0


def test_on_an_even_task_what_it_learnt_on_one_side_serves_the_other():
    """Told episodes at s_1 < 0 only, recommending at s_1 > 0: the folded GP has seen those contexts'
    mirror images, plain c-bo extrapolates across s_1 = 0."""
    regrets = {}
    test = np.random.default_rng(9).uniform([-1.0, 0.2], [1.0, 1.0], (50, 2))
    for dims in ((), (1,)):
        optimizer = make_optimizer(
            "c-bo", 2, 2, 7, symmetric_contexts=dims, mean_features="quadratic", initial_cov=0.25
        )
        rng = np.random.default_rng(8)
        for _ in range(10):
            _told(optimizer, rng.uniform([-1.0, -1.0], [1.0, -0.2], (4, 2)))
        regrets[dims] = -_even_returns(test, optimizer.recommend(test)).mean()
    assert regrets[(1,)] < 0.5 * regrets[()]  # 0.063 against 0.176


def test_the_distilled_policy_is_even_in_the_symmetric_context_and_the_affine_map_is_refused():
    """The maximisers are even in s_1, so the distilled policy's coefficient of s_1 vanishes and that of
    s_1² carries the dependence; an affine map could only drop it, and is refused."""
    optimizer = _symmetric(5, candidates=64, context_low=[-1.0, -1.0], context_high=[1.0, 1.0])
    rng = np.random.default_rng(6)
    for _ in range(8):
        _told(optimizer, rng.uniform(-1.0, 1.0, (4, 2)))
    policy = optimizer.mean_policy()
    coefficients = policy.coefficients  # rows: 1, s_0, s_1, s_0², s_1²
    np.testing.assert_allclose(coefficients[2], 0.0, atol=1e-12)
    assert np.abs(coefficients[4]).max() > 0.1
    with pytest.raises(ValueError, match=r"mean_features: with symmetric_contexts .* got 'affine'"):
        make_optimizer("c-bo", 2, 2, 0, symmetric_contexts=[1])


def test_a_restored_optimizer_keeps_the_option_and_asks_the_same(tmp_path):
    optimizer = _symmetric(5, candidates=64, context_low=[0.0, -1.0], context_high=[1.0, 1.0])
    rng = np.random.default_rng(3)
    for _ in range(4):
        _told(optimizer, rng.uniform(-1.0, 1.0, (4, 2)))
    state = load_state(save_state(optimizer.state_dict(), tmp_path / "c-bo.npz"))  # through JSON and npz
    assert state["config"]["symmetric_contexts"] == [1]
    restored = ContextualBO.from_state_dict(state)
    assert restored.config.symmetric_contexts == (1,)
    probe = rng.uniform(-1.0, 1.0, (4, 2))
    np.testing.assert_array_equal(restored.ask(probe), optimizer.ask(probe))
    state["scale_high"] = np.array([1.0, 2.0])  # not the configured box, folded
    with pytest.raises(
        ValueError, match=r"state\['scale_low'\], state\['scale_high'\]: expected the configured"
    ):
        ContextualBO.from_state_dict(state)


def _endless():
    while True:
        yield 0


@pytest.mark.parametrize(
    ("value", "error", "match"),
    [
        ([2], ValueError, r"symmetric_contexts: expected context dimensions in \[0, 2\), got 2"),
        ([-1], ValueError, r"symmetric_contexts: expected context dimensions in \[0, 2\), got -1"),
        ([1, 1], ValueError, "symmetric_contexts: expected distinct dimensions, got 1 twice"),
        ([True], TypeError, "symmetric_contexts: expected integers, got True"),
        ([0.5], TypeError, "symmetric_contexts: expected integers, got 0.5"),
        ("1", TypeError, "symmetric_contexts: expected a list, tuple or range of integers, got str"),
        (1, TypeError, "symmetric_contexts: expected a list, tuple or range of integers, got int"),
        ({1: "y"}, TypeError, "got dict"),
        ({1}, TypeError, "got set"),
        (np.array(1), TypeError, "got ndarray"),
        (np.array([0.0]), TypeError, "got ndarray"),
    ],
)
def test_bad_symmetric_contexts_are_refused_from_options_and_from_a_checkpoint(value, error, match):
    with pytest.raises(error, match=match):
        CBOConfig(2, 2, symmetric_contexts=value, mean_features="quadratic")
    optimizer = make_optimizer("c-bo", 2, 2, 0, mean_features="quadratic")
    state = copy.deepcopy(optimizer.state_dict())
    state["config"] = {**state["config"], "symmetric_contexts": value}
    with pytest.raises(error, match=match):
        ContextualBO.from_state_dict(state)


def test_symmetric_contexts_takes_a_range_or_an_integer_array_and_stops_at_the_first_repeat():
    for value in (range(2), np.array([1, 0])):
        assert CBOConfig(2, 2, symmetric_contexts=value, mean_features="quadratic").symmetric_contexts == (
            0,
            1,
        )
    with pytest.raises(TypeError, match="got generator"):  # an endless one is not iterated
        CBOConfig(2, 2, symmetric_contexts=_endless(), mean_features="quadratic")
    with pytest.raises(ValueError, match="got 0 twice"):
        CBOConfig(2, 2, symmetric_contexts=[0] * 10**6, mean_features="quadratic")
