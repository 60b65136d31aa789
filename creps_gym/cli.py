"""The ``creps-gym`` command line: list, run, resume, plot, export, policy and evaluate
(:mod:`creps_gym.cli_results`, :mod:`creps_gym.cli_policy`).

Exit codes
----------
0
    Success (including a run stopped by one of its stop conditions, or resuming a finished run).
1
    The run failed: an episode failed after its retries, or the env or optimiser raised.
2
    Usage error: unknown command, flag, env or optimiser, or a bad value (the message names the flag,
    what was expected and what was given), or a ``-o`` file that cannot be written (not a regular file,
    a run directory's own file, a full disk, ...).
3
    Run-directory error: ``--out`` holds a run or other files, ``resume``/``plot``/``export`` got a folder
    that is not a run directory (or ``policy``/``evaluate`` got no run folder or policy file), a damaged
    file, a checkpoint of another run, a ``config.json`` that names a module that is not imported
    (``--import MODULE``), or another process writes the run directory; a file in it that is not a
    regular file (a link, a FIFO, a device, a folder) or is too large; or an operating-system error on one
    of its files (disk full, read-only, ``ulimit -f``, a name too long).
4
    An optional dependency is missing (e.g. ``pip install creps-gym[plot]`` for ``plot``).
130
    Interrupted (Ctrl-C): the run completes its iteration and checkpoints first, so ``creps-gym resume
    DIR`` loses nothing (a second Ctrl-C stops at once). A Ctrl-C after the last iteration is not an
    interruption: the run has finished, its result files and plot are written, and the exit code is 0.
"""

from __future__ import annotations

import argparse
import math
import os
import shlex
import signal
import sys
import warnings
from collections.abc import Sequence
from typing import Any

from creps_gym.cli_parsers import add_import, add_progress, add_run
from creps_gym.cli_results import RESULT_COMMANDS, add_result_commands
from creps_gym.cli_types import UsageError, import_user_modules

__all__ = ["EXIT_CODES", "build_parser", "main"]

EXIT_CODES = {"ok": 0, "run_failed": 1, "usage": 2, "run_dir": 3, "missing_dependency": 4, "interrupted": 130}


def _import_modules(args: argparse.Namespace) -> None:
    """Import the ``--import`` modules, then check the names they may register: ``--env`` (a
    ``module:Env-v0``'s module is imported) and ``--optimizer``.

    The current directory is searched for an ``--import`` module, after every other path entry (so it
    never shadows an installed module); nothing is ever imported from a run directory.
    """
    from creps_gym.runner.trust import registered_env_id

    import_user_modules(args.imports)
    if getattr(args, "env", None) is not None:
        try:
            registered_env_id(args.env, import_module=True)
        except ValueError as exc:
            unknown = str(exc).startswith("expected one of")  # else: its module cannot be imported
            raise UsageError(f"argument --env: {_unknown_env(args.env) if unknown else exc}") from None
    if getattr(args, "optimizer", None) is not None:
        try:
            _registered_optimizer(args.optimizer)
        except ValueError as exc:
            raise UsageError(f"argument --optimizer: {exc}") from None


def _unknown_env(env_id: str) -> str:
    """The hint first (a short line), then the registered ids, wrapped."""
    import textwrap

    import creps_gym
    from creps_gym.listing import did_you_mean

    ids = creps_gym.registered_ids()
    listing = textwrap.fill(", ".join(ids), width=100, initial_indent="  ", subsequent_indent="  ")
    return (
        f"unknown env id {env_id!r}{did_you_mean(env_id, ids)}\n"
        f"expected one of these ids (`creps-gym list` describes them) or module:Env-v0:\n{listing}"
    )


def _registered_optimizer(name: str) -> None:
    from creps_gym.listing import did_you_mean
    from creps_gym.optimizers.registry import optimizer_names

    names = optimizer_names()
    if name not in names:
        raise ValueError(f"expected one of {names}, got {name!r}{did_you_mean(name, names)}")


