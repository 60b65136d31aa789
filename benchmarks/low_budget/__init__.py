"""The low-budget studies (issue 44): ``run.py`` (the 50–500 episode study of item 5: ``columns.py``,
``study.py``, ``report.py``), ``compare.py`` (regret after a fixed episode budget), ``gp_backends.py`` (the
GP's cost against scikit-learn's), ``active_contexts.py`` (active context choice against uniform draws),
``reach.py`` (what the low-dimensional kicks can reach at all), ``strong_kicks.py`` (the v1 kicks'
columns), ``recommenders.py`` (c-bo's recommendation rules on the same runs), ``acquisition_choices.py``
(both acquisitions' choices from the same model), ``rastrigin_ripples.py`` (where c-bo's
recommendations land on Rastrigin), ``stop_signal.py`` (when c-bo's ``no_signal`` stop fires),
``refit_data.py`` (c-bo's refit default of 2026-11-30
beside the study's runs) and ``botorch_cbo.py`` (the study's BoTorch column)."""

from __future__ import annotations

import argparse
import json
import shlex
import sys
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

from benchmarks.study_cli import json_object

#: The repository root, where the replays run (``--against`` paths are relative to it).
ROOT = Path(__file__).resolve().parents[2]


def add_output_arguments(parser: argparse.ArgumentParser) -> None:
    """``--out`` (the results' JSON) and ``--render-only`` (redraw the table from it), as both take."""
    parser.add_argument("--out", type=Path, required=True, help="the results' JSON (read with --render-only)")
    parser.add_argument("--render-only", action="store_true", help="only write the table next to --out")


def parse_runs_arguments(
    parser: argparse.ArgumentParser, argv: list[str] | None, seeds: int, render: Callable[[Path], str]
) -> argparse.Namespace | None:
    """Add ``--seeds`` (default ``seeds``), ``--workers`` and the output arguments to ``parser`` and parse
    ``argv``; with ``--render-only`` print ``render(out)`` and return None."""
    parser.add_argument("--seeds", type=int, default=seeds)
    parser.add_argument("--workers", type=int, default=1)
    add_output_arguments(parser)
    args = parser.parse_args(argv)
    if args.render_only:
        print(render(args.out))
        return None
    return args


def run_and_write(
    job: Callable[[Any], dict[str, Any]],
    jobs: Sequence[Any],
    workers: int,
    out: Path,
    render: Callable[[Path], str],
    extra: dict[str, Any] | None = None,
) -> None:
    """Run ``job`` on each of ``jobs`` in ``workers`` processes, print each result as a JSON line in the
    jobs' order, write the document ``{"command", "runs", "provenance"}`` (and the entries of ``extra``) to
    ``out`` and print ``render(out)``."""
    from benchmarks.provenance import provenance

    with ProcessPoolExecutor(workers) as pool:
        runs = []
        for result in pool.map(job, jobs):
            runs.append(result)
            print(json.dumps(result), flush=True)
    document = {"command": sys.argv, "runs": runs, "provenance": provenance(), **(extra or {})}
    out.write_text(json.dumps(document, indent=1) + "\n")
    print(render(out))


def replay_command(module: str, document: dict[str, Any]) -> str:
    """The command that wrote ``document`` (its ``command``: ``sys.argv``), as ``python -m
    benchmarks.low_budget.<module> ...`` with its arguments quoted for a shell."""
    return shlex.join(["python", "-m", f"benchmarks.low_budget.{module}", *document["command"][1:]])


def replay_results_path(text: str) -> Path:
    """Where ``--against``'s results file ``text`` is: as given when absolute, else from the repository
    root, where the replays run."""
    path = Path(text)
    return path if path.is_absolute() else ROOT / path


def _results_file(text: str) -> str:
    """``--against``: a results file (JSON) that exists (:func:`replay_results_path`), kept as given, else
    ``argparse.ArgumentTypeError``."""
    if not replay_results_path(text).is_file():
        raise argparse.ArgumentTypeError(
            f"expected a replay's results file (JSON), got {text!r}: no such file"
        )
    return text


def _add_variant_arguments(parser: argparse.ArgumentParser) -> None:
    """``--unpinned``, ``--options``, ``--first-seed`` and ``--against`` (see :func:`column_replay_main`)."""
    parser.add_argument(
        "--unpinned", action="store_true", help="the columns without the study's c-bo refit pin"
    )
    parser.add_argument(
        "--options", type=json_object, default={}, help="c-bo options the columns add (a JSON object)"
    )
    parser.add_argument(
        "--first-seed", type=int, default=0, help="seeds first-seed, …, first-seed + seeds - 1 (default 0)"
    )
    parser.add_argument(
        "--against", type=_results_file, help="a replay's results (JSON, from the repository root) to compare"
    )


def column_replay_main(
    description: str,
    tasks: Sequence[str],
    job: Callable[[tuple[Any, ...]], dict[str, Any]],
    render: Callable[[Path], str],
    argv: list[str] | None = None,
    variant_flags: bool = False,
) -> None:
    """The command line of a replay of the study's c-bo columns: ``--tasks`` (default ``tasks``),
    ``--methods`` (default ``c-bo``), ``--budget`` (500) and :func:`parse_runs_arguments`' options; runs
    ``job((task, method, seed, budget))`` for each of the study's seeds and writes the results
    (:func:`run_and_write`). With ``variant_flags`` it takes the flags of a variant of the columns too:
    ``--unpinned`` and ``--options`` (a JSON object of c-bo options the columns add), which the job gets,
    ``(task, method, seed, budget, unpinned, options)``; ``--first-seed`` (0: the study's seeds; 10: seeds
    beyond them); and ``--against``, another replay's results that the document names (``"against"``) for
    ``render`` to compare with."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--tasks", nargs="+", default=list(tasks), help="study task names")
    parser.add_argument("--methods", nargs="+", default=["c-bo"], help="the study's c-bo columns")
    parser.add_argument("--budget", type=int, default=500)
    if variant_flags:
        _add_variant_arguments(parser)
    args = parse_runs_arguments(parser, argv, 10, render)
    if args is None:
        return
    extra = (args.unpinned, args.options) if variant_flags else ()
    first = args.first_seed if variant_flags else 0
    seeds = range(first, first + args.seeds)
    jobs = [(t, m, s, args.budget, *extra) for t in args.tasks for m in args.methods for s in seeds]
    against = {"against": args.against} if variant_flags and args.against else {}
    run_and_write(job, jobs, args.workers, args.out, render, against)
