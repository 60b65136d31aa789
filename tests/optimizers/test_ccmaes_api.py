"""Contextual CMA-ES's public face: the options in ``help()`` and the diagnostics' meanings."""

from __future__ import annotations

import inspect
import math
import pydoc
from dataclasses import fields

import numpy as np
import pytest

from creps_gym.optimizers import CCMAES, CCMAESConfig


def test_help_and_the_signature_show_every_option_with_its_default():
    signature = inspect.signature(CCMAES)
    options = [f for f in fields(CCMAESConfig) if f.init]
    assert list(signature.parameters) == [f.name for f in options]
    for option in options[2:]:  # after n_params and n_context_dims: keyword-only, with the config's default
        parameter = signature.parameters[option.name]
        assert parameter.kind is inspect.Parameter.KEYWORD_ONLY and parameter.default == option.default
    text = pydoc.render_doc(CCMAES, renderer=pydoc.plaintext)
    for option in options:
        assert f"{option.name}=" in text or f"{option.name} :" in text or f"{option.name}," in text
    assert "baseline_bandwidth : float" in text and "restarts : int" in text


def _run_sphere(iterations: int) -> CCMAES:
    optimizer = CCMAES(6, 1, initial_cov=4.0, seed=1)
    rng = np.random.default_rng(2)
    for _ in range(iterations):
        contexts = rng.uniform(1.0, 2.0, (16, 1))
        params = optimizer.ask(contexts)
        optimizer.tell(contexts, params, -((params - contexts) ** 2).sum(axis=1))
    return optimizer


def test_search_scale_is_the_root_mean_variance_of_the_search_not_sigma():
    """σ alone is not the search's spread (C carries a scale too, det C drifts from 1): ``search_scale`` is
    σ·√(mean eigenvalue of C) = √(trace(σ²C)/p)."""
    optimizer = _run_sphere(60)
    diagnostics = optimizer.diagnostics
    assert diagnostics["step_size"] == optimizer.step_size
    expected = math.sqrt(float(np.trace(optimizer.cov)) / optimizer.n_params)
    assert math.isclose(diagnostics["search_scale"], expected, rel_tol=1e-9)
    assert not math.isclose(diagnostics["search_scale"], diagnostics["step_size"], rel_tol=1e-3)
    assert diagnostics["search_scale"] <= diagnostics["max_std"] * (1 + 1e-12)


def _converge_then_restart(**options) -> tuple[CCMAES, np.ndarray]:
    """A contextual sphere (θ*(s) = s·1) until tolx = 1e-2 restarts the search once."""
    optimizer = CCMAES(4, 1, initial_mean=3.0, initial_cov=1.0, tolx=1e-2, restarts=1, seed=5, **options)
    rng = np.random.default_rng(6)
    while optimizer.restarts_done == 0:
        contexts = rng.uniform(0.0, 1.0, (16, 1))
        params = optimizer.ask(contexts)
        optimizer.tell(contexts, params, -((params - contexts) ** 2).sum(axis=1))
        assert optimizer.iteration < 400
    return optimizer, np.linspace(0.0, 1.0, 5)[:, None]


def test_a_restart_keeps_the_best_mean_policy_as_the_recommendation():
    """C10: the restart resets the search to its initial mean, but ``recommend`` keeps the converged policy
    until the new search scores better; with ``keep_best=False`` the recommendation restarts too."""
    optimizer, tests = _converge_then_restart()  # keep_best=True, the default
    assert np.array_equal(optimizer.coefficients, optimizer.config.initial_mean)  # the search restarted
    regret = ((optimizer.recommend(tests) - tests) ** 2).sum(axis=1)
    assert regret.max() < 1e-2 and np.isfinite(optimizer.best_score)
    plain, _ = _converge_then_restart(keep_best=False)
    assert np.allclose(plain.recommend(tests), 3.0) and plain.best_coefficients is None


def test_the_kept_policy_survives_a_checkpoint_bit_identically(tmp_path):
    optimizer, tests = _converge_then_restart(keep_best=True)
    restored = CCMAES.load(optimizer.save(tmp_path / "c.npz"))
    assert np.array_equal(restored.recommend(tests), optimizer.recommend(tests))
    assert restored.best_score == optimizer.best_score
    contexts = np.full((16, 1), 0.5)
    assert np.array_equal(restored.ask(contexts), optimizer.ask(contexts))
    state = optimizer.state_dict()
    state["best_score"] = np.array([np.nan])
    with pytest.raises(ValueError, match="best_score"):
        CCMAES.from_state_dict(state)


def test_keep_best_must_be_a_bool():
    with pytest.raises(TypeError, match="keep_best"):
        CCMAES(3, 1, keep_best="yes")
