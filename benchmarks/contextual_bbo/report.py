"""The contextual BBO study's tables, rendered from the run documents and the published values only.

Two tables: the protocol's measure beside the published columns (GECCO 2019), and ours (the mean policy's
regret on 100 fixed test contexts, episodes to 1e-5). :func:`render` is what ``run.py`` writes and what the
test compares with the committed ``results.md``.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.contextual_bbo.problems import GENERATION, N_PARAMS, PROBLEMS
from benchmarks.contextual_bbo.protocol import TARGET

__all__ = [
    "PUBLISHED",
    "best_table",
    "load_published",
    "plot_curves",
    "protocol_table",
    "regret_table",
    "render",
    "tuned_table",
]

PUBLISHED = Path(__file__).resolve().parent / "published.json"


def load_published(path: Path = PUBLISHED) -> dict[str, Any]:
    """The published values (see ``published.json``: source, measure, provenance and the cells)."""
    return json.loads(path.read_text(encoding="utf-8"))


def _number(value: float | None) -> str:
    if value is None:
        return "–"
    return f"{value:.2g}" if value == 0 or 1e-3 <= abs(value) < 1e4 else f"{value:.1e}"


def _by_cell(documents: Sequence[dict[str, Any]]) -> dict[tuple[str, str], list[dict[str, Any]]]:
    cells: dict[tuple[str, str], list[dict[str, Any]]] = {}
    for document in documents:
        spec = document["spec"]
        cells.setdefault((spec["function"], spec["label"] or spec["method"]), []).append(document)
    return cells


def _columns(documents: Sequence[dict[str, Any]]) -> list[str]:
    return list(dict.fromkeys(d["spec"]["label"] or d["spec"]["method"] for d in documents))


def _best_tuned(published: dict[str, Any], function: str) -> str:
    """The hyperparameter study's best value on ``function`` (closest to 0) with its setting, or "–"."""
    rows = [row for row in published.get("hyperparameter_study", ()) if row["function"] == function]
    if not rows:
        return "–"
    best = max(rows, key=lambda row: row["value"])
    return f"{best['printed']} ({best['method']}, {best['setting']})"


def _best_published(published: dict[str, Any], function: str) -> tuple[float, str]:
    """The best published value on ``function`` (table and hyperparameter study) and who reached it."""
    rows = [row for row in published["values"] if row["function"] == function and row["value"] is not None]
    rows += [row for row in published.get("hyperparameter_study", ()) if row["function"] == function]
    best = max(rows, key=lambda row: row["value"])
    setting = f", {best['setting']}" if "setting" in best else ""
    return best["value"], f"{best['method']}{setting}"


def protocol_table(documents: Sequence[dict[str, Any]], published: dict[str, Any]) -> str:
    """Markdown: per function, every published column (as printed; NaN: the published runs diverged), the
    hyperparameter study's best, then ours: the mean over runs of the last generation's average return (the
    median in brackets, then the runs)."""
    ours = _columns(documents)
    cells = _by_cell(documents)
    printed = {(v["function"], v["method"]): v["printed"] for v in published["values"]}
    head = [
        "function",
        "n_s",
        "generations",
        *published["methods"],
        "hyperparameter study: best",
        *(f"{c} (ours)" for c in ours),
    ]
    lines = ["| " + " | ".join(head) + " |", "|" + " --- |" * len(head)]
    for name, problem in PROBLEMS.items():
        row = [name, str(problem.context_dim), str(problem.generations)]
        row += [printed.get((name, method), "–") for method in published["methods"]]
        row.append(_best_tuned(published, name))
        for column in ours:
            runs = [d["protocol_last"] for d in cells.get((name, column), [])]
            row.append(
                f"{_number(float(np.mean(runs)))} ({_number(float(np.median(runs)))}; {len(runs)} runs)"
                if runs
                else "–"
            )
        lines.append("| " + " | ".join(row) + " |")
    return "\n".join(lines)


def best_table(documents: Sequence[dict[str, Any]], published: dict[str, Any]) -> str:
    """Markdown: per function, the best published value (who reached it) and our best column by the mean
    over its runs (the protocol's measure), with their ratio (ours / published: below 1 is better)."""
    cells = _by_cell(documents)
    head = ["function", "best published", "by", "our best column", "its mean", "ours / published"]
    lines = ["| " + " | ".join(head) + " |", "|" + " --- |" * len(head)]
    for name in PROBLEMS:
        value, who = _best_published(published, name)
        means = {
            c: float(np.mean([d["protocol_last"] for d in runs]))
            for (f, c), runs in cells.items()
            if f == name
        }
        if not means:
            lines.append(f"| {name} | {_number(value)} | {who} | – | – | – |")
            continue
        column = max(means, key=lambda c: means[c])
        ratio = means[column] / value if value else float("nan")
        lines.append(
            f"| {name} | {_number(value)} | {who} | {column} | {_number(means[column])} | {ratio:.2g} |"
        )
    return "\n".join(lines)


