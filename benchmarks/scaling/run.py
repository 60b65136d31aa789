"""Fig. 3 of the paper: episodes CREPS-CMA-old needs to reach the target, over context and problem dimensions.

For Rosenbrock, Sphere, Shifted Schwefel 1.2 and the Shifted Rotated Elliptic (condition 1e6), each cell
(z, p) is the median number of training episodes (50 samples per iteration) until the mean regret of the mean
policy on 16 fixed test contexts is <= 1e-5. Runs that spend their budget first are censored: the cell shows
``>budget`` and is hatched. Runs are cached as JSON under ``--cache`` (the study resumes) and computed in a
process pool; the heatmaps (PNG) and the table (``results.md``) are written from the cache only.

    python benchmarks/scaling/run.py --quick     # p <= 16, 1 seed, < 10 min on 2 cores
    python benchmarks/scaling/run.py --full      # p up to 64, 3 seeds

(or ``python -m benchmarks.scaling.run ...``, from the repository root).
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

for _variable in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_variable, "1")  # one BLAS thread per process: the pool already fills the cores

# Run by path: the repository root first on sys.path, as `python -m` puts it (see benchmarks/__init__.py).
if not __package__:
    sys.path[0] = str(Path(__file__).resolve().parents[2])

import matplotlib  # noqa: E402
import matplotlib.lines  # noqa: E402

matplotlib.use("Agg")

from benchmarks.baselines import BASELINES  # noqa: E402
from benchmarks.scaling.report import (  # noqa: E402
    EXTRA_LABELS,
    METHOD,
    baseline_lines,
    grid_lines,
    method_text,
    plot_baselines,
    plot_heatmaps,
)
from benchmarks.study_cli import add_mode_options, add_output_options, resolve_outputs  # noqa: E402
from benchmarks.study_options import RESTART_PIN, pin_c3  # noqa: E402
from benchmarks.study_report import timing_text  # noqa: E402
from benchmarks.study_runner import available_methods, run_study  # noqa: E402
from benchmarks.study_tools import DIVERGENCE_GROWTH, RunSpec  # noqa: E402

HERE = Path(__file__).resolve().parent
FUNCTIONS = ("Rosenbrock", "Sphere", "ShiftedSchwefel", "ShiftedRotatedElliptic")
PRESETS = {
    "quick": {
        "dims": (2, 4, 8, 16),
        "context_dims": (1, 2, 3, 4, 5),
        "seeds": 1,
        "budget": 100_000,
        "baseline_dims": (2, 4, 8),
    },
    "full": {
        "dims": (2, 4, 8, 16, 32, 64),
        "context_dims": (1, 2, 3, 4, 5),
        "seeds": 3,
        "budget": 20_000_000,
        "baseline_dims": (2, 4, 8, 16),
    },
}
BASELINE_NAMES = ("cma-fixed", "cma-fixed-batch", "cma-regression")


def _parser() -> argparse.ArgumentParser:
    """The command line's options (:func:`parse_args` resolves and checks them)."""
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    add_mode_options(parser, quick="a fast subset", full="the whole grid")
    parser.add_argument("--functions", nargs="+", choices=FUNCTIONS, default=list(FUNCTIONS))
    parser.add_argument("--dims", nargs="+", type=int, help="problem dimensions p (>= 2)")
    parser.add_argument("--context-dims", nargs="+", type=int, help="context dimensions z")
    parser.add_argument("--seeds", type=int, help="seeds per cell (0 .. n-1)")
    parser.add_argument("--budget", type=int, help="episode budget per run (censoring level)")
    parser.add_argument("--samples", type=int, default=50, help="samples per iteration (paper: 50)")
    parser.add_argument(
        "--max-interpolation",
        type=float,
        default=1.0,
        help="cap of CREPS-CMA's λ (default 1: Eq. (14) as published); binds only where samples/p² > cap",
    )
    parser.add_argument(
        "--no-z",
        dest="divide_by_z",
        action="store_false",
        help="CREPS-CMA without Z in the old-mean covariance (default: Eq. (15) as published)",
    )
    parser.add_argument(
        "--baselines", nargs="*", choices=BASELINE_NAMES, default=list(BASELINE_NAMES), help="none: skip"
    )
    parser.add_argument("--baseline-dims", nargs="+", type=int, help="problem dimensions of the baselines")
    parser.add_argument(
        "--extra-methods",
        nargs="*",
        choices=list(EXTRA_LABELS),
        help="grid methods besides CREPS-CMA-old (default: all, as published; none with --max-interpolation "
        "or --no-z); those not registered yet are skipped",
    )
    parser.add_argument(
        "--compute-methods",
        nargs="+",
        choices=[METHOD, *EXTRA_LABELS, *BASELINE_NAMES],
        help="compute only these methods' missing runs (e.g. c-cma-es); the others' cached runs are rendered",
    )
    add_output_options(parser, HERE, out="heatmaps and table (default docs/results/scaling/<label>)")
    return parser


