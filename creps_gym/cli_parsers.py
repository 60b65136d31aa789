"""The ``creps-gym run`` parser and the flags several commands share (``--progress``, ``--import``).

Building it imports neither numpy nor Gymnasium: the defaults come from :mod:`creps_gym.cli_table`.
"""

from __future__ import annotations

import argparse
from typing import Any

from creps_gym.cli_types import (
    initial_mean,
    integer,
    key_value,
    numbers,
    positive_float,
    positive_or_none,
    selector_name,
)

__all__ = ["OPT_EXAMPLE", "add_import", "add_progress", "add_run"]

#: The ``--opt`` example of ``run --help``: an option of the README's optimiser, c-cma-es (tested).
OPT_EXAMPLE = "restarts=0"
_WORKERS_DEFAULT = "vector: one per sample for a native vector env, else one per CPU; Ray: the cluster's CPUs"
_DIVERGENCE_HELP = (
    "stop once 10 evaluations in a row are worse than the first by this factor of its size ('none': never)"
)
_INITIAL_MEAN_HELP = "a number, p comma-separated numbers, or 'uniform' in the box"


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


def add_run(commands: Any) -> None:
    """The ``run`` command's parser: the required flags, where episodes run, budgets and evaluation, the
    search's start and the optimiser's, env's and selector's options."""
    from creps_gym.cli_table import RUN_DEFAULTS  # RunConfig's (listing checks they agree): no numpy

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
    from creps_gym.cli_table import BACKENDS, VECTOR_MODES

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
        ("--initial-mean", initial_mean, _INITIAL_MEAN_HELP, "the env-declared mean"),
        ("--initial-std", numbers, "initial standard deviation(s)", "the env-declared one"),
    ]
    for flag, parse, text, if_none in optional:
        default = defaults[flag[2:].replace("-", "_")]
        shown = if_none if default is None else default
        run.add_argument(flag, type=parse, default=default, help=f"{text} (default: {shown})")


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
        run.add_argument(
            flag,
            action="append",
            type=key_value,
            default=[],
            metavar="KEY=VALUE",
            help=f"{text}; VALUE is JSON or a string (repeatable)",
        )


def add_import(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--import",
        dest="imports",
        action="append",
        default=[],
        metavar="MODULE",
        help="import MODULE first (e.g. the module that registers your env or optimiser; repeatable; "
        "searched in the current directory too); a run directory never makes creps-gym import anything",
    )
