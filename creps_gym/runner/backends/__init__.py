"""Evaluation backends: where an iteration's episodes run.

An episode is identified by its reset seed, its context and its parameters (the runner draws them, see
:mod:`creps_gym.runner.contexts`). A backend's worker resets with the seed (and, for batched context
draws, ``options={"context": context}``), checks the reset gives the recorded context, then steps with the
parameters. Every backend therefore computes the same returns, bit for bit, in the same order:

* ``auto`` (the default): ``vector`` with the native vector env for a registered id that has one, else
  ``serial``.
* ``serial``: one env in the main process.
* ``vector``: a Gymnasium vector env. The native one (``vector_entry_point``, one batched ``evaluate`` call,
  contexts set through ``reset(options={"context": ...})``) where registered, else ``AsyncVectorEnv`` (or
  ``SyncVectorEnv`` with ``vector_mode="sync"``) reset with the per-episode seeds (and contexts), see
  :mod:`.vector`.
* ``ray``: Ray tasks (``pip install creps-gym[ray]``), one chunk of episodes per cluster CPU; Ray is imported
  only when this backend is built. An already initialised Ray is used as is; a running cluster at
  ``ray_address`` (or ``RAY_ADDRESS``) is joined and left running; otherwise a local instance is started
  and shut down by ``RayBackend.close``, with a watchdog that stops it if the run's process dies without
  shutting it down (see :mod:`.ray`).

**Failure policy** (the same on every backend). Every episode gets ``retries + 1`` attempts of its own:
an episode whose reset or step raises, or whose reward is not a finite real number (a str, bool, None or
complex reward is refused, never converted), is re-run up to ``retries`` times; episodes are
deterministic, so a retry that succeeds gives the value the first attempt should have given, and no
sample is ever dropped. A batch that fails as a whole (a vector env, a Ray task whose worker process
died) cannot be blamed on one episode and is not charged to any: a vector env is rebuilt and its chunk
re-run up to ``retries`` times, then the chunk's episodes run one by one in the main process, each with
the full budget; Ray re-submits a task whose worker died up to ``retries`` times. When an episode's
attempts are spent the run stops with :class:`EpisodeError`, whose message names the iteration, the
episode, its seed and context, and the last error: the same message on every backend. A reset whose
context differs from the recorded one raises :class:`EpisodeError` at once (the env is not
deterministic under ``reset(seed=...)``, so no backend could reproduce the run). Set-up errors (a
vector env that cannot be built from the env given) are raised when the backend is built, before any
episode runs.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from creps_gym.runner.backends.episodes import (
    Array,
    Backend,
    EnvSource,
    check_context,
    episode_return,
    reset_context,
    retry,
    run_episodes,
)

__all__ = [
    "Backend",
    "EnvSource",
    "SerialBackend",
    "check_context",
    "episode_return",
    "has_native_vector",
    "make_backend",
    "reset_context",
    "retry",
    "run_episodes",
]


class SerialBackend(Backend):
    """Episodes one after the other in the main process."""

    name = "serial"

    def __init__(self, source: EnvSource, retries: int, env: gym.Env | None = None) -> None:
        super().__init__(source, retries)
        self.env = env if env is not None else source.make()

    def evaluate(self, seeds: NDArray[np.int64], contexts: Array, params: Array, label: str) -> Array:
        return run_episodes(
            self.env,
            seeds,
            contexts,
            params,
            first=0,
            label=label,
            retries=self.retries,
            set_context=self.source.set_context,
        )


def has_native_vector(source: EnvSource) -> bool:
    """Whether ``source`` is a registered id with a native vector entry point and no added wrappers."""
    if source.env_id is None:
        return False
    spec = source.registered_spec()
    return spec.vector_entry_point is not None and not spec.additional_wrappers


def make_backend(
    name: str,
    source: EnvSource,
    *,
    retries: int,
    workers: int | None,
    vector_mode: str,
    samples: int,
    env: gym.Env | None = None,
    ray_address: str | None = None,
) -> Backend:
    """Build a backend by name (``"auto"``, ``"serial"``, ``"vector"`` or ``"ray"``).

    ``"auto"`` is the fastest correct backend: the native vector env of a registered id that has one
    (:func:`has_native_vector`), else ``"serial"``. ``ray_address`` is for ``"ray"`` only. ``workers`` (vector
    sub-envs or Ray chunks) is capped at ``samples``: an iteration has no more episodes to share out.
    """
    workers = None if workers is None else min(workers, samples)
    if name == "auto":
        name = "vector" if has_native_vector(source) else "serial"
    if name == "serial":
        return SerialBackend(source, retries, env)
    if name == "vector":
        from creps_gym.runner.backends.vector import VectorBackend

        return VectorBackend(source, retries, workers, vector_mode, samples)
    if name == "ray":
        from creps_gym.runner.backends.ray import RayBackend  # imports Ray only when asked for

        return RayBackend(source, retries, workers, ray_address)
    raise ValueError(f"backend: expected one of ['auto', 'serial', 'vector', 'ray'], got {name!r}")
