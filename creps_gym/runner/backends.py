"""Evaluation backends: where an iteration's episodes run.

An episode is identified by its reset seed and its parameters. The runner draws one seed per episode from
its env stream and reads the context from ``env.reset(seed=seed)`` in the main process; a backend's worker
replays ``reset(seed=seed)`` (and checks it gives the same context) then ``step(params)``. Every backend
therefore computes the same returns, bit for bit, in the same order:

* ``serial``: one env in the main process.
* ``vector``: a Gymnasium vector env. The native one (``vector_entry_point``, one batched ``evaluate`` call,
  contexts set through ``reset(options={"context": ...})``) where registered, else ``AsyncVectorEnv`` (or
  ``SyncVectorEnv`` with ``vector_mode="sync"``) reset with the per-episode seeds.
* ``ray``: Ray tasks (``pip install creps-gym[ray]``), one chunk of episodes per task; Ray is imported only
  when this backend is built. An already initialised Ray (e.g. ``ray.init(address=...)`` for a cluster) is
  used as is; otherwise a local instance is started and shut down by :meth:`RayBackend.close`.

**Failure policy.** An episode that raises, or returns a non-finite value, is re-run up to ``retries``
times (episodes are deterministic, so a retry that succeeds gives the value the first attempt should have
given). A Ray task whose worker process dies is re-submitted by Ray up to ``retries`` times. A vector env
that fails is rebuilt and the chunk re-run up to ``retries`` times, then the chunk is re-run episode by
episode to find the failing one. When the retries are spent the run stops with :class:`EpisodeError`,
whose message names the iteration, the episode, its seed and context, and the last error. No sample is
ever dropped. A reset whose context differs from the recorded one raises :class:`EpisodeError` at once
(the env is not deterministic under ``reset(seed=...)``, so no backend could reproduce the run).
"""

from __future__ import annotations

import itertools
import math
import os
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from creps_gym.optimizers.adapters.base import import_optional

__all__ = [
    "Backend",
    "EnvSource",
    "EpisodeError",
    "RayBackend",
    "SerialBackend",
    "VectorBackend",
    "make_backend",
    "retry",
    "run_episodes",
]

Array = NDArray[np.float64]


class EpisodeError(RuntimeError):
    """An episode failed after all retries (the message names it); the run cannot continue."""


@dataclass
class EnvSource:
    """How a worker builds its env: a registered id with kwargs, or an env object (copied to workers)."""

    env_id: str | None = None
    kwargs: dict[str, Any] = field(default_factory=dict)
    env: Any = None

    def make(self) -> gym.Env:
        """A fresh env (the object itself for object sources)."""
        return gym.make(self.env_id, **self.kwargs) if self.env_id is not None else self.env

    def spec(self) -> Any:
        """What ``gymnasium.make_vec`` takes: the id, or the object's spec (TypeError if it has none)."""
        if self.env_id is not None:
            return self.env_id
        if getattr(self.env, "spec", None) is None:
            raise TypeError(
                "env: the vector backend expected a registered env id or an env made by gymnasium.make "
                f"(with a spec), got {type(self.env).__name__} without a spec"
            )
        return self.env.spec


def _episode_text(label: str, index: int, seed: int, context: Array) -> str:
    return f"{label}, episode {index} (reset seed {seed}, context {np.asarray(context).tolist()})"


def _check_context(obs: Any, context: Array, where: str) -> None:
    got = np.asarray(obs, dtype=np.float64).reshape(-1)
    if not np.array_equal(got, np.asarray(context).reshape(-1)):
        raise EpisodeError(
            f"{where}: reset(seed=...) gave context {got.tolist()}, expected the recorded "
            f"{np.asarray(context).tolist()}; the env must be deterministic under reset(seed=...)"
        )


def retry(
    call: Callable[[], Any],
    attempts: int,
    *,
    on_failure: Callable[[], None] | None = None,
    reraise: tuple[type[Exception], ...] = (EpisodeError,),
) -> tuple[bool, Any, Exception | None]:
    """Call ``call()`` up to ``attempts`` times: ``(True, value, None)``, or ``(False, None, last error)``.

    Exceptions in ``reraise`` (by default ``EpisodeError``: an episode already named) propagate at once;
    ``on_failure`` runs after each other failure (e.g. to rebuild a broken vector env).
    """
    last: Exception | None = None
    for _ in range(attempts):
        try:
            return True, call(), None
        except reraise:
            raise
        except Exception as exc:  # any failure of user env code is retried, then reported by the caller
            last = exc
            if on_failure is not None:
                on_failure()
    return False, None, last


