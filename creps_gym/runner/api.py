"""The public entry points: :func:`run` and :func:`resume`."""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import Any

from creps_gym.errors import ConfigError, RunDirError
from creps_gym.runner.config import RunConfig
from creps_gym.runner.history import History
from creps_gym.runner.loop import Runner
from creps_gym.runner.manual_records import refuse_resume
from creps_gym.runner.rundir import RunDir

__all__ = ["resume", "resumed_runner", "run"]


def run(
    optimizer: Any,
    env: Any,
    iterations: int,
    samples_per_iteration: int | None,
    seed: int,
    *,
    run_dir: str | os.PathLike[str] | None = None,
    overwrite: bool = False,
    callbacks: Sequence[Any] = (),
    env_kwargs: dict[str, Any] | None = None,
    optimizer_options: dict[str, Any] | None = None,
    context_selector: Any = None,
    **options: Any,
) -> History:
    """Run an ask/tell optimiser on a contextual episodic env.

    Parameters
    ----------
    optimizer : str or AskTellOptimizer
        A registry name (see :func:`creps_gym.optimizers.optimizer_names`), built with the run's optimiser
        seed and initial distribution, or an optimiser object (used as given).
    env : str or gymnasium.Env
        A registered id (made with ``env_kwargs``) or an env object.
    iterations : int
        Maximum number of iterations.
    samples_per_iteration : int or None
        Episodes per iteration (>= 2, and at least the optimiser's minimum,
        :func:`creps_gym.optimizers.minimum_samples`, else ``ValueError``); None takes the optimiser's
        recommended batch size (:func:`creps_gym.optimizers.recommended_samples`).
    seed : int
        Master seed (>= 0).
    run_dir : path-like, optional
        A new or empty directory for the config, log, checkpoints and final history (see
        :mod:`creps_gym.runner.rundir`). ``FileExistsError`` if it holds other files, or a run (unless
        ``overwrite``); :class:`~creps_gym.errors.RunDirError` while another process writes it.
    overwrite : bool
        Replace a run already in ``run_dir`` (only the run's own files are deleted), like ``--overwrite``.
    callbacks : sequence of Callback or callables ``f(record, history) -> bool | None``
    env_kwargs, optimizer_options : dict, optional
        Keyword arguments of ``gymnasium.make`` (id envs) and of the optimiser (name optimisers).
    context_selector : str or ContextSelector, optional
        Who chooses the training contexts instead of the env's sampler: a registered name
        (:func:`creps_gym.selectors.selector_names`, with ``context_selector_options``) or an object (see
        ``docs/contexts.md``). The evaluation stays on the env's test contexts.
    **options
        The other :class:`~creps_gym.runner.config.RunConfig` fields: ``eval_every``, ``eval_contexts``,
        ``context_draws``, ``backend``, ``workers``, ``vector_mode``, ``retries``, ``max_episodes``,
        ``target_regret``, ``max_time``, ``checkpoint_every``, ``initial_mean``, ``initial_std``,
        ``ray_address``, ``context_selector_options``.

    Returns
    -------
    History
    """
    by_name, by_id = isinstance(optimizer, str), isinstance(env, str)
    if not by_id and env_kwargs:
        raise ValueError(f"env_kwargs: expected none with an env object, got {env_kwargs}")
    if not by_name and optimizer_options:
        raise ValueError(
            f"optimizer_options: expected none with an optimiser object, got {optimizer_options}"
        )
    names = {"env": env if by_id else None, "optimizer": optimizer if by_name else None}
    sizes = {"iterations": iterations, "samples": samples_per_iteration, "seed": seed}
    kwargs = {"env_kwargs": env_kwargs or {}, "optimizer_options": optimizer_options or {}}
    selector_name = context_selector if isinstance(context_selector, str) else None
    config = RunConfig(**names, **sizes, **kwargs, context_selector=selector_name, **options)
    objects = {"env": None if by_id else env, "optimizer": None if by_name else optimizer}
    selector = None if selector_name is not None else context_selector
    try:
        runner = Runner(
            config,
            **objects,
            callbacks=callbacks,
            run_dir=run_dir,
            overwrite=overwrite,
            context_selector=selector,
        )
    except ConfigError as exc:  # e.g. a batch below the optimiser's minimum: name this function's argument
        if exc.field == "samples":
            raise ConfigError("samples_per_iteration", exc.reason) from None
        raise
    return runner.run()


def resume(
    run_dir: str | os.PathLike[str],
    *,
    env: Any = None,
    optimizer_class: Any = None,
    callbacks: Sequence[Any] = (),
    context_selector: Any = None,
) -> History:
    """Continue a run from its last checkpoint (or from the start if it has none); returns the History.

    The resumed History equals the one an uninterrupted run would have produced (wall times aside). A
    finished run is returned as is (its missing or damaged result files are rewritten first).

    A run directory is untrusted input: its ``config.json`` never makes this import a module (see
    :mod:`creps_gym.runner.rundir.references`; import the module that registers the env first), and a
    damaged file,
    a checkpoint of another run or a live writer raise :class:`~creps_gym.errors.RunDirError`.

    Parameters
    ----------
    run_dir : path-like
        A directory written by :func:`run` or ``creps-gym run``.
    env : gymnasium.Env, optional
        Required when the run was started with an env object instead of an id.
    optimizer_class : type, optional
        Required when the run was started with an optimiser object: the class whose ``from_state_dict``
        restores it. Such runs resume from a checkpoint only.
    callbacks : sequence of Callback or callables
    context_selector : ContextSelector, optional
        Required when the run was started with a selector object: a new one of the same kind (its state
        is restored from the checkpoint).
    """
    directory = RunDir.open(run_dir)
    refuse_resume(directory)  # an ask/tell run's episodes run outside creps_gym
    config = directory.config()
    if config.env is None and env is None:
        raise ValueError("env: expected the env object this run was started with (its config has no env id)")
    if config.optimizer is None and optimizer_class is None:
        raise ValueError("optimizer_class: expected the class of the run's optimiser object, got None")
    runner = resumed_runner(
        directory,
        config,
        env=env,
        optimizer_class=optimizer_class,
        callbacks=callbacks,
        context_selector=context_selector,
    )
    return runner.run()


def resumed_runner(
    directory: RunDir,
    config: RunConfig,
    *,
    env: Any = None,
    optimizer_class: Any = None,
    callbacks: Sequence[Any] = (),
    context_selector: Any = None,
) -> Runner:
    """The :class:`Runner` that continues ``directory`` (its ``config``, already checked for trust).

    Values of ``config.json`` that the env or the optimiser refuse (a ``TypeError`` or ``ValueError`` while
    building them) raise :class:`~creps_gym.errors.RunDirError` when ``config.json`` names both
    the env and the optimiser: the run directory is untrusted input, and a config that cannot run is a
    damaged one. With an env or optimiser object of the caller's, the error is raised as it is.
    """
    try:
        return Runner(
            config,
            env=env if config.env is None else None,
            optimizer_class=optimizer_class,
            run_dir=directory,
            callbacks=callbacks,
            context_selector=context_selector,
        )
    except (TypeError, ValueError) as exc:
        if isinstance(exc, RunDirError) or config.env is None or config.optimizer is None:
            raise
        raise RunDirError(
            f"{directory.file(RunDir.CONFIG)}: the env or the optimiser refuses its values "
            f"({type(exc).__name__}: {exc}); correct them or start a new run"
        ) from None
