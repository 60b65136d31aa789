"""The low-budget study's report, drawn from its run documents only: tables per task (median over seeds with
min–max, per budget), the issue's targets as ratios, the optimiser's time per asked episode, the published
anchors (as text, labelled as such) and the curves (matplotlib PNG).

A cell with fewer finished seeds than the study's says how many (``[k/n]``); a cell with none is ``—``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.low_budget.study import BUDGETS, NON_QUADRATIC, task_by_name

__all__ = [
    "ANCHORS",
    "Cells",
    "anchors_text",
    "cells",
    "completeness_text",
    "cost_text",
    "grouped_tasks",
    "library_table",
    "median_at",
    "median_range",
    "paired_table",
    "plot_curves",
    "ratio_text",
    "sign_test",
    "targets_table",
    "task_table",
    "timing_table",
    "values_by_seed",
]

Cells = dict[tuple[str, str], list[dict[str, Any]]]

#: Issue 44's published anchor figures (its list and targets paragraph), quoted as text: not our numbers.
ANCHORS = (
    "BO-CPS on a real arm throwing a ball (2 parameters, 2-D target): 9.0 cm mean error on 16 unseen targets "
    "after 80 episodes with entropy search, 19.7 cm with GP-UCB (Gutzeit et al. 2018; Metzen, Fabisch, "
    "Hansen 2015).",
    "VTAE + BO-CPS on a real UR5 reach (2-D latent parameters, 2-D context): return −0.03 after 63 episodes "
    "against 180 for C-REPS.",
    'Fabisch (GECCO 2019): in the first 500 episodes C-REPS (ε = 1) beats every C-CMA-ES variant "by orders '
    'of magnitude" and then stalls; the surrogate CMA-ES variants help only after about 8,000 episodes.',
    "The paper's kick: 0.34 m mean precision error after 20,000 episodes, 6.5 m mean flexibility distance "
    "after 70,000 episodes (the issue's targets: ≤ 0.34 m within 300 episodes, ≥ 6.5 m within 500).",
    "The issue's own measurement before c-bo (p = 4, z = 1, 200 episodes, mean 0, σ = 2): best model-free "
    "regret 0.24 on the Sphere (creps-cma-old) and 84 on Rosenbrock (creps); c-cma-es-surrogate 6e−9 on the "
    "Sphere, 1.1e+3 on Rosenbrock; a plain scikit-learn GP-UCB 0.18–0.44 and 51–95.",
)


def anchors_text() -> str:
    """The anchors as a Markdown list under a heading that says they are published figures."""
    lines = ["## Published anchors (quoted from issue 44, not computed here)", ""]
    return "\n".join(lines + [f"- {anchor}" for anchor in ANCHORS]) + "\n"


def cells(documents: Sequence[dict[str, Any]]) -> Cells:
    """The documents by (task, method name)."""
    grouped: Cells = {}
    for document in documents:
        grouped.setdefault((document["spec"]["task"], document["spec"]["method"]), []).append(document)
    return grouped


def _values(runs: Sequence[dict[str, Any]], budget: int, field: str = "values") -> np.ndarray:
    """The runs' ``field`` at ``budget`` (the runs that recorded it, finite ones), in the runs' order."""
    return np.asarray(list(values_by_seed(runs, budget, field).values()), dtype=np.float64)


def values_by_seed(
    runs: Sequence[dict[str, Any]] | None, budget: int, field: str = "values"
) -> dict[int, float]:
    """Each run's ``field`` at ``budget`` by its seed (the runs that recorded it)."""
    found = {}
    for run in runs or []:
        if budget in run["budgets"] and (value := run[field][run["budgets"].index(budget)]) is not None:
            found[int(run["spec"]["seed"])] = float(value)
    return found


