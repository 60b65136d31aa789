"""Contextual Bayesian optimisation (c-bo): the GP's maths against closed forms, the acquisitions'
properties, convergence on a small contextual sphere, the distilled policy, options and restored states.

The protocol, determinism and checkpoint contracts are checked for every registered optimiser, c-bo
included, by the registry-driven tests (test_optimizers.py, test_optimizer_state.py, test_adapters.py,
test_policy.py)."""

from __future__ import annotations

import copy
import dataclasses
import functools
import math

import numpy as np
import pytest
from helpers import check_posterior_gradients

from creps_gym.optimizers import make_optimizer
from creps_gym.optimizers.acquisitions import gumbel_max_values, mes, ucb
from creps_gym.optimizers.cbo import ContextualBO
from creps_gym.optimizers.gp_model import (
    fit_gp,
    log_marginal_likelihood,
    matern52,
    mean_ranks,
    transformed_returns,
)

H = 1e-6


def _matern(r: float, signal: float) -> float:
    return signal * (1 + math.sqrt(5) * r + 5 * r * r / 3) * math.exp(-math.sqrt(5) * r)


def test_the_posterior_of_two_points_matches_the_closed_form():
    """μ = k*ᵀK⁻¹y and σ² = k** − k*ᵀK⁻¹k* with K = k(X, X) + σ_n²I, written out for two 1-D points."""
    inputs, targets = np.array([[0.1], [0.7]]), np.array([1.0, -0.5])
    lengthscale, signal, noise = 0.4, 1.5, 0.01
    model = fit_gp(inputs, targets, np.log([lengthscale, signal, noise]))
    x = 0.3
    k12 = _matern(0.6 / lengthscale, signal)
    gram = np.array([[signal + noise, k12], [k12, signal + noise]])
    cross = np.array(
        [_matern(abs(x - 0.1) / lengthscale, signal), _matern(abs(x - 0.7) / lengthscale, signal)]
    )
    inverse = np.array([[gram[1, 1], -gram[0, 1]], [-gram[1, 0], gram[0, 0]]]) / np.linalg.det(gram)
    mean, variance = model.predict(np.array([[x]]))
    np.testing.assert_allclose(mean[0], cross @ inverse @ targets, rtol=1e-8)
    np.testing.assert_allclose(variance[0], signal - cross @ inverse @ cross, rtol=1e-6)


def test_the_kernel_is_the_matern_52_with_ard_lengthscales():
    a, b = np.array([[0.0, 0.0]]), np.array([[0.3, -0.8]])
    lengthscales = np.array([0.5, 2.0])
    r = math.hypot(0.3 / 0.5, 0.8 / 2.0)
    np.testing.assert_allclose(matern52(a, b, lengthscales, 2.0)[0, 0], _matern(r, 2.0), rtol=1e-12)
    np.testing.assert_allclose(matern52(a, a, lengthscales, 2.0)[0, 0], 2.0, rtol=1e-12)


def _problem(n: int = 25, d: int = 3, seed: int = 0):
    rng = np.random.default_rng(seed)
    inputs = rng.uniform(size=(n, d))
    targets = np.sin(3 * inputs).sum(axis=1)
    return inputs, (targets - targets.mean()) / targets.std()


def test_the_likelihood_gradient_matches_finite_differences():
    inputs, targets = _problem()
    log_hyper = np.log([0.5, 0.3, 0.8, 1.2, 1e-3])
    _, gradient = log_marginal_likelihood(inputs, targets, log_hyper)
    steps = np.eye(log_hyper.shape[0]) * H
    numeric = [
        (
            log_marginal_likelihood(inputs, targets, log_hyper + e)[0]
            - log_marginal_likelihood(inputs, targets, log_hyper - e)[0]
        )
        / (2 * H)
        for e in steps
    ]
    np.testing.assert_allclose(gradient, numeric, rtol=1e-5, atol=1e-6)


def test_the_posterior_gradients_match_finite_differences_and_condition_equals_a_refit():
    inputs, targets = _problem()
    log_hyper = np.log([0.5, 0.3, 0.8, 1.2, 1e-3])
    model = fit_gp(inputs, targets, log_hyper)
    x = np.random.default_rng(1).uniform(size=(4, 3))
    check_posterior_gradients(model, x, H)
    grown = model.condition(x[0], 0.25)
    refit = fit_gp(np.vstack([inputs, x[:1]]), np.append(targets, 0.25), log_hyper)
    for a, b in zip(grown.predict(x), refit.predict(x), strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-12)


