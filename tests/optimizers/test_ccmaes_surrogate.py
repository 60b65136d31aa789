"""Surrogate-assisted contextual CMA-ES (``c-cma-es-surrogate``): the model's maths, the τ safeguard and its
fallback to plain ``c-cma-es`` (a twin check), the episode count, the options, checkpoints and convergence."""

from __future__ import annotations

import numpy as np
import pytest

from creps_gym.optimizers import make_optimizer
from creps_gym.optimizers.base import load_state
from creps_gym.optimizers.ccmaes_surrogate import CCMAESSurrogate, next_model_generations
from creps_gym.optimizers.features import make_features
from creps_gym.optimizers.surrogate_model import (
    choose_kind,
    fit_model,
    kendall_tau,
    model_coefficients,
    richest_kind,
)

P, Z, N = 6, 1, 20


def _sphere(seed: int, p: int = P, z: int = Z):
    """A contextual sphere R = −‖θ + G s‖² (a full quadratic in (s, θ)) and its regret of a mean policy."""
    matrix = np.random.default_rng(100 + seed).normal(size=(p, z))

    def returns(contexts, params):
        return -((params + contexts @ matrix.T) ** 2).sum(axis=1)

    return returns


def _drive(optimizer, returns_of, iterations, seed=0, samples=N, z=Z):
    rng = np.random.default_rng(seed)
    for _ in range(iterations):
        contexts = rng.uniform(0, 3, (samples, z))
        params = optimizer.ask(contexts)
        optimizer.tell(contexts, params, returns_of(contexts, params))
    return rng


def test_the_full_quadratic_model_is_exact_on_a_contextual_sphere():
    rng = np.random.default_rng(0)
    returns_of = _sphere(0)
    contexts, params = rng.uniform(0, 3, (80, Z)), rng.normal(size=(80, P))
    mean_map = make_features("affine", Z)
    whitening = np.linalg.inv(np.linalg.cholesky(np.diag(rng.uniform(0.5, 2.0, P)))).T
    coefficients = rng.normal(size=(2, P))
    model = fit_model(
        "full", mean_map, coefficients, 0.3, whitening, (contexts, params, returns_of(contexts, params))
    )
    fresh_s, fresh_theta = rng.uniform(0, 3, (50, Z)), rng.normal(size=(50, P))
    truth = returns_of(fresh_s, fresh_theta)
    predicted = model.predict(mean_map, fresh_s, fresh_theta)
    np.testing.assert_allclose(predicted, truth, rtol=0, atol=1e-8)
    assert kendall_tau(predicted, truth) == 1.0
    linear = fit_model(
        "linear", mean_map, coefficients, 0.3, whitening, (contexts, params, returns_of(contexts, params))
    )
    assert np.abs(linear.predict(mean_map, fresh_s, fresh_theta) - truth).max() > 1.0  # not exact: no square


def test_in_the_optimiser_tau_is_one_once_the_model_is_a_full_quadratic():
    optimizer = make_optimizer("c-cma-es-surrogate", P, Z, 0, initial_mean=1.0)
    returns_of = _sphere(1)
    rng = np.random.default_rng(1)
    full = model_coefficients("full", P, Z)
    while optimizer.diagnostics.get("model_kind") != 3.0:
        _drive(optimizer, returns_of, 1, seed=int(rng.integers(1000)))
    assert optimizer.archive[2].size >= 1.2 * full
    contexts = rng.uniform(0, 3, (N, Z))
    params = optimizer.ask(contexts)
    predicted = optimizer.model.predict(optimizer.policy.mean_map, contexts, params)
    truth = returns_of(contexts, params)
    np.testing.assert_allclose(predicted, truth, rtol=0, atol=1e-8 * np.abs(truth).max())
    optimizer.tell(contexts, params, truth)
    assert optimizer.diagnostics["kendall_tau"] == pytest.approx(1.0, abs=1e-12)
    assert optimizer.diagnostics["planned_generations"] >= 1.0


