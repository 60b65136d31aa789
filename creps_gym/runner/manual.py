"""A run driven episode by episode from outside: ``ask`` the parameters for a context, ``tell`` the return.

For a real robot (or any episode that creps_gym cannot run itself). The run folder is a run directory
(:class:`~creps_gym.runner.rundir.RunDir`) like any other: ``config.json`` (the :class:`RunConfig` with
``env`` None or a registered id to rehearse on, and in its ``meta`` the ``"ask_tell"`` spaces: the
parameter and context boxes), ``checkpoint.npz``, ``log.jsonl`` (one ``ask`` and one ``tell`` event per
episode, one iteration record per batch), ``run.lock``, ``policy.npz`` (the mean policy after the last
batch) and, once the run has finished, ``history.json``/``.csv``.

**Episodes.** :meth:`AskTellRun.ask` asks the optimiser for one context and keeps the episode pending,
with an id (1, 2, ... over the run). Up to ``samples`` episodes of a batch may be pending at once;
:meth:`AskTellRun.tell` records one's return (or drops it as failed: another episode takes its place).
When ``samples`` returns are told, the optimiser's ``tell`` gets the batch, the iteration is logged and
checkpointed, and ``policy.npz`` is rewritten. Each asked row is kept in the optimiser's pending batch
(its ``state_dict``'s ``pending_contexts``/``pending_params``), so the batch is told as the rows asked,
one ask at a time. A parameter outside the parameter box is clipped before it is printed: a robot never
gets one; the clipped row is what the optimiser is told (an external sample, counted in its
``external_samples`` diagnostic).

**Crash safety.** Every command takes the run's lock, writes its log event first and then the checkpoint
(atomically): a crash between two writes leaves the checkpoint of the step before, and the step done again
gives the same bits (asks are deterministic from the checkpointed Generator), its repeated log line
replacing the first (the log keeps the last copy of an episode and of an iteration). ``policy.npz`` and
the final result files are rewritten by the next command if a crash left them stale.

**Untrusted folder.** Everything read back is checked like the rest of a run directory (bounded reads,
no link followed, :func:`~creps_gym.runner.trust.check_trusted`, memory checked before allocating); the
episodes in the checkpoint must match the optimiser's pending batch and the spaces ``config.json``'s, or
the checkpoint is refused naming the file.
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass, replace
from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from creps_gym.envs.evaluation import finite_mean
from creps_gym.errors import ConfigError, RunDirError
from creps_gym.optimizers.base import ContextualOptimizer
from creps_gym.optimizers.registry import optimizer_class, recommended_samples, restore_optimizer
from creps_gym.runner import build, checks
from creps_gym.runner.config import RunConfig
from creps_gym.runner.history import History, IterationRecord, decode_float, encode_float
from creps_gym.runner.policy_store import RunPolicies
from creps_gym.runner.recovery import RESTART, chain_crc
from creps_gym.runner.rundir import RunDir
from creps_gym.runner.seeds import split_seed
from creps_gym.runner.trust import check_run_memory

__all__ = ["ASK_TELL", "AskTellRun", "Episode", "Spaces", "is_ask_tell", "refuse_resume"]

Array = NDArray[np.float64]
#: The key of an ask/tell run's spaces in ``config.json``'s ``meta`` and of its state in the checkpoint.
ASK_TELL = "ask_tell"
#: Where a box's options go for an optimiser whose configuration takes them (c-bo: its search box).
_BOX_OPTIONS = ("param_low", "param_high", "context_low", "context_high")


@dataclass(frozen=True)
class Spaces:
    """The parameter box (p,) and the context box (z,) of an ask/tell run (infinite bounds allowed)."""

    param_low: Array
    param_high: Array
    context_low: Array
    context_high: Array

    @classmethod
    def of(cls, **boxes: Any) -> Spaces:
        """Checked boxes: 1-D, non-empty, no NaN, low < high (``ValueError`` naming the box)."""
        arrays = {}
        for name in _BOX_OPTIONS:
            value = np.asarray(boxes[name], dtype=np.float64)
            if value.ndim != 1 or value.size == 0 or np.isnan(value).any():
                raise ValueError(f"{name}: expected a non-empty list of numbers, got {boxes[name]!r}")
            arrays[name] = value
        for kind in ("param", "context"):
            low, high = arrays[f"{kind}_low"], arrays[f"{kind}_high"]
            if low.shape != high.shape or not (low < high).all():
                raise ValueError(
                    f"{kind}_high: expected {low.size} numbers above {kind}_low {low.tolist()}, got "
                    f"{high.tolist()}"
                )
        return cls(**arrays)

    @classmethod
    def from_dict(cls, data: Any) -> Spaces:
        if not isinstance(data, dict) or sorted(data) != sorted(_BOX_OPTIONS):
            raise ValueError(f"expected the boxes {list(_BOX_OPTIONS)}, got {str(data)[:200]}")
        if not all(isinstance(v, list) for v in data.values()):
            raise ValueError("expected each box as a list of numbers")
        return cls.of(**{k: [decode_float(x) for x in v] for k, v in data.items()})

    def to_dict(self) -> dict[str, list[Any]]:
        return {name: [encode_float(x) for x in getattr(self, name)] for name in _BOX_OPTIONS}

    def env(self) -> gym.Env:
        """A stand-in env holding the boxes: what the optimiser's start and the policy files read."""
        return _SpacesEnv(self)

    def equals(self, other: Spaces) -> bool:
        return all(np.array_equal(getattr(self, n), getattr(other, n)) for n in _BOX_OPTIONS)