def _one_episode(env: gym.Env, seed: int, context: Array, params: Array) -> float:
    obs, _ = env.reset(seed=int(seed))
    _check_context(obs, context, "reset")
    _, reward, terminated, truncated, _ = env.step(params)
    if not (terminated or truncated):
        raise RuntimeError("expected a one-step episode (terminated or truncated after the first step)")
    value = float(reward)
    if not math.isfinite(value):
        raise ValueError(f"expected a finite return, got {value}")
    return value


def run_episodes(
    env: gym.Env, seeds: Any, contexts: Array, params: Array, *, first: int, label: str, retries: int
) -> Array:
    """Run episodes one by one with the retry policy of the module docstring.

    Parameters
    ----------
    env : gymnasium.Env
    seeds : array_like of int, shape (n,)
    contexts : ndarray, shape (n, z)
        The recorded contexts (checked against each reset).
    params : ndarray, shape (n, p)
    first : int
        Index of the first episode within the iteration (for error messages).
    label : str
        E.g. ``"iteration 3"``.
    retries : int

    Returns
    -------
    ndarray, shape (n,)
    """
    returns = np.empty(len(seeds))
    for k, seed in enumerate(seeds):
        where = _episode_text(label, first + k, int(seed), contexts[k])
        try:
            ok, value, last = retry(
                lambda k=k, seed=seed: _one_episode(env, int(seed), contexts[k], params[k]), retries + 1
            )
        except EpisodeError as exc:
            raise EpisodeError(f"{where}: {exc}") from None
        if not ok:
            raise EpisodeError(
                f"{where} failed {retries + 1} time(s); last error: {type(last).__name__}: {last}"
            ) from last
        returns[k] = value
    return returns


class Backend(ABC):
    """Runs a batch of episodes and returns their returns, in order."""

    name: str = "base"

    def __init__(self, source: EnvSource, retries: int) -> None:
        self.source = source
        self.retries = retries

    @abstractmethod
    def evaluate(self, seeds: NDArray[np.int64], contexts: Array, params: Array, label: str) -> Array:
        """Returns (n,) of the episodes ``(seeds (n,), contexts (n, z), params (n, p))``."""

    def close(self) -> None:  # noqa: B027 (most backends hold nothing to release)
        """Release workers (idempotent)."""


class SerialBackend(Backend):
    """Episodes one after the other in the main process."""

    name = "serial"

    def __init__(self, source: EnvSource, retries: int, env: gym.Env | None = None) -> None:
        super().__init__(source, retries)
        self.env = env if env is not None else source.make()

    def evaluate(self, seeds: NDArray[np.int64], contexts: Array, params: Array, label: str) -> Array:
        return run_episodes(self.env, seeds, contexts, params, first=0, label=label, retries=self.retries)


