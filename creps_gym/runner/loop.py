"""The generic loop: any ask/tell optimiser on any contextual episodic env.

One iteration draws its episodes' reset seeds and contexts from the env stream
(:mod:`creps_gym.runner.contexts`: one batched draw where the env allows it, else one seeded
``env.reset`` per episode), asks the optimiser, runs the episodes on the backend and tells the returns. At
the configured interval (and at the last iteration) the recommended (mean) policy is evaluated on a fixed,
seeded set of test contexts with :func:`creps_gym.envs.evaluation.evaluate_policy` (mean regret where the
env supports it, mean return otherwise). For envs that are not creps_gym models, or models under wrappers
that may change what the agent sees, sends or gets (e.g. ``TransformReward``, ``NormalizeParams``; see
:func:`creps_gym.runner.env_model.unwrapped_model`), the evaluation runs test episodes of the env itself
with seeded resets, so it sees what training sees.
**Failures.** Resets that read contexts and the evaluation are retried like episodes (``config.retries``
times, then :class:`~creps_gym.errors.EpisodeError`); episodes follow the backends' policy.
**Seeds.** :func:`~creps_gym.runner.seeds.split_seed` splits the master seed into the env stream (episode
seeds and contexts), the optimiser's seed and the test contexts' seed (a context selector has its own;
:class:`~creps_gym.runner.seeds.SeedPlan` names every stream's child). The same seed gives a bit-identical
History (wall times aside) on every backend and after any resume. **Checkpoints** hold the optimiser's and
the loop's state (env stream, counts, wall time, stop reason, a checksum of the records, the best evaluated
policy: :mod:`~creps_gym.runner.rundir.policies`): O(1). A resume rebuilds the history from the log.
**Stop reasons** (``History.stop_reason``): ``"iterations"``, ``"max_episodes"`` (the next iteration would
exceed the budget), ``"target_regret"``, ``"max_time"``, ``"divergence"`` (see
:mod:`~creps_gym.runner.divergence`), ``"optimizer: <criteria>"`` (its own ``stop()``), ``"callback"``.
"""

from __future__ import annotations

import functools
import math
import os
import time
from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from creps_gym._validation import config_field
from creps_gym.envs.evaluation import finite_mean, test_contexts
from creps_gym.errors import ConfigError, EpisodeError
from creps_gym.optimizers.registry import recommended_samples
from creps_gym.runner import build, env_model, protocol
from creps_gym.runner.backends import Backend, EnvSource, retry
from creps_gym.runner.backends.ray import check_ray_cluster
from creps_gym.runner.build import build_backend, build_optimizer
from creps_gym.runner.callbacks import as_callback
from creps_gym.runner.config import RunConfig
from creps_gym.runner.contexts import ContextDraws
from creps_gym.runner.divergence import DivergenceWatch, evaluation_loss
from creps_gym.runner.history import History, IterationRecord
from creps_gym.runner.loop_state import loop_state, restore
from creps_gym.runner.rundir import RunDir
from creps_gym.runner.rundir.checkpoint import check_run_memory
from creps_gym.runner.rundir.log_chain import chain_crc
from creps_gym.runner.rundir.policies import RunPolicies, evaluate_contexts, evaluated_policy
from creps_gym.runner.rundir.session import DeferredInterrupt
from creps_gym.runner.seeds import split_seed

__all__ = ["Runner"]

Array = NDArray[np.float64]