def test_the_triangular_solves_are_scipys_bit_for_bit():
    """The posterior's L⁻¹K(X, x) and L⁻ᵀ(...) call LAPACK ``trtrs`` directly; twin: ``solve_triangular``,
    for C- and Fortran-ordered factors, transposed right-hand sides (as the predictions pass them) and the
    strides of the result; a zero on L's diagonal raises ``LinAlgError``."""
    from scipy import linalg

    from creps_gym.optimizers import gp_model

    rng = np.random.default_rng(5)
    for n, m in [(1, 1), (2, 7), (30, 1), (45, 64)]:
        a = rng.standard_normal((n, n))
        chol = np.linalg.cholesky(a @ a.T + n * np.eye(n))
        rhs = rng.standard_normal((m, n)).T
        for factor in (chol, np.asfortranarray(chol)):
            for transposed in (False, True):
                direct = gp_model._solve_lower(factor, rhs, transposed)
                twin = linalg.solve_triangular(
                    factor, rhs, lower=True, trans="T" if transposed else "N", check_finite=False
                )
                assert np.array_equal(direct, twin) and direct.strides == twin.strides
    with pytest.raises(np.linalg.LinAlgError, match="chol: expected a nonsingular triangular factor"):
        gp_model._solve_lower(np.zeros((2, 2)), np.ones((2, 1)))


def test_the_posterior_interpolates_noise_free_data_and_reverts_to_the_prior_far_away():
    inputs, targets = _problem(n=10)
    model = fit_gp(inputs, targets, np.log([0.3, 0.3, 0.3, 1.0, 1e-6]))
    mean, variance = model.predict(inputs)
    np.testing.assert_allclose(mean, targets, atol=1e-4)
    assert variance.max() < 1e-4
    far_mean, far_variance = model.predict(np.full((1, 3), 50.0))
    assert abs(far_mean[0]) < 1e-9 and far_variance[0] == pytest.approx(1.0)


def test_ucb_and_mes_grow_with_the_mean_and_the_uncertainty_and_their_derivatives_are_exact():
    mean, variance = np.array([-1.0, 0.0, 0.5]), np.array([0.2, 0.5, 1.0])
    maxima = np.array([1.0, 1.5, 2.5])
    for name, function in (("ucb", lambda m, v: ucb(m, v, 4.0)), ("mes", lambda m, v: mes(m, v, maxima))):
        _, by_mean, by_variance = function(mean, variance)
        assert (by_mean > 0).all() and (by_variance > 0).all(), name
        numeric_mean = (function(mean + H, variance)[0] - function(mean - H, variance)[0]) / (2 * H)
        numeric_variance = (function(mean, variance + H)[0] - function(mean, variance - H)[0]) / (2 * H)
        np.testing.assert_allclose(by_mean, numeric_mean, rtol=1e-5)
        np.testing.assert_allclose(by_variance, numeric_variance, rtol=1e-5)
    assert (mes(mean, variance, maxima)[0] > 0).all()  # an entropy reduction
    np.testing.assert_allclose(ucb(mean, variance, 4.0)[0], mean + 2 * np.sqrt(variance))


def test_mes_of_a_point_far_below_the_maximum_is_stable_and_near_zero():
    value, by_mean, by_variance = mes(np.array([-40.0]), np.array([1e-4]), np.array([1.0]))
    assert np.isfinite([value, by_mean, by_variance]).all() and 0 <= value[0] < 1e-12


def test_sampled_maximum_values_are_at_least_the_best_mean_and_follow_its_spread():
    rng = np.random.default_rng(0)
    mean = np.linspace(-1.0, 1.0, 50)
    tight = gumbel_max_values(mean, np.full(50, 1e-10), 200, rng)
    assert tight.min() >= 1.0 and tight.max() < 1.0 + 1e-4
    wide = gumbel_max_values(mean, np.full(50, 0.25), 2000, rng)
    assert wide.min() >= 1.0 and 1.1 < np.median(wide) < 2.5


