"""The Ray backend on a real local Ray (``ray.init(num_cpus=2)``); skipped if Ray is not installed."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np
import pytest

ray = pytest.importorskip("ray")

import flaky_envs  # noqa: E402
from helpers import SPHERE  # noqa: E402

from creps_gym.envs.base import ContextualEpisodicEnv  # noqa: E402
from creps_gym.errors import EpisodeError  # noqa: E402
from creps_gym.optimizers import CREPSCMA  # noqa: E402
from creps_gym.runner import run  # noqa: E402


class Target(ContextualEpisodicEnv):
    """theta*(s) = (s, -s). A Ray worker (never the test process) dies while ``marker`` says so."""

    def __init__(self, marker: str | None = None, deaths: int = 0, fail: bool = False):
        super().__init__([0.0], [1.0], [-2.0, -2.0], [2.0, 2.0])
        self.marker, self.deaths, self.fail, self.owner = marker, deaths, fail, os.getpid()

    def evaluate(self, contexts, params):
        if self.marker is not None and os.getpid() != self.owner:
            died = Path(self.marker).read_text().count("x") if Path(self.marker).exists() else 0
            if died < self.deaths:
                Path(self.marker).write_text("x" * (died + 1))
                os._exit(1)  # a crash of the worker process, not a Python exception
        if self.fail and os.getpid() != self.owner and params[:, 0].max() > 0.3:
            raise RuntimeError("simulated crash in a worker")
        best = np.concatenate([contexts, -contexts], axis=1)
        return -np.sum((params - best) ** 2, axis=1), {}


@pytest.fixture(scope="module")
def local_ray():
    ray.cloudpickle.register_pickle_by_value(sys.modules[__name__])  # workers cannot import this test file
    ray.cloudpickle.register_pickle_by_value(flaky_envs)
    started = not ray.is_initialized()
    if started:
        ray.init(num_cpus=2, include_dashboard=False, logging_level="ERROR", log_to_driver=False)
    yield
    if started:
        ray.shutdown()


@pytest.mark.slow
def test_ray_matches_serial_bit_for_bit_and_keeps_the_users_ray(local_ray):
    serial = run("creps-cma-old", SPHERE, 3, 10, 2, env_kwargs={"dim": 4})
    distributed = run("creps-cma-old", SPHERE, 3, 10, 2, env_kwargs={"dim": 4}, backend="ray")
    uneven = run("creps-cma-old", SPHERE, 3, 10, 2, env_kwargs={"dim": 4}, backend="ray", workers=3)
    assert distributed.equals(serial) and uneven.equals(serial)
    assert ray.is_initialized()  # the runner shuts down only a Ray it started itself


@pytest.mark.slow
def test_a_dead_worker_is_retried_and_no_sample_is_lost(local_ray, tmp_path):
    marker = tmp_path / "deaths"
    reference = run(CREPSCMA(2, 1, seed=0), Target(), 2, 10, 0)
    survived = run(CREPSCMA(2, 1, seed=0), Target(str(marker), deaths=1), 2, 10, 0, backend="ray")
    assert marker.read_text() == "x" and survived.equals(reference)


@pytest.mark.slow
def test_failures_after_the_retries_stop_the_run_with_a_clear_error(local_ray, tmp_path):
    with pytest.raises(EpisodeError, match=r"iteration 1, episode \d+ .*failed 2 time\(s\).*simulated crash"):
        run(CREPSCMA(2, 1, seed=0, initial_cov=0.5), Target(fail=True), 2, 10, 0, backend="ray", retries=1)
    marker = tmp_path / "deaths"
    with pytest.raises(EpisodeError, match=r"iteration 1, episodes \d+\.\.\d+: the Ray task failed 1 time"):
        run(CREPSCMA(2, 1, seed=0), Target(str(marker), deaths=5), 2, 10, 0, backend="ray", retries=0)


@pytest.mark.slow
def test_flaky_episodes_and_resets_are_retried_as_on_serial(local_ray):
    """The retry policy of every backend (tests/runner/backends/test_failures.py), on Ray."""
    for seed in (0, 1):
        reference = run(CREPSCMA(2, 1, seed=seed), flaky_envs.flaky(), 3, 20, seed)
        for flakes in ({"step_rate": 0.1}, {"reset_rate": 0.1}):
            env = flaky_envs.flaky(flake_seed=seed, **flakes)
            history = run(CREPSCMA(2, 1, seed=seed), env, 3, 20, seed, retries=3, backend="ray")
            assert history.equals(reference), (seed, flakes)
    errors = []
    for options in ({}, {"backend": "ray"}):
        with pytest.raises(EpisodeError) as caught:
            run(CREPSCMA(2, 1, seed=0), flaky_envs.flaky(fail_above=0.5), 2, 10, 0, **options)
        errors.append(str(caught.value))
    assert errors[0] == errors[1] and "failed 3 time(s)" in errors[0]
