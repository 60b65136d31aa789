"""The ``creps-gym`` command line: list, run, resume, plot and export.

Exit codes
----------
0
    Success (including a run stopped by one of its stop conditions, or resuming a finished run).
1
    The run failed: an episode failed after its retries, or the env or optimiser raised.
2
    Usage error: unknown command, flag, env or optimiser, or a bad value (the message names the flag,
    what was expected and what was given).
3
    Run-directory error: ``--out`` holds a run or other files, ``resume``/``plot``/``export`` got a folder
    that is not a run directory, a damaged file, a checkpoint of another run, a ``config.json`` that names
    a module that is not imported (``--import MODULE``), or another process writes the run directory.
4
    An optional dependency is missing (e.g. ``pip install creps-gym[plot]`` for ``plot``).
130
    Interrupted (Ctrl-C): the run completes its iteration and checkpoints first, so ``creps-gym resume
    DIR`` loses nothing (a second Ctrl-C stops at once).
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import warnings
from collections.abc import Sequence
from dataclasses import fields
from typing import Any

from creps_gym.cli_types import (
    initial_mean,
    integer,
    key_value,
    numbers,
    optimizer_name,
    positive_float,
    positive_or_none,
)

__all__ = ["EXIT_CODES", "build_parser", "main"]

EXIT_CODES = {"ok": 0, "run_failed": 1, "usage": 2, "run_dir": 3, "missing_dependency": 4, "interrupted": 130}


class UsageError(Exception):
    """A bad command line (exit code 2)."""


def _import_modules(args: argparse.Namespace) -> None:
    """Import the ``--import`` modules, then check ``--env`` (a ``module:Env-v0``'s module is imported)."""
    from creps_gym.runner.trust import import_modules, registered_env_id

    checks = [("--import", lambda: import_modules(args.imports))]
    if getattr(args, "env", None) is not None:
        checks.append(("--env", lambda: registered_env_id(args.env, import_module=True)))
    for flag, check in checks:
        try:
            check()
        except ValueError as exc:
            hint = ""
            if flag == "--env":  # a mistyped id: suggest the registered ones it resembles
                import creps_gym
                from creps_gym.listing import did_you_mean

                hint = did_you_mean(args.env, creps_gym.registered_ids())
            raise UsageError(f"argument {flag}: {exc}{hint}") from None


# -- parser -------------------------------------------------------------------------------------------------
def _add_progress(parser: argparse.ArgumentParser) -> None:
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
    _add_import(parser)


def _add_run(commands: Any) -> None:
    from creps_gym.runner.config import BACKENDS, VECTOR_MODES, RunConfig

    run_defaults = {f.name: f.default for f in fields(RunConfig)}  # one source for the defaults

    run = commands.add_parser(
        "run", help="run an optimiser on an env", description="Run an optimiser on an env."
    )
    required = [
        ("--env", str, "registered env id (see `creps-gym list`), or module:Env-v0"),
        ("--optimizer", optimizer_name, "optimiser name (see `creps-gym list`)"),
        ("--iterations", integer(1), "maximum number of iterations"),
        ("--seed", integer(0), "master seed (>= 0)"),
        ("--out", str, "new run directory"),
    ]
    for flag, parse, text in required:
        run.add_argument(flag, required=True, type=parse, help=text)
    run.add_argument(
        "--samples",
        type=integer(2),
        default=None,
        help="episodes per iteration (>= 2; default: the optimiser's recommended batch size)",
    )
    run.add_argument("--overwrite", action="store_true", help="replace a run already in --out (deletes it)")
    run.add_argument(
        "--backend", default=run_defaults["backend"], choices=BACKENDS, help="where episodes run"
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
        default=run_defaults["vector_mode"],
        choices=VECTOR_MODES,
        help="vector backend flavour",
    )
    optional = [
        ("--workers", integer(1), "vector sub-envs or Ray tasks per iteration"),
        ("--retries", integer(0), "re-runs of a failed episode"),
        ("--eval-every", integer(1), "evaluate the mean policy every N iterations"),
        ("--eval-contexts", integer(1), "number of test contexts"),
        ("--checkpoint-every", integer(1), "checkpoint every N iterations"),
        ("--max-episodes", integer(2), "episode budget"),
        ("--target-regret", positive_float, "stop once the mean regret is at most this"),
        ("--max-time", positive_float, "stop after this many seconds"),
        (
            "--divergence",
            positive_or_none,
            "stop once 10 evaluations in a row are worse than the first by "
            "this factor of its size ('none': never)",
        ),
        ("--initial-mean", initial_mean, "a number, p comma-separated numbers, or 'uniform' in the box"),
        ("--initial-std", numbers, "initial standard deviation(s); default: the env-declared one"),
    ]
    for flag, parse, text in optional:
        default = run_defaults[flag[2:].replace("-", "_")]
        run.add_argument(flag, type=parse, default=default, help=f"{text} (default {default})")
    for flag, text in (("--opt", "optimiser option, e.g. --opt epsilon=1.0"), ("--env-kwarg", "e.g. dim=5")):
        run.add_argument(
            flag,
            action="append",
            type=key_value,
            default=[],
            metavar="KEY=VALUE",
            help=f"{text}; VALUE is JSON or a string (repeatable)",
        )
    _add_progress(run)


def _add_import(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--import",
        dest="imports",
        action="append",
        default=[],
        metavar="MODULE",
        help="import MODULE first (e.g. the package that registers the env; repeatable); a run directory "
        "never makes creps-gym import anything",
    )


def build_parser() -> argparse.ArgumentParser:
    """The ``creps-gym`` argument parser."""
    parser = argparse.ArgumentParser(
        prog="creps-gym",
        description="Contextual direct policy search on contextual episodic Gymnasium envs.",
        epilog="Exit codes: 0 ok, 1 run failed, 2 usage error, 3 run-directory error, "
        "4 missing optional dependency, 130 interrupted.",
    )
    from creps_gym import __version__

    parser.add_argument("--version", action="version", version=f"creps-gym {__version__}")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    commands.add_parser(
        "list",
        help="list the envs and optimisers",
        description="List the envs (context and parameter spaces, the default initial search distribution) "
        "and the optimisers.",
    )
    _add_run(commands)
    resume = commands.add_parser("resume", help="continue a run from its last checkpoint")
    resume.add_argument("run_dir", metavar="DIR")
    _add_progress(resume)
    plot = commands.add_parser("plot", help="plot learning curves of run directories")
    plot.add_argument("run_dirs", nargs="+", metavar="DIR")
    plot.add_argument("-o", "--output", required=True, metavar="FILE", help="image file, e.g. curves.png")
    plot.add_argument("--title", help="figure title (default: the env and its dimensions)")
    export = commands.add_parser("export", help="write run directories as one IOHanalyzer CSV")
    export.add_argument("run_dirs", nargs="+", metavar="DIR")
    export.add_argument("-o", "--output", required=True, metavar="FILE", help="CSV file")
    for command in (plot, export):
        command.add_argument("--mix-envs", action="store_true", help="allow runs of different envs")
    return parser


# -- commands -----------------------------------------------------------------------------------------------
def _cmd_list(_: argparse.Namespace) -> int:
    import creps_gym
    from creps_gym.listing import env_rows, optimizer_rows, table
    from creps_gym.optimizers.registry import describe_optimizers

    print("Environments:")
    print(table(env_rows(creps_gym.registered_ids())))
    print("Optimizers:")
    print(table(optimizer_rows(describe_optimizers())))
    return 0


_FLAGS = {"samples": "--samples", "optimizer_options": "--opt", "env_kwargs": "--env-kwarg"}


def _as_usage_error(exc: Exception, args: argparse.Namespace) -> UsageError:
    """Name the flag in a configuration error (``'eval_every: ...'`` -> ``'argument --eval-every: ...'``).

    Errors about an optimiser option or an env keyword argument name ``--opt`` or ``--env-kwarg``.
    """
    from creps_gym.runner.config import RunConfig

    message = str(exc)
    field, sep, rest = message.partition(":")
    if sep and field in {f.name for f in fields(RunConfig)}:
        flag = _FLAGS.get(field, "--" + field.replace("_", "-"))
        return UsageError(f"argument {flag}:{rest}")
    for flag, given in (("--opt", args.opt), ("--env-kwarg", args.env_kwarg)):
        if any(key in message.split(":", 1)[0] or f"'{key}'" in message for key, _ in given):
            return UsageError(f"argument {flag}: {message}")
    return UsageError(message)


def _finish(runner: Any, args: argparse.Namespace) -> int:
    from creps_gym.runner.rundir import RunDir

    history = runner.run()
    last = history.records[-1] if history.records else None
    if last is not None:
        value = last.eval_regret if not math.isnan(last.eval_regret) else last.eval_return
        metric = history.meta.get("metric", "return")
        print(
            f"iterations {last.iteration}, episodes {last.episodes}, {metric} {value:.6g}, "
            f"stop: {history.stop_reason}; run directory {runner.run_dir.path}"
        )
    if not args.no_plot and history.records:
        try:
            from creps_gym.runner.plots import plot_run_dirs

            plot_run_dirs([runner.run_dir.path], runner.run_dir.file(RunDir.PLOT))
            print(f"plot: {runner.run_dir.file(RunDir.PLOT)}")
        except ImportError as exc:
            print(f"creps-gym: no plot written ({exc})", file=sys.stderr)
    return 0


def _cmd_run(args: argparse.Namespace) -> int:
    from creps_gym.runner.callbacks import ProgressBar
    from creps_gym.runner.config import RunConfig
    from creps_gym.runner.loop import Runner
    from creps_gym.runner.session import RunDirError

    _import_modules(args)
    options = {f.name: getattr(args, f.name) for f in fields(RunConfig) if hasattr(args, f.name)}
    options.update(optimizer_options=dict(args.opt), env_kwargs=dict(args.env_kwarg))
    try:
        config = RunConfig(**options)
        runner = Runner(
            config, callbacks=[ProgressBar(args.progress)], run_dir=args.out, overwrite=args.overwrite
        )
    except RunDirError:
        raise
    except (ValueError, TypeError) as exc:
        raise _as_usage_error(exc, args) from None
    return _finish(runner, args)


def _cmd_resume(args: argparse.Namespace) -> int:
    from creps_gym.runner.api import resumed_runner
    from creps_gym.runner.callbacks import ProgressBar
    from creps_gym.runner.rundir import RunDir

    _import_modules(args)
    directory = RunDir.open(args.run_dir)
    config = directory.config()
    if config.env is None or config.optimizer is None:
        raise UsageError(
            f"DIR: expected a run started by `creps-gym run`, got {directory.path} (use the Python API)"
        )
    runner = resumed_runner(directory, config, callbacks=[ProgressBar(args.progress)])
    return _finish(runner, args)


def _cmd_plot(args: argparse.Namespace) -> int:
    from creps_gym.runner.plots import plot_run_dirs

    try:
        plot_run_dirs(args.run_dirs, args.output, title=args.title, mix_envs=args.mix_envs)
    except ValueError as exc:  # e.g. runs of different envs without --mix-envs
        raise UsageError(str(exc)) from None
    print(f"plot: {args.output}")
    return 0


def _cmd_export(args: argparse.Namespace) -> int:
    from creps_gym.runner.export import write_iohanalyzer
    from creps_gym.runner.plots import load_history

    try:
        write_iohanalyzer([load_history(p) for p in args.run_dirs], args.output, mix_envs=args.mix_envs)
    except ValueError as exc:  # e.g. runs of different envs without --mix-envs
        raise UsageError(str(exc)) from None
    print(f"IOHanalyzer CSV: {args.output}")
    return 0


_COMMANDS = {
    "list": _cmd_list,
    "run": _cmd_run,
    "resume": _cmd_resume,
    "plot": _cmd_plot,
    "export": _cmd_export,
}


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``creps-gym`` console script; returns the exit code (see the module docstring)."""
    from gymnasium.error import Error as GymnasiumError

    from creps_gym.runner.backends import EpisodeError
    from creps_gym.runner.session import RunDirError

    parser = build_parser()
    args = parser.parse_args(argv)  # exits with code 2 on usage errors
    prog = f"creps-gym {args.command}"

    def show_warning(message: Any, category: type, *_: Any, **__: Any) -> None:
        print(f"{prog}: warning: {message}", file=sys.stderr)

    try:
        with warnings.catch_warnings():
            warnings.showwarning = show_warning
            return _COMMANDS[args.command](args)
    except UsageError as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return EXIT_CODES["usage"]
    except (FileExistsError, FileNotFoundError, NotADirectoryError, RunDirError) as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return EXIT_CODES["run_dir"]
    except ImportError as exc:
        print(f"{prog}: error: missing optional dependency: {exc}", file=sys.stderr)
        return EXIT_CODES["missing_dependency"]
    except BrokenPipeError:  # e.g. `creps-gym list | head`: the reader left, which is not an error
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_CODES["ok"]
    except KeyboardInterrupt:
        print(
            f"{prog}: interrupted; `creps-gym resume DIR` continues from the last checkpoint", file=sys.stderr
        )
        return EXIT_CODES["interrupted"]
    except (EpisodeError, RuntimeError, ValueError, TypeError, ArithmeticError, GymnasiumError) as exc:
        print(f"{prog}: run failed: {type(exc).__name__}: {exc}", file=sys.stderr)
        return EXIT_CODES["run_failed"]


if __name__ == "__main__":
    sys.exit(main())