def test_the_log_transform_keeps_the_order_and_compresses_the_tail():
    returns = -np.array([0.0, 1.0, 2.0, 1e4])
    values = transformed_returns(returns, "log", "mean")
    assert (np.diff(values) < 0).all()
    assert values[2] - values[3] < 30 * (values[1] - values[2])  # not 9998 times the gap: about 23
    assert transformed_returns(returns, "none", "min").min() == 0.0


@pytest.mark.parametrize("distinct", [1, 2, 3, 7, 1000])
def test_mean_ranks_are_scipys_average_ranks_bit_for_bit(distinct):
    """The rank transform's ranks (ties share their mean rank) are ``scipy.stats.rankdata``'s."""
    from scipy.stats import rankdata

    rng = np.random.default_rng(distinct)
    for n in (1, 2, 9, 500):
        values = rng.integers(0, distinct, n) * 0.1 if distinct < 1000 else rng.standard_normal(n)
        assert np.array_equal(mean_ranks(values), rankdata(values))
    assert mean_ranks(np.array([3.0, -1.0, 3.0, 3.0])).tolist() == [3.0, 1.0, 3.0, 3.0]


def _sphere_regret(optimizer, matrix, contexts):
    return ((optimizer.recommend(contexts) + contexts @ matrix.T) ** 2).sum(axis=1).mean()


@pytest.mark.parametrize("acquisition", ["mes", "ucb"])
@pytest.mark.slow
def test_it_solves_a_contextual_sphere_with_two_parameters_in_100_episodes(acquisition):
    matrix = np.random.default_rng(0).uniform(-1, 1, (2, 1))
    optimizer = make_optimizer("c-bo", 2, 1, 0, initial_mean=2.0, initial_cov=4.0, acquisition=acquisition)
    rng, test = np.random.default_rng(1), np.linspace(0, 3, 20)[:, None]
    start = _sphere_regret(optimizer, matrix, test)
    for _ in range(25):
        contexts = rng.uniform(0, 3, (4, 1))
        params = optimizer.ask(contexts)
        optimizer.tell(contexts, params, -((params + contexts @ matrix.T) ** 2).sum(axis=1))
    assert optimizer.evaluations == 100 and _sphere_regret(optimizer, matrix, test) < 0.02 < start / 100


def _trained(p: int = 3, z: int = 1, batches: int = 5, **options) -> ContextualBO:
    optimizer = make_optimizer("c-bo", p, z, 4, **options)
    rng = np.random.default_rng(2)
    for _ in range(batches):
        contexts = rng.uniform(0, 1, (4, z))
        params = optimizer.ask(contexts)
        optimizer.tell(contexts, params, -((params - contexts.sum(1, keepdims=True)) ** 2).sum(1))
    return optimizer


@functools.cache
def _trained_state() -> dict:
    """``_trained()``'s state, computed once per test process (copy it before changing it)."""
    return _trained().state_dict()


@pytest.mark.slow
def test_recommend_is_deterministic_stays_in_the_box_and_ignores_the_batch():
    optimizer = _trained()
    contexts = np.linspace(0, 1, 5)[:, None]
    before = optimizer.state_dict()["rng"]
    batch = optimizer.recommend(contexts)
    assert batch.tobytes() == optimizer.recommend(contexts).tobytes()
    assert batch[2].tobytes() == optimizer.recommend(contexts[2:3])[0].tobytes()
    low, high = optimizer.config.param_box
    assert (batch >= low).all() and (batch <= high).all() and optimizer.state_dict()["rng"] == before


def _climbed_halfway(**options) -> ContextualBO:
    """Nine episodes that climbed R = −|θ − 0.5| from θ = 0.1 to its peak 0.5 and never went past it
    (the log transform's scale at the median gap, ``log_quantile=0.5``, under which the GP fitted to the
    climb extrapolates past it; the default's smaller scale fits a flatter slope that stops short of the
    face, and the trust region is still what keeps the recommendation at the peak)."""
    optimizer = make_optimizer(
        "c-bo",
        1,
        1,
        0,
        param_low=0.0,
        param_high=1.0,
        context_low=0.0,
        context_high=1.0,
        **{"log_quantile": 0.5, **options},
    )
    theta = np.linspace(0.1, 0.5, 9)[:, None]
    contexts = np.random.default_rng(0).uniform(size=(9, 1))
    optimizer.tell(contexts, theta, -np.abs(theta[:, 0] - 0.5), allow_external=True)
    return optimizer


