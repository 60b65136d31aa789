"""Restored optimiser state is checked like a constructor argument, and the last input gaps of the protocol.

Parametrised over every optimiser of this package in the registry (the adapters restore by replay).
"""

from __future__ import annotations

import copy
import functools
import io
import json
import tracemalloc
import zipfile

import numpy as np
import pytest

from creps_gym.errors import RunDirError
from creps_gym.optimizers import CREPSCMA, load_state, make_optimizer, optimizer_names, save_state
from creps_gym.optimizers.policies import PolicyAccess
from creps_gym.optimizers.registry import optimizer_class, restore_optimizer
from creps_gym.runner import resume, run

NATIVE = [name for name in optimizer_names() if ".adapters." not in optimizer_class(name).__module__]
#: The native optimisers that keep a linear-Gaussian search distribution (its covariance, coefficients, mean
#: features and stop criteria); c-bo keeps a GP's data instead (its own state tests are in test_cbo.py).
GAUSSIAN = [name for name in NATIVE if issubclass(optimizer_class(name), PolicyAccess)]


def _trained_state(name: str) -> dict:
    """A copy of the state of ``name`` trained for 3 iterations (trained once per test process): batches of
    20, of 8 for c-bo, whose every ask optimises an acquisition per row (its state, the GP's data and fitted
    hyperparameters, has the same keys; it feeds only the tampered-key refusals)."""
    return copy.deepcopy(_trained(name))


@functools.cache
def _trained(name: str) -> dict:
    optimizer = make_optimizer(name, 4, 1, 0, initial_mean=1.0, initial_cov=0.5)
    rng = np.random.default_rng(0)
    for _ in range(3):
        contexts = rng.uniform(0, 3, (8 if name == "c-bo" else 20, 1))
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


def _overflowing_cov(state):
    state["cov"] = np.eye(4) * 1e308  # positive definite, but Σ + Σᵀ overflows: every sample is inf


def _zero_step_size(state):
    state["step_size"] = 0.0


CORRUPTIONS = {
    "negative-definite cov": (_negative_definite, "state\\['cov'\\]: expected a positive-definite"),
    "NaN cov": (_nan_cov, "state\\['cov'\\]"),
    "inf coefficients": (_inf_coefficients, "state\\['coefficients'\\]"),
    "wrong shape": (_wrong_shape, "state\\['coefficients'\\]: expected shape \\(2, 4\\)"),
    "asymmetric cov": (_asymmetric, "state\\['cov'\\]: expected a symmetric"),
    "string cov": (_string_cov, "state\\['cov'\\]"),
    "overflowing cov": (_overflowing_cov, "state\\['cov'\\]: expected a covariance whose doubled entries"),
    "zero step size": (_zero_step_size, "state\\['step_size'\\]: expected a finite value > 0"),
}


@pytest.mark.parametrize("name", GAUSSIAN)
@pytest.mark.parametrize("corruption", sorted(CORRUPTIONS))
def test_a_corrupted_checkpoint_is_refused_at_load(name, corruption, tmp_path):
    """Before: a cov of −I became 1e-300·I and NaN arrays made ``ask`` return NaN."""
    state = _trained_state(name)
    corrupt, match = CORRUPTIONS[corruption]
    corrupt(state)
    with pytest.raises((ValueError, TypeError), match=match):  # a string cov is refused by save_state
        restore_optimizer(name, load_state(save_state(state, tmp_path / "opt.npz")))


# An intact checkpoint restores bit-identically: tests/optimizers/test_contract_checkpoint.py.


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
    if "cov" in before:  # the linear-Gaussian search distribution
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
@pytest.mark.slow
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


@pytest.mark.parametrize("name", GAUSSIAN)
def test_tolstagnation_is_validated(name):
    with pytest.raises(ValueError, match="tolstagnation: expected an integer >= 1, got 0"):
        make_optimizer(name, 3, 1, 0, tolstagnation=0)


def _set(key, value):
    def tamper(state):
        state[key] = value

    return tamper


def _drop(key):
    def tamper(state):
        del state[key]

    return tamper


@pytest.mark.parametrize("name", NATIVE)
@pytest.mark.parametrize(
    ("tamper", "error", "match"),
    [
        (_set("iteration", -5), ValueError, r"state\['iteration'\]: expected an integer >= 0, got -5"),
        (_set("iteration", 2.7), TypeError, r"state\['iteration'\]: expected an integer"),
        (_set("evaluations", True), TypeError, r"state\['evaluations'\]: expected an integer"),
        (_set("diagnostics", {"kl": "x"}), TypeError, r"state\['diagnostics'\]\['kl'\]: expected a number"),
        (_drop("rng"), ValueError, "state: expected the key 'rng' of a"),
        (_drop("config"), ValueError, "state: expected the key 'config' of a"),
    ],
)
def test_a_tampered_state_is_refused_naming_the_key(name, tamper, error, match):
    state = _trained_state(name)
    tamper(state)
    with pytest.raises(error, match=match):
        restore_optimizer(name, state)


