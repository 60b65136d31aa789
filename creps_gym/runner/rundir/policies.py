"""The policies a run keeps, :func:`load_policy`, and the evaluation of a policy on fresh test contexts.

A run folder holds two policy files (:class:`~creps_gym.optimizers.policy_file.Policy`, ``.npz`` + JSON):

``best_policy.npz``
    The best evaluated mean policy (highest mean evaluation return on the run's test contexts, the first
    one on ties), kept across the optimiser's restarts. The runner keeps it in its checkpoints, so a resumed
    run keeps it too (bit for bit); the file is written at each checkpoint where it changed and at the end.
    Its ``source`` says which iteration it came from (``History.best_iteration`` says so as well).
``policy.npz``
    The optimiser's mean policy at the end of the run.

Each is bound to its run: its ``source`` holds the run's fingerprint (``"run"``, the SHA-256 that binds a
checkpoint to its configuration), and :func:`load_policy` and a resume check a kept policy like the loop's
own state (:func:`check_kept_policy`: the run's fingerprint, env id and keywords, optimiser, parameter
count, context dimension, and an iteration the run can have reached), so a policy file copied from another
run, or a best policy forged in a checkpoint, is refused naming the file.

Both exist only for optimisers with a ``mean_policy()`` method (every registered one); they are written
like the checkpoint (a temporary file and a rename). A run folder is untrusted input: the files are read
bounded, without pickle and without following a symbolic link (:mod:`creps_gym.optimizers.policy_io`).
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from creps_gym.envs.evaluation import evaluate_policy, finite_mean, test_contexts
from creps_gym.errors import RunDirError
from creps_gym.optimizers.policy_file import Policy
from creps_gym.optimizers.policy_io import policy_bytes
from creps_gym.runner.backends import run_episodes
from creps_gym.runner.config import RunConfig
from creps_gym.runner.contexts import ContextDraws
from creps_gym.runner.env_model import unwrapped_model
from creps_gym.runner.history import History, encode_float
from creps_gym.runner.protocol import real_params
from creps_gym.runner.rundir import RunDir
from creps_gym.runner.rundir.checkpoint import config_fingerprint
from creps_gym.runner.rundir.files import os_failure, write_run_file

__all__ = [
    "WHICH",
    "RunPolicies",
    "check_kept_policy",
    "evaluate_contexts",
    "evaluate_on_env",
    "evaluated_policy",
    "evaluation_draws",
    "load_policy",
]

#: ``load_policy``'s choices: the run folder's file for each.
WHICH = {"best": RunDir.BEST_POLICY, "final": RunDir.POLICY}


class RunPolicies:
    """What a :class:`~creps_gym.runner.loop.Runner` keeps of its policies: the best evaluated one.

    Parameters
    ----------
    config : RunConfig
    env : gymnasium.Env
        The run's env: its id, keyword arguments, context box and parameter box go into each policy.
    """

    def __init__(self, config: RunConfig, env: gym.Env) -> None:
        spec = getattr(env, "spec", None)
        self.env_id = config.env or (spec.id if spec is not None and spec.id else None)
        self.env_kwargs = dict(config.env_kwargs) if config.env else {}
        self.boxes = {
            f"{name}_box": (space.low.ravel().astype(np.float64), space.high.ravel().astype(np.float64))
            for name, space in (("context", env.observation_space), ("param", env.action_space))
        }
        self.optimizer_name = config.optimizer
        self.config, self.fingerprint = config, config_fingerprint(config)
        self.best: Policy | None = None
        self.best_return = -math.inf
        self._written: Policy | None = None  # the best policy last written to the run folder

    def describe(self, optimizer: Any, iteration: int, which: str, record: Any = None) -> Policy | None:
        """``optimizer.mean_policy()`` with the run's env and where it comes from; None without one."""
        make = getattr(optimizer, "mean_policy", None)
        if make is None:
            return None
        policy = make()
        if not isinstance(policy, Policy):
            raise TypeError(f"optimizer.mean_policy(): expected a Policy, got {type(policy).__name__}")
        source = {"optimizer": self.optimizer_name or type(optimizer).__name__, "which": which}
        source.update(iteration=int(iteration), run=self.fingerprint)
        if record is not None:
            source.update(eval_return=encode_float(record[0]), eval_regret=encode_float(record[1]))
        arrays = {"features": policy.features, "coefficients": policy.coefficients}
        return Policy(**arrays, env=self.env_id, env_kwargs=self.env_kwargs, source=source, **self.boxes)

    def offer(self, optimizer: Any, iteration: int, eval_return: float, eval_regret: float) -> None:
        """Keep the optimiser's mean policy if its evaluation return is the best so far (NaN: none)."""
        if math.isfinite(eval_return) and eval_return > self.best_return:
            best = self.describe(optimizer, iteration, "best", (eval_return, eval_regret))
            if best is not None:
                self.best, self.best_return = best, float(eval_return)

    def checkpoint_state(self, run_dir: RunDir | None) -> dict[str, Any] | None:
        """The best policy as a JSON document for the checkpoint (None before the first); writes
        ``best_policy.npz`` first if the best policy changed since it was last written."""
        if run_dir is not None and self.best is not None and self.best is not self._written:
            _write(run_dir, RunDir.BEST_POLICY, self.best)
            self._written = self.best
        return None if self.best is None else self.best.to_dict()

    def restore(self, document: Any, history: History | None = None) -> None:
        """Take the best policy back from a checkpoint's :meth:`checkpoint_state`, checked against the run
        and its ``history`` up to the checkpoint (``ValueError`` if damaged or forged)."""
        self.best, self.best_return = None, -math.inf
        if document is not None:
            best = Policy.from_dict(document)
            p, z = (self.boxes[f"{name}_box"][0].shape[0] for name in ("param", "context"))
            last = len(history) if history is not None else self.config.iterations
            check_kept_policy(best, self.config, self.fingerprint, p, z, "best", last, "best_policy")
            value = best.source.get("eval_return")
            if not isinstance(value, (int, float)) or isinstance(value, bool) or not math.isfinite(value):
                raise ValueError(f"best_policy: expected a finite eval_return in its source, got {value!r}")
            if history is not None:
                _check_best_record(best, history)
            self.best, self.best_return = best, float(value)
        self._written = self.best

    def write_final(
        self, run_dir: RunDir | None, optimizer: Any, history: History, only_changed: bool
    ) -> None:
        """Write ``policy.npz`` (the optimiser's mean policy now) and ``best_policy.npz``; with
        ``only_changed`` (completing a finished run), only files that are missing or differ."""
        if run_dir is None:
            return
        last = history.records[-1] if history.records else None
        record = None if last is None else (last.eval_return, last.eval_regret)
        iteration = 0 if last is None else last.iteration
        final = self.describe(optimizer, iteration, "final", record)
        for name, policy in ((RunDir.POLICY, final), (RunDir.BEST_POLICY, self.best)):
            if policy is not None and not (only_changed and _holds(run_dir, name, policy)):
                _write(run_dir, name, policy)
        self._written = self.best


