"""The ``creps-gym`` commands that read: ``list`` (envs and optimisers), ``plot`` and ``export`` (results).

``list`` prints the static table :mod:`creps_gym._table` (generated from the registries), so it starts
without importing numpy, Gymnasium or any env. ``plot`` and ``export`` group their run directories by
setting (:mod:`creps_gym.runner.results.groups`: everything fingerprinted but the seed) and take ``--label``.
"""

from __future__ import annotations

import argparse
import os
from typing import Any

from creps_gym.cli.types import add_import, import_user_modules
from creps_gym.errors import UsageError

__all__ = ["COMMANDS", "add_commands"]

_LABEL_HELP = (
    "legend / algorithm_id label (repeatable): one per DIR (runs with the same label are pooled as seeds) "
    "or one per setting group, in the order of each group's first DIR (default: the optimiser and the "
    "settings that differ between the groups)"
)


def add_commands(commands: Any) -> None:
    """Add ``list``, ``plot`` and ``export`` to the sub-command parsers ``commands``."""
    commands.add_parser(
        "list",
        help="list the envs and optimisers",
        description="List the envs (context and parameter spaces, the default initial search distribution) "
        "and the optimisers.",
    )
    plot = _runs_command(
        commands,
        "plot",
        "plot learning curves of run directories",
        "Plot learning curves: one curve (median and quartile band over seeds) per setting.",
        "image file, e.g. curves.png",
    )
    plot.add_argument("--title", help="figure title (default: the env and its dimensions)")
    export = _runs_command(
        commands,
        "export",
        "write run directories as one IOHanalyzer CSV",
        "Write run directories as one IOHanalyzer CSV, one algorithm_id per setting.",
        "CSV file",
    )
    for command in (plot, export):
        command.add_argument("--mix-envs", action="store_true", help="allow runs of different envs")
        command.add_argument("--label", dest="labels", action="append", metavar="TEXT", help=_LABEL_HELP)
        add_import(command)


def _runs_command(commands: Any, name: str, summary: str, description: str, output: str) -> Any:
    """A command that reads run directories (``DIR ...``) and writes one file (``-o FILE``)."""
    command = commands.add_parser(name, help=summary, description=description)
    command.add_argument("run_dirs", nargs="+", metavar="DIR")
    command.add_argument("-o", "--output", required=True, metavar="FILE", help=output)
    return command


def _cmd_list(_: argparse.Namespace) -> int:
    from creps_gym._table import ENVS, OPTIMIZERS
    from creps_gym.listing import OPTIMIZER_HEADER, available_env_rows, env_listing, table_wrapped

    print("Environments: id, context space, parameter space θ, initial search distribution by default")
    print(env_listing(available_env_rows(ENVS)))
    print("Optimizers:")
    print(table_wrapped([OPTIMIZER_HEADER, *OPTIMIZERS]))
    return 0


def _import(args: argparse.Namespace) -> None:
    """The ``--import`` modules, if any (a user's env, optimiser or selector class that a run names)."""
    if args.imports:
        import_user_modules(args.imports)


def _grouped(args: argparse.Namespace) -> tuple[list[Any], dict, list[str]]:
    """The runs of ``args.run_dirs`` (read before anything may turn a ``RunDirError`` into a usage
    error), their groups and each run's label."""
    from creps_gym.runner.results.export import check_one_env
    from creps_gym.runner.results.groups import group_runs, load_runs

    runs = load_runs(args.run_dirs)
    try:
        check_one_env([history for _, history in runs], args.mix_envs)
        groups, labels = group_runs(runs, args.labels)
    except ValueError as exc:  # runs of different envs without --mix-envs, or a bad number of labels
        field, _, rest = str(exc).partition(": ")
        raise UsageError(f"argument --label: {rest}" if field == "labels" else str(exc)) from None
    return runs, groups, labels


def _write_output(write: Any, args: argparse.Namespace, what: str) -> int:
    """Write ``-o`` with ``write(path)`` (exit 2 if it cannot be) and print the file actually written."""
    try:
        written = write(args.output)
    except (ValueError, OSError) as exc:
        cause = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
        cause = cause.removeprefix("path: ")
        where = f"cannot write {args.output}: " if isinstance(exc, OSError) else ""
        raise UsageError(f"argument -o/--output: {where}{cause}") from None
    named = os.path.abspath(args.output) == str(written)
    print(f"{what}: {args.output}" if named else f"{what}: {written} (through the link {args.output})")
    return 0


def _cmd_plot(args: argparse.Namespace) -> int:
    from creps_gym.runner.results.plots import check_title, plot_histories, save_figure

    _import(args)

    if args.title is not None:
        try:
            check_title(args.title)
        except ValueError as exc:
            raise UsageError(f"argument --title: {str(exc).removeprefix('title: ')}") from None
    runs, groups, _ = _grouped(args)
    targets = {config.target_regret for config, _ in runs}
    target = targets.pop() if len(targets) == 1 else None
    figure = plot_histories(groups, title=args.title, mix_envs=args.mix_envs, target_regret=target)
    return _write_output(lambda path: save_figure(figure, path), args, "plot")


def _cmd_export(args: argparse.Namespace) -> int:
    from creps_gym.runner.results.export import write_iohanalyzer

    _import(args)

    runs, _, labels = _grouped(args)
    histories = [history for _, history in runs]

    def write(path: str) -> Any:
        return write_iohanalyzer(histories, path, mix_envs=args.mix_envs, labels=labels)

    return _write_output(write, args, "IOHanalyzer CSV")


COMMANDS = {"list": _cmd_list, "plot": _cmd_plot, "export": _cmd_export}
