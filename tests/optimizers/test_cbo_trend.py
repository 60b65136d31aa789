"""c-bo's quadratic prior mean, Eq. (G4) of :mod:`creps_gym.optimizers.gp_trend`: the basis and its
gradient, the fit, the GP of the residuals (predictions, gradients, the kriging believer), and the option
through the optimiser (exact on a quadratic, restored bit for bit, its stop rule)."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import check_posterior_gradients

from creps_gym.optimizers import make_optimizer
from creps_gym.optimizers.cbo import ContextualBO
from creps_gym.optimizers.gp_model import default_start, fit_gp
from creps_gym.optimizers.gp_trend import (
    TREND_RATIO,
    chosen_transform,
    detrend,
    quadratic_basis,
    trend_and_gradient,
    trend_maximiser,
    trend_p_value,
    with_trend_maximiser,
)

H = 1e-6


def _quadratic(x: np.ndarray) -> np.ndarray:
    return 1.5 - 2.0 * x[:, 0] + x[:, 1] * x[:, 2] - 3.0 * (x[:, 1] - 0.4) ** 2


def test_the_basis_has_q_columns_and_the_trends_gradient_is_exact():
    rng = np.random.default_rng(0)
    x, beta = rng.uniform(size=(5, 3)), rng.standard_normal(10)
    basis = quadratic_basis(x)
    assert basis.shape == (5, 1 + 3 + 6) and np.array_equal(basis[:, 0], np.ones(5))
    assert np.array_equal(basis[:, 4], x[:, 0] ** 2) and np.array_equal(basis[:, 5], x[:, 0] * x[:, 1])
    value, gradient = trend_and_gradient(x, beta)
    np.testing.assert_allclose(value, basis @ beta, rtol=1e-15)
    for j in range(3):
        step = np.zeros(3)
        step[j] = H
        up, down = trend_and_gradient(x + step, beta)[0], trend_and_gradient(x - step, beta)[0]
        np.testing.assert_allclose(gradient[:, j], (up - down) / (2 * H), rtol=1e-7, atol=1e-8)


def test_detrend_recovers_a_quadratic_and_waits_for_two_episodes_per_coefficient():
    rng = np.random.default_rng(1)
    x = rng.uniform(size=(2 * 10, 3))
    residuals, beta, scale = detrend(x, _quadratic(x))
    np.testing.assert_allclose(quadratic_basis(x) @ beta, _quadratic(x), atol=1e-12)
    assert scale == pytest.approx(1e-12 * np.sqrt(np.mean(_quadratic(x) ** 2)), rel=0.5)  # the floor
    assert np.isfinite(residuals).all()
    few = x[: TREND_RATIO * 10 - 1]
    targets = _quadratic(few)
    assert detrend(few, targets) == (targets, None, 1.0)


def test_the_residual_gp_predicts_in_the_returns_units_and_its_gradients_are_exact():
    rng = np.random.default_rng(2)
    inputs = rng.uniform(size=(30, 3))
    targets = _quadratic(inputs) + 0.3 * np.sin(5 * inputs[:, 0])
    model = fit_gp(inputs, targets, default_start(3), trend=True)
    assert model.beta is not None and 0.0 < model.scale < targets.std()
    plain = fit_gp(inputs, model.targets, default_start(3))  # the GP of the standardised residuals
    x = rng.uniform(size=(4, 3))
    mean, variance, _, _ = model.predict_with_gradient(x)
    np.testing.assert_allclose(mean, model.predict(x)[0], rtol=1e-12)
    expected = trend_and_gradient(x, model.beta)[0] + model.scale * plain.predict(x)[0]
    np.testing.assert_allclose(mean, expected, rtol=1e-12)
    np.testing.assert_allclose(variance, model.scale**2 * plain.predict(x)[1], rtol=1e-12)
    np.testing.assert_allclose(model.latent_variance(x), plain.predict(x)[1], rtol=1e-12)
    check_posterior_gradients(model, x, H, variance_atol=1e-9)


def test_the_kriging_believer_keeps_the_mean_and_lowers_the_variance():
    """Conditioning on the posterior mean at x (the batch's fantasy) leaves the mean everywhere and shrinks
    the variance at x: the residual is taken in the GP's own units, after the trend."""
    rng = np.random.default_rng(3)
    inputs = rng.uniform(size=(30, 3))
    model = fit_gp(inputs, _quadratic(inputs) + 0.2 * np.cos(4 * inputs[:, 2]), default_start(3), trend=True)
    x, others = rng.uniform(size=3), rng.uniform(size=(5, 3))
    grown = model.condition(x, float(model.predict(x[None])[0][0]))
    np.testing.assert_allclose(grown.predict(others)[0], model.predict(others)[0], rtol=1e-9, atol=1e-12)
    assert grown.predict(x[None])[1][0] < 0.1 * model.predict(x[None])[1][0]
    assert grown.beta is model.beta and grown.scale == model.scale


def test_the_trends_p_value_is_the_f_tests():
    from scipy.stats import f

    for n, q, explained in [(60, 10, 0.206), (60, 10, 0.5), (200, 21, 0.05), (30, 3, 0.0)]:
        statistic = (explained / (q - 1)) / ((1 - explained) / (n - q))
        assert trend_p_value(n, q, explained) == pytest.approx(f.sf(statistic, q - 1, n - q), rel=1e-10)
    assert trend_p_value(60, 10, 1.0) == 0.0 and trend_p_value(10, 10, 0.9) == 1.0
    assert trend_p_value(60, 10, -0.1) == 1.0  # a fit worse than the mean explains nothing


def test_the_trends_maximiser_over_theta_solves_its_gradient_and_is_a_candidate_where_concave():
    """At a fixed s the trend is a quadratic in θ: an ill-conditioned one (eigenvalues 1 to 1e-6, where
    L-BFGS-B stops early) has its maximiser in closed form, clipped to the box; a non-concave one has none."""
    rng = np.random.default_rng(5)
    c, q = 1, 3
    rotation = np.linalg.qr(rng.standard_normal((q, q)))[0]
    hessian = -rotation @ np.diag([1.0, 1e-3, 1e-6]) @ rotation.T
    optimum, context = np.array([0.3, 0.6, 0.5]), np.array([0.7])
    x = rng.uniform(size=(200, c + q))
    targets = 0.5 * np.einsum("nq,qr,nr->n", x[:, c:] - optimum, hessian, x[:, c:] - optimum) + x[:, 0]
    beta = detrend(x, targets)[1]
    np.testing.assert_allclose(trend_maximiser(beta, context, np.zeros(q), np.ones(q)), optimum, atol=1e-6)
    assert trend_maximiser(beta, context, np.zeros(q), np.full(q, 0.4)).max() == 0.4  # clipped
    assert trend_maximiser(-beta, context, np.zeros(q), np.ones(q)) is None  # convex: no maximiser
    candidates = rng.uniform(size=(5, q))
    grown = with_trend_maximiser(candidates, beta, context, (0.0, 1.0))
    assert grown.shape == (6, q) and np.array_equal(grown[:5], candidates)
    assert with_trend_maximiser(candidates, None, context, (0.0, 1.0)) is candidates


def test_auto_chooses_no_transform_for_quadratic_returns_and_the_log_for_a_long_tail():
    """Eq. (G5), the Box–Cox choice in the returns' units: an exact quadratic leaves no residual
    untransformed; Rosenbrock's quartic walls, a long tail of bad returns, fit better after the log (its
    Jacobian included)."""
    rng = np.random.default_rng(6)
    x = rng.uniform(size=(60, 3))
    assert chosen_transform(x, _quadratic(x), trend=True) == "none"
    theta = 4.0 * x - 2.0
    walls = 100.0 * (theta[:, 1:] - theta[:, :-1] ** 2) ** 2 + (1.0 - theta[:, :-1]) ** 2
    assert chosen_transform(x, -walls.sum(axis=1), trend=True) == "log"
    assert chosen_transform(x, -walls.sum(axis=1), trend=False) == "log"


def test_auto_is_recomputed_on_restore_and_reported():
    optimizer, regret = _sphere(2, trend="quadratic", transform="auto")
    assert optimizer.diagnostics["transform_log"] == 0.0 and regret < 1e-20
    restored = ContextualBO.from_state_dict(optimizer.state_dict())
    assert restored._transform == "none" and restored.model.alpha.tobytes() == optimizer.model.alpha.tobytes()


def _sphere(p: int, **options) -> tuple[ContextualBO, float]:
    """60 episodes on a contextual sphere whose optimum is affine in s; the recommendation's mean regret."""
    matrix = np.random.default_rng(0).uniform(-1, 1, (p, 1))
    optimizer = make_optimizer("c-bo", p, 1, 0, initial_mean=0.0, initial_cov=4.0, **options)
    rng, test = np.random.default_rng(1), np.linspace(0, 1, 9)[:, None]
    for _ in range(15):
        contexts = rng.uniform(0, 1, (4, 1))
        params = optimizer.ask(contexts)
        optimizer.tell(contexts, params, -((params - contexts @ matrix.T) ** 2).sum(axis=1))
    regret = ((optimizer.recommend(test) - test @ matrix.T) ** 2).sum(axis=1).mean()
    return optimizer, float(regret)


@pytest.mark.slow
def test_a_quadratic_trend_solves_a_contextual_sphere_to_rounding_and_restores_bit_for_bit():
    optimizer, regret = _sphere(2, trend="quadratic", transform="none")
    assert regret < 1e-20 and optimizer.model.beta is not None
    assert _sphere(2)[1] > 1e-6  # the constant prior mean alone, the default
    assert optimizer.stop() == {}  # the residuals are rounding: no "no_signal" stop of a solved task
    restored = ContextualBO.from_state_dict(optimizer.state_dict())
    assert restored.model.beta.tobytes() == optimizer.model.beta.tobytes()
    assert restored.config.trend == "quadratic"
    contexts = np.linspace(0, 1, 4)[:, None]
    assert restored.ask(contexts).tobytes() == optimizer.ask(contexts).tobytes()


def test_pure_noise_still_stops_with_a_trend():
    optimizer = make_optimizer("c-bo", 2, 1, 0, trend="quadratic")
    rng = np.random.default_rng(4)
    for _ in range(10):
        contexts = rng.uniform(0, 1, (6, 1))
        optimizer.tell(contexts, optimizer.ask(contexts), rng.standard_normal(6))
    assert optimizer.model.beta is not None and "no_signal" in optimizer.stop()


@pytest.mark.parametrize("trend", ["cubic", 2])
def test_an_unknown_trend_is_refused_naming_it(trend):
    with pytest.raises(ValueError, match="trend: expected one of \\('constant', 'quadratic'\\)"):
        make_optimizer("c-bo", 2, 1, 0, trend=trend)
