"""The surrogate's check of its model generations on the next true batch (S7): a model that led the search
where every sample is worse is undone, its cap halves, and the cell that diverged (issue 45: GECCO 2019's
Different Powers with ``standardise_advantages=True``) no longer does; checkpoints keep the rollback."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.contextual_bbo.problems import GENERATION, N_PARAMS, PROBLEMS, draw_run
from creps_gym.optimizers import make_optimizer
from creps_gym.optimizers.ccmaes_surrogate import CCMAESSurrogate

P, Z, N = 6, 1, 20
#: The cell of issue 45 that diverged to −2e+55 before S7 (both runs tried).
DIVERGED = {"restarts": 0, "ridge": 1e-14, "baseline_ridge": 1e-16, "standardise_advantages": True}


def _sphere(contexts, params):
    return -((params + 0.5 * contexts) ** 2).sum(axis=1)


def _until_model_generations(seed: int = 0) -> tuple[CCMAESSurrogate, np.random.Generator]:
    """A surrogate on a contextual sphere, told batches until model generations have just run."""
    optimizer = make_optimizer("c-cma-es-surrogate", P, Z, seed, initial_mean=1.0)
    rng = np.random.default_rng(seed)
    for _ in range(60):
        contexts = rng.uniform(0, 3, (N, Z))
        params = optimizer.ask(contexts)
        optimizer.tell(contexts, params, _sphere(contexts, params))
        if optimizer.rollback is not None:
            return optimizer, rng
    raise AssertionError("no model generation ran")


@pytest.mark.slow
def test_the_diverging_cell_of_issue_45_now_converges():
    """Before S7 this run's batch mean return was −1.3e+28 after 60 generations (σ ≈ 8e+10) and −1e+51 when
    tolupsigma stopped it; with S7 the model generations that made it worse are undone and it converges."""
    problem = PROBLEMS["DifferentPowers"]
    draw = draw_run(problem, seed=0)
    optimizer = make_optimizer(
        "c-cma-es-surrogate", N_PARAMS, 1, draw.optimizer_seed, initial_mean=draw.initial_mean, **DIVERGED
    )
    means = []
    for _ in range(60):
        contexts = draw.contexts(GENERATION)
        params = optimizer.ask(contexts)
        returns = -draw.evaluate(contexts, params)
        optimizer.tell(contexts, params, returns)
        means.append(float(returns.mean()))
    assert optimizer.model_rejections >= 1
    assert max(means[-5:]) > -0.1 and optimizer.step_size < 0.5, (means[-5:], optimizer.step_size)
    assert min(means) > -100.0  # the worst batch is the one that was rejected


def test_a_batch_worse_than_the_one_before_the_model_generations_undoes_them():
    optimizer, rng = _until_model_generations()
    rollback, cap = optimizer.rollback, optimizer.model_cap
    archived, iteration = optimizer.archive[2].size, optimizer.iteration
    contexts = rng.uniform(0, 3, (N, Z))
    params = optimizer.ask(contexts)
    worse = np.full(
        N, rollback.floor - 1.0
    )  # every return below the smallest one before the model generations
    optimizer.tell(contexts, params, worse)
    np.testing.assert_array_equal(optimizer.policy.coefficients, rollback.policy.coefficients)
    np.testing.assert_array_equal(optimizer.policy.cov, rollback.policy.cov)
    assert optimizer.step_size == rollback.policy.step_size
    np.testing.assert_array_equal(optimizer.path_sigma, rollback.path_sigma)
    assert optimizer.rollback is None and optimizer.planned_generations == 0
    assert optimizer.model_cap == cap // 2 and optimizer.model_rejections == 1  # cap: 10 -> 5
    assert optimizer.diagnostics["model_rejections"] == 1.0
    assert optimizer.archive[2].size == min(archived + N, optimizer.config.archive_size)
    assert optimizer.iteration == iteration + 1 and optimizer.evaluations == (iteration + 1) * N


def test_a_batch_as_good_as_the_one_before_is_an_ordinary_true_generation():
    optimizer, rng = _until_model_generations()
    contexts = rng.uniform(0, 3, (N, Z))
    params = optimizer.ask(contexts)
    optimizer.tell(contexts, params, np.full(N, optimizer.rollback.floor))  # the median is not below it
    assert optimizer.model_rejections == 0 and optimizer.model_cap == optimizer.config.max_model_generations


def test_a_batch_better_than_the_one_before_the_model_generations_doubles_the_cap_again():
    optimizer, rng = _until_model_generations()
    optimizer.model_cap = 2  # as after two rejections
    contexts = rng.uniform(0, 3, (N, Z))
    params = optimizer.ask(contexts)
    optimizer.tell(contexts, params, np.full(N, optimizer.rollback.median))  # as good as the batch before
    assert optimizer.model_rejections == 0 and optimizer.model_cap == 5


def test_a_checkpoint_keeps_the_rollback_and_resumes_bit_identically(tmp_path):
    first, rng = _until_model_generations(seed=3)
    second = CCMAESSurrogate.load(first.save(tmp_path / "s.npz"))
    assert second.rollback is not None and second.rollback.floor == first.rollback.floor
    for step in range(6):
        contexts = rng.uniform(0, 3, (N, Z))
        a, b = first.ask(contexts), second.ask(contexts)
        np.testing.assert_array_equal(a, b)
        returns = _sphere(contexts, a) - (1e3 if step == 0 else 0.0)  # the first batch is rejected
        first.tell(contexts, a, returns)
        second.tell(contexts, b, returns)
        assert first.diagnostics == second.diagnostics
    assert first.model_rejections == second.model_rejections == 1 and first.model_cap == second.model_cap
    np.testing.assert_array_equal(first.policy.coefficients, second.policy.coefficients)


def test_a_checkpoint_from_before_the_check_loads_with_no_rollback_and_the_full_cap():
    optimizer, rng = _until_model_generations()
    state = optimizer.state_dict()
    for key in [k for k in state if k.startswith("rollback_")] + ["model_rejections", "model_cap"]:
        del state[key]
    restored = CCMAESSurrogate.from_state_dict(state)
    assert restored.rollback is None and restored.model_rejections == 0
    assert restored.model_cap == restored.config.max_model_generations
    contexts = rng.uniform(0, 3, (N, Z))
    params = restored.ask(contexts)
    restored.tell(contexts, params, _sphere(contexts, params))  # no rollback: an ordinary true generation
    assert restored.model_rejections == 0


@pytest.mark.parametrize(
    ("key", "value", "error", "match"),
    [
        ("rollback_cov", -np.eye(P), ValueError, r"state\['rollback_cov'\]: expected a positive-definite"),
        ("rollback_coefficients", np.zeros((3, P)), ValueError, r"state\['rollback_coefficients'\]"),
        ("rollback_path_sigma", np.full((P, 1), np.nan), ValueError, r"state\['rollback_path_sigma'\]"),
        ("rollback_floor", np.zeros(2), ValueError, r"state\['rollback_floor'\]"),
        ("rollback_path_cov", None, ValueError, "expected the key 'rollback_path_cov'"),
        ("rollback_median", None, ValueError, "expected the key 'rollback_median'"),
        ("rollback_median", np.array([np.inf]), ValueError, r"state\['rollback_median'\]"),
        ("model_cap", 11, ValueError, r"state\['model_cap'\]: expected an integer <= 10, got 11"),
        ("model_cap", 2.5, TypeError, r"state\['model_cap'\]"),
    ],
)
def test_a_bad_rollback_in_a_checkpoint_is_refused_naming_the_key(key, value, error, match):
    optimizer, _ = _until_model_generations()
    state = optimizer.state_dict()
    if value is None:
        del state[key]
    else:
        state[key] = value
    with pytest.raises(error, match=match):
        CCMAESSurrogate.from_state_dict(state)


def test_the_median_is_numpys_bit_for_bit_and_finite_near_the_float_limit():
    from creps_gym.optimizers.cma_rules import median

    rng = np.random.default_rng(7)
    for n in (1, 2, 7, 50, 51):
        values = rng.standard_normal(n) * 10.0 ** rng.integers(-20, 20)
        assert median(values) == float(np.median(values))
    huge = np.array([1.7e308, 1.6e308, -1.0, 1.65e308])
    assert median(huge) == pytest.approx(1.625e308, rel=1e-12)  # np.median overflows to inf here