def median_range(values: np.ndarray, seeds: int | None = None) -> str:
    """``median (min–max)`` of ``values`` (n,), ``[k/n]`` after it when fewer than ``seeds`` seeds finished
    (None: all did), ``—`` with none."""
    if values.size == 0:
        return "—"
    text = f"{np.median(values):.3g} ({values.min():.3g}–{values.max():.3g})"
    return text + (f" [{values.size}/{seeds}]" if seeds is not None and values.size < seeds else "")


def median_at(runs: Sequence[dict[str, Any]] | None, budget: int) -> float | None:
    """The median over the study documents ``runs`` of their values at ``budget`` (None: none has it)."""
    values = _values(runs or [], budget)
    return float(np.median(values)) if values.size else None


def task_table(grouped: Cells, task: str, methods: Sequence[Any], seeds: int, budgets: Sequence[int]) -> str:
    """One task's table: a row per method (its batch size), a column per budget."""
    metric = task_by_name(task).metric
    head = " | ".join(f"{b} episodes" for b in budgets)
    lines = [f"| method | batch | {head} |", "|---|---|" + "---|" * len(budgets)]
    for method in methods:
        runs = grouped.get((task, method.name), [])
        batch = str(runs[0]["spec"]["samples"]) if runs else "—"
        row = " | ".join(median_range(_values(runs, b), seeds) for b in budgets)
        lines.append(f"| `{method.name}` | {batch} | {row} |")
    better = "lower" if task_by_name(task).lower_is_better else "higher"
    return "\n".join(lines) + f"\n\nMetric: {metric} ({better} is better).\n"


#: The c-bo columns of the targets table, beside the best other method.
CBO_COLUMNS = ("c-bo", "c-bo-ucb", "c-bo+quadratic")


def targets_table(grouped: Cells, tasks: Sequence[str], methods: Sequence[Any], budget: int) -> str:
    """c-bo's median against the best other method's (medians over seeds) at ``budget``, per task.

    The ratio is c-bo's over the best other's for a lower-is-better metric (the targets: ≤ 0.5 on the
    non-quadratic functions, ≤ 10 against ``c-cma-es-surrogate`` on the quadratic ones, ≤ 0.7 on the kick
    precision), the other's over c-bo's for the kick flexibility's distance. ``c-bo+quadratic`` (c-bo with
    the quadratic prior mean of Eq. G4) is set beside them, with its ratio to ``c-cma-es-surrogate``.
    """
    lines = [
        "| task | c-bo | c-bo-ucb | c-bo+quadratic | best other (method) | c-bo ÷ best other "
        "| c-bo ÷ c-cma-es-surrogate | c-bo+quadratic ÷ c-cma-es-surrogate |",
        "|---|---|---|---|---|---|---|---|",
    ]
    others = [m.name for m in methods if not m.name.startswith("c-bo")]
    for task in tasks:
        lower = task_by_name(task).lower_is_better
        ours, ucb, quadratic = (median_at(grouped.get((task, m)), budget) for m in CBO_COLUMNS)
        rivals = {m: v for m in others if (v := median_at(grouped.get((task, m)), budget)) is not None}
        best = (min if lower else max)(rivals, key=rivals.get) if rivals else None
        surrogate = rivals.get("c-cma-es-surrogate")
        lines.append(
            f"| {task} | {_g(ours)} | {_g(ucb)} | {_g(quadratic)} | "
            + (f"{_g(rivals[best])} (`{best}`)" if best else "—")
            + f" | {ratio_text(ours, rivals.get(best), lower)} | {ratio_text(ours, surrogate, lower)} "
            + f"| {ratio_text(quadratic, surrogate, lower)} |"
        )
    return "\n".join(lines) + "\n"


def sign_test(wins: int, trials: int) -> float:
    """The two-sided sign test's p-value of ``wins`` in ``trials`` fair coin flips (exact binomial)."""
    if trials == 0:
        return 1.0
    tail = sum(math.comb(trials, k) for k in range(min(wins, trials - wins) + 1)) / 2.0**trials
    return min(1.0, 2.0 * tail)