@pytest.mark.parametrize("name", NATIVE)
def test_a_pending_batch_of_the_wrong_shape_or_values_is_refused(name):
    optimizer = make_optimizer(name, 4, 1, 0)
    optimizer.ask(np.zeros((6, 1)))
    for key, value, match in (
        ("pending_contexts", np.full((6, 1), np.nan), r"state\['pending_contexts'\]: expected finite values"),
        ("pending_params", np.zeros((6, 3)), r"state\['pending_params'\]: expected shape \(6, 4\)"),
    ):
        state = optimizer.state_dict()
        state[key] = value
        with pytest.raises(ValueError, match=match):
            restore_optimizer(name, state)


@pytest.mark.parametrize("name", GAUSSIAN)
def test_finite_returns_near_the_float_limit_still_checkpoint(tmp_path, name):
    """Their sum overflows; the recorded mean return must not (else the checkpoint would not load)."""
    optimizer = make_optimizer(name, 2, 1, 0)
    contexts = np.linspace(0, 1, 12)[:, None]
    optimizer.tell(contexts, optimizer.ask(contexts), 1.5e308 - np.arange(12) * 1e295)
    restored = type(optimizer).load(optimizer.save(tmp_path / "ckpt.npz"))
    assert np.isfinite(restored.mean_returns).all() and restored.mean_returns == optimizer.mean_returns


def test_a_state_of_another_registered_name_of_the_same_class_is_refused():
    state = make_optimizer("creps-cma-csa", 3, 1, 0).state_dict()
    with pytest.raises(ValueError, match=r"state: expected a state of 'creps-cma-old'.*'step_size': 'csa'"):
        restore_optimizer("creps-cma-old", state)
    assert type(restore_optimizer("creps-cma-csa", state)).__name__ == "CREPSCMA"


@pytest.mark.parametrize(
    ("content", "match"),
    [
        (b"", "expected a creps_gym checkpoint \\(.npz\\)"),
        (b"PK\x03\x04 truncated", "expected a creps_gym checkpoint \\(.npz\\)"),
    ],
)
def test_a_damaged_checkpoint_file_raises_value_error_naming_the_path(tmp_path, content, match):
    path = tmp_path / "ckpt.npz"
    path.write_bytes(content)
    with pytest.raises(ValueError, match=f"path: {match}"):
        load_state(path)


def test_a_single_array_or_a_non_object_document_is_not_a_checkpoint(tmp_path):
    np.save(tmp_path / "array.npy", np.zeros(3))
    with pytest.raises(ValueError, match="got a single array"):
        load_state(tmp_path / "array.npy")
    good = make_optimizer("creps", 2, 1, 0).save(tmp_path / "good.npz")
    key = next(k for k in np.load(good).files if k.endswith(".json"))
    np.savez(tmp_path / "list.npz", **{key: np.frombuffer(b"[1, 2]", np.uint8)})
    with pytest.raises(ValueError, match="a JSON list, not an object"):
        load_state(tmp_path / "list.npz")
    assert save_state({"x": np.ones(2)}, tmp_path / "x.npz").exists()


@pytest.mark.parametrize("name", GAUSSIAN)
def test_the_coefficients_property_is_a_read_only_view(name):
    optimizer = make_optimizer(name, 3, 1, 0)
    with pytest.raises(ValueError, match="read-only"):
        optimizer.coefficients[0, 0] = np.nan
    assert np.isfinite(optimizer.ask(np.zeros((4, 1)))).all()


@pytest.mark.parametrize("name", NATIVE)
@pytest.mark.parametrize("option", ["initial_mean", "initial_cov"])
def test_a_python_int_beyond_the_float_range_is_named(name, option):
    with pytest.raises(ValueError, match=f"{option}: expected finite values, got an integer beyond"):
        make_optimizer(name, 3, 1, 0, **{option: 10**400})


def test_recommended_batch_size_checks_its_arguments():
    from creps_gym.optimizers.ccmaes import recommended_batch_size

    assert recommended_batch_size(15, 1) == 24
    cases = (((0, 1), ValueError), ((3, -1), ValueError), ((True, 1), TypeError), ((3.0, 1), TypeError))
    for args, error in cases:
        with pytest.raises(error, match=r"n_params|n_context_dims"):
            recommended_batch_size(*args)


@pytest.mark.parametrize("name", GAUSSIAN)
def test_contexts_whose_features_overflow_are_refused_and_change_nothing(name):
    """Contexts pass the magnitude check (|s| <= 1e100) but a degree-4 polynomial of 1e90 overflows."""
    optimizer = make_optimizer(name, 2, 1, 0, mean_features={"name": "polynomial", "degree": 4})
    before = optimizer.state_dict()
    for method in (optimizer.ask, optimizer.recommend):
        with pytest.raises(ValueError, match="contexts: expected contexts whose mean features are finite"):
            method(np.array([[1e90]]))
    after = optimizer.state_dict()
    assert all(np.array_equal(after[key], value) for key, value in before.items())
    assert np.isfinite(optimizer.ask(np.ones((3, 1)))).all()