def test_recommend_stays_where_the_good_episodes_are_instead_of_extrapolating_to_a_face():
    """Issue 44's late blow-ups: the posterior mean fitted to a climb keeps rising past the data (here to
    μ(1) far above μ(0.5), the best told θ), so its maximiser over the whole box is the face θ = 1, 0.5 from
    every episode, with the true return −0.5; within the trust region of Eq. (R1) (by default the best third
    of the episodes, ⌈9/3⌉ = 3: θ = 0.4, 0.45, 0.5) it is the peak."""
    contexts = np.array([[0.2], [0.5], [0.8]])
    old = _climbed_halfway(trust_share=None)
    mean = old.model.predict(np.array([[0.5, 0.5], [0.5, 1.0]]))[0]
    assert mean[1] > mean[0] + 1.0  # the extrapolation
    np.testing.assert_array_equal(old.recommend(contexts), 1.0)
    new = _climbed_halfway()
    good, (low, high) = new.trust_region(np.array([0.5]))
    np.testing.assert_allclose(np.sort(good[:, 0]), [0.4, 0.45, 0.5])
    np.testing.assert_allclose([low, high], [[0.4], [0.5]])
    np.testing.assert_allclose(new.recommend(contexts), 0.5, atol=1e-9)


def test_recommend_over_observed_returns_the_told_theta_with_the_best_posterior_mean_at_each_context():
    """Eq. (R2): each recommended row is one of the told θ, bit for bit, and no told θ has a larger
    posterior mean at that context; the rule changes nothing else (the same state, the same asks), and a
    checkpoint keeps it."""
    default, observed = _trained(), _trained(recommend_over="observed")
    state, other = default.state_dict(), observed.state_dict()
    assert other["config"]["recommend_over"] == "observed"
    for key in ("data_contexts", "data_params", "data_returns", "log_hyper"):
        np.testing.assert_array_equal(state[key], other[key])
    contexts = np.linspace(0, 1, 5)[:, None]
    chosen = observed.recommend(contexts)
    told = np.clip(observed._scaled_params(observed.params), 0.0, 1.0)
    for context, row in zip(observed._scaled_contexts(contexts), chosen, strict=True):
        index = np.flatnonzero((observed.params == row).all(axis=1))
        assert index.size >= 1  # a told θ itself
        mean = observed.model.predict(np.hstack([np.tile(context, (told.shape[0], 1)), told]))[0]
        assert mean[index[0]] == mean.max()
    assert chosen[3].tobytes() == observed.recommend(contexts[3:4])[0].tobytes()  # alone or in a batch
    restored = ContextualBO.from_state_dict(copy.deepcopy(other))
    assert restored.recommend(contexts).tobytes() == chosen.tobytes()
    assert not np.array_equal(default.recommend(contexts), chosen)  # R1 interpolates between them


def test_recommend_over_neighbours_returns_the_best_told_theta_of_the_nearest_contexts():
    """Eq. (R3): with k = candidates // 4 = 4 of the 20 episodes, each recommended row is the told θ of one
    of the 4 episodes whose contexts are nearest, and none of the 4 has a larger posterior mean at s; with
    k ≥ 20 (the default 64) N(s) holds every episode and R3 is R2 bit for bit."""
    optimizer = _trained(recommend_over="neighbours", candidates=16)
    contexts = np.linspace(0, 1, 5)[:, None]
    chosen = optimizer.recommend(contexts)
    told = np.clip(optimizer._scaled_params(optimizer.params), 0.0, 1.0)
    for context, row in zip(optimizer._scaled_contexts(contexts), chosen, strict=True):
        nearest = np.argsort(((optimizer._scaled_contexts(optimizer.contexts) - context) ** 2).sum(1))[:4]
        index = [i for i in nearest if np.array_equal(optimizer.params[i], row)]
        assert index  # a told θ of N(s)
        mean = optimizer.model.predict(np.hstack([np.tile(context, (4, 1)), told[nearest]]))[0]
        assert mean[list(nearest).index(index[0])] == mean.max()
    assert (
        optimizer.state_dict()["rng"]
        == _trained(recommend_over="neighbours", candidates=16).state_dict()["rng"]
    )
    restored = ContextualBO.from_state_dict(copy.deepcopy(optimizer.state_dict()))
    assert restored.config.recommend_over == "neighbours"
    assert restored.recommend(contexts).tobytes() == chosen.tobytes()
    everyone = dataclasses.replace(optimizer.config, recommend_over="observed")
    optimizer.config = everyone
    assert not np.array_equal(optimizer.recommend(contexts), chosen)  # R2 reaches farther contexts' θ
    default_k = _trained(recommend_over="neighbours")
    observed = _trained(recommend_over="observed")
    assert default_k.recommend(contexts).tobytes() == observed.recommend(contexts).tobytes()