def paired_table(
    grouped: Cells, tasks: Sequence[str], budgets: Sequence[int], first: str, second: str
) -> str:
    """Method ``first`` against ``second``, paired by seed (the same seed draws the same initial design):
    per task and budget, the seeds where ``first`` is better, of those both finished, and the sign test's
    two-sided p-value; a tie counts for neither. The tables of ``c-bo`` (max-value entropy search) against
    ``c-bo-ucb``, and of each acquisition with active contexts against its uniform draws."""
    head = " | ".join(f"{b} episodes" for b in budgets)
    lines = [f"| task | {head} |", "|---|" + "---|" * len(budgets)]
    for task in tasks:
        lower = task_by_name(task).lower_is_better
        ours, theirs = grouped.get((task, first)), grouped.get((task, second))
        cells_ = [_paired_cell(ours, theirs, budget, lower) for budget in budgets]
        if any(cell != "—" for cell in cells_):
            lines.append(f"| {task} | {' | '.join(cells_)} |")
    return "\n".join(lines) + "\n"


def _paired_cell(ours: Any, theirs: Any, budget: int, lower: bool) -> str:
    """``k/n (p …)``: the seeds where ``ours`` ends better than ``theirs`` at ``budget``, of the n seeds both
    finished without a tie, and the sign test's p-value; ``—`` with no such seed."""
    first, second = values_by_seed(ours, budget), values_by_seed(theirs, budget)
    pairs = [(first[s], second[s]) for s in sorted(set(first) & set(second)) if first[s] != second[s]]
    wins = sum((a < b) == lower for a, b in pairs)
    return f"{wins}/{len(pairs)} (p {sign_test(wins, len(pairs)):.2g})" if pairs else "—"


#: The columns of c-bo on a library's GP (library_gp.py), set beside c-bo on its own.
LIBRARY_COLUMNS = ("c-bo-botorch", "c-bo-sklearn")


def library_table(grouped: Cells, tasks: Sequence[str], seeds: int, budgets: Sequence[int]) -> str:
    """c-bo on its own GP against the same c-bo on BoTorch's and on scikit-learn's (issue 44: "measure both
    on this issue's study and choose"), on the tasks where a library column has runs: the medians over seeds
    at each budget (``[k/n]``: k of the n seeds), and at the last budget the seeds where the library's run
    ends better than c-bo's of the same seed, of those both finished, with the sign test's p-value."""
    head = " | ".join(f"{b} episodes" for b in budgets)
    lines = [
        f"| task | method | {head} | better than c-bo at {budgets[-1]} |",
        "|---|---|" + "---|" * (len(budgets) + 1),
    ]
    for task in tasks:
        if any(grouped.get((task, m)) for m in LIBRARY_COLUMNS):
            own = grouped.get((task, "c-bo"))
            lines += [
                _library_row(task, m, grouped.get((task, m)), own, seeds, budgets)
                for m in ("c-bo", *LIBRARY_COLUMNS)
            ]
    return "\n".join(lines) + "\n"


def _library_row(task: str, method: str, runs: Any, own: Any, seeds: int, budgets: Sequence[int]) -> str:
    """:func:`library_table`'s row of ``method``'s ``runs`` (``own``: c-bo's)."""
    medians = []
    for budget in budgets:
        values = _values(runs or [], budget)
        partial = f" [{values.size}/{seeds}]" if 0 < values.size < seeds else ""
        medians.append(_g(float(np.median(values)) if values.size else None) + partial)
    lower = task_by_name(task).lower_is_better
    paired = "" if method == "c-bo" else _paired_cell(runs, own, budgets[-1], lower)
    return f"| {task} | `{method}` | {' | '.join(medians)} | {paired} |"


def _g(value: float | None) -> str:
    return "—" if value is None else f"{value:.3g}"