def tuned_table(published: dict[str, Any]) -> str:
    """Markdown: the published hyperparameter study, every row as printed."""
    lines = ["| function | method | setting | generations | value |", "| --- | --- | --- | --- | --- |"]
    for row in published.get("hyperparameter_study", ()):
        cells = (row["function"], row["method"], row["setting"], str(row["generations"]), row["printed"])
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def regret_table(documents: Sequence[dict[str, Any]]) -> str:
    """Markdown: per (function, column), the median episodes to a mean test regret ≤ 1e-5 (a run that missed
    counts as infinitely many), the runs that got there, and the final regret's median, mean and worst."""
    head = [
        "function",
        "column",
        "episodes to 1e-5 (median)",
        "runs at 1e-5",
        "final regret: median",
        "mean",
        "worst",
        "runs restarted",
        "running mean's final regret: median",
        "worst",
    ]
    lines = ["| " + " | ".join(head) + " |", "|" + " --- |" * len(head)]
    cells = _by_cell(documents)
    for name, problem in PROBLEMS.items():
        for column in _columns(documents):
            runs = cells.get((name, column))
            if not runs:
                continue
            hits = [d["hit"] if d["hit"] is not None else np.inf for d in runs]
            median = float(np.median(hits))
            episodes = f"{median:,.0f}" if np.isfinite(median) else f">{problem.episodes:,}"
            finals = [d["final"] for d in runs]
            restarted = sum(d["restarts"] > 0 for d in runs)
            running = [d["final_running"] for d in runs]
            lines.append(
                f"| {name} | {column} | {episodes} | {sum(d['hit'] is not None for d in runs)}/{len(runs)} "
                f"| {_number(float(np.median(finals)))} | {_number(float(np.mean(finals)))} "
                f"| {_number(float(np.max(finals)))} | {restarted}/{len(runs)} "
                f"| {_number(float(np.median(running)))} | {_number(float(np.max(running)))} |"
            )
    return "\n".join(lines)


def _environments(documents: Sequence[dict[str, Any]]) -> str:
    seen = sorted({json.dumps(d["environment"], sort_keys=True) for d in documents})
    items = []
    for text in seen:
        env = json.loads(text)
        items.append(", ".join(f"{key} {env[key]}" for key in sorted(env)))
    return "\n".join(f"- {item}" for item in items)


def render(documents: Sequence[dict[str, Any]], published: dict[str, Any], command: str, timing: str) -> str:
    """The study's ``results.md``: the setting, both tables and the stacks the runs computed on."""
    runs = len(documents)
    return f"""# Contextual BBO: the IJCAI 2017 / GECCO 2019 protocol

Command: `{command}`. θ ∈ R^{N_PARAMS}, f_s(θ) = f(θ + G s), G ~ N(0, 1) per run, s ~ U[1, 2)^n_s,
initial mean ~ N(0, I), covariance σ0² I, N = {GENERATION} episodes per generation; {runs} runs. {timing}

## The protocol's measure beside the published values

The average return of the last generation (the mean of −f_s over its {GENERATION} episodes), averaged over
the runs; ours also give the median and the number of runs. Published: {published["source"]};
{published["measure"]}.
{published["provenance"]}

{protocol_table(documents, published)}

The best published value per function (the table and the hyperparameter study) beside our best column
(the highest mean over its runs; both are negative, so a ratio below 1 means ours is closer to 0):

{best_table(documents, published)}

The same source's hyperparameter study of C-ACM-ES (20 runs each, the budget of the table):

{tuned_table(published)}

## Ours: the mean policy on fixed test contexts

The mean over 100 fixed test contexts of the regret f_s(m(s)) of the optimiser's mean policy m(s), after every
generation; episodes until it is ≤ {TARGET:g} (the median over the runs, a run that missed counting as
infinitely many) and its value at the end of the budget. The last two columns give the final regret of the
running search's mean instead, which is what `c-cma-es` recommends with `keep_best=False` on the same runs
(the samples, and so the protocol's measure, do not depend on `keep_best`).

{regret_table(documents)}

## Computed on

{_environments(documents)}
"""


def plot_curves(documents: Sequence[dict[str, Any]], path: Path) -> Path:
    """One panel per function: the median over the runs of the mean policy's test regret against the
    episodes, one line per column (log scale); saved to ``path`` (PNG)."""
    import matplotlib.pyplot as plt

    cells = _by_cell(documents)
    figure, axes = plt.subplots(2, 3, figsize=(13, 7), constrained_layout=True)
    for axis, (name, problem) in zip(axes.flat, PROBLEMS.items(), strict=True):
        for column in _columns(documents):
            runs = cells.get((name, column))
            if runs:
                episodes = np.asarray(runs[0]["curve"]["generation"]) * GENERATION
                median = np.median([d["curve"]["regret"] for d in runs], axis=0)
                axis.plot(episodes, np.maximum(median, 1e-16), label=column)
        axis.axhline(TARGET, color="grey", linestyle=":", linewidth=1)
        axis.set(title=f"{name} (n_s = {problem.context_dim})", xlabel="episodes", yscale="log")
        axis.set_ylabel("median test regret")
    handles, labels = axes.flat[0].get_legend_handles_labels()
    figure.legend(handles, labels, loc="outside lower center", ncols=max(1, len(labels)))
    figure.savefig(path, dpi=90)
    plt.close(figure)
    return path