class _SpacesEnv(gym.Env):  # type: ignore[type-arg]
    """The spaces of an ask/tell run; its episodes run outside creps_gym."""

    def __init__(self, spaces: Spaces) -> None:
        self.action_space = gym.spaces.Box(spaces.param_low, spaces.param_high, dtype=np.float64)
        self.observation_space = gym.spaces.Box(spaces.context_low, spaces.context_high, dtype=np.float64)

    def step(self, action: Any) -> Any:
        raise RuntimeError("an ask/tell run's episodes run outside creps_gym: `creps-gym tell` their returns")


@dataclass
class Episode:
    """One episode of the current batch: its id, context (z,), asked and clipped params (p,), return."""

    episode: int
    context: Array
    asked: Array
    params: Array
    value: float | None = None  # the told return (None: pending)
    failed: bool = False

    @property
    def pending(self) -> bool:
        return self.value is None and not self.failed

    def to_dict(self) -> dict[str, Any]:
        data = {"episode": self.episode, "failed": self.failed, "value": self.value}
        data.update({k: getattr(self, k).tolist() for k in ("context", "asked", "params")})
        return data

    @classmethod
    def from_dict(cls, data: Any, p: int, z: int) -> Episode:
        """An episode of the checkpoint, checked (``ValueError`` naming what is wrong)."""
        if not isinstance(data, dict) or sorted(data) != ["asked", "context", "episode", "failed", "params",
                                                           "value"]:  # fmt: skip
            raise ValueError(f"expected an episode record, got {str(data)[:200]}")
        episode, value, failed = data["episode"], data["value"], data["failed"]
        if type(episode) is not int or episode < 1 or type(failed) is not bool:
            raise ValueError(f"expected an episode id >= 1 and a failed flag, got {episode!r}, {failed!r}")
        if value is not None and (type(value) is not float or not math.isfinite(value) or failed):
            raise ValueError(f"episode {episode}: expected a finite return or none, got {value!r}")
        arrays = {}
        for key, size in (("context", z), ("asked", p), ("params", p)):
            row = data[key]
            if not isinstance(row, list) or len(row) != size or not all(type(x) is float for x in row):
                raise ValueError(f"episode {episode}: expected {key} of {size} numbers, got {str(row)[:200]}")
            arrays[key] = np.array(row, dtype=np.float64)
            if not np.isfinite(arrays[key]).all():
                raise ValueError(f"episode {episode}: expected finite {key}, got {row}")
        return cls(episode, value=value, failed=failed, **arrays)


def is_ask_tell(run_dir: RunDir) -> bool:
    """Whether ``run_dir`` is an ask/tell run (its ``config.json``'s ``meta`` holds its spaces)."""
    return ASK_TELL in run_dir.document().get("meta", {})


