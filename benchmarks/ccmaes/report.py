"""Tables and figures of the C-CMA-ES target study, computed only from the cached run results.

A *column* is a method at a batch size (:mod:`benchmarks.ccmaes.columns`); a *cell* is (function, z). Every
figure is a median over seeds of the episodes until the mean regret of the mean policy on the test contexts is
<= 1e-5, where a run that never got there (budget spent, or stopped by its own criteria) counts as infinitely
many episodes, so a median over seeds that mostly missed shows as ``>budget``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.ccmaes.columns import (
    BATCH_SWEEP,
    BOUND_CELLS,
    BOUND_ROWS,
    HEADLINE,
    REMEDIES,
    REMEDY_FUNCTION,
    SIGNAL_PAIRS,
    SWEEP_FUNCTION,
    YARDSTICK,
    Column,
)
from benchmarks.functions.report import curve
from benchmarks.study_tools import function_spec

__all__ = [
    "TARGETS",
    "bound_table",
    "csa_text",
    "headline_table",
    "median_episodes",
    "plot_curves",
    "remedies_table",
    "seed_table",
    "signal_table",
    "target_met",
]

#: Runs of one column in one cell, over seeds: (function, z, column name) -> documents.
Cells = Mapping[tuple[str, int, str], Sequence[dict[str, Any]]]

#: Issue 12's targets for C-CMA-ES at N = 50: (function, z) -> (most episodes, least fraction of seeds).
TARGETS = {
    ("Sphere", 1): (5_500, 0.0),
    ("Sphere", 3): (11_000, 0.0),
    ("Rosenbrock", 1): (25_000, 0.95),
    ("Rosenbrock", 3): (39_000, 0.95),
    ("ShiftedRotatedElliptic", 1): (13_000, 0.0),
    ("ShiftedRotatedElliptic", 3): (20_000, 0.0),
}
#: Panel titles.
TITLES = {"Sphere": "Sphere", "Rosenbrock": "Rosenbrock", "ShiftedRotatedElliptic": "Elliptic (1e6)"}
#: At its recommended batch size, C-CMA-ES may need at most this multiple of pycma's episodes for one context
#: at pycma's default population.
RECOMMENDED_FACTOR = 2.0


def median_episodes(documents: Sequence[dict[str, Any]]) -> float | None:
    """Median over runs of the episodes to the target, a missed run counting as infinity (None: no runs)."""
    if not documents:
        return None
    return float(np.median([math.inf if d["hit"] is None else d["hit"] for d in documents]))


def _episodes_text(documents: Sequence[dict[str, Any]], budget: int) -> str:
    median = median_episodes(documents)
    if median is None:
        return "–"
    hits = sum(d["hit"] is not None for d in documents)
    text = f">{budget:,}" if math.isinf(median) else f"{median:,.0f}"
    return f"{text} ({hits}/{len(documents)})"


def _batch_text(documents: Sequence[dict[str, Any]]) -> str:
    sizes = sorted({d["spec"]["samples"] for d in documents})
    return f", N = {'/'.join(str(n) for n in sizes)}" if sizes else ""


def target_met(documents: Sequence[dict[str, Any]], most: float, fraction: float) -> str:
    """``"met"`` when the median episodes are at most ``most`` and at least ``fraction`` of the runs hit the
    target, ``"not met"`` otherwise, ``"–"`` without runs."""
    median = median_episodes(documents)
    if median is None:
        return "–"
    hits = sum(d["hit"] is not None for d in documents)
    return "met" if median <= most and hits >= math.ceil(fraction * len(documents) - 1e-9) else "not met"


def _target_text(most: float, fraction: float, runs: int) -> str:
    seeds = f", ≥ {math.ceil(fraction * runs - 1e-9)}/{runs} seeds" if fraction and runs else ""
    return f"≤ {most:,.0f}{seeds}"


def seed_table(cells: Cells, columns: Sequence[Column], rows: Sequence[tuple[str, int]], budget: int) -> str:
    """Every column, one row per (function, z): median episodes (seeds that got there / seeds)."""
    lines = ["| function | z | " + " | ".join(c.label for c in columns) + " |"]
    lines.append("|---|---" + "|---" * len(columns) + "|")
    for name, z in rows:
        texts = []
        for column in columns:
            runs = cells.get((name, z, column.name), [])
            extra = _batch_text(runs) if column.batch == "recommended" else ""
            texts.append(_episodes_text(runs, budget) + extra)
        lines.append(f"| {name} | {z} | " + " | ".join(texts) + " |")
    return "\n".join(lines) + "\n"


def headline_table(cells: Cells, rows: Sequence[tuple[str, int]], budget: int) -> str:
    """The issue's targets against the data: C-CMA-ES at N = 50 against the fixed targets, and at its
    recommended N against :data:`RECOMMENDED_FACTOR` times pycma's episodes for one context (at z = 1, where
    the issue sets that target; larger z only report the episodes)."""
    head = (
        "| function | z | CREPS-CMA-old, N = 50 | C-CMA-ES, N = 50 | target | met? | C-CMA-ES, recommended N "
        f"| pycma, 1 context, default N | target ({RECOMMENDED_FACTOR:g} × pycma) | met? |"
    )
    lines = [head, "|---" * 10 + "|"]
    for name, z in rows:
        old, ours, rec, pycma = (cells.get((name, z, c), []) for c in HEADLINE)
        most, fraction = TARGETS.get((name, z), (math.nan, 0.0))
        reference = median_episodes(pycma)
        if reference is None or math.isinf(reference) or z != 1:  # the issue sets this target at z = 1
            rec_target, rec_met = "–", "–"
        else:
            rec_target = f"≤ {RECOMMENDED_FACTOR * reference:,.0f}"
            rec_met = target_met(rec, RECOMMENDED_FACTOR * reference, 0.0)
        texts = [
            _episodes_text(old, budget),
            _episodes_text(ours, budget),
            _target_text(most, fraction, len(ours) or 20) if not math.isnan(most) else "–",
            target_met(ours, most, fraction) if not math.isnan(most) else "–",
            _episodes_text(rec, budget) + _batch_text(rec),
            _episodes_text(pycma, budget),
            rec_target,
            rec_met,
        ]
        lines.append(f"| {name} | {z} | " + " | ".join(texts) + " |")
    return "\n".join(lines) + "\n"


def _partial_line(missing: Sequence[str], seeds: int) -> str:
    """The bold line naming the cells (``"<label>: <runs>"``) with fewer than ``seeds`` runs cached."""
    return f"**Partial: runs cached of {seeds} seeds: " + "; ".join(missing) + ".**"


def remedies_table(cells: Cells, dims: Sequence[int], budget: int, seeds: int) -> str:
    """The :data:`REMEDIES` on :data:`REMEDY_FUNCTION`, one row per z: median episodes (seeds that got
    there / seeds), and a line naming the cells with fewer than ``seeds`` runs cached."""
    options = {c.name: ", ".join(f"`{k}={v}`" for k, v in c.options) or "defaults" for c in REMEDIES}
    lines = ["| z | " + " | ".join(c.label for c in REMEDIES) + " |", "|---" * (len(REMEDIES) + 1) + "|"]
    lines.append("| options | " + " | ".join(options[c.name] for c in REMEDIES) + " |")
    missing = []
    for z in dims:
        runs = [cells.get((REMEDY_FUNCTION, z, c.name), []) for c in REMEDIES]
        lines.append(f"| {z} | " + " | ".join(_episodes_text(r, budget) for r in runs) + " |")
        missing += [
            f"{c.label} at z = {z}: {len(r)}" for c, r in zip(REMEDIES, runs, strict=True) if len(r) < seeds
        ]
    if missing:
        lines += ["", _partial_line(missing, seeds)]
    return "\n".join(lines) + "\n"


def _recommended_bound(cells: Cells, function: str) -> float | None:
    """:data:`RECOMMENDED_FACTOR` × pycma's median episodes for one context on ``function`` at z = 1 (None
    without runs, or when the median run missed)."""
    reference = median_episodes(cells.get((function, 1, "cma-fixed"), []))
    return None if reference is None or math.isinf(reference) else RECOMMENDED_FACTOR * reference


def sweep_table(cells: Cells, budget: int, seeds: int) -> str:
    """:data:`BATCH_SWEEP` on :data:`SWEEP_FUNCTION` at z = 1: median episodes (seeds that got there / seeds)
    per batch size, the recommended-N target (:data:`RECOMMENDED_FACTOR` × pycma's episodes for one context at
    its default population) and the batch sizes that meet it."""
    runs = [cells.get((SWEEP_FUNCTION, 1, c.name), []) for c in BATCH_SWEEP]
    bound = _recommended_bound(cells, SWEEP_FUNCTION)
    lines = [
        "| " + " | ".join(c.label for c in BATCH_SWEEP) + " | target |",
        "|---" * (len(BATCH_SWEEP) + 1) + "|",
    ]
    target = "–" if bound is None else f"≤ {bound:,.0f}"
    lines.append("| " + " | ".join(_episodes_text(r, budget) for r in runs) + f" | {target} |")
    if bound is not None and all(runs):
        meeting = [
            c.label for c, r in zip(BATCH_SWEEP, runs, strict=True) if target_met(r, bound, 0.0) == "met"
        ]
        lines += ["", f"Batch sizes that meet the target: {', '.join(meeting) or 'none'}."]
    missing = [f"{c.label}: {len(r)}" for c, r in zip(BATCH_SWEEP, runs, strict=True) if len(r) < seeds]
    if missing:
        lines += ["", _partial_line(missing, seeds)]
    return "\n".join(lines) + "\n"


def signal_table(cells: Cells, rows: Sequence[tuple[str, int]], budget: int, seeds: int) -> str:
    """C-CMA-ES's default step-size signal (``mean``, C4) beside ``coefficients`` (C4'), at N = 50 and at the
    recommended N, one row per (function, z); then in how many (cell, batch size) pairs the coefficients'
    median is lower, and a line naming the cells with fewer than ``seeds`` runs cached."""
    lines = [
        "| function | z | mean, N = 50 | coefficients, N = 50 | mean, recommended N "
        "| coefficients, recommended N |",
        "|---" * 6 + "|",
    ]
    compared = lower = 0
    missing = []
    for name, z in rows:
        texts = []
        for pair, (default, coefficients) in enumerate(SIGNAL_PAIRS):  # pair 1: the recommended N
            runs = [cells.get((name, z, column), []) for column in (default, coefficients)]
            texts += [_episodes_text(r, budget) + (_batch_text(r) if pair == 1 else "") for r in runs]
            medians = [median_episodes(r) for r in runs]
            if None not in medians and not all(math.isinf(m) for m in medians):
                compared += 1
                lower += medians[1] < medians[0]
            missing += [
                f"{c} at {name}, z = {z}: {len(r)}"
                for c, r in zip((default, coefficients), runs, strict=True)
                if len(r) < seeds
            ]
        lines.append(f"| {name} | {z} | " + " | ".join(texts) + " |")
    lines.append("")
    if compared:
        lines.append(
            f"The coefficients' median is lower in {lower} of the {compared} (cell, batch size) pairs where "
            "either reached the target."
        )
    else:
        lines.append("No (cell, batch size) pair has a median that reached the target yet.")
    if missing:
        lines += ["", _partial_line(missing, seeds)]
    return "\n".join(lines) + "\n"


def bound_table(cells: Cells, budget: int, seeds: int) -> str:
    """:data:`BOUND_ROWS` in the two :data:`BOUND_CELLS` against their targets, the variants that meet both,
    the :data:`YARDSTICK` line, and a line naming the cells with fewer than ``seeds`` runs cached."""
    bound = _recommended_bound(cells, BOUND_CELLS[0][0])
    most, fraction = TARGETS[BOUND_CELLS[1][:2]]
    targets = [(bound, 0.0), (most, fraction)]
    lines = [
        "| C-CMA-ES | options | Sphere, z = 1, recommended N | Rosenbrock, z = 3, N = 50 |",
        "|---" * 4 + "|",
    ]
    meeting, missing = [], []
    for label, options, names in BOUND_ROWS:
        runs = [cells.get((f, z, name), []) for (f, z, _), name in zip(BOUND_CELLS, names, strict=True)]
        texts = [_episodes_text(runs[0], budget) + _batch_text(runs[0]), _episodes_text(runs[1], budget)]
        shown = ", ".join(f"`{k}={v}`" for k, v in options) or "defaults"
        lines.append(f"| {label} | {shown} | " + " | ".join(texts) + " |")
        met = [t[0] is not None and target_met(r, *t) == "met" for r, t in zip(runs, targets, strict=True)]
        meeting += [label] if all(met) else []
        missing += [
            f"{label}, {f} z = {z}: {len(r)}"
            for (f, z, _), r in zip(BOUND_CELLS, runs, strict=True)
            if len(r) < seeds
        ]
    sphere_target = "–" if bound is None else f"≤ {bound:,.0f} (2 × pycma)"
    lines.append(f"| target | | {sphere_target} | {_target_text(most, fraction, seeds)} |")
    lines += ["", f"Variants that meet both targets: {', '.join(meeting) or 'none'}."]
    yardstick = [cells.get((BOUND_CELLS[0][0], 1, c.name), []) for c in YARDSTICK]
    if all(yardstick):
        from creps_gym.optimizers.ccmaes import recommended_batch_size  # at z = 0: CMA-ES's population

        dim = yardstick[0][0]["spec"]["dim"]
        lines += [
            "",
            f"pycma on one context of a Sphere with 2p = {dim} parameters (as many as the affine mean's "
            f"coefficients at z = 1), from a mean U[-5, 5]^{dim} with σ0 = 1: "
            f"{_episodes_text(yardstick[0], budget)} episodes at its default population, "
            f"N = {recommended_batch_size(dim, 0)}, and {_episodes_text(yardstick[1], budget)} at C-CMA-ES's "
            f"recommended{_batch_text(yardstick[1])[1:]}.",
        ]
    if missing:
        lines += ["", _partial_line(missing, seeds)]
    return "\n".join(lines) + "\n"


def csa_text(cells: Cells, rows: Sequence[tuple[str, int]]) -> str:
    """Whether CREPS-CMA with CSA helps: in how many cells its median is below CREPS-CMA-old's."""
    compared = faster = 0
    for name, z in rows:
        old = median_episodes(cells.get((name, z, "creps-cma-old"), []))
        csa = median_episodes(cells.get((name, z, "creps-cma-csa"), []))
        if old is None or csa is None or (math.isinf(old) and math.isinf(csa)):
            continue
        compared += 1
        faster += csa < old
    if not compared:
        return "CREPS-CMA-CSA against CREPS-CMA-old: no cell has runs of both yet."
    return (
        f"CREPS-CMA-CSA against CREPS-CMA-old (same seeds, N = 50): its median is lower in {faster} of the "
        f"{compared} cells where either reached the target."
    )