@pytest.mark.slow
@pytest.mark.parametrize(("share", "count"), [(1.0 / 3.0, 7), (0.5, 10)])
def test_recommend_lies_in_the_box_of_the_best_episodes_near_each_context(share, count):
    """Eq. (R1): θ̂(s) within the box of G(s), the best ⌈qk⌉ of the k = 64 episodes with the nearest
    contexts (all 20 here: the best 7 at q = 1/3, 10 at q = 1/2), and no worse by the posterior mean than
    every θ of G(s) at s."""
    optimizer = _trained(trust_share=share)
    contexts = np.linspace(0, 1, 5)[:, None]
    units = optimizer._scaled_params(optimizer.recommend(contexts))
    order = np.argsort(-optimizer.returns, kind="stable")[:count]
    best = np.clip(optimizer._scaled_params(optimizer.params[order]), 0.0, 1.0)
    for context, unit in zip(optimizer._scaled_contexts(contexts), units, strict=True):
        good, (low, high) = optimizer.trust_region(context)
        np.testing.assert_array_equal(good, best)
        np.testing.assert_array_equal([low, high], [best.min(axis=0), best.max(axis=0)])
        assert (unit >= low).all() and (unit <= high).all()
        inputs = np.hstack([np.tile(context, (count + 1, 1)), np.vstack([unit, good])])
        mean = optimizer.model.predict(inputs)[0]
        assert mean[0] >= mean[1:].max()


def _believer_spread(optimizer: ContextualBO, n: int) -> np.ndarray:
    """σ at each row of a batch of n asked at one context, under the model conditioned on the rows before
    it with their posterior means (the kriging believer's fantasies): shape (n,)."""
    contexts = np.full((n, 1), 0.5)
    inputs, model, spread = optimizer._inputs(contexts, optimizer.ask(contexts)), optimizer.model, []
    for row in inputs:
        mean, variance = model.predict(row[None, :])
        spread.append(math.sqrt(variance[0]))
        model = model.condition(row, float(mean[0]))
    return np.array(spread)


@pytest.mark.slow
@pytest.mark.parametrize("log_quantile", [0.25, 0.5])
def test_a_batch_at_one_context_spreads_where_the_believer_is_unsure(log_quantile):
    """Eq. (A4): MES's maxima stay five noise deviations above the inputs the model holds at the asked
    context (here the batch's fantasies), so each later row of a batch of 6 at one context goes where σ
    given the earlier rows is at least 3 σ_n (σ_n = 1e-3 on this toy, a sphere after 20 episodes). Under
    the former floor (``mes_floor="candidates"``) the sampled maxima fall below the first row's fantasy and
    at least four of the five later rows return to the rows before them: σ there is the noise's."""
    optimizer = _trained(log_quantile=log_quantile)
    noise = math.sqrt(optimizer.model.noise)
    assert noise == pytest.approx(1e-3) and (_believer_spread(optimizer, 6)[1:] > 3.0 * noise).all()
    former = _trained(log_quantile=log_quantile, mes_floor="candidates")
    assert (np.sort(_believer_spread(former, 6)[1:])[:4] < 1.1 * noise).all()


def test_the_distilled_policy_fits_the_maximisers_on_the_grid_and_reports_its_error():
    optimizer = _trained(z=2, distillation_points=3)
    policy = optimizer.mean_policy()
    grid = optimizer.distillation_contexts()
    assert grid.shape == (9, 2)
    residual = policy(grid, extrapolate=True) - optimizer.recommend(grid)
    np.testing.assert_allclose(optimizer.diagnostics["distillation_rmse"], np.sqrt(np.mean(residual**2)))
    np.testing.assert_allclose(optimizer.diagnostics["distillation_max_error"], np.abs(residual).max())
    features = optimizer.config.mean_map(grid)  # least squares: the residual is orthogonal to the features
    np.testing.assert_allclose(features.T @ residual, 0.0, atol=1e-8)


