"""Issue 12's targets: the episodes C-CMA-ES needs on Sphere, Rosenbrock and the Elliptic, and its peers'.

The setting of every run: p = 15, contexts U[0, 3]^z with z in {1, 3}, initial mean U[-5, 5]^p (drawn from the
seed, the same for every context), σ0 = 1, and the regret of the mean policy averaged over 100 fixed test
contexts after every iteration, until it is <= 1e-5 or the budget is spent. The methods (columns of
:mod:`benchmarks.ccmaes.report`) are registry optimisers at N = 50 or at their recommended batch size, and
pycma on one context at N = 50 and at its default population; an optimiser that is not registered yet is
skipped with a message. Runs are cached as JSON under ``--cache`` (the study resumes) and computed in a
process pool; the tables (``results.md``) and the figure are written from the cache only.

    python benchmarks/ccmaes/run.py --quick     # 2 seeds per cell, budget 100k
    python benchmarks/ccmaes/run.py --full      # 5 seeds per cell, 20 for the headline table, budget 200k
    python benchmarks/ccmaes/run.py --full --remedies   # only the remedies table's runs (Rosenbrock)

(or ``python -m benchmarks.ccmaes.run ...``, from the repository root).
"""

from __future__ import annotations

import argparse
import itertools
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

# Run by path: the repository root first on sys.path, as `python -m` puts it (see benchmarks/__init__.py).
if not __package__:
    sys.path[0] = str(Path(__file__).resolve().parents[2])

import matplotlib

matplotlib.use("Agg")

from benchmarks.baselines import BASELINES
from benchmarks.ccmaes.columns import (
    BATCH_SWEEP,
    BOUND_COLUMNS,
    COLUMNS,
    HEADLINE,
    REMEDIES,
    REMEDY_FUNCTION,
    SIGNAL_COLUMNS,
    SWEEP_FUNCTION,
    YARDSTICK,
    Column,
)
from benchmarks.ccmaes.report import (
    bound_table,
    csa_text,
    headline_table,
    plot_curves,
    remedies_table,
    seed_table,
    signal_table,
    sweep_table,
)
from benchmarks.ccmaes.surrogate_table import SURROGATE_COLUMNS, surrogate_table
from benchmarks.study_cli import add_mode_options, add_output_options, resolve_outputs
from benchmarks.study_options import pin_c3
from benchmarks.study_report import timing_text
from benchmarks.study_runner import available_methods, run_study
from benchmarks.study_tools import RunSpec, ended_early

HERE = Path(__file__).resolve().parent
FUNCTIONS = ("Sphere", "Rosenbrock", "ShiftedRotatedElliptic")
#: The issue's setting: N = 50 samples per iteration, 100 test contexts, mean U[-5, 5]^p with σ0 = 1.
SAMPLES, EVAL_CONTEXTS, INITIAL = 50, 100, "uniform5"
#: Every column: the methods', then the remedies' variants of C-CMA-ES (on Rosenbrock), its batch sizes (on
#: the Sphere at z = 1), its step-size signals (every cell), the bound table's variants (each in its cell) and
#: pycma on the Sphere with 2p parameters (at z = 1) and the surrogate (issue 33's cells); all but the
#: methods' with the headline seeds.
REMEDY_VARIANTS = tuple(c for c in REMEDIES if c.name not in {m.name for m in COLUMNS})
ALL_COLUMNS = (
    COLUMNS + REMEDY_VARIANTS + BATCH_SWEEP + SIGNAL_COLUMNS + BOUND_COLUMNS + YARDSTICK + SURROGATE_COLUMNS
)
PRESETS = {
    "quick": {"seeds": 2, "headline_seeds": 2, "budget": 100_000},
    "full": {"seeds": 5, "headline_seeds": 20, "budget": 200_000},
}


