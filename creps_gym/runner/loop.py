"""The generic loop: any ask/tell optimiser on any contextual episodic env.

One iteration draws ``samples`` episode seeds from the env stream, reads each episode's context from
``env.reset(seed=...)``, asks the optimiser, runs the episodes on the backend and tells the returns. At the
configured interval (and at the last iteration) the recommended (mean) policy is evaluated on a fixed,
seeded set of test contexts with :func:`creps_gym.envs.evaluation.evaluate_policy` (mean regret where the
env supports it, mean return otherwise). For envs that are not creps_gym models, or models under wrappers
that may change what the agent sees, sends or gets (e.g. ``TransformReward``, ``NormalizeParams``; see
:func:`creps_gym.runner.checks.unwrapped_model`), the evaluation runs test episodes of the env itself
with seeded resets, so it sees what training sees.

**Failures.** Resets that read contexts (for training and test episodes) are retried like episodes
(``config.retries`` times, then :class:`~creps_gym.runner.backends.EpisodeError`), and so is the
evaluation; the episodes themselves follow the backends' failure policy.

**Seeds.** The master seed is split with ``numpy.random.SeedSequence(seed).spawn(3)`` into the env stream
(episode seeds), the optimiser's seed and the test contexts' seed. The same seed gives a bit-identical
:class:`~creps_gym.runner.history.History` (wall times aside) on every backend and after any resume.

**Stop reasons** (``History.stop_reason``): ``"iterations"``, ``"max_episodes"`` (the next iteration would
exceed the budget), ``"target_regret"``, ``"max_time"``, ``"optimizer: <criteria>"`` (the optimiser's own
``stop()``), ``"callback"``.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import time
from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from creps_gym.envs.base import box_initial_distribution, initial_distribution
from creps_gym.envs.evaluation import evaluate_policy, test_contexts
from creps_gym.optimizers.registry import make_optimizer, recommended_samples, restore_optimizer
from creps_gym.optimizers.registry import optimizer_class as registered_class
from creps_gym.runner.backends import (
    EnvSource,
    EpisodeError,
    make_backend,
    reset_context,
    retry,
    run_episodes,
)
from creps_gym.runner.callbacks import as_callback
from creps_gym.runner.checks import check_batch_size, check_optimizer, unwrapped_model
from creps_gym.runner.config import RunConfig
from creps_gym.runner.history import History, IterationRecord
from creps_gym.runner.rundir import RESTART, RunDir
from creps_gym.runner.session import DeferredInterrupt
from creps_gym.runner.trust import check_run_memory

__all__ = ["Runner", "default_initial_distribution", "split_seed"]

Array = NDArray[np.float64]


def split_seed(seed: int) -> tuple[np.random.Generator, int, int]:
    """The env stream (a Generator), the optimiser's seed and the test contexts' seed from a master seed."""
    env_seq, optimizer_seq, eval_seq = np.random.SeedSequence(seed).spawn(3)
    return (
        np.random.default_rng(env_seq),
        int(optimizer_seq.generate_state(1)[0]),
        int(eval_seq.generate_state(1)[0]),
    )


def default_initial_distribution(action_space: gym.spaces.Box) -> tuple[Array, Array]:
    """Mean and standard deviations (p,) of the default initial search distribution.

    The centre of the action box and a quarter of its width per coordinate (so mean ± 2 std spans the box);
    coordinates with an infinite bound get mean 0 and standard deviation 1.
    """
    return box_initial_distribution(action_space)


class Runner:
    """Runs one configuration; :func:`creps_gym.runner.run` and :func:`creps_gym.runner.resume` use it.

    Parameters
    ----------
    config : RunConfig
    env : gymnasium.Env, optional
        The env object (required when ``config.env`` is None).
    optimizer : AskTellOptimizer, optional
        An optimiser object (required when ``config.optimizer`` is None).
    run_dir : RunDir, optional
        Where to log and checkpoint; its checkpoint, if any, is restored.
    callbacks : sequence of Callback or callables
    optimizer_class : type, optional
        Class whose ``from_state_dict`` restores an object optimiser's checkpoint (default: its type).
    """

    def __init__(
        self,
        config: RunConfig,
        *,
        env: gym.Env | None = None,
        optimizer: Any = None,
        run_dir: RunDir | None = None,
        callbacks: Sequence[Any] = (),
        optimizer_class: Any = None,
    ) -> None:
        self.config = config
        if (config.env is None) == (env is None):
            raise TypeError("env: expected an env id in the config or an env object (exactly one)")
        if (config.optimizer is None) == (optimizer is None) and optimizer_class is None:
            raise TypeError("optimizer: expected a registry name or an optimiser object (exactly one)")
        self.env = env if env is not None else gym.make(config.env, **config.env_kwargs)
        for name in ("observation_space", "action_space"):
            space = getattr(self.env, name)
            if not isinstance(space, gym.spaces.Box):
                raise TypeError(f"env: expected a Box {name} (contexts and parameters θ), got {space}")
        self.source = EnvSource(config.env, dict(config.env_kwargs), None if config.env else self.env)
        self.env_rng, optimizer_seed, eval_seed = split_seed(config.seed)
        self.n_context_dims = int(np.prod(self.env.observation_space.shape))
        self.n_params = int(np.prod(self.env.action_space.shape))
        if config.samples is None:
            batch = recommended_samples(config.optimizer or optimizer, self.n_params, self.n_context_dims)
            self.config = config = dataclasses.replace(config, samples=batch)
        check_run_memory(config, self.n_params, self.n_context_dims, covariance=config.optimizer is not None)
        if optimizer is not None:
            check_optimizer(optimizer)
        self.optimizer = optimizer
        if optimizer is None and config.optimizer is not None:
            self.optimizer = self._make_optimizer(optimizer_seed)
        self._optimizer_class = optimizer_class or (type(optimizer) if optimizer is not None else None)
        self._check_optimizer_sizes("optimizer")
        self._model = unwrapped_model(self.env)
        self.test_contexts = self._test_contexts(eval_seed)
        if config.optimizer is not None and run_dir is None:  # a new run: its batch size must suit it
            self._check_batch_size(optimizer_seed)
        if config.target_regret is not None and not self.has_regret:
            raise ValueError(
                f"target_regret: expected None for {self.env_name}, which has no regret, "
                f"got {config.target_regret}"
            )
        self.run_dir = run_dir
        self.callbacks = [as_callback(c) for c in callbacks]
        self.history = History(meta=self._meta())
        self.iteration = self.episodes = 0
        self._elapsed_before = 0.0
        self._clock = time.perf_counter()
        if run_dir is not None:
            run_dir.lock.acquire()  # held until run() ends: one writer per run directory
            try:
                self._restore(run_dir)
            except BaseException:
                run_dir.lock.release()
                raise

    # -- set-up ----------------------------------------------------------------------------------------------
    @property
    def env_name(self) -> str:
        """The env id, or the env's class name for env objects without a spec."""
        spec = getattr(self.env, "spec", None)
        return self.config.env or (spec.id if spec is not None else type(self.env.unwrapped).__name__)

    def _check_optimizer_sizes(self, name: str) -> None:
        for attribute, expected in (("n_params", self.n_params), ("n_context_dims", self.n_context_dims)):
            got = getattr(self.optimizer, attribute, expected)
            if got != expected:
                raise ValueError(f"{name}: expected {attribute} = {expected} for {self.env_name}, got {got}")

    def _uniform_mean(self) -> Array:
        """The paper's initialisation: a mean drawn uniformly in the action box from the master seed."""
        low, high = self.env.action_space.low, self.env.action_space.high
        if not (np.isfinite(low).all() and np.isfinite(high).all()):
            raise ValueError("initial_mean: expected a number for an unbounded action box, got 'uniform'")
        init_seq = np.random.SeedSequence(self.config.seed).spawn(4)[3]  # children 0-2: split_seed
        return np.random.default_rng(init_seq).uniform(low, high)

    def _make_optimizer(self, seed: int) -> Any:
        mean, std = initial_distribution(self.env)  # the env-declared start (box rule for foreign envs)
        if isinstance(self.config.initial_mean, str) and self.config.initial_mean == "uniform":
            mean = self._uniform_mean()
        else:
            mean = self._per_parameter("initial_mean", mean)
        std = self._per_parameter("initial_std", std)
        options = dict(self.config.optimizer_options)
        budget_option = getattr(registered_class(self.config.optimizer), "budget_option", None)
        if budget_option is not None and budget_option not in options:  # e.g. nevergrad's NGOpt needs it
            options[budget_option] = min(
                self.config.iterations * self.config.samples, self.config.max_episodes or math.inf
            )
        return make_optimizer(
            self.config.optimizer,
            self.n_params,
            self.n_context_dims,
            seed,
            initial_mean=mean,
            initial_cov=std**2,
            **options,
        )

    def _per_parameter(self, name: str, default: Array) -> Array:
        """The config's ``name`` (a number or one per parameter) as shape (p,), or ``default`` if unset."""
        given = getattr(self.config, name)
        if given is None or isinstance(given, str):
            return default
        values = np.atleast_1d(np.asarray(given, np.float64))
        if values.shape not in ((1,), (self.n_params,)):
            raise ValueError(
                f"{name}: expected a number or {self.n_params} numbers (one per parameter), "
                f"got {values.shape[0]}"
            )
        return np.broadcast_to(values, (self.n_params,)).copy()

    def _check_batch_size(self, seed: int) -> None:
        """One ask/tell of a fresh optimiser on a synthetic batch of ``samples`` contexts (see checks)."""
        n = self.config.samples
        if self._model is not None:
            contexts = self._model.sample_contexts(np.random.default_rng(seed), n)
        else:
            contexts = self.test_contexts[np.arange(n) % len(self.test_contexts)]
        make = functools.partial(self._make_optimizer, seed)
        check_batch_size(make, contexts, self.config.optimizer_options, repr(self.config.optimizer))

    @property
    def has_regret(self) -> bool:
        """Whether the evaluation reports a regret (the env is a creps_gym model with ``SupportsRegret``)."""
        return self._model is not None and callable(getattr(self._model, "regret", None))

    def _test_contexts(self, seed: int) -> Array:
        if self._model is not None:
            return test_contexts(self._model, self.config.eval_contexts, seed)
        self._eval_seeds = np.random.default_rng(seed).integers(0, 2**63 - 1, size=self.config.eval_contexts)
        return self._reset_contexts(self._eval_seeds, "evaluation")

    def _meta(self) -> dict[str, Any]:
        optimizer = self.config.optimizer or type(self.optimizer).__name__
        return {
            "env": self.env_name,
            "optimizer": optimizer,
            "seed": self.config.seed,
            "n_params": self.n_params,
            "n_context_dims": self.n_context_dims,
            "samples": self.config.samples,
            "metric": "regret" if self.has_regret else "return",
        }

    # -- checkpoints -----------------------------------------------------------------------------------------
    def _restore(self, run_dir: RunDir) -> None:
        """Continue from the run's checkpoint (RunDirError if it is damaged or belongs to another run)."""
        loaded = run_dir.load_checkpoint(self.config)
        if loaded is None:
            return
        state, optimizer_state = loaded
        try:
            if self.config.optimizer is not None:
                self.optimizer = restore_optimizer(self.config.optimizer, optimizer_state)
            else:
                self.optimizer = self._optimizer_class.from_state_dict(optimizer_state)
            self._check_optimizer_sizes("optimizer state")
            self.env_rng.bit_generator.state = state["env_rng"]
            self.history = History.from_dict(state["history"])
            self.iteration, self.episodes = int(state["iteration"]), int(state["episodes"])
            self._elapsed_before = float(state["elapsed"])
        except (KeyError, TypeError, ValueError, IndexError, AttributeError) as exc:
            raise run_dir.damaged(RunDir.CHECKPOINT, exc, RESTART) from None

    def _checkpoint(self) -> None:
        if self.run_dir is None:
            return
        state = {
            "env_rng": self.env_rng.bit_generator.state,
            "history": self.history.to_dict(),
            "iteration": self.iteration,
            "episodes": self.episodes,
            "elapsed": self.elapsed,
        }
        self.run_dir.save_checkpoint(state, self.optimizer.state_dict(), self.config)

    @property
    def elapsed(self) -> float:
        """Wall time of the run so far in seconds (summed over resumes)."""
        return self._elapsed_before + time.perf_counter() - self._clock

    # -- one iteration ---------------------------------------------------------------------------------------
    def _reset_contexts(self, seeds: NDArray[np.int64], label: str) -> Array:
        """The contexts of ``env.reset(seed=s)``, shape (n, z); each reset retried like an episode."""
        retries = self.config.retries
        rows = [
            np.asarray(reset_context(self.env, int(s), retries, f"{label}, episode {k}"), np.float64).ravel()
            for k, s in enumerate(seeds)
        ]
        return np.array(rows).reshape(len(seeds), self.n_context_dims)

    def _evaluate(self) -> tuple[float, float]:
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
        if self._model is not None:
            result = evaluate_policy(self._model, self.optimizer.recommend, self.test_contexts)
            regret = math.nan if result.mean_regret is None else result.mean_regret
            return result.mean_return, regret
        params = np.asarray(self.optimizer.recommend(self.test_contexts), dtype=np.float64)
        returns = run_episodes(
            self.env,
            self._eval_seeds,
            self.test_contexts,
            params,
            first=0,
            label="evaluation",
            retries=self.config.retries,
        )
        return float(returns.mean()), math.nan

    def _stop_before_evaluation(self) -> str | None:
        config = self.config
        if self.iteration >= config.iterations:
            return "iterations"
        if config.max_episodes is not None and self.episodes + config.samples > config.max_episodes:
            return "max_episodes"
        if config.max_time is not None and self.elapsed >= config.max_time:
            return "max_time"
        met = self.optimizer.stop()
        return f"optimizer: {', '.join(sorted(met))}" if met else None

    def step(self, backend: Any) -> tuple[IterationRecord, str | None]:
        """Run one iteration on ``backend``; returns its record and the stop reason (None: go on)."""
        n = self.config.samples
        seeds = self.env_rng.integers(0, 2**63 - 1, size=n)
        contexts = self._reset_contexts(seeds, f"iteration {self.iteration + 1}")
        params = np.asarray(self.optimizer.ask(contexts), dtype=np.float64)
        returns = backend.evaluate(seeds, contexts, params, f"iteration {self.iteration + 1}")
        self.optimizer.tell(contexts, params, returns)
        self.iteration += 1
        self.episodes += n
        reason = self._stop_before_evaluation()
        eval_return = eval_regret = math.nan
        if reason is not None or self.iteration % self.config.eval_every == 0:
            eval_return, eval_regret = self._evaluate()
            target = self.config.target_regret
            if reason is None and target is not None and eval_regret <= target:
                reason = "target_regret"
        diagnostics = {str(k): float(v) for k, v in dict(self.optimizer.diagnostics).items()}
        counts = (self.iteration, self.episodes, float(returns.mean()))
        record = IterationRecord(*counts, eval_return, eval_regret, self.elapsed, diagnostics)
        return record, reason

    # -- the loop --------------------------------------------------------------------------------------------
    def run(self) -> History:
        """Iterate until a stop condition holds; log, checkpoint and call the callbacks on the way.

        With a run directory: holds its lock; a finished run only gets its missing or damaged result files
        rewritten; the first Ctrl-C completes the iteration and checkpoints before ``KeyboardInterrupt``.
        """
        if self.run_dir is not None:
            self.run_dir.lock.acquire()
        try:
            finished = self.history.stop_reason is not None
            if not finished:
                with DeferredInterrupt(enabled=self.run_dir is not None) as interrupt:
                    self._iterate(interrupt)
            self._finish(completing=finished)
        finally:
            if self.run_dir is not None:
                self.run_dir.lock.release()
        return self.history

    def _iterate(self, interrupt: DeferredInterrupt) -> None:
        self._clock = time.perf_counter()
        if self.run_dir is not None:
            self.run_dir.remove_temporaries()
        self._log({"event": "resume" if self.iteration else "start", "iteration": self.iteration})
        backend = make_backend(
            self.config.backend,
            self.source,
            retries=self.config.retries,
            workers=self.config.workers,
            vector_mode=self.config.vector_mode,
            samples=self.config.samples,
            env=self.env,
            ray_address=self.config.ray_address,
        )
        try:
            if (entry := backend.log_entry()) is not None:
                self._log(entry)  # e.g. the Ray cluster the run joined
            for callback in self.callbacks:
                callback.on_start(self.history, self.config.iterations)
            reason = None
            while reason is None:
                record, reason = self.step(backend)
                self.history.append(record)
                self._log(record.to_dict())
                wants_stop = [bool(c.on_iteration(record, self.history)) for c in self.callbacks]
                if any(wants_stop) and reason is None:
                    reason = "callback"
                self.history.stop_reason = reason
                if (
                    reason is not None
                    or interrupt.requested
                    or self.iteration % self.config.checkpoint_every == 0
                ):
                    self._checkpoint()
                if interrupt.requested and reason is None:
                    raise KeyboardInterrupt
        finally:
            backend.close()
            if self.config.optimizer is not None and hasattr(self.optimizer, "close"):
                self.optimizer.close()  # built by name here: release its library's threads
            for callback in self.callbacks:
                callback.on_end(self.history)

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
        written = self.run_dir.write_results(self.history, only_changed=completing)
        if completing and written:  # killed between its last checkpoint and its result files
            self._log({**end, "rewritten": written})