def test_the_first_asks_draw_the_initial_design_inside_the_box():
    optimizer = make_optimizer("c-bo", 2, 1, 0, initial_mean=[1.0, -1.0], initial_cov=0.25, initial_samples=6)
    params = optimizer.ask(np.zeros((6, 1)))
    assert (params >= [-0.5, -2.5]).all() and (params <= [2.5, 0.5]).all()
    np.testing.assert_array_equal(optimizer.recommend(np.zeros((2, 1))), [[1.0, -1.0]] * 2)


@pytest.mark.parametrize(
    ("options", "error", "match"),
    [
        ({"acquisition": "ei"}, ValueError, r"acquisition: expected one of \('ucb', 'mes'\), got 'ei'"),
        ({"transform": "sqrt"}, ValueError, "transform: expected one of"),
        ({"prior_mean": 0.0}, ValueError, "prior_mean: expected one of"),
        ({"beta": -1.0}, ValueError, "beta: expected a finite value"),
        ({"refit_growth": 1.0}, ValueError, "refit_growth: expected a finite value in \\(1.0"),
        ({"initial_samples": 1}, ValueError, "initial_samples: expected an integer >= 2"),
        ({"param_low": -1.0}, ValueError, "param_low, param_high: expected both or neither"),
        ({"param_low": 1.0, "param_high": 1.0}, ValueError, "expected low < high"),
        ({"context_low": [0.0], "context_high": [1.0, 2.0]}, ValueError, "context_high: expected shape"),
        ({"starts": 0}, ValueError, "starts: expected an integer >= 1"),
        ({"kappa": 1.0}, TypeError, "options: expected names in .* got unknown \\['kappa'\\]"),
        ({"candidates": 10**9}, ValueError, "candidates: expected an integer of at most 100000"),
        ({"distillation_points": 20_000}, ValueError, "distillation_points: expected an integer of at most"),
        ({"trust_share": 0.0}, ValueError, r"trust_share: expected a finite value in \(0.0, 1.0\], got 0.0"),
        ({"trust_share": "all"}, TypeError, "trust_share: expected a real number"),
        (
            {"recommend_over": "best"},
            ValueError,
            r"recommend_over: expected one of \('trust_region', 'observed', 'neighbours'\), got 'best'",
        ),
    ],
)
def test_bad_options_are_refused_naming_them(options, error, match):
    with pytest.raises(error, match=match):
        make_optimizer("c-bo", 2, 1, 0, **options)


@pytest.mark.parametrize(
    ("key", "value", "match"),
    [
        ("log_hyper", np.full(6, 50.0), r"state\['log_hyper'\]: expected values within"),
        ("log_hyper", np.zeros(3), r"state\['log_hyper'\]: expected shape"),
        ("fitted_at", 10_000, r"state\['fitted_at'\]: expected at most the 20 stored episodes"),
        ("data_params", np.zeros((19, 3)), r"state\['data_params'\]: expected shape \(20, 3\)"),
        ("scale_high", np.array([-5.0]), r"state\['scale_low'\], state\['scale_high'\]: expected low < high"),
        ("data_returns", np.full(20, np.nan), r"state\['data_returns'\]"),
    ],
)
def test_a_tampered_state_is_refused_naming_the_key(key, value, match):
    state = copy.deepcopy(_trained_state())
    state[key] = value
    with pytest.raises((ValueError, TypeError), match=match):
        ContextualBO.from_state_dict(state)


@pytest.mark.parametrize(
    ("option", "value", "match"),
    [
        ("trend", "cubic", r"trend: expected one of \('constant', 'quadratic'\), got 'cubic'"),
        ("transform", ["auto"], r"transform: expected one of .*'auto'\), got \['auto'\]"),
        ("recommend_over", None, r"recommend_over: expected one of .*, got None"),
    ],
)
def test_a_checkpoints_config_with_an_unknown_trend_or_transform_is_refused(option, value, match):
    """The options of c-bo's quadratic prior mean (Eq. G4, G5) and of its recommendation (R1, R2) come
    from an untrusted checkpoint too."""
    state = copy.deepcopy(_trained_state())
    state["config"] = {**state["config"], option: value}
    with pytest.raises(ValueError, match=match):
        ContextualBO.from_state_dict(state)