def parse_args(argv: Sequence[str] | None = None) -> argparse.Namespace:
    """Command-line options; ``--quick``/``--full`` pick the defaults of the others."""
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    add_mode_options(parser, quick="2 seeds per cell", full="the whole protocol")
    parser.add_argument("--functions", nargs="+", choices=FUNCTIONS, default=list(FUNCTIONS))
    parser.add_argument("--context-dims", nargs="+", type=int, default=[1, 3], help="context dimensions z")
    parser.add_argument("--seeds", type=int, help="seeds per cell (0 .. n-1)")
    parser.add_argument("--headline-seeds", type=int, help="seeds of the headline table's columns")
    parser.add_argument("--budget", type=int, help="episode budget per run (censoring level)")
    parser.add_argument("--dim", type=int, default=15, help="problem dimension p (the targets are for 15)")
    names = list(dict.fromkeys(c.name for c in ALL_COLUMNS))
    parser.add_argument("--columns", nargs="+", choices=names, default=names, help="methods to run")
    parser.add_argument(
        "--remedies",
        action="store_true",
        help=f"only the remedies table's runs: --functions {REMEDY_FUNCTION} and its columns",
    )
    add_output_options(parser, HERE, out="figure and tables (default docs/results/ccmaes/<mode>)")
    args = parser.parse_args(argv)
    args.mode = args.mode or "full"
    if args.remedies:
        args.functions, args.columns = [REMEDY_FUNCTION], [c.name for c in REMEDIES]
    resolve_outputs(args, argv, HERE, args.mode)
    preset = PRESETS[args.mode]
    args.context_dims = sorted(set(args.context_dims))
    for name in ("seeds", "headline_seeds", "budget"):
        setattr(args, name, getattr(args, name) if getattr(args, name) is not None else preset[name])
    for name in ("seeds", "headline_seeds", "budget", "workers"):
        if getattr(args, name) < 1:
            parser.error(
                f"--{name.replace('_', '-')}: expected a positive integer, got {getattr(args, name)}"
            )
    if args.dim < 2 or min(args.context_dims) < 1:
        parser.error(f"--dim/--context-dims: expected p >= 2 and z >= 1, got {args.dim}, {args.context_dims}")
    return args


def recommended_batch(dim: int, context_dim: int) -> int | None:
    """C-CMA-ES's ``recommended_batch_size(p, z)``; None while :mod:`creps_gym.optimizers.ccmaes` lacks it."""
    try:
        from creps_gym.optimizers.ccmaes import recommended_batch_size
    except ImportError:
        return None
    return int(recommended_batch_size(dim, context_dim))


def column_specs(args: argparse.Namespace, log: Any = print) -> list[tuple[str, RunSpec]]:
    """(column name, spec) of every run; the columns whose optimiser (or recommended batch size) does not
    exist yet are skipped with a message."""
    chosen = [c for c in ALL_COLUMNS if c.name in args.columns]
    methods = available_methods(list(dict.fromkeys(c.method for c in chosen)), BASELINES, log)
    pairs = []
    for column in chosen:
        if column.method not in methods:
            continue
        if column.batch == "recommended" and recommended_batch(args.dim, 1) is None:
            log(f"skipped column {column.name!r}: creps_gym.optimizers.ccmaes has no recommended_batch_size")
            continue
        restricted = bool(column.functions or column.context_dims)
        headline = column.name in HEADLINE or column in SIGNAL_COLUMNS or restricted
        seeds = max(args.seeds, args.headline_seeds) if headline else args.seeds
        functions = [f for f in args.functions if not column.functions or f in column.functions]
        dims = [z for z in args.context_dims if not column.context_dims or z in column.context_dims]
        for name, z, seed in itertools.product(functions, dims, range(seeds)):
            pairs.append((column.name, make_spec(column, name, args.dim, z, seed, args.budget)))
    return pairs


def make_spec(column: Column, function: str, dim: int, z: int, seed: int, budget: int) -> RunSpec:
    """The run of ``column`` in the study's setting (the ``"default"`` batch keeps N = 50 in the key:
    ``cma-fixed`` uses pycma's own population whatever ``samples`` is)."""
    if column.batch == "recommended":
        samples = recommended_batch(dim, z)  # p's, also for a column with dim_factor > 1
    else:
        samples = SAMPLES if column.batch == "default" else column.batch
    return RunSpec(
        function,
        dim * column.dim_factor,
        z,
        column.method,
        seed,
        max(budget, samples),
        samples,
        eval_contexts=EVAL_CONTEXTS,
        initial=INITIAL,
        options=pin_c3(column.method, column.options),  # the committed runs' C3 (benchmarks/study_options.py)
    )


def group(pairs: Sequence[tuple[str, RunSpec]], documents: Sequence[dict], seeds: int | None = None) -> dict:
    """The cached documents by (function, z, column); with ``seeds``, only the seeds below it.

    A run cached with a smaller budget that ended early stands for the run with the larger budget (the
    cache's reuse rule, :func:`~benchmarks.study_tools.cached_result`).
    """
    by_key = {RunSpec(**d["spec"]).key: d for d in documents}
    by_prefix = {(RunSpec(**d["spec"]).prefix, d["spec"]["samples"]): d for d in documents if ended_early(d)}
    cells: dict[tuple[str, int, str], list[dict]] = {}
    for column, spec in pairs:
        document = by_key.get(spec.key) or by_prefix.get((spec.prefix, spec.samples))
        if (
            document is not None
            and document["spec"]["budget"] <= spec.budget
            and (seeds is None or spec.seed < seeds)
        ):
            cells.setdefault((spec.function, spec.context_dim, column), []).append(document)
    return cells