def refuse_resume(run_dir: RunDir) -> None:
    """``ValueError`` for an ask/tell run: its episodes run outside creps_gym, ``resume`` cannot run them."""
    if is_ask_tell(run_dir):
        raise ValueError(
            f"run_dir: expected a run that creps_gym runs, got {run_dir.path}, an ask/tell run (its episodes "
            "run outside creps_gym): continue it with `creps-gym ask` and `creps-gym tell`"
        )


def _check_optimizer(name: str | None) -> None:
    if name is None or not issubclass(optimizer_class(name), ContextualOptimizer):
        raise ConfigError(
            "optimizer",
            "expected one of creps_gym's own optimisers (an adapter asks and tells whole populations, not "
            f"one episode at a time), got {name!r}",
        )


def _with_box_options(config: RunConfig, spaces: Spaces) -> RunConfig:
    """``config`` with the boxes as options of an optimiser that takes them (c-bo) and was not given them:
    the parameter box the user typed is the robot's, so the search stays inside it."""
    fields = getattr(optimizer_class(config.optimizer), "config_class", None)
    names = getattr(fields, "__dataclass_fields__", {})
    options = dict(config.optimizer_options)
    for name in _BOX_OPTIONS:
        value = getattr(spaces, name)
        if name in names and name not in options and np.isfinite(value).all():
            options[name] = value.tolist()
    return replace(config, optimizer_options=options)