# -- parser -------------------------------------------------------------------------------------------------
class _Version(argparse.Action):
    """``--version``, looked up only when asked (``importlib.metadata`` is slow to import)."""

    def __call__(self, parser: argparse.ArgumentParser, *_: Any, **__: Any) -> None:
        from creps_gym import __version__

        print(f"creps-gym {__version__}")
        parser.exit()


def build_parser() -> argparse.ArgumentParser:
    """The ``creps-gym`` argument parser."""
    parser = argparse.ArgumentParser(
        prog="creps-gym",
        description="Contextual direct policy search on contextual episodic Gymnasium envs.",
        epilog="Exit codes: 0 ok, 1 run failed, 2 usage error, 3 run-directory error, "
        "4 missing optional dependency, 130 interrupted.",
    )
    parser.add_argument("--version", action=_Version, nargs=0, help="show the version and exit")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    add_run(commands)
    resume = commands.add_parser("resume", help="continue a run from its last checkpoint")
    resume.add_argument("run_dir", metavar="DIR")
    add_progress(resume)
    add_result_commands(commands, add_import)
    from creps_gym.cli_policy import add_commands

    add_commands(commands)  # policy, evaluate
    return parser


# -- commands -----------------------------------------------------------------------------------------------
_FLAGS = {
    "samples": "--samples",
    "optimizer_options": "--opt",
    "env_kwargs": "--env-kwarg",
    "context_selector_options": "--selector-opt",
}


def _as_usage_error(exc: Exception, args: argparse.Namespace) -> UsageError:
    """Name the flag in a configuration error (``'eval_every: ...'`` -> ``'argument --eval-every: ...'``).

    Errors about an optimiser option or an env keyword argument name ``--opt`` or ``--env-kwarg``.
    """
    from dataclasses import fields

    from creps_gym.runner.config import RunConfig

    message = str(exc)
    field, sep, rest = message.partition(":")
    if sep and field in dict(getattr(args, "opt", [])):
        return UsageError(f"argument --opt: {message}")  # e.g. nevergrad's own `optimizer` option
    if sep and field in {f.name for f in fields(RunConfig)}:
        flag = _FLAGS.get(field, "--" + field.replace("_", "-"))
        return UsageError(f"argument {flag}:{rest}")
    named = (("--opt", args.opt), ("--env-kwarg", args.env_kwarg), ("--selector-opt", args.selector_opt))
    for flag, given in named:
        if any(key in message.split(":", 1)[0] or f"'{key}'" in message for key, _ in given):
            return UsageError(f"argument {flag}: {message}")
    return UsageError(message)


def _finish(runner: Any, args: argparse.Namespace) -> int:
    from creps_gym.runner.session import DeferredInterrupt

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
        from creps_gym.runner.plots import figure_bytes, plot_run_dirs

        figure = plot_run_dirs([run_dir.path])
        run_dir.write_file(RunDir.PLOT, figure_bytes(figure))  # never through a link
        print(f"plot: {run_dir.file(RunDir.PLOT)}")
    except ImportError as exc:
        print(f"creps-gym: no plot written ({exc})", file=sys.stderr)


def _cmd_run(args: argparse.Namespace) -> int:
    from dataclasses import fields

    from creps_gym.runner.callbacks import ProgressBar
    from creps_gym.runner.config import RunConfig
    from creps_gym.runner.loop import Runner
    from creps_gym.runner.session import RunDirError

    _import_modules(args)
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
        raise _as_usage_error(exc, args) from None
    return _finish(runner, args)


def _cmd_resume(args: argparse.Namespace) -> int:
    from creps_gym.runner.api import resumed_runner
    from creps_gym.runner.callbacks import ProgressBar
    from creps_gym.runner.checks import check_ray_cluster
    from creps_gym.runner.rundir import RunDir

    _import_modules(args)
    directory = RunDir.open(args.run_dir)
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


def _cmd_policy(args: argparse.Namespace) -> int:
    from creps_gym.cli_policy import COMMANDS

    return COMMANDS[args.command](args)


_COMMANDS = {"run": _cmd_run, "resume": _cmd_resume, "policy": _cmd_policy, "evaluate": _cmd_policy}