def write_report(args: argparse.Namespace, documents: list[dict], timing: dict[str, Any]) -> Path:
    """Write the figure and ``results.md`` into ``args.out``; returns the table's path."""
    args.out.mkdir(parents=True, exist_ok=True)
    rows = [(name, z) for name in args.functions for z in args.context_dims]
    columns = [c for c in COLUMNS if any(column == c.name for column, _ in args.pairs)]
    skipped = [c.label for c in COLUMNS if c.name in args.columns and c not in columns]
    few = group(args.pairs, documents, args.seeds)
    figure = plot_curves(few, columns, rows, args.seeds, args.out / "curves.png").name
    targets = "" if args.dim == 15 else f" (the targets are for p = 15; this is p = {args.dim})"
    text = [
        f"# C-CMA-ES target study ({args.mode}): generated by `benchmarks/ccmaes/run.py`",
        "",
        f"Command: `python benchmarks/ccmaes/run.py {args.flags}`. p = {args.dim}, contexts U[0, 3]^z, "
        "initial mean U[-5, 5]^p (from the seed, the same for every context), σ0 = 1, "
        f"{EVAL_CONTEXTS} test contexts, episode budget {args.budget:,} per run, function instance = seed.",
        timing_text(timing, documents),
        "",
        "Cells: median over the seeds of the training episodes until the mean regret of the mean policy on "
        f"the {EVAL_CONTEXTS} test contexts is <= 1e-5, a seed that never got there counting as infinitely "
        f"many (`>{args.budget:,}`: the median seed missed), and (seeds that got there / seeds). pycma on 1 "
        "context: episodes until the regret at that single context (the first test context) met 1e-5."
        + (f" Not run (not available in this version): {'; '.join(skipped)}." if skipped else ""),
        "",
        f"## Issue 12's targets ({args.headline_seeds} seed(s)){targets}",
        "",
        headline_table(group(args.pairs, documents), rows, args.budget),
        f"## Every method ({args.seeds} seed(s))",
        "",
        seed_table(few, columns, rows, args.budget),
        csa_text(few, rows),
        "",
        *extra_sections(args, documents),
        "## Figures",
        "",
        f"![curves]({figure})",
        "",
    ]
    path = args.out / "results.md"
    path.write_text("\n".join(text), encoding="utf-8")
    return path


def extra_sections(args: argparse.Namespace, documents: list[dict]) -> list[str]:
    """The remedies, batch-size and step-size-signal sections of ``results.md`` (each empty without its runs
    in the study)."""
    names = {column for column, _ in args.pairs}
    seeds = max(args.seeds, args.headline_seeds)
    cells = group(args.pairs, documents)
    text = []
    if names & {c.name for c in REMEDIES} - {c.name for c in COLUMNS}:
        text += [
            f"## {REMEDY_FUNCTION}: the remedies ({seeds} seed(s), C-CMA-ES, N = 50)",
            "",
            remedies_table(cells, args.context_dims, args.budget, seeds),
        ]
    if names & {c.name for c in BATCH_SWEEP}:
        text += [
            f"## {SWEEP_FUNCTION}, z = 1: C-CMA-ES's batch size ({seeds} seed(s))",
            "",
            sweep_table(cells, args.budget, seeds),
        ]
    if names & {c.name for c in BOUND_COLUMNS + YARDSTICK}:
        text += [
            f"## Sphere at z = 1 against Rosenbrock at z = 3: faster step-size control ({seeds} seed(s))",
            "",
            bound_table(cells, args.budget, seeds),
        ]
    if names & {c.name for c in SIGNAL_COLUMNS}:
        rows = [(name, z) for name in args.functions for z in args.context_dims]
        text += [
            f"## C-CMA-ES's step-size signal ({seeds} seed(s))",
            "",
            signal_table(cells, rows, args.budget, seeds),
        ]
    if names & {c.name for c in SURROGATE_COLUMNS}:
        text += [
            f"## The surrogate: C-CMA-ES + surrogate against C-CMA-ES and pycma ({seeds} seed(s))",
            "",
            surrogate_table(cells, args.budget),
        ]
    return text


def main(argv: Sequence[str] | None = None) -> int:
    """Run (or resume) the study and write its report."""
    args = parse_args(argv)
    args.pairs = column_specs(args)
    return run_study(
        args,
        [spec for _, spec in args.pairs],
        write_report,
        baselines=BASELINES,
        title="C-CMA-ES target study (issue 12)",
        script="benchmarks/ccmaes/run.py",
        figures_marker="\n## Figures",
        readme=HERE / "README.md",
    )


if __name__ == "__main__":
    raise SystemExit(main())