def ratio_text(ours: float | None, other: float | None, lower: bool) -> str:
    """``ours`` over ``other`` for a lower-is-better metric, else ``other`` over ``ours`` (≤ 1: ours is as
    good or better); "—" where either is missing."""
    if ours is None or other is None:
        return "—"
    top, bottom = (ours, other) if lower else (other, ours)
    return f"{top / bottom:.3g}" if bottom > 0 else "inf"


def timing_table(grouped: Cells, tasks: Sequence[str], methods: Sequence[Any], budget: int) -> str:
    """The optimiser's own seconds per asked episode at ``budget``: the last batch's ask + tell per episode
    in CPU seconds of the run's process (median, and the largest, over seeds), its wall seconds (median),
    and the run's mean CPU seconds per episode up to ``budget``."""
    names = [m.name for m in methods]
    lines = [f"| task | {' | '.join(f'`{n}`' for n in names)} |", "|---|" + "---|" * len(names)]
    for task in tasks:
        row = []
        for name in names:
            runs = grouped.get((task, name), [])
            last = _values(runs, budget, "last_batch_cpu_seconds_per_episode")
            wall = _values(runs, budget, "last_batch_seconds_per_episode")
            total = _values(runs, budget, "optimizer_cpu_seconds")
            episodes = _values(runs, budget, "episodes")
            if last.size == 0 or total.size != episodes.size:
                row.append("—")
                continue
            mean = np.median(total / np.maximum(episodes, 1))
            row.append(
                f"{np.median(last):.2g} (max {last.max():.2g}), wall {np.median(wall):.2g}; mean {mean:.2g}"
            )
        lines.append(f"| {task} | {' | '.join(row)} |")
    return "\n".join(lines) + "\n"


