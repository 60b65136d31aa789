"""The low-budget study's library columns (``benchmarks/low_budget/library_gp.py``): c-bo on BoTorch's and on
scikit-learn's GP pass the same tests, each skipped where its library is not installed (no extra of
creps_gym installs them); then what is each library's own."""

from __future__ import annotations

import importlib
from importlib.util import find_spec
from typing import Any

import numpy as np
import pytest
from helpers import EXTRAS

from benchmarks.low_budget import columns, study

pytestmark = EXTRAS


def _needs(*modules: str) -> Any:
    """Skipped without ``modules``: found, not imported (torch takes about 2 s to import, which every test
    process would pay at collection)."""
    missing = [module for module in modules if find_spec(module) is None]
    return pytest.mark.skipif(bool(missing), reason=f"needs {', '.join(modules)}")


BOTORCH, SKLEARN = _needs("torch", "botorch"), _needs("sklearn")
#: The study's columns on a library's GP. BoTorch's is slow (torch takes about 2 s to import, and its asks
#: cost ten times c-bo's), so ``-m "not slow"`` leaves it out.
COLUMNS = [
    pytest.param("c-bo-botorch", marks=[BOTORCH, pytest.mark.slow]),
    pytest.param("c-bo-sklearn", marks=SKLEARN),
]


def _class(column: str) -> type:
    module, name = columns.method_by_name(column).factory.split(":")
    return getattr(importlib.import_module(module), name)


def _optimum(contexts: np.ndarray) -> np.ndarray:
    return np.hstack([contexts, -contexts])  # θ*(s) = (s, −s)


def returns(contexts: np.ndarray, params: np.ndarray) -> np.ndarray:
    return -((params - _optimum(contexts)) ** 2).sum(axis=1)


def driven(cls: type, batches: int = 6, seed: int = 0, **options: Any) -> Any:
    """p = 2, z = 1, batches of 4 on a contextual sphere (contexts from their own stream); UCB unless
    ``acquisition`` says otherwise (BoTorch's MES costs about ten times as much per ask)."""
    options = {"acquisition": "ucb", **options}
    optimizer = cls(2, 1, seed=seed, initial_cov=0.25, **options)
    rng = np.random.default_rng(7)
    for _ in range(batches):
        contexts = rng.uniform(-0.5, 0.5, size=(4, 1))
        params = optimizer.ask(contexts)
        optimizer.tell(contexts, params, returns(contexts, params))
    return optimizer


@pytest.fixture(scope="module", params=COLUMNS)
def column(request: pytest.FixtureRequest) -> str:
    return request.param


@pytest.fixture(scope="module")
def run(column: str) -> Any:
    return driven(_class(column))


def test_same_seed_same_run(run: Any) -> None:
    again = driven(type(run), batches=3)  # the first three batches of the fixture's run, bit for bit
    assert np.array_equal(again.params, run.params[:12]) and np.array_equal(again.returns, run.returns[:12])
    other = driven(type(run), batches=3, seed=1)
    assert not np.array_equal(other.params[8:], run.params[8:12])  # the model's asks follow the seed


def test_a_checkpoint_restores_the_same_next_ask_and_recommendation(run: Any) -> None:
    state = run.state_dict()
    restored = type(run).from_state_dict(state)
    contexts, test = np.array([[0.1], [-0.3]]), np.array([[0.2], [-0.4]])
    assert np.array_equal(restored.recommend(test), run.recommend(test))
    copy = type(run).from_state_dict(state)  # asking changes the Generator: compare two restored copies
    assert np.array_equal(restored.ask(contexts), copy.ask(contexts))
    assert restored.config.to_json() == run.config.to_json()


def test_a_forged_checkpoint_is_rejected_naming_the_field(run: Any) -> None:
    state, cls = run.state_dict(), type(run)
    with pytest.raises(ValueError, match="hyper_names"):
        cls.from_state_dict({**state, "hyper_names": state["hyper_names"][::-1]})
    with pytest.raises(ValueError, match=r"state\['hyper'\]"):
        cls.from_state_dict({**state, "hyper": np.full_like(state["hyper"], np.nan)})
    with pytest.raises(TypeError, match=r"state\['hyper_names'\]"):
        cls.from_state_dict({**state, "hyper_names": state["hyper_names"][0]})


