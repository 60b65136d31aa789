"""A study's command line: the options every study shares and the command its report names.

Every study's ``parse_args`` adds ``--quick``/``--full`` (:func:`add_mode_options`) and the output options
(:func:`add_output_options`), then :func:`resolve_outputs` fills in the default cache and output folders
and the flags that determine the results (:func:`command_flags`), which the report and the results index
quote as the command that computed them.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

__all__ = [
    "NEUTRAL_OPTIONS",
    "add_mode_options",
    "add_output_options",
    "command_flags",
    "json_object",
    "resolve_outputs",
]


def json_object(text: str) -> dict[str, Any]:
    """An argument that holds a JSON object (options), else ``argparse.ArgumentTypeError``, which argparse
    reports naming the argument."""
    try:
        value = json.loads(text)
    except json.JSONDecodeError as error:
        raise argparse.ArgumentTypeError(f"expected a JSON object, got {text!r} ({error})") from None
    if not isinstance(value, dict):
        raise argparse.ArgumentTypeError(f"expected a JSON object, got {text!r}")
    return value


def add_mode_options(parser: argparse.ArgumentParser, quick: str, full: str) -> None:
    """``--quick``/``--full`` (into ``mode``), with their help texts."""
    mode = parser.add_mutually_exclusive_group()
    quick += ", computing every run again (a reproduction; --render-only redraws the committed runs)"
    mode.add_argument("--quick", action="store_const", dest="mode", const="quick", help=quick)
    mode.add_argument("--full", action="store_const", dest="mode", const="full", help=full)


def add_output_options(parser: argparse.ArgumentParser, study_dir: Path, out: str) -> None:
    """Add ``--workers``, ``--render-only``, ``--cache`` (default: see :func:`resolve_outputs`) and ``--out``
    (help text ``out``)."""
    parser.add_argument("--workers", type=int, default=2, help="processes (default 2)")
    parser.add_argument(
        "--render-only", action="store_true", help="compute nothing: render the runs already cached"
    )
    parser.add_argument(
        "--cache",
        type=Path,
        help="per-run JSON (committed; default runs/quick/ with --quick, which computes every run again, "
        "else runs/, where runs already cached are reused)",
    )
    parser.add_argument("--out", type=Path, help=out)


def resolve_outputs(
    args: argparse.Namespace, argv: Sequence[str] | None, study_dir: Path, label: str
) -> None:
    """Set ``args.flags`` (see :func:`command_flags`), ``args.index`` (the results index, or None with
    ``--out``), ``args.out`` (default ``docs/results/<study>/<label>``) and ``args.cache`` (default
    ``<study>/runs/quick`` for ``--quick``, whose runs are computed again by every invocation, so that they
    never replace the documents a ``--full`` rendering reads, and ``<study>/runs`` otherwise)."""
    results = study_dir.parents[1] / "docs" / "results"
    if args.cache is None:
        args.cache = study_dir / "runs" / "quick" if args.mode == "quick" else study_dir / "runs"
    args.flags = command_flags(argv, args.mode)
    args.index = results / "README.md" if args.out is None else None
    args.out = args.out or results / study_dir.name / label


#: Options that change where or how fast a study runs, not its results, with their argument counts (None:
#: every argument up to the next option): the reported command leaves them out.
NEUTRAL_OPTIONS = {"--render-only": 0, "--workers": 1, "--cache": 1, "--out": 1, "--compute-methods": None}


def command_flags(argv: Sequence[str] | None, mode: str) -> str:
    """The options of a study's command line (``sys.argv[1:]`` if ``argv`` is None) that determine its
    results, i.e. without :data:`NEUTRAL_OPTIONS`; ``--<mode>`` when none is left."""
    given = sys.argv[1:] if argv is None else list(argv)
    kept, skip = [], 0
    for arg in given:
        name, has_value, _ = arg.partition("=")
        if skip and not (skip < 0 and arg.startswith("--")):
            skip -= 1
        elif name in NEUTRAL_OPTIONS:
            count = NEUTRAL_OPTIONS[name]
            skip = 0 if has_value else (-1 if count is None else count)  # -1: until the next option
        else:
            skip = 0
            kept.append(arg)
    return " ".join(kept) or f"--{mode}"
