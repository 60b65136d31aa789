"""The baseline's ridge (C1) and its scaled form (C1s, ``baseline_ridge_scale="unexplained"``): the ridge
is relative to the standardised features, so scaling or shifting the returns leaves its effect unchanged;
where the best return depends on the context, a fixed ridge biases V by ``ridge`` times that effect and
floors the ranking, and C1s, which scales it by the unexplained fraction of the returns, removes that
floor."""

from __future__ import annotations

import numpy as np
import pytest

from creps_gym.optimizers import CCMAES
from creps_gym.optimizers.contextual import (
    MIN_UNEXPLAINED,
    context_advantages,
    detrended_local_advantages,
    local_advantages,
    scaled_ridge,
)

SHIFT = np.array([3.0, -2.0, 1.0, 0.5, -1.0])  # θ*(s) = −SHIFT·s


def _batch(rng, level: float, spread: float, n: int = 60):
    """Contexts s ~ U[1, 2) and returns −level·s·(1 + s) (a best return that depends on s) plus a θ part of
    standard deviation ``spread``, and that θ part."""
    contexts = rng.uniform(1.0, 2.0, (n, 1))
    theta_part = spread * rng.standard_normal(n)
    return contexts, -level * contexts[:, 0] * (1.0 + contexts[:, 0]) + theta_part, theta_part


@pytest.mark.parametrize("ridge_scale", ["fixed", "unexplained"])
@pytest.mark.parametrize(("factor", "offset"), [(1e-12, 0.0), (1e6, -3e7), (1.0, 5.0)])
def test_scaling_and_shifting_the_returns_scales_the_advantages_alike(ridge_scale, factor, offset):
    """R → c·R + b gives c·a and the same R², with either ridge: the ridge's relative effect does not
    depend on the scale of the problem."""
    contexts, returns, _ = _batch(np.random.default_rng(0), 1.0, 1e-3)
    base, explained = context_advantages(contexts, returns, 2, 1e-4, ridge_scale=ridge_scale)
    moved, moved_explained = context_advantages(
        contexts, factor * returns + offset, 2, 1e-4, ridge_scale=ridge_scale
    )
    np.testing.assert_allclose(moved / factor, base, rtol=1e-6, atol=1e-9 * np.abs(base).max())
    assert moved_explained == pytest.approx(explained, rel=1e-9)


@pytest.mark.parametrize("ridge_scale", ["fixed", "unexplained"])
def test_an_affine_change_of_the_contexts_leaves_the_advantages_unchanged(ridge_scale):
    contexts, returns, _ = _batch(np.random.default_rng(1), 1.0, 1e-2)
    base, _ = context_advantages(contexts, returns, 2, 1e-4, ridge_scale=ridge_scale)
    moved, _ = context_advantages(1e-3 * contexts + 1e3, returns, 2, 1e-4, ridge_scale=ridge_scale)
    np.testing.assert_allclose(moved, base, rtol=0, atol=1e-7 * np.abs(base).max())


def test_the_fixed_ridge_biases_v_by_ridge_times_the_context_effect_and_c1s_by_much_less():
    """With a context effect 1e6 times the θ part, the fixed ridge 1e-7 moves V by about 1e-7 of the
    effect, 10 % of the θ part; C1s scales the ridge by 1 − R² (about 1e-12, clipped to 1e-6)."""
    contexts, returns, theta_part = _batch(np.random.default_rng(2), 1.0, 1e-6)
    exact, _ = context_advantages(contexts, returns, 2, 0.0)
    fixed, explained = context_advantages(contexts, returns, 2, 1e-7)
    scaled, _ = context_advantages(contexts, returns, 2, 1e-7, ridge_scale="unexplained")
    effect = np.std(returns - theta_part)
    assert 0.5e-7 * effect < np.std(fixed - exact) < 2e-7 * effect
    assert np.std(fixed - exact) > 0.05 * np.std(theta_part)
    assert np.std(scaled - exact) < 1e-5 * np.std(theta_part)
    assert 1.0 - explained < 1e-10


