"""The mean fit's ridge centre (C3r, ``ridge_centre="old"``): the ridge shrinks the step instead of the
coefficients, so its bias shrinks with the search and no longer floors the regret on an ill-conditioned
contextual function; the default (C3) and old checkpoints are unchanged."""

from __future__ import annotations

import numpy as np
import pytest

from creps_gym.optimizers import CCMAES
from creps_gym.optimizers.ccmaes_surrogate import CCMAESSurrogate
from creps_gym.optimizers.contextual import contextual_mean
from creps_gym.optimizers.features import make_features

AFFINE = make_features("affine", 1, "mean_features")
SHIFT = np.array([3.0, -2.0, 1.0, 0.5, -1.0])  # θ*(s) = −SHIFT·s


def _batch(rng, slope: float, noise: float):
    """A batch around the mean A_oldᵀϕ(s) with a steep slope and a tiny spread, and rank weights."""
    contexts = rng.uniform(1.0, 2.0, (30, 1))
    old = np.array([[0.5, -1.0], [slope, -slope]])  # (k, p): intercepts, slopes
    params = AFFINE(contexts) @ old + noise * rng.standard_normal((30, 2))
    weights = np.log(15.5) - np.log(np.arange(1, 31.0))
    return contexts, params, np.where(weights > 0, weights, -0.1), old


def test_without_a_ridge_both_centres_are_the_same_least_squares_fit():
    contexts, params, weights, old = _batch(np.random.default_rng(0), 3.0, 0.1)
    zero = contextual_mean(AFFINE, contexts, params, weights, 0.0, old)
    shifted = contextual_mean(AFFINE, contexts, params, weights, 0.0, old, ridge_centre="old")
    np.testing.assert_allclose(shifted, zero, rtol=0, atol=1e-14)
    selected = weights > 0
    root = np.sqrt(weights[selected] / weights[selected].sum())[:, None]
    expected = np.linalg.lstsq(root * AFFINE(contexts[selected]), root * params[selected], rcond=None)[0]
    np.testing.assert_allclose(zero, expected, rtol=0, atol=1e-12)


def test_the_classic_ridge_biases_the_slope_by_ridge_times_the_slope_and_c3r_by_ridge_times_the_step():
    """(C3) shrinks the slopes towards 0: an error of about ridge·|slope| however small the step; (C3r)
    shrinks the step: an error of about ridge·|step|, here 1e-9 of the slope's."""
    ridge, slope = 1e-8, 1e3
    contexts, params, weights, old = _batch(np.random.default_rng(1), slope, 1e-9)
    exact = contextual_mean(AFFINE, contexts, params, weights, 0.0, old)
    zero = contextual_mean(AFFINE, contexts, params, weights, ridge, old)
    shifted = contextual_mean(AFFINE, contexts, params, weights, ridge, old, ridge_centre="old")
    assert np.abs(zero - exact)[1].max() == pytest.approx(ridge * slope, rel=0.05)
    step = np.abs(exact - old)[1].max()
    assert 0 < step < 1e-8 and np.abs(shifted - exact)[1].max() <= 1e-12 * slope


def test_c3r_is_equivariant_to_adding_an_affine_function_of_the_context_to_theta():
    """θ → θ + Bᵀϕ(s) with A_old → A_old + B moves the C3r fit by B (up to round-off); C3's ridge does not."""
    contexts, params, weights, old = _batch(np.random.default_rng(2), 3.0, 0.1)
    moved = np.array([[2.0, -1.0], [5e4, 7e4]])
    ridge = 1e-4
    base = contextual_mean(AFFINE, contexts, params, weights, ridge, old, ridge_centre="old")
    lifted = contextual_mean(
        AFFINE, contexts, params + AFFINE(contexts) @ moved, weights, ridge, old + moved, ridge_centre="old"
    )
    np.testing.assert_allclose(lifted - moved, base, rtol=0, atol=1e-9)
    plain = contextual_mean(AFFINE, contexts, params, weights, ridge, old)
    plain_lifted = contextual_mean(AFFINE, contexts, params + AFFINE(contexts) @ moved, weights, ridge, old)
    assert np.abs(plain_lifted - moved - plain).max() > 1.0  # ridge·|B| = 7 on the slope


