"""Figs 1-2 of the paper: CREPS, CREPS-CMA-old and CREPS-CMA-current on the 15 contextual test functions.

Protocol: p = 15, context dimensions z = 1 and 3, 50 samples per iteration, the regret of the mean policy on
16 fixed test contexts after every iteration (mean f for Plane and the ridges), each run stopped at the
paper's target (regret 1e-5, or f <= -1e4) or at the episode budget; with the baselines of :mod:`baselines`.
Every run is cached as JSON under ``--cache`` (skipped when present: the study resumes), runs go to a
process pool, and the table (``results.md``) and one PNG per function are written from the cache only.

    python benchmarks/functions/run.py --quick     # a subset, < 10 min on 2 cores
    python benchmarks/functions/run.py --full      # all 15 functions x z in {1, 3} x 5 seeds

(or ``python -m benchmarks.functions.run ...``, from the repository root).
"""

from __future__ import annotations

import argparse
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
from benchmarks.functions.report import METHODS, claims, plot_function, results_table
from benchmarks.study_cli import add_mode_options, add_output_options, resolve_outputs
from benchmarks.study_options import pin_c3
from benchmarks.study_report import timing_text
from benchmarks.study_runner import available_methods, run_study
from benchmarks.study_tools import RunSpec
from creps_gym.envs.functions import SPECS

HERE = Path(__file__).resolve().parent

ALL_FUNCTIONS = tuple(spec.name for spec in SPECS)
PRESETS = {
    "quick": {
        "functions": ("Sphere", "Rosenbrock", "ShiftedRotatedElliptic", "Plane", "Rastrigin"),
        "context_dims": (1, 3),
        "seeds": 3,
        "budget": 100_000,
    },
    "full": {"functions": ALL_FUNCTIONS, "context_dims": (1, 3), "seeds": 5, "budget": 200_000},
}


def parse_args(argv: Sequence[str] | None = None) -> argparse.Namespace:
    """Command-line options; ``--quick``/``--full`` pick the defaults of the others."""
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    add_mode_options(parser, quick="a fast subset", full="the whole protocol")
    parser.add_argument("--functions", nargs="+", choices=ALL_FUNCTIONS, help="functions to run")
    parser.add_argument("--context-dims", nargs="+", type=int, help="context dimensions z")
    parser.add_argument("--seeds", type=int, help="seeds per configuration (0 .. n-1)")
    parser.add_argument("--budget", type=int, help="episode budget per run")
    parser.add_argument("--dim", type=int, default=15, help="problem dimension p (paper: 15)")
    parser.add_argument("--samples", type=int, default=50, help="samples per iteration (paper: 50)")
    parser.add_argument("--methods", nargs="+", choices=METHODS, default=list(METHODS))
    add_output_options(parser, HERE, out="figures and table (default docs/results/functions/<mode>)")
    args = parser.parse_args(argv)
    args.mode = args.mode or "full"
    resolve_outputs(args, argv, HERE, args.mode)
    args.methods = available_methods(args.methods, BASELINES)  # skips the optimisers not registered yet
    preset = PRESETS[args.mode]
    args.functions = args.functions or list(preset["functions"])
    args.context_dims = args.context_dims or list(preset["context_dims"])
    args.seeds = args.seeds if args.seeds is not None else preset["seeds"]
    args.budget = args.budget if args.budget is not None else preset["budget"]
    for name in ("seeds", "budget", "dim", "samples", "workers"):
        if getattr(args, name) < 1:
            parser.error(f"--{name}: expected a positive integer, got {getattr(args, name)}")
    if args.budget < args.samples:
        parser.error(f"--budget: expected at least --samples ({args.samples}), got {args.budget}")
    return args


def make_specs(args: argparse.Namespace) -> list[RunSpec]:
    """Every run of the study, cheapest first within each function (the pool balances better)."""
    return [
        RunSpec(name, args.dim, z, method, seed, args.budget, args.samples, options=pin_c3(method))
        for name in args.functions
        for z in args.context_dims
        for seed in range(args.seeds)
        for method in args.methods
    ]


def write_report(args: argparse.Namespace, documents: list[dict], timing: dict[str, Any]) -> Path:
    """Write the figures and ``results.md`` into ``args.out``; returns the table's path."""
    args.out.mkdir(parents=True, exist_ok=True)
    figures = []
    for name in args.functions:
        runs = [d for d in documents if d["spec"]["function"] == name]
        if not runs:
            continue
        figures.append(plot_function(runs, name, args.context_dims, args.out / f"{name}.png").name)
    command = f"python benchmarks/functions/run.py {args.flags}"
    text = [
        f"# Function study ({args.mode}): generated by `benchmarks/functions/run.py`",
        "",
        f"Command: `{command}`. p = {args.dim}, {args.samples} samples per iteration, "
        f"{args.seeds} seed(s), episode budget {args.budget:,} per run, functions instance = seed.",
        timing_text(timing, documents),
        "",
        "Cells: median training episodes until the mean regret of the mean policy on 16 test contexts is "
        "<= 1e-5 (mean f <= -1e4 for Plane and the ridges), over the seeds that got there, and "
        "(seeds that got there / seeds); ✗ = no seed got there, with the median final value. "
        "pycma on 1 fixed context: episodes until the regret at that single context met the target, at "
        "pycma's default population 4 + floor(3 ln p) or at N = samples. "
        "Regression baseline: total episodes of the independent CMA-ES runs, the resulting mean test "
        "regret (mean f) and how many seeds met the target.",
        "",
        "## The paper's claims on these runs",
        "",
        claims(documents),
        "",
        results_table(documents, args.functions, args.context_dims, args.methods),
        "## Figures",
        "",
        *[f"![{name}]({name})" for name in figures],
        "",
    ]
    path = args.out / "results.md"
    path.write_text("\n".join(text), encoding="utf-8")
    return path


def main(argv: Sequence[str] | None = None) -> int:
    """Run (or resume) the study and write its report."""
    args = parse_args(argv)
    return run_study(
        args,
        make_specs(args),
        write_report,
        baselines=BASELINES,
        title="Function study",
        script="benchmarks/functions/run.py",
        figures_marker="\n## Figures",
        readme=HERE / "README.md",
    )


if __name__ == "__main__":
    raise SystemExit(main())