def plot_curves(grouped: Cells, tasks: Sequence[str], methods: Sequence[Any], path: Path) -> Path:
    """The median metric over seeds against the budget (log–log; min–max shaded), one panel per task with
    runs, one line per method; returns ``path``."""
    import matplotlib
    import matplotlib.ticker

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    shown = [t for t in tasks if any((t, m.name) in grouped for m in methods)]
    cols = min(6, max(1, len(shown)))
    rows = max(1, -(-len(shown) // cols))
    figure, axes = plt.subplots(rows, cols, figsize=(3.2 * cols, 2.6 * rows), squeeze=False)
    for ax, task in zip(axes.ravel(), shown, strict=False):
        for method in methods:
            runs = grouped.get((task, method.name))
            if not runs:
                continue
            budgets = [b for b in BUDGETS + tuple(runs[0]["budgets"]) if _values(runs, b).size]
            budgets = sorted(set(budgets))
            stats = np.array([[f(_values(runs, b)) for f in (np.median, np.min, np.max)] for b in budgets])
            line = ax.plot(budgets, stats[:, 0], marker="o", ms=3, label=method.name)[0]
            ax.fill_between(budgets, stats[:, 1], stats[:, 2], color=line.get_color(), alpha=0.15)
        metric = task_by_name(task).metric
        ax.set(xscale="log", title=task, xlabel="episodes (budget)", ylabel=metric)
        ticks = sorted({b for m in methods for r in grouped.get((task, m.name), []) for b in r["budgets"]})
        ax.set_xticks(ticks, [str(b) for b in ticks])
        ax.xaxis.set_minor_locator(matplotlib.ticker.NullLocator())
        if metric == "regret":
            ax.set_yscale("log")
    for ax in axes.ravel()[len(shown) :]:
        ax.set_visible(False)
    if shown:
        axes.ravel()[0].legend(fontsize=6)
    figure.tight_layout()
    figure.savefig(path, dpi=80)
    plt.close(figure)
    return path


def grouped_tasks(tasks: Sequence[str]) -> dict[str, list[str]]:
    """The tasks by section: the non-quadratic functions, the quadratic ones, the robot tasks."""
    sections: dict[str, list[str]] = {
        "Non-quadratic functions": [],
        "Quadratic functions": [],
        "Robot tasks": [],
    }
    for task in tasks:
        function = task_by_name(task).function
        key = (
            "Robot tasks"
            if function is None
            else ("Non-quadratic functions" if function in NON_QUADRATIC else "Quadratic functions")
        )
        sections[key].append(task)
    return {k: v for k, v in sections.items() if v}


def _families(task: str) -> tuple[str, str, str]:
    """The keys a run's cost is looked up by, narrowest first: the task, its family (the functions at the
    same p and z, or both kicks) and its env's cost class (the kicks' MuJoCo episodes, or a cheap env)."""
    spec = task_by_name(task)
    if spec.function is None:
        kick = task.startswith("Kick")
        return task, "kicks" if kick else task, "MuJoCo env" if kick else "cheap env"
    kwargs = dict(spec.env_kwargs)
    return task, f"functions p{kwargs['dim']} z{kwargs['context_dim']}", "cheap env"


def cost_text(documents: Sequence[dict[str, Any]], specs: Sequence[Any]) -> str:
    """The measured CPU seconds per run (the run's process: optimiser, env and evaluations) and an estimate
    of the missing runs' CPU time.

    A missing run is estimated as the median CPU seconds of the finished runs of the same method on the same
    task, else in the same family, else on an env of the same cost class (:func:`_families`; the last is
    a rough figure: it ignores how p and z change the cost); a (cost class, method) with no finished run is
    left out of the estimate and named.
    """
    seconds: dict[tuple[int, str, str], list[float]] = {}
    for document in documents:
        spec = document["spec"]
        for level, name in enumerate(_families(spec["task"])):
            seconds.setdefault((level, name, spec["method"]), []).append(float(document["cpu_seconds"]))
    done = {(d["spec"]["task"], d["spec"]["method"], d["spec"]["seed"]) for d in documents}
    missing = [s for s in specs if (s.task, s.method, s.seed) not in done]
    total, unknown = 0.0, set()
    for spec in missing:
        for key in ((level, name, spec.method) for level, name in enumerate(_families(spec.task))):
            if key in seconds:
                total += float(np.median(seconds[key]))
                break
        else:
            unknown.add(f"{_families(spec.task)[2]}: {spec.method}")
    lines = ["| task | method | runs | CPU seconds per run: median (min–max) |", "|---|---|---|---|"]
    for _, task, method in sorted(k for k in seconds if k[0] == 0):
        values = np.asarray(seconds[(0, task, method)])
        lines.append(f"| {task} | `{method}` | {values.size} | {median_range(values)} |")
    text = (
        f"{len(documents)} runs finished, {len(missing)} missing; estimated CPU time of the missing runs: "
        f"{total / 3600:.1f} h of one core (medians of the finished runs' CPU seconds, see "
        "`report.cost_text`)"
        + (f"; not estimated (no finished run): {', '.join(sorted(unknown))}" if unknown else "")
        + ".\n\n"
    )
    return text + "\n".join(lines) + "\n"


def completeness_text(documents: Sequence[dict[str, Any]], specs: Sequence[Any]) -> str:
    """Which tasks have all their runs, which some (how many) and how many have none, in the study's order."""
    done = {(d["spec"]["task"], d["spec"]["method"], d["spec"]["seed"]) for d in documents}
    counts: dict[str, list[int]] = {}
    for spec in specs:
        count = counts.setdefault(spec.task, [0, 0])
        count[0] += (spec.task, spec.method, spec.seed) in done
        count[1] += 1
    complete = [task for task, (k, n) in counts.items() if k == n]
    partial = [f"{task} ({k} of {n} runs)" for task, (k, n) in counts.items() if 0 < k < n]
    empty = [task for task, (k, _) in counts.items() if k == 0]
    return (
        f"Complete tasks: {', '.join(complete) or 'none'}. Partial: {', '.join(partial) or 'none'}. "
        f"Not started: {len(empty)} task(s)" + (f" ({', '.join(empty)})" if empty else "") + ".\n"
    )
