"""A run driven episode by episode from outside: ``ask`` the parameters for a context, ``tell`` the return.

For a real robot (or any episode that creps_gym cannot run itself). The folder is a run directory
(:class:`~creps_gym.runner.rundir.RunDir`): ``config.json`` (``env`` None or a registered id to rehearse
on; its ``meta``'s ``"ask_tell"``: the parameter and context boxes), ``checkpoint.npz``, ``log.jsonl``
(an ``ask`` and a ``tell`` event per episode, an iteration record per batch), ``run.lock``, ``policy.npz``
(the mean policy after the last batch) and, once finished, ``history.json``/``.csv``.

**Episodes.** :meth:`AskTellRun.ask` asks the optimiser for one context and keeps the episode pending,
with an id (1, 2, ... over the run); up to ``samples`` of a batch may be pending at once. It asks with
``ask_more``, as one more row of the batch asked so far: c-bo chooses it after the batch's episodes (its
kriging believer), so episodes asked at one context spread out instead of repeating one θ.
:meth:`AskTellRun.tell` records one's return (or drops it as failed: another episode takes its place).
At ``samples`` returns the optimiser's ``tell`` gets the batch, the iteration is logged and checkpointed
and ``policy.npz`` rewritten. The asked rows are kept as the optimiser's pending batch (its
``state_dict``'s ``pending_contexts``/``pending_params``), so the batch is told as asked, one ask at a
time. A parameter outside the box is clipped before it is printed (a robot never gets one) and told as
clipped (an external sample, counted in the ``external_samples`` diagnostic).

**Crash safety.** Every command holds the run's lock, appends its log event, then replaces the checkpoint
atomically: after a crash between two writes the checkpoint is the step's before, and the step done again
gives the same bits (asks draw from the checkpointed Generator) and repeats its log line (same episode
id: the last copy counts). The next command rewrites a ``policy.npz`` or result file a crash left stale.

**Untrusted folder.** Everything read back is checked like the rest of a run directory (bounded reads,
no link followed, :func:`~creps_gym.runner.rundir.references.check_trusted`, memory checked before
allocating); the checkpoint's episodes must be the optimiser's pending rows and its spaces
``config.json``'s, or the checkpoint is refused naming the file.
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import replace
from typing import Any

import numpy as np

from creps_gym.envs.evaluation import finite_mean
from creps_gym.errors import RunDirError
from creps_gym.optimizers.policy_file import Policy
from creps_gym.optimizers.registry import recommended_samples, restore_optimizer
from creps_gym.runner import build, protocol
from creps_gym.runner.config import RunConfig
from creps_gym.runner.env_model import check_box_spaces
from creps_gym.runner.history import History, IterationRecord
from creps_gym.runner.manual_records import (
    ASK_TELL,
    Episode,
    Sizes,
    Spaces,
    check_optimizer,
    is_ask_tell,
    refuse_resume,
    with_box_options,
)
from creps_gym.runner.rundir import RunDir
from creps_gym.runner.rundir.checkpoint import check_run_memory
from creps_gym.runner.rundir.log_chain import chain_crc
from creps_gym.runner.rundir.policies import RunPolicies
from creps_gym.runner.rundir.recovery import RESTART
from creps_gym.runner.seeds import split_seed

__all__ = ["ASK_TELL", "AskTellRun", "Episode", "Spaces", "is_ask_tell", "refuse_resume"]


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
        check_optimizer(config.optimizer)
        if (config.env is None) == (spaces is None):
            raise TypeError("spaces: expected an env id in the config or the spaces (exactly one)")
        if spaces is None:
            env = build.make_env(str(config.env), dict(config.env_kwargs))
            try:
                check_box_spaces(env)
                boxes = {"param": env.action_space, "context": env.observation_space}
                ends = {
                    f"{kind}_{end}": getattr(box, end).ravel()
                    for kind, box in boxes.items()
                    for end in ("low", "high")
                }
                spaces = Spaces.of(**ends)
            finally:
                env.close()
        p, z = spaces.param_low.size, spaces.context_low.size
        if config.samples is None:
            config = replace(config, samples=recommended_samples(config.optimizer, p, z))
        config = with_box_options(config, spaces)
        check_run_memory(config, p, z, covariance=True)
        optimizer = build.build_optimizer(config, spaces.env(), z, split_seed(config.seed)[1])
        protocol.check_minimum_batch(optimizer, Sizes(config, p, z))
        meta = {"env": config.env or "ask/tell", "optimizer": config.optimizer, "seed": config.seed}
        meta.update(n_params=p, n_context_dims=z, samples=config.samples, metric="return")
        meta[ASK_TELL] = spaces.to_dict()
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
            check_optimizer(config.optimizer)
            if config.samples is None:
                raise ValueError("samples: expected the batch size, got None")
            check_run_memory(config, spaces.param_low.size, spaces.context_low.size, covariance=True)
        except (TypeError, ValueError) as exc:
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
            protocol.check_optimizer_sizes(
                self.optimizer, "optimizer state", Sizes(self.config, self.p, self.z)
            )
            self._check_pending(optimizer_state)
            self.env_rng.bit_generator.state = protocol.generator_state(state["env_rng"])
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
        if self.iteration and not self._policy_written():
            self.policies.write_final(self.run_dir, self.optimizer, self.history(), only_changed=False)
        if self.stop_reason is not None:
            self.run_dir.write_results(self.history(), only_changed=True)

    def _policy_written(self) -> bool:
        """Whether ``policy.npz`` is this run's after the checkpoint's iteration (its source says so)."""
        try:
            source = Policy.load(self.run_dir.file(RunDir.POLICY)).source
        except (OSError, ValueError):
            return False
        return source.get("iteration") == self.iteration and source.get("run") == self.policies.fingerprint

    def history(self) -> History:
        """The history of the told batches (the checkpoint's, from the log)."""
        from creps_gym.runner.rundir.recovery import checkpoint_history

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
        own = {"spaces": self.spaces.to_dict(), "batch": [e.to_dict() for e in self.batch]}
        own.update(next_episode=self.next_episode, started=self.started)
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
                f"context: expected a context in the box [{low.tolist()}, {high.tolist()}], got "
                f"{row.tolist()} (pass extrapolate to ask outside it)"
            )
        self._check_open()
        if self._slots() == 0:
            ids = [e.episode for e in self.pending]
            raise RuntimeError(
                f"ask: expected a batch with room, got {self.config.samples} episodes asked and episodes "
                f"{ids} pending: tell their returns (or that they failed) first"
            )
        asked = protocol.real_params(self.optimizer.ask_more(row[None, :]), "ask", (1, self.p))[0]
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
            known = episode is not None and 1 <= episode < self.next_episode
            why = "told already, or failed" if known else "never asked"
            raise ValueError(
                f"episode: expected a pending episode {ids or '(none pending)'}, got {episode} ({why})"
            )
        target, told = found[0], sum(e.value is not None for e in self.batch) + (not failed)
        history = self.history() if told == self.config.samples else None  # a damaged log: before writing
        outcome = {"failed": True} if failed else {"return": float(value)}  # type: ignore[arg-type]
        self.run_dir.append_log({"event": "tell", "episode": target.episode, **outcome})
        target.failed, target.value = failed, None if failed else float(value)  # type: ignore[arg-type]
        if history is None:
            self._checkpoint(self.optimizer.state_dict())
            return {"episode": target.episode, "iteration": None}
        return {"episode": target.episode, "iteration": self._tell_batch(history)}

    def _tell_batch(self, history: History) -> IterationRecord:
        """Tell the optimiser the batch, log its record, checkpoint, write ``policy.npz`` (and, when the
        run has finished, its results; ``history``: the iterations before)."""
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
        history.append(record)
        history.stop_reason = self.stop_reason
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
        met = protocol.stop_criteria(self.optimizer.stop())
        return f"optimizer: {', '.join(met)}" if met else None
