"""Properties of the CREPS dual (Eqs. 8-9): weights form a distribution, KL = ε, invariances, stress."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from creps_gym.optimizers import CREPSCMA, BaselineFeatures, solve_dual
from creps_gym.optimizers.dual import DUAL_KL_TOL

BASELINE = BaselineFeatures(context_dim=2)


def kl_to_uniform(weights: np.ndarray) -> float:
    nonzero = weights[weights > 0]
    return float(np.log(weights.shape[0]) + nonzero @ np.log(nonzero))


batches = st.tuples(
    st.integers(min_value=8, max_value=120),  # N
    st.integers(min_value=0, max_value=2**32 - 1),  # seed
    st.floats(min_value=0.05, max_value=1.5),  # epsilon
    st.sampled_from(["gaussian", "heavy", "baseline", "ties"]),
    st.sampled_from(["box", "constant", "one-constant", "offset", "huge"]),
)


def make_contexts(rng, n, layout):
    """Context layouts that once broke the solver: constant, partly constant, far-offset and huge boxes."""
    contexts = rng.uniform(0, 3, (n, 2))
    if layout == "constant":
        return np.full((n, 2), 1.3)
    if layout == "one-constant":
        contexts[:, 1] = 1.3
    elif layout == "offset":
        contexts += 1e5
    elif layout == "huge":
        contexts *= 1e7
    return contexts


def make_batch(n, seed, kind, layout="box"):
    rng = np.random.default_rng(seed)
    contexts = make_contexts(rng, n, layout)
    if kind == "gaussian":
        returns = rng.normal(size=n)
    elif kind == "heavy":
        returns = -np.exp(rng.normal(scale=3.0, size=n))
    elif kind == "baseline":  # returns mostly explained by the context baseline
        scaled = (contexts - contexts.mean(axis=0)) / (np.ptp(contexts, axis=0) + 1.0)
        returns = -(scaled**2).sum(1) * 1e3 + 1e-3 * rng.normal(size=n)
    else:  # several samples tie for the best return
        returns = np.round(rng.normal(size=n), 1)
    return contexts, returns


@settings(max_examples=150, deadline=None)
@given(batches)
@pytest.mark.slow
def test_weights_form_a_distribution_and_kl_meets_the_bound(batch):
    n, seed, epsilon, kind, layout = batch
    epsilon = min(epsilon, 0.9 * np.log(n))
    contexts, returns = make_batch(n, seed, kind, layout)
    solution = solve_dual(returns, BASELINE(contexts), epsilon)
    assert (solution.weights >= 0).all()
    assert solution.weights.sum() == pytest.approx(1.0, abs=1e-12)
    kl = kl_to_uniform(solution.weights)
    assert kl == pytest.approx(solution.kl, abs=1e-9)
    assert kl <= epsilon + DUAL_KL_TOL
    if kind != "ties" and n >= 40:  # KL can reach ε: the constraint is active at the optimum
        assert kl == pytest.approx(epsilon, abs=DUAL_KL_TOL)


@settings(max_examples=80, deadline=None)
@given(batches, st.floats(min_value=-1e6, max_value=1e6), st.floats(min_value=1e-3, max_value=1e3))
@pytest.mark.slow
def test_weights_invariant_to_shift_and_positive_scale(batch, shift, scale):
    n, seed, epsilon, kind, layout = batch
    epsilon = min(epsilon, 0.9 * np.log(n))
    contexts, returns = make_batch(n, seed, kind, layout)
    base = solve_dual(returns, BASELINE(contexts), epsilon).weights
    moved = solve_dual(scale * returns + shift, BASELINE(contexts), epsilon).weights
    # Round-off limits how well shifted returns still carry their information: the part the baseline cannot
    # explain may sit ~1e-10 below their magnitude. Such ill-conditioned draws are skipped, not tolerated.
    phi = BASELINE(contexts)
    spread = phi.std(axis=0)
    design = np.column_stack([np.ones(n), (phi - phi.mean(axis=0)) / np.where(spread > 0, spread, 1.0)])
    unexplained = (returns - design @ np.linalg.lstsq(design, returns, rcond=None)[0]).std()
    assume(unexplained > 0 and (abs(shift) + scale * np.abs(returns).max()) / (scale * unexplained) < 1e7)
    np.testing.assert_allclose(moved, base, rtol=1e-5, atol=1e-8)


@pytest.mark.parametrize("exponent", [-12, -6, -3, 3, 6, 12])
def test_extreme_return_scales_neither_overflow_nor_underflow(exponent):
    contexts, returns = make_batch(50, 3, "gaussian")
    reference = solve_dual(returns, BASELINE(contexts), 0.5).weights
    scaled = solve_dual(returns * 10.0**exponent, BASELINE(contexts), 0.5)
    assert np.isfinite(scaled.weights).all()
    np.testing.assert_allclose(scaled.weights, reference, rtol=1e-6, atol=1e-10)


def test_weighted_baseline_features_match_the_batch_means():
    """Stationarity in w: the weighted mean of φ equals φ̂ (docs/algorithms.md, point 5)."""
    contexts, returns = make_batch(60, 11, "gaussian")
    phi = BASELINE(contexts)
    solution = solve_dual(returns, phi, 0.7)
    np.testing.assert_allclose(solution.weights @ phi, phi.mean(axis=0), atol=1e-8)


def test_adding_a_context_baseline_leaves_weights_unchanged():
    contexts, returns = make_batch(40, 5, "gaussian")
    phi = BASELINE(contexts)
    base = solve_dual(returns, phi, 0.5).weights
    shifted = solve_dual(returns + phi @ np.array([3.0, -2.0, 0.5, 7.0]), phi, 0.5).weights
    np.testing.assert_allclose(shifted, base, rtol=1e-6, atol=1e-10)


def test_degenerate_batches_give_uniform_weights():
    contexts = np.random.default_rng(0).uniform(0, 3, (30, 2))
    equal = solve_dual(np.full(30, -4.2), BASELINE(contexts), 0.5)
    np.testing.assert_array_equal(equal.weights, np.full(30, 1 / 30))
    explained = solve_dual(2.0 * contexts[:, 0] - contexts[:, 1] ** 2, BASELINE(contexts), 0.5)
    np.testing.assert_allclose(explained.weights, np.full(30, 1 / 30), atol=1e-12)
    assert explained.kl == 0.0


def test_ties_for_the_best_return_share_the_weight():
    returns = np.zeros(20)
    returns[:4] = 1.0  # KL of uniform-over-4 is log 5 ≈ 1.61 > ε is impossible: weights hit the floor
    solution = solve_dual(returns, np.zeros((20, 0)), 1.9)
    np.testing.assert_allclose(solution.weights[:4], 0.25, atol=1e-6)
    assert solution.kl <= 1.9 + DUAL_KL_TOL


@pytest.mark.slow
def test_kl_stays_on_the_bound_across_a_real_run():
    """Stress: every batch of a long CREPS-CMA run on a contextual sphere meets KL = ε tightly."""
    rng = np.random.default_rng(1)
    shift = rng.uniform(-1, 1, (6, 2))
    optimizer = CREPSCMA(6, 2, initial_mean=3.0, initial_cov=4.0, seed=2)
    gaps = []
    for _ in range(400):
        contexts = rng.uniform(0, 3, (30, 2))
        params = optimizer.ask(contexts)
        optimizer.tell(contexts, params, -((params + contexts @ shift.T) ** 2).sum(1))
        gaps.append(abs(optimizer.diagnostics["kl"] - 0.5))
    assert max(gaps) <= DUAL_KL_TOL


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        ({"epsilon": -1.0}, ValueError, r"epsilon: expected a finite value in \(0.0, 2.30"),
        ({"epsilon": 10.0}, ValueError, "epsilon: expected a finite value in"),
        ({"returns": np.r_[np.nan, np.arange(9.0)]}, ValueError, "returns: expected finite"),
        ({"baseline_features": np.zeros((9, 1))}, ValueError, r"baseline_features: expected shape \(10, n\)"),
        ({"eta0": 0.0}, ValueError, "eta0"),
        ({"max_iter": 0}, ValueError, "max_iter"),
    ],
)
def test_solve_dual_checks_its_arguments(kwargs, error, match):
    arguments = {"returns": np.arange(10.0), "baseline_features": np.zeros((10, 1)), "epsilon": 0.5, **kwargs}
    with pytest.raises(error, match=match):
        solve_dual(**arguments)
