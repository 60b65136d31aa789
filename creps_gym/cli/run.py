"""``creps-gym run`` and ``creps-gym resume``: their arguments and handlers.

Building the parsers imports neither numpy nor Gymnasium: the defaults come from :mod:`creps_gym._table`.
"""

from __future__ import annotations

import argparse
import math
import sys
from typing import Any

from creps_gym.cli.types import (
    add_import,
    add_key_value,
    add_search_start,
    import_modules_and_check_names,
    integer,
    positive_float,
    positive_or_none,
    selector_name,
)
from creps_gym.errors import UsageError

__all__ = ["COMMANDS", "OPT_EXAMPLE", "add_commands", "add_progress"]

#: The ``--opt`` example of ``run --help``: an option of the README's optimiser, c-cma-es (tested).
OPT_EXAMPLE = "restarts=0"
_WORKERS_DEFAULT = "vector: one per sample for a native vector env, else one per CPU; Ray: the cluster's CPUs"
_DIVERGENCE_HELP = (
    "stop once 10 evaluations in a row are worse than the first by this factor of its size ('none': never)"
)


def add_commands(commands: Any) -> None:
    """Add ``run`` and ``resume`` to the sub-command parsers ``commands``."""
    _add_run(commands)
    resume = commands.add_parser("resume", help="continue a run from its last checkpoint")
    resume.add_argument("run_dir", metavar="DIR")
    add_progress(resume)


def add_progress(parser: argparse.ArgumentParser) -> None:
    group = parser.add_mutually_exclusive_group()
    group.add_argument(
        "--progress",
        dest="progress",
        action="store_true",
        default=None,
        help="show the progress bar even when not on a terminal",
    )
    group.add_argument(
        "--no-progress", dest="progress", action="store_false", help="never show the progress bar"
    )
    parser.add_argument("--no-plot", action="store_true", help="do not write learning_curve.png at the end")
    add_import(parser)


def _add_run(commands: Any) -> None:
    """The ``run`` command's parser: the required flags, where episodes run, budgets and evaluation, the
    search's start and the optimiser's, env's and selector's options."""
    from creps_gym._table import RUN_DEFAULTS  # RunConfig's (listing checks they agree): no numpy

    run = commands.add_parser(
        "run", help="run an optimiser on an env", description="Run an optimiser on an env."
    )
    _add_required(run)
    _add_backend(run, RUN_DEFAULTS)
    _add_budgets(run, RUN_DEFAULTS)
    _add_options(run)
    add_progress(run)


def _add_required(run: argparse.ArgumentParser) -> None:
    required = [
        ("--env", str, "registered env id (see `creps-gym list`), or module:Env-v0"),
        ("--optimizer", str, "optimiser name (see `creps-gym list`; or one an --import module registers)"),
        ("--iterations", integer(1), "maximum number of iterations"),
        ("--seed", integer(0), "master seed (>= 0)"),
        ("--out", str, "new run directory"),
    ]
    for flag, parse, text in required:
        aliases = ("--optimiser",) if flag == "--optimizer" else ()  # the spelling of the docs' prose
        run.add_argument(flag, *aliases, dest=flag[2:], required=True, type=parse, help=text)
    run.add_argument(
        "--samples",
        type=integer(2),
        default=None,
        help="episodes per iteration (>= 2; default: the optimiser's recommended batch size)",
    )
    run.add_argument("--overwrite", action="store_true", help="replace a run already in --out (deletes it)")


def _add_backend(run: argparse.ArgumentParser, defaults: dict[str, Any]) -> None:
    from creps_gym._table import BACKENDS, VECTOR_MODES

    run.add_argument(
        "--backend",
        default=defaults["backend"],
        choices=BACKENDS,
        help=f"where episodes run (default: {defaults['backend']})",
    )
    run.add_argument(
        "--ray-address",
        default=None,
        metavar="HOST:PORT",
        help="--backend ray: join the running Ray cluster at HOST:PORT (or 'auto') and leave it running "
        "(default: $RAY_ADDRESS if set, else a local Ray for this run)",
    )
    run.add_argument(
        "--vector-mode",
        default=defaults["vector_mode"],
        choices=VECTOR_MODES,
        help=f"vector backend flavour (default: {defaults['vector_mode']})",
    )


def _add_budgets(run: argparse.ArgumentParser, defaults: dict[str, Any]) -> None:
    optional = [  # flag, type, help, what the default None means
        ("--workers", integer(1), "vector sub-envs or Ray tasks per iteration", _WORKERS_DEFAULT),
        ("--retries", integer(0), "re-runs of a failed episode", None),
        ("--eval-every", integer(1), "evaluate the mean policy every N iterations", None),
        ("--eval-contexts", integer(1), "number of test contexts", None),
        ("--checkpoint-every", integer(1), "checkpoint every N iterations", None),
        ("--max-episodes", integer(2), "episode budget", "no limit"),
        ("--target-regret", positive_float, "stop once the mean regret is at most this", "no target"),
        ("--max-time", positive_float, "stop after this many seconds", "no limit"),
        ("--divergence", positive_or_none, _DIVERGENCE_HELP, None),
    ]
    for flag, parse, text, if_none in optional:
        default = defaults[flag[2:].replace("-", "_")]
        shown = if_none if default is None else default
        run.add_argument(flag, type=parse, default=default, help=f"{text} (default: {shown})")
    add_search_start(run, defaults["initial_mean"], defaults["initial_std"])