def test_the_recommendation_beats_the_start_and_holds_the_posterior_means_best(run: Any) -> None:
    test = np.linspace(-0.5, 0.5, 5)[:, None]
    chosen = run.recommend(test)
    start = np.tile(run.config.initial_mean, (5, 1))
    # Measured: 0.032 (BoTorch) and 0.036 (scikit-learn) against the start's 0.25.
    assert -returns(test, chosen).mean() < 0.5 * -returns(test, start).mean()
    assert np.array_equal(run.recommend(test[2:3]), chosen[2:3])  # alone as in a batch
    for context, theta in zip(run._scaled_contexts(test), run._scaled_params(chosen), strict=True):
        good = run.trust_region(context)[0]
        means = run.model.predict(np.hstack([np.tile(context, (len(good) + 1, 1)), [theta, *good]]))[0]
        assert means[0] >= means[1:].max()  # R1 never ends below G(s)'s best θ


@pytest.mark.parametrize("rule", ["observed", "neighbours"])
def test_the_told_parameter_rules_return_told_parameters(column: str, rule: str) -> None:
    """R2 returns told θ; R3 (with k = candidates // 4 = 4 of the 12 episodes) the told θ of one of the 4
    episodes with the nearest contexts."""
    observed = driven(_class(column), batches=3, recommend_over=rule, candidates=16)
    contexts = np.array([[0.0], [0.4]])
    rows = observed.recommend(contexts)
    for context, row in zip(contexts, rows, strict=True):
        nearest = np.argsort(np.abs(observed.contexts[:, 0] - context[0]))[:4]
        among = nearest if rule == "neighbours" else slice(None)
        assert (observed.params[among] == row).all(axis=-1).any()


def test_symmetric_contexts_reach_the_librarys_gp_and_its_checkpoint(column: str) -> None:
    """With c-bo's ``symmetric_contexts`` the library's GP sees |s| too: the same recommendation at s and
    at −s, and a restored optimiser asks the same."""
    optimizer = driven(_class(column), batches=3, symmetric_contexts=[0], mean_features="quadratic")
    probe = np.array([[0.1], [0.3]])
    assert np.array_equal(optimizer.recommend(probe), optimizer.recommend(-probe))
    restored = type(optimizer).from_state_dict(optimizer.state_dict())
    assert restored.config.symmetric_contexts == (0,)
    assert np.array_equal(restored.ask(-probe), optimizer.ask(-probe))


def test_mes_asks_inside_the_box_and_the_batch_spreads(column: str) -> None:
    optimizer = driven(_class(column), batches=3, acquisition="mes")
    asked = optimizer.ask(np.zeros((4, 1)))  # the kriging believer: four different θ at one context
    low, high = optimizer.config.param_box
    assert (asked >= low).all() and (asked <= high).all() and len({tuple(row) for row in asked}) == 4


@pytest.mark.parametrize(
    ("options", "error", "match"),
    [
        ({"trend": "quadratic"}, ValueError, "trend: expected 'constant'"),
        ({"prior_mean": "mean"}, ValueError, "prior_mean: expected 'min'"),
        ({"hyper_restarts": 3}, ValueError, "hyper_restarts: expected 1"),
        ({"thread": 2}, TypeError, "unknown"),
    ],
)
def test_options_of_c_bos_own_gp_are_rejected(column: str, options: dict, error: type, match: str) -> None:
    with pytest.raises(error, match=match):
        _class(column)(2, 1, **options)


