"""The vector backend: a Gymnasium vector env runs each chunk of an iteration's episodes.

The native vector env (``vector_entry_point``: one batched ``evaluate`` call, contexts set through
``reset(options={"context": ...})``) where registered, else ``AsyncVectorEnv`` (or ``SyncVectorEnv`` with
``vector_mode="sync"``) whose sub-envs are reset with the per-episode seeds (and contexts, for batched
context draws). The failure policy is that of :mod:`creps_gym.runner.backends`.
"""

from __future__ import annotations

import os
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.envs.registration import load_env_creator
from gymnasium.vector import AutoresetMode
from numpy.typing import NDArray

from creps_gym.envs.base import ContextualEpisodicVectorEnv
from creps_gym.runner.backends.episodes import (
    Array,
    Backend,
    EnvSource,
    check_context,
    episode_return,
    retry,
    run_episodes,
)

__all__ = ["SubEnvEpisode", "VectorBackend"]


class SubEnvEpisode(gym.Wrapper):
    """The runner's wrapper of a Sync/Async vector env's sub-envs.

    It checks each reward with :func:`episode_return` (the vector env would otherwise store a str or bool
    reward as a float), and a reset with ``options={"contexts": {seed: context}}`` (the batch's table,
    the same for every sub-env) resets with the sub-env's own context: ``reset(seed=seed,
    options={"context": table[seed]})``.
    """

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict]:
        """Reset; a ``"contexts"`` table picks this sub-env's context by its seed."""
        if options is not None and "contexts" in options:
            options = {"context": options["contexts"][seed]}
        return self.env.reset(seed=seed, options=options)

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict]:
        """Step the env and check its reward."""
        obs, reward, terminated, truncated, info = self.env.step(action)
        return obs, episode_return(reward), terminated, truncated, info


class VectorBackend(Backend):
    """A Gymnasium vector env; batches larger than ``num_envs`` run in chunks (the last one padded).

    The vector env is built when the backend is: an env it cannot replicate (a wrapper that Gymnasium
    cannot re-create from the spec, or copies whose spaces differ from the env's) raises TypeError then,
    not as an episode failure.
    """

    name = "vector"

    def __init__(self, source: EnvSource, retries: int, workers: int | None, mode: str, samples: int) -> None:
        super().__init__(source, retries)
        spec = source.spec()
        registered = source.registered_spec() if isinstance(spec, str) else spec
        wrapped = bool(registered.additional_wrappers)  # a native vector env cannot apply them
        native = registered.vector_entry_point is not None and not wrapped
        if mode == "native" and not native:
            why = "its spec adds wrappers" if wrapped else "not native"
            raise ValueError(
                f"vector_mode: expected 'auto', 'sync' or 'async' for {registered.id} ({why}), got 'native'"
            )
        self.mode = ("native" if native else "async") if mode == "auto" else mode
        default = samples if self.mode == "native" else min(samples, os.cpu_count() or 1)
        self.num_envs = workers or default
        self._single: gym.Env | None = None
        self._vec: Any = self._build(registered.id)

    def _make_vec(self) -> Any:
        modes = {"native": "vector_entry_point", "sync": "sync", "async": "async"}
        wrappers = None if self.mode == "native" else [SubEnvEpisode]
        return gym.make_vec(
            self.source.spec(),
            self.num_envs,
            vectorization_mode=modes[self.mode],
            wrappers=wrappers,
            **self._no_autoreset(),
            **self.source.kwargs,
        )

    def _no_autoreset(self) -> dict[str, Any]:
        """A creps_gym native vector env need not draw the next contexts after each step: the backend
        sets them at every reset (``DISABLED`` autoreset mode)."""
        if self.mode != "native":
            return {}
        spec = self.source.spec()
        creator = (self.source.registered_spec() if isinstance(spec, str) else spec).vector_entry_point
        if isinstance(creator, str):
            creator = load_env_creator(creator)
        ours = isinstance(creator, type) and issubclass(creator, ContextualEpisodicVectorEnv)
        return {"autoreset_mode": AutoresetMode.DISABLED} if ours else {}

    def _build(self, env_name: str) -> Any:
        """The first vector env, with set-up errors named as such."""
        try:
            vec = self._make_vec()
        except Exception as exc:  # a wrapper Gymnasium cannot re-create, an entry point that fails, ...
            raise TypeError(
                f"env: the vector backend ({self.mode}) could not build copies of {env_name}: "
                f"{type(exc).__name__}: {exc}. Register the env, make its wrappers inherit "
                "gymnasium.utils.RecordConstructorArgs, or use backend='serial' or 'ray'"
            ) from exc
        env = self.source.env
        for name in ("observation_space", "action_space"):
            if env is not None and getattr(vec, "single_" + name) != getattr(env, name):
                vec.close()
                raise TypeError(
                    f"env: the vector backend's copies of {env_name} have {name} "
                    f"{getattr(vec, 'single_' + name)}, expected the env object's {getattr(env, name)}; "
                    "use backend='serial' or 'ray'"
                )
        return vec

    def _chunk(self, seeds: NDArray[np.int64], contexts: Array, params: Array) -> Array:
        if self._vec is None:
            self._vec = self._make_vec()
        if self.mode == "native":
            obs, _ = self._vec.reset(options={"context": contexts})
        else:
            table = {"contexts": dict(zip(map(int, seeds), contexts, strict=True))}
            options = table if self.source.set_context else None
            obs, _ = self._vec.reset(seed=[int(s) for s in seeds], options=options)
        got = np.asarray(obs, dtype=np.float64).reshape(len(seeds), -1)
        if got.shape != contexts.shape or not np.array_equal(got, contexts):
            for k in range(len(seeds)):  # find and name the first sub-env that differs
                check_context(obs[k], contexts[k], f"sub-env {k}")
        _, rewards, terminated, truncated, _ = self._vec.step(params)
        rewards = np.asarray(rewards, dtype=np.float64)
        if not np.all(terminated | truncated) or not np.isfinite(rewards).all():
            raise RuntimeError(f"expected one-step episodes with finite returns, got {rewards.tolist()}")
        return rewards

    def evaluate(self, seeds: NDArray[np.int64], contexts: Array, params: Array, label: str) -> Array:
        n, m = len(seeds), self.num_envs
        returns = np.empty(n)
        for start in range(0, n, m):
            stop = min(start + m, n)
            rows = np.minimum(np.arange(start, start + m), n - 1)  # pad by repeating the last episode
            ok, chunk, _ = retry(  # a failed async env is unusable: rebuild it before the next try
                lambda rows=rows: self._chunk(seeds[rows], contexts[rows], params[rows]),
                self.retries + 1,
                on_failure=self.close,
                reraise=(),  # even a named failure is retried, then re-run episode by episode
            )
            if ok:
                returns[start:stop] = chunk[: stop - start]
            else:  # not charged to the chunk's episodes: each runs alone with the serial budget
                returns[start:stop] = self._one_by_one(seeds, contexts, params, label, start, stop)
        return returns

    def _one_by_one(self, seeds: Any, contexts: Array, params: Array, label: str, a: int, b: int) -> Array:
        """Episodes a..b-1 one by one in the main process, with the serial backend's retry policy."""
        if self._single is None:
            self._single = self.source.make()
        return run_episodes(
            self._single,
            seeds[a:b],
            contexts[a:b],
            params[a:b],
            first=a,
            label=label,
            retries=self.retries,
            set_context=self.source.set_context,
        )

    def close(self) -> None:
        if self._vec is not None:
            vec, self._vec = self._vec, None
            try:
                vec.close()
            except Exception:  # a broken async env may fail to close; it is discarded either way
                pass
