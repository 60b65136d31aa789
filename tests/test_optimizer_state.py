"""Restored optimiser state is checked like a constructor argument, and the last input gaps of the protocol.

Parametrised over every optimiser of this package in the registry (the adapters restore by replay).
"""

from __future__ import annotations

import numpy as np
import pytest

from creps_gym.optimizers import load_state, make_optimizer, optimizer_names, save_state
from creps_gym.optimizers.registry import optimizer_class, restore_optimizer

NATIVE = [name for name in optimizer_names() if ".adapters." not in optimizer_class(name).__module__]


def _trained_state(name: str) -> dict:
    optimizer = make_optimizer(name, 4, 1, 0, initial_mean=1.0, initial_cov=0.5)
    rng = np.random.default_rng(0)
    for _ in range(3):
        contexts = rng.uniform(0, 3, (20, 1))
        params = optimizer.ask(contexts)
        optimizer.tell(contexts, params, -(params**2).sum(axis=1))
    return optimizer.state_dict()


def _negative_definite(state):
    state["cov"] = -np.eye(4)


def _nan_cov(state):
    state["cov"] = state["cov"].copy()
    state["cov"][0, 0] = np.nan


def _inf_coefficients(state):
    state["coefficients"] = state["coefficients"].copy()
    state["coefficients"][1, 2] = np.inf


def _wrong_shape(state):
    state["coefficients"] = np.zeros((3, 4))


def _asymmetric(state):
    state["cov"] = state["cov"] + np.triu(np.full((4, 4), 0.1), 1)


def _string_cov(state):
    state["cov"] = np.array([["a"] * 4] * 4)


def _zero_step_size(state):
    state["step_size"] = 0.0


CORRUPTIONS = {
    "negative-definite cov": (_negative_definite, "state\\['cov'\\]: expected a positive-definite"),
    "NaN cov": (_nan_cov, "state\\['cov'\\]"),
    "inf coefficients": (_inf_coefficients, "state\\['coefficients'\\]"),
    "wrong shape": (_wrong_shape, "state\\['coefficients'\\]: expected shape \\(2, 4\\)"),
    "asymmetric cov": (_asymmetric, "state\\['cov'\\]: expected a symmetric"),
    "string cov": (_string_cov, "state\\['cov'\\]"),
    "zero step size": (_zero_step_size, "state\\['step_size'\\]: expected a finite value > 0"),
}


@pytest.mark.parametrize("name", NATIVE)
@pytest.mark.parametrize("corruption", sorted(CORRUPTIONS))
def test_a_corrupted_checkpoint_is_refused_at_load(name, corruption, tmp_path):
    """Before: a cov of −I became 1e-300·I and NaN arrays made ``ask`` return NaN."""
    state = _trained_state(name)
    corrupt, match = CORRUPTIONS[corruption]
    corrupt(state)
    path = save_state(state, tmp_path / "opt.npz")
    with pytest.raises((ValueError, TypeError), match=match):
        restore_optimizer(name, load_state(path))


@pytest.mark.parametrize("name", NATIVE)
def test_an_intact_checkpoint_still_restores_bit_identically(name, tmp_path):
    state = _trained_state(name)
    restored = restore_optimizer(name, load_state(save_state(state, tmp_path / "opt.npz")))
    original = restore_optimizer(name, state)
    contexts = np.linspace(0, 3, 7)[:, None]
    np.testing.assert_array_equal(original.ask(contexts), restored.ask(contexts))


@pytest.mark.parametrize("name", NATIVE)
def test_huge_contexts_are_refused_by_ask_and_tell_with_the_state_unchanged(name):
    """Contexts of 1e160 made quadratic features overflow: ``ask`` returned inf parameters and ``tell``
    failed inside an SVD."""
    optimizer = (
        make_optimizer(name, 3, 1, 0, mean_features="quadratic")
        if name.startswith("creps")
        else (make_optimizer(name, 3, 1, 0))
    )
    before = optimizer.state_dict()
    with pytest.raises(ValueError, match=r"contexts: expected \|s\| <= 1e\+100.*got max \|s\| = 1e\+160"):
        optimizer.ask(np.full((5, 1), 1e160))
    contexts = np.linspace(0, 1, 20)[:, None]
    params = optimizer.ask(contexts)
    with pytest.raises(ValueError, match="contexts: expected \\|s\\| <= 1e\\+100"):
        optimizer.tell(np.full((20, 1), 1e160), params, np.zeros(20), allow_external=True)
    assert before["rng"] != optimizer.state_dict()["rng"]  # the second ask drew; the refused calls did not
    np.testing.assert_array_equal(optimizer.state_dict()["cov"], before["cov"])


@pytest.mark.parametrize("name", NATIVE)
def test_allow_external_must_be_a_bool_and_seed_non_negative(name):
    optimizer = make_optimizer(name, 3, 1, 0)
    contexts = np.linspace(0, 1, 20)[:, None]
    params = optimizer.ask(contexts)
    with pytest.raises(TypeError, match="allow_external"):
        optimizer.tell(contexts, params, np.zeros(20), allow_external="yes")
    assert optimizer.iteration == 0
    with pytest.raises(ValueError, match="seed: expected an int >= 0 or None, got -1"):
        make_optimizer(name, 3, 1, -1)


@pytest.mark.parametrize("n_params", [1, 5])
@pytest.mark.parametrize("name", NATIVE)
def test_pure_noise_returns_end_in_a_stop_criterion(name, n_params):
    """Returns that ignore θ carry no signal: before, Σ grew to a std of 1e15 (or collapsed and stalled) for
    10k iterations without a stop. Now the stagnation criterion (or another) ends the run."""
    optimizer = make_optimizer(name, n_params, 1, 0)
    rng = np.random.default_rng(0)
    for _ in range(2000):
        contexts = rng.uniform(0, 3, (20, 1))
        optimizer.tell(contexts, optimizer.ask(contexts), rng.standard_normal(20))
        if optimizer.stop():
            break
    assert optimizer.stop(), f"{name} ran 2000 noise iterations without a stop"


@pytest.mark.parametrize("name", NATIVE)
def test_tolstagnation_is_validated(name):
    with pytest.raises(ValueError, match="tolstagnation: expected an integer >= 1, got 0"):
        make_optimizer(name, 3, 1, 0, tolstagnation=0)