def test_model_kind_grows_with_the_archive():
    p, z = 15, 1
    counts = [model_coefficients(kind, p, z) for kind in ("linear", "diagonal", "full")]
    assert counts == [17, 48, 153]
    assert [choose_kind(n, p, z, 1.0) for n in (16, 17, 47, 48, 152, 153)] == [
        "none",
        "linear",
        "linear",
        "diagonal",
        "diagonal",
        "full",
    ]


def test_models_beyond_600_coefficients_are_never_used():
    assert [richest_kind(p, 1) for p in (15, 32, 33, 64, 199, 200, 598, 599)] == [
        "full",
        "full",
        "diagonal",
        "diagonal",
        "diagonal",
        "linear",
        "linear",
        "none",
    ]
    assert choose_kind(10**6, 64, 1, 1.0) == "diagonal"
    config = CCMAESSurrogate(64, 1).config
    assert config.archive_size == 2 * model_coefficients("diagonal", 64, 1)


def test_tau_decides_the_number_of_model_generations():
    assert next_model_generations(None, 5, 10, 0.5) == 0
    assert next_model_generations(0.49, 5, 10, 0.5) == 0
    assert [next_model_generations(1.0, n, 10, 0.5) for n in (0, 1, 3, 7)] == [1, 3, 7, 10]
    assert next_model_generations(0.75, 9, 10, 0.5) == 5  # the target 10·(0.75 − 0.5)/0.5


def test_on_pure_noise_tau_falls_and_the_optimiser_is_plain_c_cma_es():
    """The fallback is a twin of ``c-cma-es`` on the same seed: bit-identical asks and distributions."""
    surrogate = make_optimizer("c-cma-es-surrogate", P, Z, 3, initial_mean=1.0)
    plain = make_optimizer("c-cma-es", P, Z, 3, initial_mean=1.0)
    noise = np.random.default_rng(7)
    rng = np.random.default_rng(5)
    taus = []
    for _ in range(40):
        contexts = rng.uniform(0, 3, (N, Z))
        asked = surrogate.ask(contexts)
        np.testing.assert_array_equal(asked, plain.ask(contexts))
        returns = noise.normal(size=N)
        surrogate.tell(contexts, asked, returns)
        plain.tell(contexts, asked, returns)
        taus.append(surrogate.diagnostics.get("kendall_tau", np.nan))
        assert surrogate.diagnostics["model_generations"] == 0.0
        assert surrogate.diagnostics["planned_generations"] == 0.0
    measured = np.asarray(taus)[np.isfinite(taus)]
    assert measured.size >= 30 and np.abs(measured).max() < 0.5
    np.testing.assert_array_equal(surrogate.policy.coefficients, plain.policy.coefficients)
    np.testing.assert_array_equal(surrogate.policy.cov, plain.policy.cov)
    assert surrogate.step_size == plain.step_size
    assert surrogate.model_generations_total == 0


@pytest.mark.slow
def test_model_generations_never_count_as_episodes():
    optimizer = make_optimizer("c-cma-es-surrogate", P, Z, 0, initial_mean=1.0)
    _drive(optimizer, _sphere(2), 40)
    assert optimizer.model_generations_total > 40  # the model drove most generations
    assert optimizer.evaluations == 40 * N
    assert optimizer.diagnostics["true_episodes"] == 40 * N
    assert optimizer.iteration == 40
    # The baseline's reuse held true batches from a distribution the model generations left: emptied (S6).
    assert optimizer.diagnostics["model_generations"] > 0 and optimizer.past_returns.size == 0


BAD_OPTIONS = [
    ("max_model_generations", -1, ValueError),
    ("max_model_generations", 2.5, TypeError),
    ("min_tau", 1.0, ValueError),  # [-1, 1): τ = 1 would never run a model generation
    ("min_tau", 2, ValueError),
    ("min_tau", -1.5, ValueError),
    ("min_tau", float("nan"), ValueError),
    ("archive_factor", 0.5, ValueError),
    ("model_margin", float("inf"), ValueError),
    ("model_margin", "2", TypeError),
]