def plot_curves(
    cells: Cells, columns: Sequence[Column], rows: Sequence[tuple[str, int]], seeds: int, path: Path
) -> Path:
    """One panel per (function, z): every column's regret curves (one line per seed, the first ``seeds``)."""
    from matplotlib.figure import Figure  # Agg canvas: no display needed
    from matplotlib.ticker import FuncFormatter

    functions = list(dict.fromkeys(name for name, _ in rows))
    dims = sorted({z for _, z in rows})
    figure = Figure(figsize=(4.6 * len(functions), 3.9 * len(dims)), layout="constrained")
    axes = figure.subplots(len(dims), len(functions), squeeze=False)
    for (name, z), axis in ((row, axes[dims.index(row[1])][functions.index(row[0])]) for row in rows):
        for column in columns:
            runs = [d for d in cells.get((name, z, column.name), []) if d["spec"]["seed"] < seeds]
            style = "--" if column.method.startswith("cma-") else "-"
            for i, document in enumerate(runs):
                label = column.label if i == 0 else None
                axis.plot(*curve(document), style, color=column.colour, alpha=0.7, lw=0.9, label=label)
        axis.axhline(function_spec(name).target, color="k", lw=0.8, ls=":")
        axis.set(yscale="log", xlabel="training episodes", title=f"{TITLES.get(name, name)}, z = {z}")
        axis.xaxis.set_major_formatter(FuncFormatter(lambda value, _: f"{value / 1000:g}k" if value else "0"))
        axis.grid(True, alpha=0.3)
    axes[0][0].set_ylabel("mean regret of the mean policy (log)")
    handles, labels = axes[0][0].get_legend_handles_labels()
    figure.legend(handles, labels, loc="outside lower center", ncols=min(3, len(functions)), fontsize="small")
    figure.savefig(path, dpi=110)
    return path
