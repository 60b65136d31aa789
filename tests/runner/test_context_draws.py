"""Batched context draws, the default backend and O(1) checkpoints (issue 14)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from helpers import SPHERE

from creps_gym.envs.functions.env import ContextualFunctionEnv as FunctionEnv
from creps_gym.optimizers import CREPSCMA
from creps_gym.runner import RunConfig, RunDir, Runner, run
from creps_gym.runner.backends import SerialBackend
from creps_gym.runner.backends.vector import VectorBackend
from creps_gym.runner.contexts import ContextDraws
from creps_gym.wrappers import FixedContexts, HideContext, NormalizeParams, SampleContexts, UniformContexts

SMALL = {"env_kwargs": {"dim": 3}}


def test_an_iteration_draws_its_contexts_with_one_call_and_no_reset(monkeypatch):
    calls = {"sample": 0, "reset": 0}
    sample, reset = FunctionEnv.sample_contexts, FunctionEnv.reset

    def counted_sample(self, rng, n):
        calls["sample"] += 1
        return sample(self, rng, n)

    def counted_reset(self, **kwargs):
        calls["reset"] += 1
        return reset(self, **kwargs)

    monkeypatch.setattr(FunctionEnv, "sample_contexts", counted_sample)
    monkeypatch.setattr(FunctionEnv, "reset", counted_reset)
    run(CREPSCMA(3, 1, seed=0), gym.make(SPHERE, dim=3), 5, 50, 0)  # serial: the episodes reset
    assert calls == {"sample": 5 + 1, "reset": 5 * 50}  # + the test contexts
    calls.update(sample=0, reset=0)
    run("creps-cma-old", SPHERE, 5, 50, 0, **SMALL)  # the default backend: the native vector env
    assert calls == {"sample": 5 + 2, "reset": 0}  # + the test contexts and the batch-size check
    # (the native vector env draws no contexts of its own: the backend turns its autoreset off)


def test_the_layer_that_chooses_contexts_draws_them():
    rng = np.random.default_rng(0)
    sphere = gym.make(SPHERE, dim=2)
    cycle = ContextDraws(FixedContexts(sphere, [[0.5], [1.0], [1.5]]), "batch", 0)
    seeds, contexts = cycle.draw(rng, 7, "x")
    assert cycle.batched and seeds.shape == (7,) and contexts.ravel().tolist() == [0.5, 1.0, 1.5] * 2 + [0.5]
    sampler = UniformContexts([1.0], [1.25])
    drawn = ContextDraws(SampleContexts(sphere, sampler), "batch", 0).draw(np.random.default_rng(1), 4, "x")[
        1
    ]
    again = np.random.default_rng(1)
    again.integers(0, 2**63 - 1, size=4)  # the seeds come first
    assert np.array_equal(drawn, sampler(again, 4))
    assert ContextDraws(NormalizeParams(sphere), "batch", 0).batched  # an action wrapper passes contexts on
    assert not ContextDraws(HideContext(sphere), "batch", 0).batched  # the observation is not the context
    assert not ContextDraws(sphere, "reset", 0).batched


@pytest.mark.parametrize("draws", ["batch", "reset"])
def test_both_streams_are_the_same_on_every_backend_and_differ_from_each_other(draws):
    serial = run("creps-cma-old", SPHERE, 3, 10, 2, backend="serial", context_draws=draws, **SMALL)
    native = run("creps-cma-old", SPHERE, 3, 10, 2, context_draws=draws, **SMALL)
    synced = run(
        "creps-cma-old",
        SPHERE,
        3,
        10,
        2,
        backend="vector",
        vector_mode="sync",
        context_draws=draws,
        workers=3,
        **SMALL,
    )
    assert native.equals(serial) and synced.equals(serial)
    other = "reset" if draws == "batch" else "batch"
    assert not serial.equals(run("creps-cma-old", SPHERE, 3, 10, 2, context_draws=other, **SMALL))


def test_a_wrapped_env_object_gives_the_same_history_on_serial_and_vector_backends():
    def env():
        return FixedContexts(gym.make(SPHERE, dim=2), [[0.5], [1.0], [2.0]], order="random")

    serial = run(CREPSCMA(2, 1, seed=0), env(), 3, 10, 0, backend="serial")
    synced = run(CREPSCMA(2, 1, seed=0), env(), 3, 10, 0, backend="vector", vector_mode="sync", workers=3)
    assert synced.equals(serial)


def test_the_default_backend_is_the_native_vector_env_of_a_registered_id():
    runner = Runner(RunConfig(SPHERE, "creps", 1, 10, 0, **SMALL))
    backend = runner.make_backend()
    assert runner.config.backend == "auto" and isinstance(backend, VectorBackend) and backend.mode == "native"
    objects = Runner(RunConfig(None, "creps", 1, 10, 0), env=gym.make(SPHERE, dim=3))  # the object is used
    assert isinstance(objects.make_backend(), SerialBackend)
    with pytest.raises(ValueError, match=r"context_draws: expected one of \['batch', 'reset'\], got 'x'"):
        RunConfig(SPHERE, "creps", 1, 10, 0, context_draws="x")


@pytest.mark.slow
def test_a_checkpoint_does_not_grow_with_the_run(tmp_path):
    """It holds the loop's and the optimiser's state; the optimiser keeps a bounded window of returns."""
    sizes = []
    path = tmp_path / "run" / RunDir.CHECKPOINT

    def measure(record, history):
        if record.iteration == 151:  # the checkpoint of iteration 150, beyond the stagnation window (~130)
            sizes.append(path.stat().st_size)

    history = run(
        "creps-cma-old",
        SPHERE,
        300,
        10,
        0,
        run_dir=tmp_path / "run",
        checkpoint_every=150,
        callbacks=[measure],
        **SMALL,
    )
    assert len(history) == 300 and abs(path.stat().st_size - sizes[0]) < 512  # the history alone: > 50 kB