def _discus_regret(optimizer, limit: int = 400) -> float:
    """Run a contextual Discus 10^6 x_1² + Σ_{i≥2} x_i², x = θ + SHIFT·s, s ~ U[1, 2), N = 20, until a stop
    criterion or ``limit`` iterations; the mean policy's final regret over 9 test contexts."""
    rng, test = np.random.default_rng(0), np.linspace(1.0, 2.0, 9)[:, None]

    def discus(contexts, params):
        x = params + contexts * SHIFT
        return 1e6 * x[:, 0] ** 2 + (x[:, 1:] ** 2).sum(axis=1)

    for _ in range(limit):
        contexts = rng.uniform(1.0, 2.0, (20, 1))
        params = optimizer.ask(contexts)
        optimizer.tell(contexts, params, -discus(contexts, params))
        if optimizer.stop():
            break
    return float(discus(test, optimizer.recommend(test)).mean())


@pytest.mark.slow
def test_c3r_removes_the_ridge_floor_on_an_ill_conditioned_contextual_function():
    """With the default ridge 1e-8, C3 (the default before issue 45) stalls near a regret of 1e-8 (the slope
    bias ridge·|SHIFT| in x_1, weighted 1e6); C3r, the default since, converges until tolx, 13 orders
    further (measured: 2.3e-8 against 6.4e-23)."""
    zero = _discus_regret(CCMAES(5, 1, initial_mean=1.0, seed=1, restarts=0, ridge_centre="zero"))
    shifted = _discus_regret(CCMAES(5, 1, initial_mean=1.0, seed=1, restarts=0))
    assert CCMAES(5, 1).config.ridge_centre == "old"
    assert zero > 1e-10 and shifted < 1e-18, (zero, shifted)


def test_a_checkpoint_without_the_field_loads_as_c3_and_resumes_bit_identically():
    """An optimiser saved before ``ridge_centre`` existed (its config has no such key) ran C3, the default
    until issue 45, and loads as C3 (``FORMER_ABSENT``), not as today's default C3r."""
    rng = np.random.default_rng(3)
    optimizer = _told(CCMAES(4, 1, initial_mean=0.5, seed=2, ridge_centre="zero"), rng, 5)
    state = optimizer.state_dict()
    del state["config"]["ridge_centre"]
    restored = CCMAES.from_state_dict(state)
    assert restored.config.ridge_centre == "zero"
    _twins_agree(optimizer, restored, rng)


def _told(optimizer, rng, iterations):
    """``optimizer`` after ``iterations`` batches of 12 on a contextual sphere with optimum 0.3 s."""
    for _ in range(iterations):
        contexts = rng.uniform(0, 3, (12, 1))
        params = optimizer.ask(contexts)
        optimizer.tell(contexts, params, -np.square(params - 0.3 * contexts).sum(axis=1))
    return optimizer


def _twins_agree(optimizer, restored, rng):
    """The next ask and tell give the same bits in ``optimizer`` and its ``restored`` copy."""
    contexts = rng.uniform(0, 3, (12, 1))
    params = optimizer.ask(contexts)
    np.testing.assert_array_equal(params, restored.ask(contexts))
    for twin in (optimizer, restored):
        twin.tell(contexts, params, -np.square(params - 0.3 * contexts).sum(axis=1))
    np.testing.assert_array_equal(optimizer.policy.coefficients, restored.policy.coefficients)
    np.testing.assert_array_equal(optimizer.policy.cov, restored.policy.cov)
    assert optimizer.policy.step_size == restored.policy.step_size


def test_c3r_survives_a_checkpoint_bit_identically(tmp_path):
    rng = np.random.default_rng(4)
    optimizer = _told(CCMAES(4, 1, initial_mean=0.5, seed=2, ridge_centre="old"), rng, 3)
    restored = CCMAES.load(optimizer.save(tmp_path / "c.npz"))
    assert restored.config.ridge_centre == "old"
    _twins_agree(optimizer, restored, rng)


@pytest.mark.parametrize(
    ("value", "error"), [("step", ValueError), ("", ValueError), (None, TypeError), (0, TypeError)]
)
def test_a_bad_ridge_centre_is_rejected_with_its_name(value, error):
    with pytest.raises(error, match=r"ridge_centre: expected one of \('zero', 'old'\), got"):
        CCMAES(3, 1, ridge_centre=value)


def test_a_surrogate_checkpoint_without_the_field_loads_as_c3_too():
    """The surrogate shares C-CMA-ES's config and its loading: an old state without ``ridge_centre`` is C3."""
    rng = np.random.default_rng(4)
    optimizer = _told(CCMAESSurrogate(4, 1, initial_mean=0.5, seed=3, ridge_centre="zero"), rng, 6)
    state = optimizer.state_dict()
    del state["config"]["ridge_centre"]
    restored = CCMAESSurrogate.from_state_dict(state)
    assert restored.config.ridge_centre == "zero" and CCMAESSurrogate(4, 1).config.ridge_centre == "old"
    _twins_agree(optimizer, restored, rng)