def check_kept_policy(
    policy: Policy,
    config: RunConfig,
    fingerprint: str,
    n_params: int,
    context_dim: int,
    which: str,
    last_iteration: int,
    name: str,
) -> None:
    """``ValueError`` naming ``name`` unless ``policy`` is one this run can have kept: its fingerprint
    (where the source has one: files written before it existed have none), env id and keywords,
    optimiser, p and z, ``which``, and an iteration in [0, ``last_iteration``]."""
    source = policy.source
    iteration = source.get("iteration")
    expected = {
        "fingerprint": (source.get("run", fingerprint), fingerprint),
        "env": (policy.env, config.env or policy.env),
        "env_kwargs": (policy.env_kwargs, dict(config.env_kwargs) if config.env else policy.env_kwargs),
        "optimizer": (source.get("optimizer"), config.optimizer or source.get("optimizer")),
        "which": (source.get("which"), which),
        "n_params": (policy.n_params, n_params),
        "context_dim": (policy.context_dim, context_dim),
    }
    for field, (found, wanted) in expected.items():
        if found != wanted:
            raise ValueError(
                f"{name}: expected a policy kept by this run (its {field} {wanted!r}), got {found!r} (a "
                "policy of another run?)"
            )
    if type(iteration) is not int or not 0 <= iteration <= last_iteration:
        raise ValueError(
            f"{name}: expected an iteration in [0, {last_iteration}] in its source, got {iteration!r}"
        )