def parse_args(argv: Sequence[str] | None = None) -> argparse.Namespace:
    """Command-line options; ``--quick``/``--full`` pick the defaults of the others."""
    parser = _parser()
    args = parser.parse_args(argv)
    args.mode = args.mode or "full"
    preset = PRESETS[args.mode]
    if not 0.0 < args.max_interpolation <= 1.0:
        parser.error(f"--max-interpolation: expected a value in (0, 1], got {args.max_interpolation}")
    args.label = args.mode + (f"-cap{args.max_interpolation:g}" if args.max_interpolation < 1.0 else "")
    args.label += "" if args.divide_by_z else "-noz"
    resolve_outputs(args, argv, HERE, args.label)
    published = args.max_interpolation == 1.0 and args.divide_by_z
    if args.extra_methods and not published:
        parser.error(
            f"--extra-methods: expected none with --max-interpolation or --no-z, got {args.extra_methods}"
        )
    extra = list(EXTRA_LABELS) if args.extra_methods is None and published else args.extra_methods or []
    args.extra_methods = available_methods(extra, BASELINES)
    args.dims = sorted(args.dims or preset["dims"])
    args.context_dims = sorted(args.context_dims or preset["context_dims"])
    args.seeds = args.seeds if args.seeds is not None else preset["seeds"]
    args.budget = args.budget if args.budget is not None else preset["budget"]
    baseline_dims = args.baseline_dims or preset["baseline_dims"]
    args.baseline_dims = sorted(set(baseline_dims) & set(args.dims))
    if min(args.dims) < 2 or min(args.context_dims) < 1:
        parser.error(
            f"--dims/--context-dims: expected p >= 2 and z >= 1, got {args.dims}, {args.context_dims}"
        )
    for name in ("seeds", "budget", "samples", "workers"):
        if getattr(args, name) < 1:
            parser.error(f"--{name}: expected a positive integer, got {getattr(args, name)}")
    return args


def make_specs(args: argparse.Namespace) -> list[RunSpec]:
    """Every run: the grid (smallest problems first, and per p every cell's seed 0 before any seed 1), the
    same grid for each of ``args.extra_methods``, then the baselines on ``args.baseline_dims``."""
    grid_specs = [
        RunSpec(
            name,
            p,
            z,
            method,
            seed,
            args.budget,
            args.samples,
            *_options(args, method),
            options=PINNED.get(method, ()),
        )
        for method in (METHOD, *args.extra_methods)
        for p in args.dims
        for seed in range(args.seeds)
        for name in args.functions
        for z in args.context_dims
    ]
    baseline_specs = [
        RunSpec(name, p, z, method, seed, args.budget, args.samples)
        for p in args.baseline_dims
        for method in args.baselines
        for seed in range(args.seeds)
        for name in args.functions
        for z in args.context_dims
    ]
    return grid_specs + baseline_specs


#: Options pinned per extra method: ``c-cma-es`` keeps the restart defaults from before issue 33 (no kept
#: best, squared restarts; ``benchmarks/restart_defaults.py``), with which its 440 committed runs were
#: computed (see the README's "C-CMA-ES's restart options"), and the mean fit's ridge towards 0 (C3, the
#: default until issue 45; benchmarks/study_options.py).
PINNED = {"c-cma-es": pin_c3("c-cma-es", RESTART_PIN)}


def _options(args: argparse.Namespace, method: str) -> tuple[float, bool]:
    """``max_interpolation`` and ``divide_by_z`` of a grid run: the study's for CREPS-CMA-old, else none."""
    return (args.max_interpolation, args.divide_by_z) if method == METHOD else (1.0, True)


def write_report(args: argparse.Namespace, documents: list[dict], timing: dict[str, Any]) -> Path:
    """Write the heatmaps and ``results.md`` into ``args.out``; returns the table's path."""
    args.out.mkdir(parents=True, exist_ok=True)
    figure = plot_heatmaps(documents, args, args.out / "heatmaps.png").name
    command = f"python benchmarks/scaling/run.py {args.flags}"
    lines = [
        f"# Scaling study ({args.label}): generated by `benchmarks/scaling/run.py`",
        "",
        f"Command: `{command}`. {method_text(args)}, {args.samples} samples per iteration, "
        f"{args.seeds} seed(s), episode budget {args.budget:,} per run (censoring level), "
        "function instance = seed.",
        timing_text(timing, documents),
        "",
        "Cells: median training episodes until the mean regret of the mean policy on 16 test contexts is "
        "<= 1e-5 ((seeds that got there / seeds) when not all did). No seed got there: `>budget` = censored "
        "(the budget ran out), `stopped` = the optimiser's own stop criteria (covariance condition > 1e14 or "
        "step size < 1e-12) ended every run first, i.e. premature convergence, `diverged` = the search "
        f"distribution spread out until its largest standard deviation was {DIVERGENCE_GROWTH:g} times the "
        "initial one; with the median final regret.",
        "",
    ]
    lines += grid_lines(documents, args)
    for method in args.extra_methods:
        pinned = ", ".join(f"{name}={value!r}" for name, value in PINNED.get(method, ()))
        note = (
            f"; `{pinned}`: its restart defaults before issue 33 and its ridge before issue 45"
            if pinned
            else ""
        )
        lines += [f"## {EXTRA_LABELS[method]} (`{method}`{note})", "", *grid_lines(documents, args, method)]
    lines += baseline_lines(documents, args)
    lines += [f"![heatmaps]({figure})", ""]
    for method in args.extra_methods:
        extra = plot_heatmaps(documents, args, args.out / f"heatmaps-{method}.png", method).name
        lines += [f"![heatmaps of {EXTRA_LABELS[method]}]({extra})", ""]
    if args.baselines and args.baseline_dims:
        lines += [f"![baselines]({plot_baselines(documents, args, args.out / 'baselines.png').name})", ""]
    path = args.out / "results.md"
    path.write_text("\n".join(lines), encoding="utf-8")
    return path


def main(argv: Sequence[str] | None = None) -> int:
    """Run (or resume) the grid and write its report."""
    args = parse_args(argv)
    return run_study(
        args,
        make_specs(args),
        write_report,
        baselines=BASELINES,
        title="Scaling study (Fig. 3)",
        script="benchmarks/scaling/run.py",
        figures_marker="\n![heatmaps]",
        readme=HERE / "README.md",
    )


if __name__ == "__main__":
    raise SystemExit(main())