# -- never pickle, bounded reads (issue 30, items 4, 6 and 12) ---------------------------------------------
class _UserState(CREPSCMA):
    """A user optimiser whose ``state_dict`` adds ``extra`` (None: nothing)."""

    extra = None

    def state_dict(self):
        state = super().state_dict()
        if self.extra is not None:
            state["extra"] = self.extra
        return state


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (
            np.array([{"a": 1}, None], dtype=object),
            r"state\['optimizer\.extra'\]: expected a numeric array .* object",
        ),
        (np.array(["a", "b"]), r"state\['optimizer\.extra'\]: expected a numeric array .* got dtype <U1"),
        (
            np.int64(3),
            r"state\['optimizer\.extra'\]: expected a numeric array or a JSON value .* numpy\.int64",
        ),
        ({"deep": [1, {2}]}, r"state\['optimizer\.extra'\]\['deep'\]\[1\]: expected .* builtins\.set"),
        ({1: 2}, r"state\['optimizer\.extra'\]: expected str keys \(JSON\), got int 1"),
    ],
    ids=["object array", "str array", "np.int64", "nested set", "int key"],
)
def test_a_user_state_that_needs_pickle_stops_the_run_at_its_first_checkpoint(tmp_path, extra, message):
    """Before: np.savez pickled an object array into every checkpoint, and np.int64 named no key."""
    optimizer = _UserState(2, 1, seed=0)
    optimizer.extra = extra
    with pytest.raises(TypeError, match=message):
        run(
            optimizer,
            "creps_gym/Sphere-v0",
            5,
            10,
            0,
            env_kwargs={"dim": 2},
            run_dir=tmp_path,
            checkpoint_every=1,
        )
    assert not (tmp_path / "checkpoint.npz").exists() and not list(tmp_path.glob("*.tmp"))
    entries = [json.loads(line) for line in (tmp_path / "log.jsonl").read_text().splitlines()]
    assert [e["iteration"] for e in entries if "event" not in e] == [1]  # stopped at its first checkpoint


def _add_bomb(path, size):
    """Add to the .npz ``path`` an entry ``bomb.npy``: ``size`` zero bytes, deflated (about size / 1000)."""
    with zipfile.ZipFile(path, "a", compression=zipfile.ZIP_DEFLATED) as archive:
        with archive.open("bomb.npy", "w", force_zip64=True) as stream:
            chunk = bytes(2**20)
            for _ in range(size // 2**20):
                stream.write(chunk)


def test_a_deflated_entry_is_refused_before_it_is_decompressed(tmp_path):
    """Before: a 64 KB entry deflated from 64 MB was decompressed (and copied) by CREPSCMA.load."""
    path = _UserState(2, 1, seed=0).save(tmp_path / "opt.npz")
    _add_bomb(path, 64 * 2**20)
    assert path.stat().st_size < 2**20
    tracemalloc.start()
    try:
        with pytest.raises(
            ValueError, match=r"entry 'bomb\.npy': expected an uncompressed array, got \d+ bytes"
        ):
            CREPSCMA.load(path)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 4 * 2**20


def test_an_entry_the_state_does_not_list_is_refused(tmp_path):
    path = _UserState(2, 1, seed=0).save(tmp_path / "opt.npz")
    buffer = io.BytesIO()
    np.save(buffer, np.zeros(3))
    with zipfile.ZipFile(path, "a") as archive:  # stored, like np.savez's entries
        archive.writestr("unknown.npy", buffer.getvalue())
    with pytest.raises(ValueError, match=r"unknown entries \['unknown'\] \(its manifest '__arrays__' lists"):
        CREPSCMA.load(path)
    assert isinstance(CREPSCMA.from_state_dict(load_state(_UserState(2, 1, seed=0).save(path))), CREPSCMA)


def test_resume_refuses_a_checkpoint_with_a_deflated_entry(tmp_path):
    run("creps-cma-old", "creps_gym/Sphere-v0", 2, 10, 0, env_kwargs={"dim": 2}, run_dir=tmp_path)
    _add_bomb(tmp_path / "checkpoint.npz", 8 * 2**20)
    with pytest.raises(
        RunDirError, match=r"checkpoint\.npz: damaged .*entry 'bomb\.npy': expected an uncompressed"
    ):
        resume(tmp_path)


@pytest.mark.parametrize("name", NATIVE)
def test_an_initial_covariance_that_overflows_is_refused_naming_it(name):
    """Before: an initial_cov of 1e308 was accepted and the first ask blamed the contexts."""
    with pytest.raises(ValueError, match=r"initial_cov: expected a covariance whose doubled entries"):
        make_optimizer(name, 2, 1, 0, initial_cov=1e308)
    make_optimizer(name, 2, 1, 0, initial_cov=1e280).ask(np.zeros((4, 1)))  # large but usable