def _check_best_record(best: Policy, history: History) -> None:
    """The best policy's iteration and evaluation must be the history's best record's."""
    at = history.best_iteration
    record = None if at is None else history.records[at - 1]
    found = (best.source.get("iteration"), best.source.get("eval_return"), best.source.get("eval_regret"))
    wanted = (
        None if record is None else (at, encode_float(record.eval_return), encode_float(record.eval_regret))
    )
    if found != wanted:
        raise ValueError(
            f"best_policy: expected the evaluation of the history's best iteration {wanted}, got {found} "
            "(iteration, eval_return, eval_regret)"
        )


def _write(run_dir: RunDir, name: str, policy: Policy) -> None:
    """Write a run folder's policy file like its other files (a link or special file there is refused)."""
    path = write_run_file(run_dir.file(name), policy_bytes(policy.to_dict(arrays=False), policy.arrays()))
    try:
        os.chmod(path, os.lstat(run_dir.file(RunDir.CONFIG)).st_mode & 0o777)  # one mode for the run's files
    except OSError as exc:
        raise os_failure(path, exc, "set its mode") from None


def _holds(run_dir: RunDir, name: str, policy: Policy) -> bool:
    try:
        return Policy.load(run_dir.file(name)).equals(policy)
    except (OSError, ValueError):
        return False


def load_policy(path: str | os.PathLike[str], which: str = "best") -> Policy:
    """The policy of a run folder (``which``: ``"best"`` or ``"final"``), or of a policy file.

    Parameters
    ----------
    path : path-like
        A run folder (``creps-gym run --out``, ``run(..., run_dir=...)``) or a file written by
        :meth:`Policy.save` (then ``which`` is not used).
    which : {"best", "final"}
        The best evaluated mean policy (``best_policy.npz``) or the optimiser's mean policy at the end
        (``policy.npz``). A run folder without ``policy.npz`` (unfinished, or written before policy files
        existed) gives the policy of its last checkpoint for ``"final"``.

    Raises
    ------
    FileNotFoundError
        No such file or folder, or a run folder without the policy asked for.
    RunDirError
        A damaged policy file or checkpoint in a run folder (a ``ValueError``).
    ValueError
        ``which`` is not a choice, or ``path`` is not a policy file.
    """
    if which not in WHICH:
        raise ValueError(f"which: expected one of {sorted(WHICH)}, got {which!r}")
    path = Path(path)
    if not os.path.lexists(path):
        raise FileNotFoundError(
            f"path: expected a run folder or a policy file (.npz), got {path}, which does not exist"
        )
    if not path.is_dir():
        return Policy.load(path)
    directory = RunDir.open(path)
    file = directory.file(WHICH[which])
    if os.path.lexists(file):
        try:
            policy = Policy.load(file)
            _check_run_file(directory, policy, which)
        except ValueError as exc:
            if isinstance(exc, RunDirError):
                raise
            raise directory.damaged(WHICH[which], exc, "delete it, or restore it from a backup") from None
        return policy
    if which == "final":
        policy = _checkpoint_policy(directory)
        if policy is not None:
            return policy
    raise FileNotFoundError(
        f"path: expected {WHICH[which]} in the run folder {path}, got none (a run without an evaluation "
        "yet, with an optimiser that has no mean_policy(), or written before policy files existed); "
        "try which='final'"
    )


def _check_run_file(directory: RunDir, policy: Policy, which: str) -> None:
    """A run folder's policy file must be this run's (:func:`check_kept_policy`): not one copied in."""
    config, meta = directory.config(), directory.document().get("meta")
    meta = meta if isinstance(meta, dict) else {}
    p, z = meta.get("n_params", policy.n_params), meta.get("n_context_dims", policy.context_dim)
    check_kept_policy(policy, config, directory.fingerprint(), p, z, which, config.iterations, "its source")