class Runner:
    """Runs one configuration; :func:`creps_gym.runner.run` and :func:`creps_gym.runner.resume` use it.

    Built once: a new run builds its optimiser (or takes the object), a continued one restores it.

    Parameters
    ----------
    config : RunConfig
    env : gymnasium.Env, optional
        The env object (required when ``config.env`` is None).
    optimizer : AskTellOptimizer, optional
        An optimiser object (required when ``config.optimizer`` is None, unless the run is continued).
    run_dir : RunDir or path-like, optional
        A :class:`RunDir` continues that run from its checkpoint, if any (its lock is held until ``run``
        ends). A path starts a new run directory there (see :meth:`RunDir.create`; ``FileExistsError`` if
        it holds a run, unless ``overwrite``).
    overwrite : bool
        Replace a run already in the new ``run_dir``.
    callbacks : sequence of Callback or callables
    optimizer_class : type, optional
        Class whose ``from_state_dict`` restores an object optimiser's checkpoint.
    context_selector : ContextSelector, optional
        A selector object, instead of ``config.context_selector``.
    """

    _watch: DivergenceWatch | None = None  # the divergence stop's, built at the first step from the history

    def __init__(
        self,
        config: RunConfig,
        *,
        env: gym.Env | None = None,
        optimizer: Any = None,
        run_dir: RunDir | str | os.PathLike[str] | None = None,
        overwrite: bool = False,
        callbacks: Sequence[Any] = (),
        optimizer_class: Any = None,
        context_selector: Any = None,
    ) -> None:
        self.config = config
        if run_dir is not None and not isinstance(run_dir, RunDir) and not os.fspath(run_dir):
            raise ValueError("out: expected a directory path, got '' (write '.' for the current directory)")
        if (config.env is None) == (env is None):
            raise TypeError("env: expected an env id in the config or an env object (exactly one)")
        if (config.optimizer is None) == (optimizer is None) and optimizer_class is None:
            raise TypeError("optimizer: expected a registry name or an optimiser object (exactly one)")
        with config_field("env_kwargs" if config.env_kwargs else None):  # the env's error about one of them
            self.env = env if env is not None else build.make_env(config.env, config.env_kwargs)
        env_model.check_box_spaces(self.env)
        self.env_rng, optimizer_seed, eval_seed = split_seed(config.seed)
        self.n_context_dims = int(np.prod(self.env.observation_space.shape))
        self.n_params = int(np.prod(self.env.action_space.shape))
        if config.samples is None:
            batch = recommended_samples(config.optimizer or optimizer, self.n_params, self.n_context_dims)
            self.config = config = replace(config, samples=batch)
        check_run_memory(config, self.n_params, self.n_context_dims, covariance=config.optimizer is not None)
        with config_field("context_selector_options" if config.context_selector_options else None):
            self.draws = ContextDraws.for_run(self.env, config, context_selector)
        obj = None if config.env else self.env
        self.source = EnvSource(config.env, dict(config.env_kwargs), obj, set_context=self.draws.batched)
        self._model = env_model.unwrapped_model(self.env)
        self.test_contexts = self._test_contexts(eval_seed)
        if config.target_regret is not None and not self.has_regret:
            raise ConfigError(
                "target_regret",
                f"expected None for {self.env_name}, which has no regret, got {config.target_regret}",
            )
        self.callbacks = [as_callback(c) for c in callbacks]
        self.policies = RunPolicies(config, self.env)  # the best evaluated mean policy
        self.iteration = self.episodes = 0
        self._elapsed_before, self._log_crc = 0.0, 0
        self._clock = time.perf_counter()
        self.run_dir = run_dir if isinstance(run_dir, RunDir) else None
        if self.run_dir is None:
            self.optimizer = self._new_optimizer(optimizer, optimizer_seed, check=True)
            self.history = History(meta=self._meta())
            if run_dir is not None:
                check_ray_cluster(self.config)  # a wrong address fails before the folder is created
                self.run_dir = RunDir.create(run_dir, self.config, self.history.meta, overwrite=overwrite)
            return
        self.run_dir.lock.acquire()  # held until run() ends: one writer per run directory
        try:
            restore(self, self.run_dir, optimizer, optimizer_class, optimizer_seed)
        except BaseException:
            self.run_dir.lock.release()
            raise

    # -- set-up ----------------------------------------------------------------------------------------------
    @property
    def env_name(self) -> str:
        """The env id, or the env's class name for env objects without a spec."""
        spec = getattr(self.env, "spec", None)
        return self.config.env or (spec.id if spec is not None else type(self.env.unwrapped).__name__)

    def _new_optimizer(self, optimizer: Any, seed: int, check: bool) -> Any:
        """The optimiser object as given, or the registered one built (batch size checked if ``check``)."""
        if optimizer is not None:
            protocol.check_optimizer(optimizer)
        else:
            make = functools.partial(build_optimizer, self.config, self.env, self.n_context_dims, seed)
            optimizer = make()
        protocol.check_optimizer_sizes(optimizer, "optimizer", self)
        if check:  # a new run: below the optimiser's minimum batch, the search diverges
            protocol.check_minimum_batch(optimizer, self)
        if check and self.config.optimizer is not None:  # and a named optimiser must accept the batch
            n, contexts, options = self.config.samples, self.test_contexts, self.config.optimizer_options
            if self._model is not None:
                contexts = self._model.sample_contexts(np.random.default_rng(seed), n)
            contexts = contexts[np.arange(n) % len(contexts)]
            protocol.check_batch_size(make, contexts, options, repr(self.config.optimizer))
        return optimizer

    @property
    def has_regret(self) -> bool:
        """Whether the evaluation reports a regret (the env is a creps_gym model with ``SupportsRegret``)."""
        return self._model is not None and callable(getattr(self._model, "regret", None))

    def _test_contexts(self, seed: int) -> Array:
        """The test contexts; ``eval_seeds`` are the reset seeds of test episodes (envs without a model)."""
        self.eval_seeds = np.random.default_rng(seed).integers(0, 2**63 - 1, size=self.config.eval_contexts)
        if self._model is not None:
            return test_contexts(self._model, self.config.eval_contexts, seed)
        return self.draws.reset_contexts(self.eval_seeds, "evaluation")

    def _meta(self) -> dict[str, Any]:
        return {
            "env": self.env_name,
            "optimizer": self.config.optimizer or type(self.optimizer).__name__,
            "seed": self.config.seed,
            "n_params": self.n_params,
            "n_context_dims": self.n_context_dims,
            "samples": self.config.samples,
            "metric": "regret" if self.has_regret else "return",
        }

    def make_backend(self) -> Backend:
        """The configured backend (the caller closes it)."""
        return build_backend(self.config, self.source, self.env)

    # -- checkpoints -----------------------------------------------------------------------------------------
    def checkpoint(self) -> None:
        """Write the optimiser's and the loop's state (no-op without a run directory); O(1) in the run."""
        if self.run_dir is not None:
            state = loop_state(self, self.run_dir)
            self.run_dir.save_checkpoint(state, self.optimizer.state_dict(), self.config)

    @property
    def elapsed(self) -> float:
        """Wall time of the run so far in seconds (summed over resumes)."""
        return self._elapsed_before + time.perf_counter() - self._clock

    # -- one iteration ---------------------------------------------------------------------------------------
    def evaluate(self) -> tuple[float, float]:
        """Mean return and mean regret (NaN if none) of the recommended policy on the test contexts.

        A failure is retried like an episode's (``config.retries`` times), then raises EpisodeError.
        """
        ok, value, last = retry(self._evaluate_once, self.config.retries + 1)
        if ok:
            return value
        raise EpisodeError(
            f"iteration {self.iteration}, evaluation of the recommended policy on the test contexts failed "
            f"{self.config.retries + 1} time(s); last error: {type(last).__name__}: {last}"
        ) from last

    def _evaluate_once(self) -> tuple[float, float]:
        where = (self.env, self._model, self.test_contexts, self.eval_seeds, self.config.retries)
        return evaluate_contexts(evaluated_policy(self.optimizer), *where)

    def _stop_before_evaluation(self) -> str | None:
        config = self.config
        if self.iteration >= config.iterations:
            return "iterations"
        if config.max_episodes is not None and self.episodes + config.samples > config.max_episodes:
            return "max_episodes"
        if config.max_time is not None and self.elapsed >= config.max_time:
            return "max_time"
        met = protocol.stop_criteria(self.optimizer.stop())
        return f"optimizer: {', '.join(met)}" if met else None

    def step(self, backend: Backend) -> tuple[IterationRecord, str | None]:
        """Run one iteration on ``backend``; returns its record and the stop reason (None: go on)."""
        self._watch = self._watch or DivergenceWatch.of_history(self.config.divergence, self.history.records)
        n, label = self.config.samples, f"iteration {self.iteration + 1}"
        seeds, contexts = self.draws.draw(self.env_rng, n, label, self.optimizer)
        params = protocol.real_params(self.optimizer.ask(contexts), "ask", (n, self.n_params))
        returns = backend.evaluate(seeds, contexts, params, label)
        self.optimizer.tell(contexts, params, returns)
        self.draws.tell(contexts, returns, self.optimizer)
        self.iteration += 1
        self.episodes += n
        reason = self._stop_before_evaluation()
        eval_return = eval_regret = math.nan
        if reason is not None or self.iteration % self.config.eval_every == 0:
            eval_return, eval_regret = self.evaluate()
            self.policies.offer(self.optimizer, self.iteration, eval_return, eval_regret)
            target = self.config.target_regret
            if reason is None and target is not None and eval_regret <= target:
                reason = "target_regret"
            diverged = self._watch.observe(evaluation_loss(eval_return, eval_regret))
            if diverged and reason is None and self._watch.restarts(self.optimizer):
                diverged = False  # the optimiser abandoned the diverged search: the run goes on
            reason = reason or ("divergence" if diverged else None)
        diagnostics = {str(k): float(v) for k, v in dict(self.optimizer.diagnostics).items()}
        counts = (self.iteration, self.episodes, finite_mean(returns))
        record = IterationRecord(*counts, eval_return, eval_regret, self.elapsed, diagnostics)
        return record, reason

    # -- the loop --------------------------------------------------------------------------------------------
    def run(self) -> History:
        """Iterate until a stop condition holds; log, checkpoint and call the callbacks on the way.

        With a run directory: holds its lock; a finished run only gets its missing or damaged result files
        rewritten; the first Ctrl-C completes the iteration and checkpoints before ``KeyboardInterrupt``
        (after the last iteration, it lets the result files be written and the run return).
        """
        if self.run_dir is not None:
            self.run_dir.lock.acquire()
        try:
            if self.run_dir is not None:  # with the lock held, any run temporary is a dead writer's
                self.run_dir.remove_temporaries()
            finished = self.history.stop_reason is not None
            with DeferredInterrupt(enabled=self.run_dir is not None) as interrupt:
                if not finished:
                    self._iterate(interrupt)
                interrupt.message = DeferredInterrupt.FINISHING  # the last iteration is checkpointed
                self._finish(completing=finished)
        finally:
            if self.run_dir is not None:
                self.run_dir.lock.release()
        return self.history

    def _iterate(self, interrupt: DeferredInterrupt) -> None:
        self._clock = time.perf_counter()
        self._log({"event": "resume" if self.iteration else "start", "iteration": self.iteration})
        backend = self.make_backend()
        try:
            if (entry := backend.log_entry()) is not None:
                self._log(entry)  # e.g. the Ray cluster the run joined
            for callback in self.callbacks:
                callback.on_start(self.history, self.config.iterations)
            reason = None
            while reason is None:
                record, reason = self.step(backend)
                self.history.append(record)
                self.log_record(record)
                wants_stop = [bool(c.on_iteration(record, self.history)) for c in self.callbacks]
                if any(wants_stop) and reason is None:
                    reason = "callback"
                self.history.stop_reason = reason
                due = self.iteration % self.config.checkpoint_every == 0
                if reason is not None or interrupt.requested or due:
                    self.checkpoint()
                if interrupt.requested and reason is None:
                    raise KeyboardInterrupt
        finally:
            backend.close()
            if self.config.optimizer is not None and hasattr(self.optimizer, "close"):
                self.optimizer.close()  # built by name here: release its library's threads
            for callback in self.callbacks:
                callback.on_end(self.history)

    def log_record(self, record: IterationRecord) -> None:
        """Append an iteration's record to the log and to the checksum the checkpoints keep."""
        if self.run_dir is not None:
            entry = record.to_dict()
            self.run_dir.append_log(entry, log_crc=self._log_crc)
            self._log_crc = chain_crc(self._log_crc, entry)

    def _log(self, entry: dict[str, Any]) -> None:
        if self.run_dir is not None:
            self.run_dir.append_log(entry)

    def _finish(self, completing: bool) -> None:
        """Write the result files; when ``completing`` a finished run, only those missing or damaged."""
        if self.run_dir is None:
            return
        end = {"event": "end", "iteration": self.iteration, "stop_reason": self.history.stop_reason}
        if not completing:
            self._log(end)
        self.policies.write_final(self.run_dir, self.optimizer, self.history, only_changed=completing)
        written = self.run_dir.write_results(self.history, only_changed=completing)
        if completing and written:  # killed between its last checkpoint and its result files
            self._log({**end, "rewritten": written})