class VectorBackend(Backend):
    """A Gymnasium vector env; batches larger than ``num_envs`` run in chunks (the last one padded)."""

    name = "vector"

    def __init__(self, source: EnvSource, retries: int, workers: int | None, mode: str, samples: int) -> None:
        super().__init__(source, retries)
        spec = source.spec()
        registered = gym.spec(spec) if isinstance(spec, str) else spec
        native = registered.vector_entry_point is not None
        if mode == "native" and not native:
            raise ValueError(
                f"vector_mode: expected 'auto', 'sync' or 'async' for {registered.id} (not native), "
                "got 'native'"
            )
        self.mode = ("native" if native else "async") if mode == "auto" else mode
        default = samples if self.mode == "native" else min(samples, os.cpu_count() or 1)
        self.num_envs = workers or default
        self._vec: Any = None
        self._single: gym.Env | None = None

    def _make_vec(self) -> Any:
        modes = {"native": "vector_entry_point", "sync": "sync", "async": "async"}
        mode = modes[self.mode]
        return gym.make_vec(self.source.spec(), self.num_envs, vectorization_mode=mode, **self.source.kwargs)

    def _chunk(self, seeds: NDArray[np.int64], contexts: Array, params: Array) -> Array:
        if self._vec is None:
            self._vec = self._make_vec()
        if self.mode == "native":
            obs, _ = self._vec.reset(options={"context": contexts})
        else:
            obs, _ = self._vec.reset(seed=[int(s) for s in seeds])
        got = np.asarray(obs, dtype=np.float64).reshape(len(seeds), -1)
        if got.shape != contexts.shape or not np.array_equal(got, contexts):
            for k in range(len(seeds)):  # find and name the first sub-env that differs
                _check_context(obs[k], contexts[k], f"sub-env {k}")
        _, rewards, terminated, truncated, _ = self._vec.step(params)
        rewards = np.asarray(rewards, dtype=np.float64)
        if not np.all(terminated | truncated) or not np.isfinite(rewards).all():
            raise RuntimeError(f"expected one-step episodes with finite returns, got {rewards.tolist()}")
        return rewards

    def evaluate(self, seeds: NDArray[np.int64], contexts: Array, params: Array, label: str) -> Array:
        n, m = len(seeds), self.num_envs
        returns = np.empty(n)
        for start in range(0, n, m):
            rows = np.minimum(np.arange(start, start + m), n - 1)  # pad by repeating the last episode
            ok, chunk, last = retry(  # a failed async env is unusable: rebuild it before the next try
                lambda rows=rows: self._chunk(seeds[rows], contexts[rows], params[rows]),
                self.retries + 1,
                on_failure=self.close,
                reraise=(),  # even a named failure is retried, then located episode by episode
            )
            if not ok:
                self._locate(seeds, contexts, params, label, start, min(start + m, n), last)
            stop = min(start + m, n)
            returns[start:stop] = chunk[: stop - start]
        return returns

    def _locate(
        self, seeds: Any, contexts: Array, params: Array, label: str, a: int, b: int, last: Any
    ) -> None:
        """Re-run episodes a..b-1 serially to name the failing one; raise EpisodeError in any case."""
        if self._single is None:
            self._single = self.source.make()
        run_episodes(self._single, seeds[a:b], contexts[a:b], params[a:b], first=a, label=label, retries=0)
        raise EpisodeError(
            f"{label}, episodes {a}..{b - 1}: the vector env failed {self.retries + 1} time(s) although each "
            f"episode runs alone; last error: {type(last).__name__}: {last}"
        )

    def close(self) -> None:
        if self._vec is not None:
            vec, self._vec = self._vec, None
            try:
                vec.close()
            except Exception:  # a broken async env may fail to close; it is discarded either way
                pass


_RAY_ENVS: dict[str, gym.Env] = {}


def _ray_chunk(
    key: str, source: EnvSource, seeds: Any, contexts: Array, params: Array, first: int, label: str, n: int
) -> Array:
    """Body of a Ray task: the worker keeps one env per source."""
    if key not in _RAY_ENVS:
        _RAY_ENVS[key] = source.make()
    return run_episodes(_RAY_ENVS[key], seeds, contexts, params, first=first, label=label, retries=n)


class RayBackend(Backend):
    """Ray tasks, ``workers`` chunks per batch (default: the cluster's CPU count)."""

    name = "ray"

    def __init__(self, source: EnvSource, retries: int, workers: int | None) -> None:
        super().__init__(source, retries)
        self._ray = ray = import_optional("ray", "ray")
        self._owns = not ray.is_initialized()
        if self._owns:
            ray.init(num_cpus=workers, include_dashboard=False, logging_level="ERROR")
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
        self._owns = False


def make_backend(
    name: str,
    source: EnvSource,
    *,
    retries: int,
    workers: int | None,
    vector_mode: str,
    samples: int,
    env: gym.Env | None = None,
) -> Backend:
    """Build a backend by name (``"serial"``, ``"vector"`` or ``"ray"``)."""
    if name == "serial":
        return SerialBackend(source, retries, env)
    if name == "vector":
        return VectorBackend(source, retries, workers, vector_mode, samples)
    if name == "ray":
        return RayBackend(source, retries, workers)
    raise ValueError(f"backend: expected one of ['serial', 'vector', 'ray'], got {name!r}")