def _drop_cwd_from_path() -> None:
    """``python -m creps_gym.cli`` puts the current directory first on ``sys.path``: drop it, so that no
    file there (or in a run directory the user works in) shadows a module; ``--import`` looks there last."""
    if not getattr(sys.flags, "safe_path", False) and sys.path and sys.path[0] in ("", os.getcwd()):
        del sys.path[0]


def _command_line_terms(message: str, prog: str) -> str:
    """A run directory's message in the command line's terms (the runner's are Python's)."""
    message = message.replace("creps-gym COMMAND", prog)  # the trust checks' advice, for this command
    message = message.replace("continue it with `resume`", "continue it with `creps-gym resume`")
    return message.replace("pass overwrite=True", "pass --overwrite")


def _failure(exc: Exception, prog: str) -> int | None:
    """Print ``exc`` and return its exit code, or None for an exception that is a bug (a traceback)."""
    from gymnasium.error import Error as GymnasiumError

    from creps_gym.runner.backends import EpisodeError
    from creps_gym.runner.session import RunDirError

    if isinstance(exc, (FileExistsError, FileNotFoundError, NotADirectoryError, RunDirError)):
        print(f"{prog}: error: {_command_line_terms(str(exc), prog)}", file=sys.stderr)
        return EXIT_CODES["run_dir"]
    if isinstance(exc, ImportError):
        print(f"{prog}: error: missing optional dependency: {exc}", file=sys.stderr)
        return EXIT_CODES["missing_dependency"]
    if isinstance(exc, (EpisodeError, RuntimeError, ValueError, TypeError, ArithmeticError, GymnasiumError)):
        print(f"{prog}: run failed: {type(exc).__name__}: {exc}", file=sys.stderr)
        return EXIT_CODES["run_failed"]
    if isinstance(exc, OSError):  # a file that the run directory's checks did not name (those: RunDirError)
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"{prog}: error: {where}{exc.strerror or exc}", file=sys.stderr)
        return EXIT_CODES["run_dir"]
    return None


def _plain_warning(text: str) -> str:
    """A warning without terminal escapes (Gymnasium colours its own) or Gymnasium's ``WARN:`` prefix."""
    import re

    text = re.sub(r"\x1b\[[0-9;?]*[A-Za-z]", "", text).strip()
    return text.removeprefix("WARN: ")


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``creps-gym`` console script; returns the exit code (see the module docstring)."""
    if hasattr(signal, "SIGXFSZ"):  # `ulimit -f`: a write past it fails with EFBIG (named, exit 3)
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    parser = build_parser()
    args = parser.parse_args(argv)  # exits with code 2 on usage errors
    prog = f"creps-gym {args.command}"

    shown: set[str] = set()

    def show_warning(message: Any, category: type, *_: Any, **__: Any) -> None:
        text = _plain_warning(str(message))
        if text not in shown:  # e.g. a deprecated id's warning, once per env the run makes
            shown.add(text)
            print(f"{prog}: warning: {text}", file=sys.stderr)

    try:
        with warnings.catch_warnings():
            warnings.showwarning = show_warning
            if args.command in RESULT_COMMANDS:
                if getattr(args, "imports", None):
                    _import_modules(args)
                return RESULT_COMMANDS[args.command](args, UsageError)
            return _COMMANDS[args.command](args)
    except UsageError as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return EXIT_CODES["usage"]
    except BrokenPipeError:  # e.g. `creps-gym list | head`: the reader left, which is not an error
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_CODES["ok"]
    except KeyboardInterrupt:
        run_dir = getattr(args, "out", None) or getattr(args, "run_dir", None)
        advice = f"; `creps-gym resume {shlex.quote(str(run_dir))}` continues from the last checkpoint"
        print(f"{prog}: interrupted{advice if run_dir else ''}", file=sys.stderr)
        return EXIT_CODES["interrupted"]
    except Exception as exc:
        code = _failure(exc, prog)
        if code is None:
            raise
        return code


if __name__ == "__main__":
    _drop_cwd_from_path()
    sys.exit(main())
