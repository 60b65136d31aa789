"""The Ray backend: one chunk of episodes per Ray task (``pip install creps-gym[ray]``).

Ray is imported only when a :class:`RayBackend` is built. An already initialised Ray (e.g.
``ray.init(address=...)`` for a cluster) is used as is and left running. Otherwise the backend starts a
local Ray (no dashboard) and :meth:`RayBackend.close` shuts it down at the end of the run.

**A hard kill of the run.** ``ray.init`` starts its services (GCS server, raylet, log monitor, and the
raylet's dashboard and runtime-env agents and workers) as processes of their own. After a ``kill -9`` of
the run's process, the GCS server, raylet and workers exit by themselves, but Ray's agents stay alive. So
a run that starts its own Ray also starts a small watchdog process (:mod:`creps_gym.runner.watchdog`,
Linux ``/proc`` only). It records the processes Ray started and their descendants, and when the run's
process dies without shutting Ray down it terminates them (SIGTERM, then SIGKILL after 2 s) and exits.
Ray's session files under its temporary directory (``/tmp/ray/session_*``) are left, as after any Ray
session. A Ray the user initialised is never watched or stopped.
"""

from __future__ import annotations

import itertools
import os
from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from creps_gym.optimizers.adapters.base import import_optional
from creps_gym.runner.backends import Array, Backend, EnvSource, EpisodeError, run_episodes
from creps_gym.runner.watchdog import Watchdog, child_pids

__all__ = ["RayBackend"]

_RAY_ENVS: dict[str, gym.Env] = {}


def _ray_chunk(
    key: str, source: EnvSource, seeds: Any, contexts: Array, params: Array, first: int, label: str, n: int
) -> Array:
    """Body of a Ray task: the worker keeps one env per source."""
    if key not in _RAY_ENVS:
        _RAY_ENVS[key] = source.make()
    env, batched = _RAY_ENVS[key], source.set_context
    return run_episodes(
        env, seeds, contexts, params, first=first, label=label, retries=n, set_context=batched
    )


class RayBackend(Backend):
    """Ray tasks, ``workers`` chunks per batch (default: the cluster's CPU count)."""

    name = "ray"

    def __init__(self, source: EnvSource, retries: int, workers: int | None) -> None:
        super().__init__(source, retries)
        self._ray = ray = import_optional("ray", "ray")
        self._owns = not ray.is_initialized()
        self._watchdog: Watchdog | None = None
        if self._owns:
            before = child_pids(os.getpid())
            ray.init(num_cpus=workers, include_dashboard=False, logging_level="ERROR")
            self._watchdog = Watchdog.start(sorted(child_pids(os.getpid()) - before))
        self.chunks = workers or max(1, int(ray.cluster_resources().get("CPU", 1)))
        self._source_ref = ray.put(source)
        self._key = self._source_ref.hex()
        self._task = ray.remote(num_cpus=1, max_retries=retries)(_ray_chunk)

    def evaluate(self, seeds: NDArray[np.int64], contexts: Array, params: Array, label: str) -> Array:
        ray = self._ray
        bounds = np.linspace(0, len(seeds), min(self.chunks, len(seeds)) + 1).astype(int)
        spans = list(itertools.pairwise(int(b) for b in bounds))
        key, ref, tries = self._key, self._source_ref, self.retries
        task = self._task.remote
        refs = [task(key, ref, seeds[a:b], contexts[a:b], params[a:b], a, label, tries) for a, b in spans]
        returns = []
        for (a, b), ref in zip(spans, refs, strict=True):
            try:
                returns.append(ray.get(ref))
            except ray.exceptions.RayTaskError as exc:
                cause = exc.cause if isinstance(exc.cause, Exception) else exc
                raise EpisodeError(str(cause).splitlines()[-1] if cause is exc else str(cause)) from None
            except ray.exceptions.RayError as exc:
                raise EpisodeError(
                    f"{label}, episodes {a}..{b - 1}: the Ray task failed {self.retries + 1} time(s) "
                    f"({type(exc).__name__}: {str(exc).splitlines()[0]})"
                ) from None
        return np.concatenate(returns)

    def close(self) -> None:
        if self._owns and self._ray.is_initialized():
            self._ray.shutdown()
        if self._watchdog is not None:
            self._watchdog.release()
            self._watchdog = None
        self._owns = False