def _checkpoint_policy(directory: RunDir) -> Policy | None:
    """The mean policy of the run's optimiser at its last checkpoint, or None without a checkpoint."""
    from creps_gym.optimizers.registry import restore_optimizer

    config = directory.config()
    loaded = directory.load_checkpoint(config)
    if loaded is None or config.optimizer is None:
        return None
    state, optimizer_state = loaded
    try:
        optimizer = restore_optimizer(config.optimizer, optimizer_state)
    except (KeyError, TypeError, ValueError, IndexError, AttributeError, OverflowError) as exc:
        raise directory.damaged(RunDir.CHECKPOINT, exc, "restore it from a backup") from None
    make = getattr(optimizer, "mean_policy", None)
    if make is None:
        return None
    policy = make()
    source = {"optimizer": config.optimizer, "which": "final", "iteration": int(state["iteration"])}
    arrays = {"features": policy.features, "coefficients": policy.coefficients}
    return Policy(**arrays, env=config.env, env_kwargs=config.env_kwargs, source=source)


def evaluated_policy(optimizer: Any) -> Any:
    """What the runner evaluates: ``optimizer.recommend``, or for an optimiser whose kept policy is a
    distillation of it (``distilled_policy``, c-bo: a linear fit of a GP's maximisers) that kept policy,
    so that a policy file's ``eval_return`` is its own evaluation. For every other optimiser the two give
    the same parameters bit for bit (``mean_policy()`` equals ``recommend``)."""
    if getattr(optimizer, "distilled_policy", False):
        policy = optimizer.mean_policy()
        return lambda contexts: policy(contexts, extrapolate=True)
    return optimizer.recommend


def evaluate_contexts(
    policy: Any, env: gym.Env, model: Any, contexts: NDArray[np.float64], seeds: Any, retries: int
) -> tuple[float, float]:
    """Mean return and mean regret (NaN without one) of ``policy`` (contexts (n, z) -> params (n, p)): on
    the creps_gym ``model`` behind ``env`` where there is one, else by episodes of ``env`` itself reset with
    ``seeds`` (the runner's evaluation of its recommended policy)."""
    if model is not None:
        result = evaluate_policy(model, policy, contexts)
        return result.mean_return, math.nan if result.mean_regret is None else result.mean_regret
    params = real_params(policy(contexts), "recommend")
    returns = run_episodes(env, seeds, contexts, params, first=0, label="evaluation", retries=retries)
    return finite_mean(returns), math.nan


def evaluate_on_env(policy: Policy, env: gym.Env, n: int, seed: int, retries: int = 0) -> tuple[float, float]:
    """Mean return and mean regret (NaN without one) of ``policy`` on ``n`` test contexts of ``env``, drawn
    as a run draws its test contexts from its evaluation seed (``seed`` here): with a run's evaluation seed
    and count, the numbers are the run's."""
    if isinstance(policy, Policy):
        policy.check_batch(n, "n")  # before the contexts are drawn
    model, contexts, seeds = evaluation_draws(env, n, seed, retries)
    return evaluate_contexts(policy, env, model, contexts, seeds, retries)


def evaluation_draws(
    env: gym.Env, n: int, seed: int, retries: int = 0
) -> tuple[Any, NDArray[np.float64], Any]:
    """The creps_gym model behind ``env`` (or None), and the ``n`` test contexts (n, z) and reset seeds (n,)
    that :func:`evaluate_on_env` evaluates for ``seed`` (a video of them shows the evaluated episodes)."""
    model = unwrapped_model(env)
    seeds = np.random.default_rng(seed).integers(0, 2**63 - 1, size=n)
    if model is not None:
        contexts = test_contexts(model, n, seed)
    else:
        contexts = ContextDraws(env, "reset", retries).reset_contexts(seeds, "evaluation")
    return model, contexts, seeds
