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
from collections import Counter
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
import numpy as np  # noqa: E402

matplotlib.use("Agg")

from benchmarks.baselines import BASELINES  # noqa: E402
from benchmarks.study_report import command_flags, run_study, summarise, timing_text  # noqa: E402
from benchmarks.study_tools import DIVERGENCE_GROWTH, RunSpec, function_spec  # noqa: E402

HERE = Path(__file__).resolve().parent
REPO = HERE.parents[1]
FUNCTIONS = ("Rosenbrock", "Sphere", "ShiftedSchwefel", "ShiftedRotatedElliptic")
METHOD = "creps-cma-old"
TITLES = {
    "Rosenbrock": "Rosenbrock",
    "Sphere": "Sphere",
    "ShiftedSchwefel": "Shifted Schwefel 1.2",
    "ShiftedRotatedElliptic": "Shifted rotated elliptic",
}
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
BASELINE_NAMES = ("cma-fixed", "cma-regression")
LEGEND_LABELS = {"cma-fixed": "pycma, 1 fixed context", "cma-regression": "indep. CMA-ES + regression"}
BASELINE_LABELS = {
    "cma-fixed": "pycma on one fixed context",
    "cma-regression": "independent CMA-ES on 2^z + 1 training contexts (5 for z = 1) + linear regression",
}