@pytest.mark.slow
def test_a_restored_optimizer_rebuilds_the_same_gp_bit_for_bit():
    optimizer = _trained(context_low=[0.0], context_high=[1.0], param_low=-2.0, param_high=3.0)
    restored = ContextualBO.from_state_dict(optimizer.state_dict())
    assert restored.model.chol.tobytes() == optimizer.model.chol.tobytes()
    assert restored.config.param_box[1].tolist() == [3.0] * 3
    contexts = np.linspace(0, 1, 4)[:, None]
    assert restored.ask(contexts).tobytes() == optimizer.ask(contexts).tobytes()


@pytest.mark.slow
def test_no_signal_and_flat_returns_stop_it():
    """Noise: four (s, θ) told 15 times each with standard normal returns, so the GP must call the
    differences at one input noise (its share ≥ 0.95 on each of seeds 0–11; at 100 episodes asked by MES
    on fresh contexts, it was on only 6 to 9 of 16)."""
    optimizer = make_optimizer("c-bo", 2, 1, 0)
    rng = np.random.default_rng(0)
    contexts, params = rng.uniform(0, 3, (4, 1)), rng.uniform(-3, 3, (4, 2))
    for _ in range(15):
        optimizer.tell(contexts, params, rng.standard_normal(4), allow_external=True)
    assert optimizer.stop()["no_signal"] >= 0.95
    flat = make_optimizer("c-bo", 2, 1, 0)
    for _ in range(3):
        contexts = rng.uniform(0, 3, (20, 1))
        flat.tell(contexts, flat.ask(contexts), np.ones(20))
    assert flat.stop() == {"tolflatfitness": 60}


def test_returns_near_the_float_limit_give_finite_asks_and_restore(tmp_path):
    optimizer = make_optimizer("c-bo", 2, 1, 0, transform="none")
    contexts = np.linspace(0, 1, 12)[:, None]
    optimizer.tell(contexts, optimizer.ask(contexts), 1.5e308 - np.arange(12) * 1e295)
    restored = type(optimizer).load(optimizer.save(tmp_path / "ckpt.npz"))
    assert np.isfinite(restored.ask(contexts[:3])).all()
    assert restored.model.chol.tobytes() == optimizer.model.chol.tobytes()


@pytest.mark.slow
def test_a_checkpoint_whose_data_would_not_fit_in_memory_is_refused_before_the_gp_is_built():
    state = _trained().state_dict()
    n = 2_000_000  # the kernel matrices would need n² x (p + z + 6) x 8 bytes: about 3e14
    state.update(data_contexts=np.zeros((n, 1)), data_params=np.zeros((n, 3)), data_returns=np.zeros(n))
    with pytest.raises(
        ValueError, match=r"state\['data_returns'\]: expected a size whose arrays fit in memory"
    ):
        ContextualBO.from_state_dict(state)


def test_many_context_dimensions_distil_on_a_bounded_design():
    optimizer = make_optimizer("c-bo", 2, 16, 0, context_low=0.0, context_high=1.0)
    assert optimizer.distillation_contexts().shape == (1000, 16)


def test_a_distillation_grid_beyond_its_bound_is_refused():
    with pytest.raises(
        ValueError, match=r"distillation_points: expected a grid of at most 10000 .* got 30 \*\* 3"
    ):
        make_optimizer("c-bo", 2, 3, 0, distillation_points=30)


@pytest.mark.slow
def test_without_context_dimensions_it_is_plain_bayesian_optimisation():
    optimizer = make_optimizer("c-bo", 2, 0, 0, initial_cov=4.0)
    for _ in range(10):
        contexts = np.zeros((4, 0))
        params = optimizer.ask(contexts)
        optimizer.tell(contexts, params, -((params - 1.0) ** 2).sum(axis=1))
    best = optimizer.recommend(np.zeros((1, 0)))[0]
    assert np.abs(best - 1.0).max() < 0.05
    policy = optimizer.mean_policy()
    assert policy(np.zeros((1, 0))).tobytes() == optimizer.recommend(np.zeros((1, 0))).tobytes()
    assert optimizer.diagnostics["distillation_rmse"] == 0.0