def test_scaled_ridge_is_the_ridge_times_the_unexplained_fraction_clipped():
    targets = np.array([1.0, 2.0, 3.0, 4.0])
    assert scaled_ridge(1e-10, targets, targets + np.array([0.1, -0.1, 0.1, -0.1])) == pytest.approx(
        1e-10 * 0.04 / 5.0
    )
    assert scaled_ridge(1e-10, targets, targets) == 1e-10 * MIN_UNEXPLAINED
    assert scaled_ridge(1e-10, targets, np.full(4, 10.0)) == 1e-10  # worse than the mean: at most the ridge
    assert scaled_ridge(1e-10, np.ones(4), np.ones(4)) == 1e-10  # flat returns: nothing explained


def _offset_sphere_regret(**options) -> float:
    """A contextual sphere x = θ + SHIFT·s, p = 5, N = 20, whose best return −10^3·s depends on the context,
    with C3r, until a stop criterion or 300 iterations; the mean policy's regret over 9 test contexts."""
    optimizer = CCMAES(5, 1, initial_mean=1.0, seed=1, restarts=0, ridge_centre="old", **options)
    rng, test = np.random.default_rng(0), np.linspace(1.0, 2.0, 9)[:, None]

    def sphere(contexts, params):
        return np.square(params + contexts * SHIFT).sum(axis=1)

    for _ in range(300):
        contexts = rng.uniform(1.0, 2.0, (20, 1))
        params = optimizer.ask(contexts)
        optimizer.tell(contexts, params, -sphere(contexts, params) - 1e3 * contexts[:, 0])
        if optimizer.stop():
            break
    return float(sphere(test, optimizer.recommend(test)).mean())


def test_c1s_removes_the_baseline_ridges_floor_where_the_best_return_depends_on_the_context():
    """The fixed ridge 1e-10 stalls near ridge·10^3·sd(s) (measured 3.7e-8); C1s reaches the float floor of
    returns near 10^3 (measured 7.3e-14, as baseline_ridge=0: 5.4e-14)."""
    fixed = _offset_sphere_regret()
    scaled = _offset_sphere_regret(baseline_ridge_scale="unexplained")
    assert fixed > 1e-9 and scaled < 1e-12, (fixed, scaled)


@pytest.mark.parametrize(("value", "error"), [("relative", ValueError), (None, TypeError), (1, TypeError)])
def test_a_bad_baseline_ridge_scale_is_rejected_with_its_name(value, error):
    with pytest.raises(error, match=r"baseline_ridge_scale: expected one of \('fixed', 'unexplained'\), got"):
        CCMAES(3, 1, baseline_ridge_scale=value)


def test_c1s_with_a_local_baseline_is_rejected():
    """The local baseline (C1'') has no ridge: the option would silently do nothing."""
    with pytest.raises(ValueError, match="baseline_ridge_scale"):
        CCMAES(3, 1, baseline_bandwidth=0.5, baseline_ridge_scale="unexplained")


def test_context_advantages_rejects_a_bad_ridge_scale():
    contexts, returns, _ = _batch(np.random.default_rng(3), 1.0, 1.0)
    with pytest.raises(ValueError, match="ridge_scale: expected one of"):
        context_advantages(contexts, returns, 2, 1e-10, ridge_scale="sigma")


def test_c1s_survives_a_checkpoint_and_an_old_checkpoint_loads_as_fixed(tmp_path):
    rng = np.random.default_rng(4)
    optimizer = CCMAES(4, 1, initial_mean=0.5, seed=2, baseline_ridge_scale="unexplained")
    for _ in range(3):
        contexts = rng.uniform(0, 3, (12, 1))
        params = optimizer.ask(contexts)
        optimizer.tell(contexts, params, -np.square(params - 0.3 * contexts).sum(axis=1))
    restored = CCMAES.load(optimizer.save(tmp_path / "c.npz"))
    assert restored.config.baseline_ridge_scale == "unexplained"
    contexts = rng.uniform(0, 3, (12, 1))
    params = optimizer.ask(contexts)
    np.testing.assert_array_equal(params, restored.ask(contexts))
    for twin in (optimizer, restored):
        twin.tell(contexts, params, -np.square(params - 0.3 * contexts).sum(axis=1) - 50.0 * contexts[:, 0])
    np.testing.assert_array_equal(optimizer.policy.coefficients, restored.policy.coefficients)
    state = optimizer.state_dict()
    del state["config"]["baseline_ridge_scale"]
    assert CCMAES.from_state_dict(state).config.baseline_ridge_scale == "fixed"