def test_the_study_column_builds_it_and_records_its_factory(
    column: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(study, "evaluation_contexts", lambda task, model: np.array([[1.5], [2.5]]))
    method = columns.method_by_name(column)
    assert isinstance(method.build(2, 1, 0, initial_mean=0.0, initial_cov=1.0), _class(column))
    spec = study.LowBudgetSpec("Sphere-p2-z1", column, 0, 8)
    assert spec.samples == 4  # c-bo's batch
    document = study.one_run(spec)
    assert document["method"]["factory"] == method.factory and document["stop_reason"] == "budget"


# -- BoTorch's own ---------------------------------------------------------------------------------------
@BOTORCH
@pytest.mark.slow
def test_torchs_generator_and_threads_are_left_as_they_were() -> None:
    import torch

    torch.manual_seed(123)
    generator, threads = torch.random.get_rng_state(), torch.get_num_threads()
    driven(_class("c-bo-botorch"), batches=3)
    assert torch.equal(torch.random.get_rng_state(), generator) and torch.get_num_threads() == threads


@BOTORCH
@pytest.mark.parametrize("threads", [0, 65, 1.5])
def test_bad_threads_are_rejected(threads: object) -> None:
    with pytest.raises((ValueError, TypeError), match="threads"):
        _class("c-bo-botorch")(2, 1, threads=threads)


# -- scikit-learn's own ----------------------------------------------------------------------------------
@SKLEARN
def test_sklearns_posterior_is_the_latent_functions_and_its_gradient_the_analytic_one() -> None:
    """Eqs. (L1) and (L2) of ``sklearn_cbo.py`` against the GP's formulas written out: with the normalised
    targets t = (y − ȳ) / sd(y), K the kernel matrix with the white noise and jitter, k the signal kernel
    c·exp(−½ Σ (x − x_j)² / ℓ²), μ(x) = ȳ + sd(y) k(x)ᵀ K⁻¹ t and σ²(x) = sd(y)² (c − k(x)ᵀ K⁻¹ k(x))."""
    model = driven(_class("c-bo-sklearn")).model
    kernel, inputs, targets = model.gp.kernel_, model.gp.X_train_, model._targets
    signal, lengthscales = kernel.k1.k1.constant_value, kernel.k1.k2.length_scale
    scale = targets.std()
    # The signal and the WhiteKernel's noise on the diagonal, and the regressor's jitter (``alpha``, 1e-10).
    matrix = kernel(inputs) + model.gp.alpha * np.eye(inputs.shape[0])
    weights = np.linalg.solve(matrix, (targets - targets.mean()) / scale)
    points = np.random.default_rng(3).uniform(size=(4, inputs.shape[1]))
    cross = kernel.k1(points, inputs)  # (4, n): no noise between distinct points
    mean, variance = model.predict(points)
    np.testing.assert_allclose(mean, targets.mean() + scale * cross @ weights, rtol=1e-9)
    latent = signal - np.einsum("ij,ji->i", cross, np.linalg.solve(matrix, cross.T))
    np.testing.assert_allclose(variance, scale**2 * latent, rtol=1e-6, atol=1e-12)
    for point, row in zip(points, cross, strict=True):
        gradient = scale * ((weights * row)[:, None] * -(point - inputs) / lengthscales**2).sum(axis=0)
        np.testing.assert_allclose(model.predict_with_gradient(point[None, :])[2][0], gradient, rtol=1e-5)


@SKLEARN
@pytest.mark.parametrize("rule", ["spread", "recent"])
def test_a_refit_fits_the_library_gp_on_the_episodes_fit_subset_chooses(
    rule: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The library columns refit on the same episodes as c-bo's own GP (Eq. G3a): a spy on ``_fit``."""
    from creps_gym.optimizers.gp_model import fit_subset

    cls, seen = _class("c-bo-sklearn"), []
    real = cls._fit

    def spy(self: Any, inputs: np.ndarray, targets: np.ndarray, seed: int) -> Any:
        seen.append(inputs.copy())
        return real(self, inputs, targets, seed)

    monkeypatch.setattr(cls, "_fit", spy)
    optimizer = driven(cls, fit_points=8, fit_subset=rule)
    n = optimizer.fitted_at
    data = optimizer._inputs(optimizer.contexts, optimizer.params, optimizer.context_scale)
    assert n > 8 and seen[-1].tobytes() == data[:n][fit_subset(n, 8, rule)].tobytes()
