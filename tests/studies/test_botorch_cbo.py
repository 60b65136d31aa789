"""The low-budget study's BoTorch column (``benchmarks/low_budget/botorch_cbo.py``): c-bo on BoTorch's model.

Skipped where torch and BoTorch are not installed (no extra of creps_gym installs them)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from helpers import EXTRAS

torch = pytest.importorskip("torch")
pytest.importorskip("botorch")

from benchmarks.low_budget import columns, study  # noqa: E402
from benchmarks.low_budget.botorch_cbo import BoTorchCBO  # noqa: E402

pytestmark = EXTRAS


def _optimum(contexts: np.ndarray) -> np.ndarray:
    return np.hstack([contexts, -contexts])  # θ*(s) = (s, −s)


def _returns(contexts: np.ndarray, params: np.ndarray) -> np.ndarray:
    return -((params - _optimum(contexts)) ** 2).sum(axis=1)


def _driven(batches: int = 5, seed: int = 0, **options: Any) -> BoTorchCBO:
    """p = 2, z = 1, batches of 4 on a contextual sphere (contexts from their own stream); UCB unless
    ``acquisition`` says otherwise (BoTorch's MES costs about ten times as much per ask)."""
    options = {"acquisition": "ucb", **options}
    optimizer = BoTorchCBO(2, 1, seed=seed, initial_cov=0.25, **options)
    rng = np.random.default_rng(7)
    for _ in range(batches):
        contexts = rng.uniform(-0.5, 0.5, size=(4, 1))
        params = optimizer.ask(contexts)
        optimizer.tell(contexts, params, _returns(contexts, params))
    return optimizer


@pytest.fixture(scope="module")
def driven() -> BoTorchCBO:
    return _driven()


def test_same_seed_same_run_and_torchs_generator_and_threads_are_left_as_they_were(
    driven: BoTorchCBO,
) -> None:
    torch.manual_seed(123)
    generator, threads = torch.random.get_rng_state(), torch.get_num_threads()
    again = _driven(batches=3)  # the first three batches of the fixture's run, bit for bit
    assert np.array_equal(again.params, driven.params[:12]) and np.array_equal(
        again.returns, driven.returns[:12]
    )
    assert torch.equal(torch.random.get_rng_state(), generator) and torch.get_num_threads() == threads
    other = _driven(batches=3, seed=1)
    assert not np.array_equal(other.params[8:], driven.params[8:12])  # the model's asks follow the seed


def test_a_checkpoint_restores_the_same_next_ask_and_recommendation(driven: BoTorchCBO) -> None:
    state = driven.state_dict()
    restored = BoTorchCBO.from_state_dict(state)
    contexts, test = np.array([[0.1], [-0.3]]), np.array([[0.2], [-0.4]])
    assert np.array_equal(restored.recommend(test), driven.recommend(test))
    copy = BoTorchCBO.from_state_dict(state)  # asking changes the Generator: compare two restored copies
    assert np.array_equal(restored.ask(contexts), copy.ask(contexts))
    assert restored.config.to_json() == driven.config.to_json()


def test_a_forged_checkpoint_is_rejected_naming_the_field(driven: BoTorchCBO) -> None:
    state = driven.state_dict()
    with pytest.raises(ValueError, match="hyper_names"):
        BoTorchCBO.from_state_dict({**state, "hyper_names": state["hyper_names"][::-1]})
    with pytest.raises(ValueError, match=r"state\['hyper'\]"):
        BoTorchCBO.from_state_dict({**state, "hyper": np.full_like(state["hyper"], np.nan)})
    with pytest.raises(TypeError, match=r"state\['hyper_names'\]"):
        BoTorchCBO.from_state_dict({**state, "hyper_names": "covar_module.raw_lengthscale"})


def test_the_recommendation_beats_the_start_and_holds_the_posterior_means_best(driven: BoTorchCBO) -> None:
    test = np.linspace(-0.5, 0.5, 5)[:, None]
    chosen = driven.recommend(test)
    start = np.tile(driven.config.initial_mean, (5, 1))
    assert -_returns(test, chosen).mean() < 0.5 * -_returns(test, start).mean()  # 0.089 against 0.25
    assert np.array_equal(driven.recommend(test[2:3]), chosen[2:3])  # alone as in a batch
    for context, theta in zip(driven._scaled_contexts(test), driven._scaled_params(chosen), strict=True):
        good = driven.trust_region(context)[0]
        means = driven.model.predict(np.hstack([np.tile(context, (len(good) + 1, 1)), [theta, *good]]))[0]
        assert means[0] >= means[1:].max()  # R1 never ends below G(s)'s best θ


def test_the_observed_rule_returns_told_parameters(driven: BoTorchCBO) -> None:
    observed = _driven(batches=3, recommend_over="observed")
    rows = observed.recommend(np.array([[0.0], [0.4]]))
    assert all(any(np.array_equal(row, told) for told in observed.params) for row in rows)


def test_mes_asks_inside_the_box_and_the_batch_spreads() -> None:
    optimizer = _driven(batches=3, acquisition="mes")
    asked = optimizer.ask(np.zeros((4, 1)))  # the kriging believer: four different θ at one context
    low, high = optimizer.config.param_box
    assert (asked >= low).all() and (asked <= high).all() and len({tuple(row) for row in asked}) == 4


@pytest.mark.parametrize(
    ("options", "error", "match"),
    [
        ({"trend": "quadratic"}, ValueError, "trend: expected 'constant'"),
        ({"prior_mean": "mean"}, ValueError, "prior_mean: expected 'min'"),
        ({"hyper_restarts": 3}, ValueError, "hyper_restarts: expected 1"),
        ({"threads": 0}, ValueError, "threads"),
        ({"thread": 2}, TypeError, "unknown"),
    ],
)
def test_options_of_c_bos_own_gp_and_bad_threads_are_rejected(options: dict, error: type, match: str) -> None:
    with pytest.raises(error, match=match):
        BoTorchCBO(2, 1, **options)


def test_the_study_column_builds_it_and_records_its_factory(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(study, "evaluation_contexts", lambda task, model: np.array([[1.5], [2.5]]))
    method = columns.method_by_name("c-bo-botorch")
    assert isinstance(method.build(2, 1, 0, initial_mean=0.0, initial_cov=1.0), BoTorchCBO)
    spec = study.LowBudgetSpec("Sphere-p2-z1", "c-bo-botorch", 0, 8)
    assert spec.samples == 4  # c-bo's batch
    document = study.one_run(spec)
    assert document["method"]["factory"] == method.factory and document["stop_reason"] == "budget"