@pytest.mark.parametrize(("option", "value", "error"), BAD_OPTIONS)
def test_bad_options_are_refused_naming_the_option(option, value, error):
    with pytest.raises(error, match=rf"^{option}: expected"):
        make_optimizer("c-cma-es-surrogate", P, Z, 0, **{option: value})


def test_a_rejected_tell_leaves_archive_model_and_distribution_unchanged():
    optimizer = make_optimizer("c-cma-es-surrogate", P, Z, 0, initial_mean=1.0)
    _drive(optimizer, _sphere(0), 12)
    before = optimizer.state_dict()
    contexts = np.full((N, Z), 1.0)
    params = optimizer.ask(contexts)
    pending = optimizer.state_dict()
    with pytest.raises(ValueError, match="returns"):
        optimizer.tell(contexts, params, np.full(N, np.nan))
    after = optimizer.state_dict()
    assert sorted(after) == sorted(pending)
    for key in before:
        if key not in ("rng",):
            np.testing.assert_array_equal(
                np.asarray(after[key], dtype=object), np.asarray(pending[key], dtype=object)
            )


@pytest.mark.slow
def test_a_checkpoint_resumes_bit_identically(tmp_path):
    returns_of = _sphere(4)
    first = make_optimizer("c-cma-es-surrogate", P, Z, 9, initial_mean=1.0)
    rng = _drive(first, returns_of, 15)
    assert first.model is not None and first.planned_generations > 0  # the archive, n̂ and model matter
    path = first.save(tmp_path / "state.npz")
    second = CCMAESSurrogate.load(path)
    assert load_state(path)["kind"] == "c-cma-es-surrogate"
    state = np.random.default_rng(rng.integers(1 << 30))
    for _ in range(10):
        contexts = state.uniform(0, 3, (N, Z))
        a, b = first.ask(contexts), second.ask(contexts)
        np.testing.assert_array_equal(a, b)
        first.tell(contexts, a, returns_of(contexts, a))
        second.tell(contexts, b, returns_of(contexts, b))
        assert first.diagnostics == second.diagnostics
    np.testing.assert_array_equal(first.policy.coefficients, second.policy.coefficients)
    for x, y in zip(first.archive, second.archive, strict=True):
        np.testing.assert_array_equal(x, y)


def test_a_checkpoint_with_too_large_an_archive_is_refused():
    optimizer = make_optimizer("c-cma-es-surrogate", P, Z, 0, initial_mean=1.0)
    _drive(optimizer, _sphere(0), 3)
    state = optimizer.state_dict()
    rows = optimizer.config.archive_size + 1
    state["archive_contexts"] = np.zeros((rows, Z))
    with pytest.raises(ValueError, match="archive_contexts"):
        CCMAESSurrogate.from_state_dict(state)


def _episodes_to_regret(name, seed, target=1e-5, p=10, z=1, samples=24):
    returns_of = _sphere(seed, p, z)
    optimizer = make_optimizer(name, p, z, seed, initial_mean=2.0)
    rng = np.random.default_rng(seed)
    test = rng.uniform(0, 3, (50, z))
    for _ in range(1000):
        contexts = rng.uniform(0, 3, (samples, z))
        params = optimizer.ask(contexts)
        optimizer.tell(contexts, params, returns_of(contexts, params))
        if -returns_of(test, optimizer.recommend(test)).mean() <= target:
            return optimizer.evaluations
    return None


@pytest.mark.slow
def test_convergence_on_the_contextual_sphere_in_fewer_true_episodes():
    """Golden numbers at seed 0 (p = 10, z = 1, N = 24), episodes to a mean regret of 1e-5: the surrogate
    needs 336 true episodes, plain c-cma-es 3,000."""
    plain = _episodes_to_regret("c-cma-es", 0)
    surrogate = _episodes_to_regret("c-cma-es-surrogate", 0)
    assert plain is not None and surrogate is not None
    assert surrogate < plain / 3
    assert (plain, surrogate) == (PLAIN_EPISODES, SURROGATE_EPISODES)


PLAIN_EPISODES, SURROGATE_EPISODES = 3000, 336
