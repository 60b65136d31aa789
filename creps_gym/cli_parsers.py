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

__all__ = ["add_import", "add_progress", "add_run"]


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
    from creps_gym.cli_table import BACKENDS, RUN_DEFAULTS, VECTOR_MODES

    run_defaults = RUN_DEFAULTS  # RunConfig's (creps_gym.listing checks they agree): numpy stays unloaded

    run = commands.add_parser(
        "run", help="run an optimiser on an env", description="Run an optimiser on an env."
    )
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
    run.add_argument(
        "--context-selector",
        type=selector_name,
        default=None,
        metavar="NAME",
        help="who chooses the training contexts (e.g. uniform, arcsine, bandit, progress; see "
        "docs/contexts.md); default: the env's own draws",
    )
    flags = (
        ("--opt", "optimiser option, e.g. --opt epsilon=1.0"),
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
    add_progress(run)


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
