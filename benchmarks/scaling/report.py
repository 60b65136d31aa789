"""Tables and figures of the scaling study, computed only from the cached run results."""

from __future__ import annotations

import argparse
from collections import Counter
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import matplotlib
import matplotlib.lines
import numpy as np

from benchmarks.study_report import summarise
from benchmarks.study_tools import function_spec

__all__ = [
    "EXTRA_LABELS",
    "METHOD",
    "baseline_cell",
    "baseline_lines",
    "cell_text",
    "grid",
    "grid_lines",
    "method_name",
    "method_text",
    "missed_kind",
    "plot_baselines",
    "plot_heatmaps",
]

#: The method of the paper's Fig. 3 grid.
METHOD = "creps-cma-old"
#: Further grid methods (issue 12), skipped while they are not registered: their names in the reports.
EXTRA_LABELS = {"c-cma-es": "C-CMA-ES", "creps-cma-csa": "CREPS-CMA with CSA"}
TITLES = {
    "Rosenbrock": "Rosenbrock",
    "Sphere": "Sphere",
    "ShiftedSchwefel": "Shifted Schwefel 1.2",
    "ShiftedRotatedElliptic": "Shifted rotated elliptic",
}
LEGEND_LABELS = {
    "cma-fixed": "pycma, 1 fixed context",
    "cma-fixed-batch": "pycma, 1 fixed context, N = samples",
    "cma-regression": "indep. CMA-ES + regression",
}
BASELINE_LABELS = {
    "cma-fixed": "pycma on one fixed context",
    "cma-fixed-batch": "pycma on one fixed context, population = samples per iteration",
    "cma-regression": "independent CMA-ES on 2^z + 1 training contexts (5 for z = 1) + linear regression",
}


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


def plot_heatmaps(
    documents: Sequence[dict[str, Any]], args: argparse.Namespace, path: Path, method: str = METHOD
) -> Path:
    """One heatmap per function: log10 median episodes of ``method`` over (z, p); censored cells hatched."""
    from matplotlib.colors import LogNorm
    from matplotlib.figure import Figure

    figure = Figure(figsize=(4.2 * len(args.functions), 4.0), layout="constrained")
    axes = figure.subplots(1, len(args.functions), squeeze=False)[0]
    norm = LogNorm(vmin=min(args.samples * 2, args.budget), vmax=args.budget)
    image = None
    for axis, name in zip(axes, args.functions, strict=True):
        cells = grid(documents, name, args, method)
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
    title = method_text(args) if method == METHOD else EXTRA_LABELS[method]
    figure.suptitle(
        f"{title}, {args.samples} samples/iteration, budget {args.budget:,}; hatched: target not "
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


def grid_lines(
    documents: Sequence[dict[str, Any]], args: argparse.Namespace, method: str = METHOD
) -> list[str]:
    """The grid's tables of one method (Markdown lines), one per function: a row per p, a column per z."""
    lines = []
    for name in args.functions:
        lines += [f"### {function_spec(name).title}", ""]
        lines.append("| p \\ z | " + " | ".join(str(z) for z in args.context_dims) + " |")
        lines.append("|---" * (len(args.context_dims) + 1) + "|")
        for p, row in zip(args.dims, grid(documents, name, args, method), strict=True):
            lines.append(f"| {p} | " + " | ".join(cell_text(c, args.budget) for c in row) + " |")
        lines.append("")
    return lines


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
    styles = {
        METHOD: ("-", "o"),
        "cma-regression": ("--", "s"),
        "cma-fixed": (":", "^"),
        "cma-fixed-batch": ("-.", "v"),
    }
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
        "context met 1e-5 (the cost of a single task), at pycma's default population 4 + floor(3 ln p) "
        "and at the grid's samples per iteration. Regression: the K = 2^z + 1 (5 for z = 1) "
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