# The detrended local baseline (C1d, ``baseline_detrend=True``): the polynomial's trend plus the local median
# of its residuals.


def _kinked_batch(rng, n: int = 150):
    """Returns −|s − 1.4| (a kink inside [1, 2), as a cone-shaped optimum's E[R | s]) plus a θ part 1e-3."""
    contexts = rng.uniform(1.0, 2.0, (n, 1))
    effect = -np.abs(contexts[:, 0] - 1.4)
    return contexts, effect + 1e-3 * rng.standard_normal(n), effect


def test_c1d_follows_a_kink_better_than_the_quadratic_and_the_local_median():
    contexts, returns, effect = _kinked_batch(np.random.default_rng(5))
    truth = returns - effect  # the θ part: what the advantages should be
    quadratic, _ = context_advantages(contexts, returns, 2, 1e-10)
    local, _ = local_advantages(contexts, returns, 0.1)
    detrended, explained = detrended_local_advantages(contexts, returns, 0.1, 2, 1e-10)
    errors = [np.std(a - truth) for a in (quadratic, local, detrended)]
    assert errors[2] < 0.7 * min(errors[:2]), errors  # measured: 4.6e-2, 7.9e-3 and 4.8e-3
    assert 0.99 < explained <= 1.0


def test_c1d_is_invariant_to_scaling_and_shifting_the_returns():
    contexts, returns, _ = _kinked_batch(np.random.default_rng(6), 60)
    base, explained = detrended_local_advantages(contexts, returns, 0.2, 2, 1e-10)
    moved, moved_explained = detrended_local_advantages(contexts, 1e-9 * (returns + 1e3), 0.2, 2, 1e-10)
    np.testing.assert_allclose(moved / 1e-9, base, rtol=0, atol=1e-6 * np.abs(base).max())
    assert moved_explained == pytest.approx(explained, rel=1e-6)


def test_c1d_solves_a_contextual_cone_whose_expected_return_is_kinked():
    """√(Σ x_i²) at x = θ + SHIFT·s, p = 5: the optimiser with C1d runs, and its mean policy converges."""
    optimizer = CCMAES(
        5,
        1,
        initial_mean=1.0,
        seed=3,
        restarts=0,
        ridge_centre="old",
        baseline_bandwidth=0.1,
        baseline_detrend=True,
    )
    rng, test = np.random.default_rng(0), np.linspace(1.0, 2.0, 9)[:, None]

    def cone(contexts, params):
        return np.sqrt(np.square(params + contexts * SHIFT).sum(axis=1))

    for _ in range(150):
        contexts = rng.uniform(1.0, 2.0, (20, 1))
        params = optimizer.ask(contexts)
        optimizer.tell(contexts, params, -cone(contexts, params))
        if optimizer.stop():
            break
    assert float(cone(test, optimizer.recommend(test)).mean()) < 1e-4


@pytest.mark.parametrize(
    ("options", "match"),
    [
        ({"baseline_detrend": True}, "baseline_detrend: expected False with baseline_bandwidth = 0"),
        ({"baseline_detrend": 1}, "baseline_detrend"),
        ({"baseline_detrend": True, "baseline_bandwidth": 0.1, "baseline_loss": "huber"}, "baseline_loss"),
        (
            {"baseline_detrend": True, "baseline_bandwidth": 0.1, "standardise_advantages": True},
            "standardise_advantages",
        ),
    ],
)
def test_bad_detrend_combinations_are_rejected(options, match):
    with pytest.raises((TypeError, ValueError), match=match):
        CCMAES(3, 1, **options)


def test_c1d_accepts_the_polynomial_options_it_uses():
    config = CCMAES(
        3,
        1,
        baseline_bandwidth=0.1,
        baseline_detrend=True,
        baseline_degree=3,
        baseline_ridge=1e-12,
        baseline_ridge_scale="unexplained",
    ).config
    assert (config.baseline_degree, config.baseline_ridge_scale) == (3, "unexplained")