def _add_options(run: argparse.ArgumentParser) -> None:
    run.add_argument(
        "--context-selector",
        type=selector_name,
        default=None,
        metavar="NAME",
        help="who chooses the training contexts (e.g. uniform, arcsine, bandit, progress; see "
        "docs/contexts.md); default: the env's own draws",
    )
    flags = (
        (
            "--opt",
            f"optimiser option, e.g. --opt {OPT_EXAMPLE} for c-cma-es (a wrong KEY lists the valid ones)",
        ),
        ("--env-kwarg", "e.g. dim=5"),
        ("--selector-opt", "context selector option, e.g. --selector-opt cells=4"),
    )
    for flag, text in flags:
        add_key_value(run, flag, text)


# -- handlers -----------------------------------------------------------------------------------------------
_FLAGS = {
    "samples": "--samples",
    "optimizer_options": "--opt",
    "env_kwargs": "--env-kwarg",
    "context_selector_options": "--selector-opt",
}


def _as_usage_error(exc: Exception) -> UsageError:
    """A configuration error as a usage error naming the flag that sets its field (``ConfigError.field``:
    ``eval_every`` -> ``--eval-every``, ``optimizer_options`` -> ``--opt``); any other as it is."""
    from creps_gym.errors import ConfigError

    if isinstance(exc, ConfigError):
        flag = _FLAGS.get(exc.field, "--" + exc.field.replace("_", "-"))
        return UsageError(f"argument {flag}: {exc.reason}")
    return UsageError(str(exc))


def _finish(runner: Any, args: argparse.Namespace) -> int:
    from creps_gym.runner.rundir.session import DeferredInterrupt

    history = runner.run()
    # The run has finished: a first Ctrl-C from here on still gets its summary and plot, and exit code 0.
    with DeferredInterrupt(message=DeferredInterrupt.FINISHING):
        last = history.records[-1] if history.records else None
        if last is not None:
            value = last.eval_regret if not math.isnan(last.eval_regret) else last.eval_return
            metric = history.meta.get("metric", "return")
            print(
                f"iterations {last.iteration}, episodes {last.episodes}, {metric} {value:.6g}, "
                f"stop: {history.stop_reason}; run directory {runner.run_dir.path}"
            )
        if not args.no_plot and history.records:
            _write_plot(runner.run_dir)
    return 0


def _write_plot(run_dir: Any) -> None:
    from creps_gym.runner.rundir import RunDir

    try:
        from creps_gym.runner.results.plots import figure_bytes, plot_run_dirs

        figure = plot_run_dirs([run_dir.path])
        run_dir.write_file(RunDir.PLOT, figure_bytes(figure))  # never through a link
        print(f"plot: {run_dir.file(RunDir.PLOT)}")
    except ImportError as exc:
        print(f"creps-gym: no plot written ({exc})", file=sys.stderr)


def _cmd_run(args: argparse.Namespace) -> int:
    from dataclasses import fields

    from creps_gym.errors import RunDirError
    from creps_gym.runner.callbacks import ProgressBar
    from creps_gym.runner.config import RunConfig
    from creps_gym.runner.loop import Runner

    import_modules_and_check_names(args)
    options = {f.name: getattr(args, f.name) for f in fields(RunConfig) if hasattr(args, f.name)}
    options.update(optimizer_options=dict(args.opt), env_kwargs=dict(args.env_kwarg))
    options.update(context_selector_options=dict(args.selector_opt))
    try:
        config = RunConfig(**options)
        runner = Runner(
            config, callbacks=[ProgressBar(args.progress)], run_dir=args.out, overwrite=args.overwrite
        )
    except RunDirError:
        raise
    except (ValueError, TypeError) as exc:
        raise _as_usage_error(exc) from None
    return _finish(runner, args)


def _cmd_resume(args: argparse.Namespace) -> int:
    from creps_gym.errors import RunDirError
    from creps_gym.runner.api import resumed_runner
    from creps_gym.runner.backends.ray import check_ray_cluster
    from creps_gym.runner.callbacks import ProgressBar
    from creps_gym.runner.manual import refuse_resume
    from creps_gym.runner.rundir import RunDir

    import_modules_and_check_names(args)
    directory = RunDir.open(args.run_dir)
    try:
        refuse_resume(directory)
    except RunDirError:
        raise
    except ValueError as exc:
        raise UsageError(str(exc).replace("run_dir: ", "DIR: ", 1)) from None
    config = directory.config()
    if config.env is None or config.optimizer is None:
        raise UsageError(
            f"DIR: expected a run started by `creps-gym run`, got {directory.path} (use the Python API)"
        )
    try:  # a wrong cluster address (RAY_ADDRESS) fails at once, as it does for `run`
        check_ray_cluster(config)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    runner = resumed_runner(directory, config, callbacks=[ProgressBar(args.progress)])
    return _finish(runner, args)


COMMANDS = {"run": _cmd_run, "resume": _cmd_resume}