def parse_args(argv: Sequence[str] | None = None) -> argparse.Namespace:
    """Command-line options; ``--quick``/``--full`` pick the defaults of the others."""
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    mode = parser.add_mutually_exclusive_group()
    mode.add_argument("--quick", action="store_const", dest="mode", const="quick", help="a fast subset")
    mode.add_argument("--full", action="store_const", dest="mode", const="full", help="the whole grid")
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
    parser.add_argument("--workers", type=int, default=2, help="processes (default 2)")
    parser.add_argument(
        "--render-only", action="store_true", help="compute nothing: render the runs already cached"
    )
    parser.add_argument("--cache", type=Path, default=HERE / "runs", help="per-run JSON (git-ignored)")
    parser.add_argument("--out", type=Path, help="heatmaps and table (default docs/results/scaling/<mode>)")
    args = parser.parse_args(argv)
    args.mode = args.mode or "full"
    preset = PRESETS[args.mode]
    if not 0.0 < args.max_interpolation <= 1.0:
        parser.error(f"--max-interpolation: expected a value in (0, 1], got {args.max_interpolation}")
    args.label = args.mode + (f"-cap{args.max_interpolation:g}" if args.max_interpolation < 1.0 else "")
    args.label += "" if args.divide_by_z else "-noz"
    args.flags = command_flags(argv, args.mode)  # what computes it
    args.index = REPO / "docs" / "results" / "README.md" if args.out is None else None
    args.out = args.out or REPO / "docs" / "results" / "scaling" / args.label
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
    """Every run: the grid (smallest problems first, and per p every cell's seed 0 before any seed 1), then
    the baselines on ``args.baseline_dims``."""
    grid_specs = [
        RunSpec(name, p, z, METHOD, seed, args.budget, args.samples, args.max_interpolation, args.divide_by_z)
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


def grid(
    documents: Sequence[dict[str, Any]],
    name: str,
    args: argparse.Namespace,
    method: str = METHOD,
    dims: Sequence[int] | None = None,
) -> list[list[dict]]:
    """Summaries (see :func:`benchmarks.study_report.summarise`) of one function and method, indexed [p][z].

    Each summary also has ``missed``: how many runs missed the target, by :func:`missed_kind`.
    """
    cells = []
    for p in args.dims if dims is None else dims:
        row = []
        for z in args.context_dims:
            runs = [
                d
                for d in documents
                if d["spec"]["function"] == name
                and d["spec"]["method"] == method
                and d["spec"]["dim"] == p
                and d["spec"]["context_dim"] == z
            ]
            summary = summarise(runs)
            summary["missed"] = Counter(missed_kind(d) for d in runs if d["hit"] is None)
            row.append(summary)
        cells.append(row)
    return cells


def missed_kind(document: dict[str, Any]) -> str:
    """Why a run missed the target: ``"diverged"`` (its spread grew past the study's limit),
    ``"stopped"`` (another stop criterion of the optimiser: premature convergence) or ``"censored"`` (the
    budget ran out)."""
    reason = str(document["stop_reason"])
    if "max_std_growth" in reason:
        return "diverged"
    return "stopped" if reason.startswith("optimizer") else "censored"


def cell_text(summary: dict[str, Any], budget: int) -> str:
    """``median episodes`` (with hits/runs if not all hit); with no hit, why the runs missed (see
    :func:`missed_kind`; censored shows as ``>budget``) and the median final regret."""
    if not summary["runs"]:
        return "–"
    if not summary["hits"]:
        final = f"regret {summary['median_final']:.2g}" if summary["median_final"] is not None else ""
        names = {"censored": f">{budget:,}", "stopped": "stopped", "diverged": "diverged"}
        missed = summary["missed"]
        if len(missed) == 1:
            return f"{names[next(iter(missed))]}, {final}"
        return " / ".join(f"{names[kind]} {count}" for kind, count in sorted(missed.items())) + f", {final}"
    text = f"{summary['median_hit']:,.0f}"
    return text if summary["hits"] == summary["runs"] else f"{text} ({summary['hits']}/{summary['runs']})"


def plot_heatmaps(documents: Sequence[dict[str, Any]], args: argparse.Namespace, path: Path) -> Path:
    """One heatmap per function: log10 median episodes over (z, p); censored cells hatched."""
    from matplotlib.colors import LogNorm
    from matplotlib.figure import Figure

    figure = Figure(figsize=(4.2 * len(args.functions), 4.0), layout="constrained")
    axes = figure.subplots(1, len(args.functions), squeeze=False)[0]
    norm = LogNorm(vmin=min(args.samples * 2, args.budget), vmax=args.budget)
    image = None
    for axis, name in zip(axes, args.functions, strict=True):
        cells = grid(documents, name, args)
        values = np.array([[c["median_hit"] or np.nan for c in row] for row in cells], dtype=np.float64)
        image = axis.imshow(values, origin="lower", cmap="viridis", norm=norm, aspect="auto")
        for i, row in enumerate(cells):
            for j, summary in enumerate(row):
                missed = summary["runs"] and not summary["hits"]
                if missed:
                    axis.add_patch(_hatch(j, i))
                    kinds = summary["missed"]
                    labels = {"censored": "cens.", "stopped": "stop", "diverged": "div."}
                    label = labels[next(iter(kinds))] if len(kinds) == 1 else "miss"
                else:
                    label = cell_text(summary, args.budget).replace(",", "")
                bright = not missed and summary["median_hit"] and norm(summary["median_hit"]) > 0.75
                colour = "k" if bright else "w"
                axis.text(j, i, _short(label), ha="center", va="center", fontsize=7, color=colour)
        axis.set_xticks(range(len(args.context_dims)), [str(z) for z in args.context_dims])
        axis.set_yticks(range(len(args.dims)), [str(p) for p in args.dims])
        axis.set(xlabel="context dimension z", ylabel="problem dimension p", title=TITLES[name])
    figure.colorbar(image, ax=list(axes), label="episodes to regret 1e-5 (median)")
    figure.suptitle(
        f"{method_text(args)}, {args.samples} samples/iteration, budget {args.budget:,}; hatched: target not "
        "reached (cens. = budget spent, stop = premature convergence, div. = diverged)"
    )
    figure.savefig(path, dpi=110)
    return path


def method_name(args: argparse.Namespace) -> str:
    """The method with its options where they differ from the paper's (the figures' legends)."""
    changes = [f"λ capped at {args.max_interpolation:g}"] if args.max_interpolation < 1.0 else []
    changes += [] if args.divide_by_z else ["no Z in the old-mean covariance"]
    return "CREPS-CMA-old" + (" with " + " and ".join(changes) if changes else "")


def method_text(args: argparse.Namespace) -> str:
    """The method as the reports name it: :func:`method_name`, or that the update is the published one."""
    name = method_name(args)
    return name if name != "CREPS-CMA-old" else f"{name} (Eqs. (14)-(16) as published)"


def baseline_cell(summary: dict[str, Any], method: str, budget: int) -> str:
    """A baseline's cell: like :func:`cell_text` for ``cma-fixed``; for ``cma-regression`` the median total
    episodes of its CMA-ES runs and the median test regret of the regression (✗ unless every seed met the
    target)."""
    if method != "cma-regression" or not summary["runs"]:
        return cell_text(summary, budget)
    mark = "" if summary["hits"] == summary["runs"] else "✗ "
    total, final = summary["median_total"], summary["median_final"]
    regret = "n/a" if final is None else f"{final:.2g}"
    return f"{mark}{total:,.0f} ep., regret {regret} ({summary['hits']}/{summary['runs']})"


def plot_baselines(documents: Sequence[dict[str, Any]], args: argparse.Namespace, path: Path) -> Path:
    """Episodes against z per function: CREPS-CMA-old (all contexts at once) against the baselines."""
    from matplotlib.figure import Figure

    figure = Figure(figsize=(4.2 * len(args.functions), 4.0), layout="constrained")
    axes = figure.subplots(1, len(args.functions), squeeze=False)[0]
    colours = matplotlib.colormaps["viridis"](np.linspace(0.0, 0.85, len(args.baseline_dims)))
    styles = {METHOD: ("-", "o"), "cma-regression": ("--", "s"), "cma-fixed": (":", "^")}
    for axis, name in zip(axes, args.functions, strict=True):
        for method in (METHOD, *args.baselines):
            cells = grid(documents, name, args, method, args.baseline_dims)
            for colour, row in zip(colours, cells, strict=True):
                key = "median_total" if method == "cma-regression" else "median_hit"
                values = [c[key] if c["hits"] == c["runs"] and c["runs"] else np.nan for c in row]
                line, marker = styles[method]
                axis.plot(args.context_dims, values, line, marker=marker, color=colour, ms=4)
        axis.set(yscale="log", xlabel="context dimension z", ylabel="episodes", title=TITLES[name])
        axis.set_xticks(args.context_dims)
    handles = [
        matplotlib.lines.Line2D([], [], color="k", linestyle=style, marker=marker, label=label)
        for (style, marker), label in (
            (styles[METHOD], f"{method_name(args)}, every context"),
            *((styles[m], LEGEND_LABELS[m]) for m in args.baselines),
        )
    ]
    handles += [
        matplotlib.lines.Line2D([], [], color=c, label=f"p = {p}")
        for c, p in zip(colours, args.baseline_dims, strict=True)
    ]
    figure.legend(handles=handles, loc="outside lower center", ncols=3, fontsize=8)
    figure.suptitle("Episodes to regret 1e-5 (median; a point only where every seed got there)")
    figure.savefig(path, dpi=110)
    return path


def baseline_lines(documents: Sequence[dict[str, Any]], args: argparse.Namespace) -> list[str]:
    """The baselines' tables (Markdown lines), one per function and baseline."""
    if not args.baselines or not args.baseline_dims:
        return []
    lines = [
        "## Baselines",
        "",
        "Same test contexts, initial distribution and episode budget as the grid "
        "(`benchmarks/baselines.py`). pycma on one fixed context: episodes until the regret at that one "
        "context met 1e-5 (the cost of a single task). Regression: the K = 2^z + 1 (5 for z = 1) "
        "independent CMA-ES runs, each given budget/K episodes, then least squares from [1, s] to θ; the "
        "total episodes of those runs and the mean test regret of the fitted map (✗: a seed missed 1e-5).",
        "",
    ]
    for name in args.functions:
        for method in args.baselines:
            lines += [f"### {function_spec(name).title}: {BASELINE_LABELS[method]}", ""]
            lines.append("| p \\ z | " + " | ".join(str(z) for z in args.context_dims) + " |")
            lines.append("|---" * (len(args.context_dims) + 1) + "|")
            cells = grid(documents, name, args, method, args.baseline_dims)
            for p, row in zip(args.baseline_dims, cells, strict=True):
                texts = [baseline_cell(c, method, args.budget) for c in row]
                lines.append(f"| {p} | " + " | ".join(texts) + " |")
            lines.append("")
    return lines


def _hatch(column: int, row: int) -> Any:
    from matplotlib.patches import Rectangle

    return Rectangle((column - 0.5, row - 0.5), 1, 1, fill=True, facecolor="0.35", hatch="//", edgecolor="w")


def _short(label: str) -> str:
    """Compact number for a heatmap cell: 12345 -> 12.3k, 2637250 -> 2.64M."""
    head = label.split(" ")[0]
    if head.isdigit():
        value = int(head)
        if value >= 1_000_000:
            return f"{value / 1e6:.2f}M"
        return f"{value / 1000:.1f}k" if value >= 1000 else head
    return label


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
    for name in args.functions:
        lines += [f"### {function_spec(name).title}", ""]
        lines.append("| p \\ z | " + " | ".join(str(z) for z in args.context_dims) + " |")
        lines.append("|---" * (len(args.context_dims) + 1) + "|")
        for p, row in zip(args.dims, grid(documents, name, args), strict=True):
            lines.append(f"| {p} | " + " | ".join(cell_text(c, args.budget) for c in row) + " |")
        lines.append("")
    lines += baseline_lines(documents, args)
    lines += [f"![heatmaps]({figure})", ""]
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