class AskTellRun:
    """An ask/tell run folder, locked while the object is open (a context manager; see the module doc).

    Build it with :meth:`create` or :meth:`open`; :meth:`close` releases the lock.
    """

    def __init__(self, run_dir: RunDir, config: RunConfig, spaces: Spaces) -> None:
        self.run_dir, self.config, self.spaces = run_dir, config, spaces
        self.p, self.z = spaces.param_low.size, spaces.context_low.size
        self.policies = RunPolicies(config, spaces.env())
        self.optimizer: Any = None
        self.batch: list[Episode] = []
        self.iteration = self.log_crc = 0
        self.next_episode = 1
        self.started, self.stop_reason = time.time(), None
        self.env_rng = split_seed(config.seed)[0]

    def __enter__(self) -> AskTellRun:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def close(self) -> None:
        self.run_dir.lock.release()

    # -- creating and opening ---------------------------------------------------------------------------
    @classmethod
    def create(
        cls,
        path: str | os.PathLike[str],
        config: RunConfig,
        spaces: Spaces | None = None,
        *,
        overwrite: bool = False,
    ) -> AskTellRun:
        """A new ask/tell run in ``path``: ``config.env`` (a registered id) or ``spaces`` (exactly one)."""
        _check_optimizer(config.optimizer)
        if (config.env is None) == (spaces is None):
            raise TypeError("spaces: expected an env id in the config or the spaces (exactly one)")
        if spaces is None:
            env = build.make_env(str(config.env), dict(config.env_kwargs))
            try:
                checks.check_box_spaces(env)
                low, high = env.action_space.low.ravel(), env.action_space.high.ravel()
                spaces = Spaces.of(param_low=low, param_high=high, context_low=env.observation_space.low.ravel(),
                                   context_high=env.observation_space.high.ravel())  # fmt: skip
            finally:
                env.close()
        p, z = spaces.param_low.size, spaces.context_low.size
        if config.samples is None:
            config = replace(config, samples=recommended_samples(config.optimizer, p, z))
        config = _with_box_options(config, spaces)
        check_run_memory(config, p, z, covariance=True)
        optimizer = build.build_optimizer(config, spaces.env(), z, split_seed(config.seed)[1])
        checks.check_minimum_batch(optimizer, _Sizes(config, p, z))
        meta = {"env": config.env or "ask/tell", "optimizer": config.optimizer, "seed": config.seed,
                "n_params": p, "n_context_dims": z, "samples": config.samples, "metric": "return",
                ASK_TELL: spaces.to_dict()}  # fmt: skip
        run = cls(RunDir.create(path, config, meta, overwrite=overwrite), config, spaces)
        try:
            run.optimizer = optimizer
            run.run_dir.append_log({"event": "start", "iteration": 0, ASK_TELL: True})
            run._checkpoint(optimizer.state_dict())
        except BaseException:
            run.close()
            raise
        return run

    @classmethod
    def open(cls, path: str | os.PathLike[str]) -> AskTellRun:
        """The ask/tell run in ``path``, locked (:class:`RunDirError` if it is not one or is damaged)."""
        run_dir = RunDir.open(path)
        document = run_dir.document()
        if ASK_TELL not in document.get("meta", {}):
            raise RunDirError(
                f"{run_dir.file(RunDir.CONFIG)}: expected an ask/tell run (started by `creps-gym ask "
                "--new`), got a run that creps_gym runs (continue it with `creps-gym resume`)"
            )
        config = run_dir.config()
        try:
            spaces = Spaces.from_dict(document["meta"][ASK_TELL])
            _check_optimizer(config.optimizer)
            check_run_memory(config, spaces.param_low.size, spaces.context_low.size, covariance=True)
        except ValueError as exc:
            if isinstance(exc, RunDirError):
                raise
            raise run_dir.damaged(RunDir.CONFIG, exc, "restore it from a backup") from None
        run_dir.lock.acquire()
        run = cls(run_dir, config, spaces)
        try:
            run_dir.remove_temporaries()  # with the lock held: a dead writer's
            run._load()
            run._repair()
        except BaseException:
            run.close()
            raise
        return run

    def _load(self) -> None:
        """Restore the optimiser, the batch and the counts from the checkpoint (checked)."""
        loaded = self.run_dir.load_checkpoint(self.config)
        if loaded is None:
            raise self.run_dir.damaged(RunDir.CHECKPOINT, "missing", "restore it from a backup")
        state, optimizer_state = loaded
        try:
            own = state[ASK_TELL]
            if not isinstance(own, dict) or not Spaces.from_dict(own["spaces"]).equals(self.spaces):
                raise ValueError(f"expected the spaces of {RunDir.CONFIG}")
            self.batch = [Episode.from_dict(e, self.p, self.z) for e in own["batch"]]
            self.next_episode, self.started = own["next_episode"], own["started"]
            self._check_batch(own)
            self.optimizer = restore_optimizer(str(self.config.optimizer), optimizer_state)
            checks.check_optimizer_sizes(
                self.optimizer, "optimizer state", _Sizes(self.config, self.p, self.z)
            )
            self._check_pending(optimizer_state)
            self.env_rng.bit_generator.state = checks.generator_state(state["env_rng"])
            self.iteration, self.log_crc = int(state["iteration"]), int(state["log_crc"])
            self.stop_reason = state["stop_reason"]
        except (KeyError, TypeError, ValueError, IndexError, AttributeError, OverflowError) as exc:
            raise self.run_dir.damaged(RunDir.CHECKPOINT, exc, RESTART) from None

    def _check_batch(self, own: dict[str, Any]) -> None:
        ids = [e.episode for e in self.batch]
        told = sum(e.value is not None for e in self.batch)
        if (
            type(self.next_episode) is not int
            or ids != sorted(set(ids))
            or any(i >= self.next_episode for i in ids)
        ):
            raise ValueError(f"expected increasing episode ids below {self.next_episode!r}, got {ids}")
        if told >= self.config.samples or sum(not e.failed for e in self.batch) > self.config.samples:
            raise ValueError(
                f"expected fewer than {self.config.samples} told episodes in the batch, got {told}"
            )
        if type(self.started) not in (int, float) or not math.isfinite(self.started):
            raise ValueError(f"expected a start time, got {self.started!r}")

    def _check_pending(self, optimizer_state: dict[str, Any]) -> None:
        """The optimiser's pending batch must be the batch's asked rows, bit for bit."""
        if not self.batch:
            found = "pending_contexts" in optimizer_state
        else:
            contexts = np.asarray(optimizer_state.get("pending_contexts"), dtype=np.float64)
            params = np.asarray(optimizer_state.get("pending_params"), dtype=np.float64)
            rows = np.array([np.concatenate([e.context, e.asked]) for e in self.batch])
            found = contexts.ndim != 2 or not np.array_equal(np.concatenate([contexts, params], axis=1), rows)
        if found:
            raise ValueError("expected the episodes of the batch to be the optimiser's pending rows")

    def _repair(self) -> None:
        """Rewrite ``policy.npz`` (and a finished run's results) if a crash left them stale or missing."""
        if self.iteration:
            history = self.history()
            self.policies.write_final(self.run_dir, self.optimizer, history, only_changed=True)
            if self.stop_reason is not None:
                self.run_dir.write_results(history, only_changed=True)

    def history(self) -> History:
        """The history of the told batches (the checkpoint's, from the log)."""
        from creps_gym.runner.recovery import checkpoint_history

        records, _ = self.run_dir.read_log([])
        state = {"iteration": self.iteration, "log_crc": self.log_crc, "stop_reason": self.stop_reason}
        history = checkpoint_history(self.run_dir, state, records)
        if history is None:
            raise self.run_dir.damaged(
                RunDir.LOG, f"iterations 1 to {self.iteration} are not all intact", RESTART
            )
        return history

    # -- state ------------------------------------------------------------------------------------------
    def _checkpoint(self, optimizer_state: dict[str, Any]) -> None:
        if self.batch:
            optimizer_state = dict(optimizer_state)
            optimizer_state["pending_contexts"] = np.array([e.context for e in self.batch])
            optimizer_state["pending_params"] = np.array([e.asked for e in self.batch])
        else:
            optimizer_state = {k: v for k, v in optimizer_state.items() if not k.startswith("pending_")}
        own = {"spaces": self.spaces.to_dict(), "batch": [e.to_dict() for e in self.batch],
               "next_episode": self.next_episode, "started": self.started}  # fmt: skip
        state = {
            "env_rng": self.env_rng.bit_generator.state,
            "iteration": self.iteration,
            "episodes": self.iteration * self.config.samples,
            "elapsed": max(0.0, time.time() - self.started),
            "stop_reason": self.stop_reason,
            "log_crc": self.log_crc,
            "best_policy": None,
            ASK_TELL: own,
        }
        self.run_dir.save_checkpoint(state, optimizer_state, self.config)

    @property
    def pending(self) -> list[Episode]:
        """The episodes asked and not told yet."""
        return [e for e in self.batch if e.pending]

    def _slots(self) -> int:
        """How many more episodes this batch may ask."""
        return self.config.samples - sum(not e.failed for e in self.batch)

    # -- ask and tell -----------------------------------------------------------------------------------
    def ask(self, context: Any, *, extrapolate: bool = False) -> Episode:
        """Ask the parameters for one ``context`` (z,); the episode stays pending until it is told.

        Raises ``ValueError`` naming ``context`` for a bad one (outside the context box unless
        ``extrapolate``), ``RuntimeError`` when the run has finished or the batch is fully asked.
        """
        row = np.asarray(context, dtype=np.float64)
        if row.shape != (self.z,) or not np.isfinite(row).all():
            raise ValueError(f"context: expected {self.z} finite numbers, got {np.asarray(context).tolist()}")
        low, high = self.spaces.context_low, self.spaces.context_high
        if not extrapolate and not ((low <= row) & (row <= high)).all():
            raise ValueError(
                f"context: expected a context in the box [{low.tolist()}, {high.tolist()}], got {row.tolist()} "
                "(pass extrapolate to ask outside it)"
            )
        self._check_open()
        if self._slots() == 0:
            ids = [e.episode for e in self.pending]
            raise RuntimeError(
                f"ask: expected a batch with room, got {self.config.samples} episodes asked and episodes {ids} "
                "pending: tell their returns (or that they failed) first"
            )
        asked = checks.real_params(self.optimizer.ask(row[None, :]), "ask", (1, self.p))[0]
        params = np.clip(asked, self.spaces.param_low, self.spaces.param_high)
        episode = Episode(self.next_episode, row.copy(), asked, params)
        entry = {"event": "ask", "episode": episode.episode, "iteration": self.iteration + 1}
        self.run_dir.append_log({**entry, "context": row.tolist(), "params": params.tolist()})
        self.batch.append(episode)
        self.next_episode += 1
        self._checkpoint(self.optimizer.state_dict())
        return episode

    def _check_open(self) -> None:
        if self.stop_reason is not None:
            raise RuntimeError(
                f"ask: expected a run that goes on, got one that has finished (stop: {self.stop_reason}, "
                f"{self.iteration} iterations); its policy is in {self.run_dir.file(RunDir.POLICY)}"
            )

    def tell(
        self, value: float | None, episode: int | None = None, *, failed: bool = False
    ) -> dict[str, Any]:
        """Record the return ``value`` of a pending ``episode`` (the only pending one if None), or that it
        ``failed``; returns what happened (``"iteration"``: the record when it completed the batch)."""
        if failed == (value is not None):
            raise ValueError(
                f"value: expected a return or failed=True (exactly one), got {value!r}, {failed}"
            )
        if value is not None and (isinstance(value, bool) or not math.isfinite(float(value))):
            raise ValueError(f"value: expected a finite return, got {value!r}")
        pending = self.pending
        ids = [e.episode for e in pending]
        if episode is None and len(pending) != 1:
            raise RuntimeError(f"episode: expected the episode to tell (pending: {ids or 'none'}), got none")
        found = [e for e in pending if episode is None or e.episode == episode]
        if not found:
            raise ValueError(f"episode: expected a pending episode {ids or '(none pending)'}, got {episode}")
        target = found[0]
        outcome = {"failed": True} if failed else {"return": float(value)}  # type: ignore[arg-type]
        self.run_dir.append_log({"event": "tell", "episode": target.episode, **outcome})
        target.failed, target.value = failed, None if failed else float(value)  # type: ignore[arg-type]
        if sum(e.value is not None for e in self.batch) < self.config.samples:
            self._checkpoint(self.optimizer.state_dict())
            return {"episode": target.episode, "iteration": None}
        return {"episode": target.episode, "iteration": self._tell_batch()}

    def _tell_batch(self) -> IterationRecord:
        """Tell the optimiser the batch, log its record, checkpoint, write ``policy.npz``."""
        told = [e for e in self.batch if e.value is not None]
        contexts = np.array([e.context for e in told])
        params = np.array([e.params for e in told])
        returns = np.array([e.value for e in told], dtype=np.float64)
        external = any(not np.array_equal(e.params, e.asked) for e in told)
        self.optimizer.tell(contexts, params, returns, allow_external=external)
        self.iteration += 1
        episodes = self.iteration * self.config.samples
        diagnostics = {str(k): float(v) for k, v in dict(self.optimizer.diagnostics).items()}
        wall = max(0.0, time.time() - self.started)
        record = IterationRecord(
            self.iteration, episodes, finite_mean(returns), math.nan, math.nan, wall, diagnostics
        )
        self.stop_reason = self._stop()
        self.run_dir.append_log(record.to_dict(), log_crc=self.log_crc)
        self.log_crc = chain_crc(self.log_crc, record.to_dict())
        self.batch = []
        self._checkpoint(self.optimizer.state_dict())
        history = self.history()
        if self.stop_reason is not None:
            self.run_dir.append_log(
                {"event": "end", "iteration": self.iteration, "stop_reason": self.stop_reason}
            )
        self.policies.write_final(self.run_dir, self.optimizer, history, only_changed=False)
        if self.stop_reason is not None:
            self.run_dir.write_results(history)
        return record

    def _stop(self) -> str | None:
        """The loop's stop reasons after a batch: the iteration and episode budgets, the optimiser's own."""
        config = self.config
        if self.iteration >= config.iterations:
            return "iterations"
        if config.max_episodes is not None and (self.iteration + 1) * config.samples > config.max_episodes:
            return "max_episodes"
        met = checks.stop_criteria(self.optimizer.stop())
        return f"optimizer: {', '.join(met)}" if met else None


@dataclass
class _Sizes:
    """What the runner's checks read of a run: its config and sizes."""

    config: RunConfig
    n_params: int
    n_context_dims: int
    env_name: str = "the run's spaces"
