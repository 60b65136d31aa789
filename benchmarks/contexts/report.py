"""Render the context selection study's results (``results/<mode>.json``) as markdown tables.

Per task and optimiser, the **target** is the median over trials of uniform training's final loss. The
**median curve** of a selector is the median over trials of the loss at every evaluation; its **episodes
to target** is the first evaluation at which it is at or below the target, and the **ratio** divides that
by uniform's own (the issue asks for <= 0.67). Every trial's own first evaluation at or below the target is
counted too (``k/n`` trials, their episodes mean ± sd). The final loss is given as median and mean ± sd
over trials (a diverging trial shows in the mean).
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["DOC_END", "DOC_START", "first_at_or_below", "headline", "render", "summary", "with_headline"]

DOC_START, DOC_END = "<!-- contexts-study:start -->", "<!-- contexts-study:end -->"


def first_at_or_below(episodes: list[int], loss: Any, target: float) -> int | None:
    """The episodes at the first evaluation whose loss is <= ``target`` (None if none is)."""
    hits = np.flatnonzero(np.asarray(loss, dtype=np.float64) <= target)
    return int(episodes[hits[0]]) if len(hits) else None


def _runs(document: dict[str, Any], task: str, optimizer: str, selector: str) -> list[dict[str, Any]]:
    prefix = f"{task}/{optimizer}/{selector}/"
    keys = sorted(
        (k for k in document["runs"] if k.startswith(prefix)), key=lambda k: int(k.rsplit("/", 1)[1])
    )
    return [document["runs"][k] for k in keys]


def summary(
    document: dict[str, Any], task: str, optimizer: str, selectors: list[str]
) -> list[dict[str, Any]]:
    """One row per selector: final loss statistics, episodes to uniform's final loss, ratio to uniform's."""
    uniform = _runs(document, task, optimizer, "uniform")
    target = float(np.median([r["loss"][-1] for r in uniform]))
    rows, own = [], None
    for selector in selectors:
        runs = _runs(document, task, optimizer, selector)
        if not runs:
            continue
        episodes = runs[0]["episodes"]
        curve = np.median(np.array([r["loss"] for r in runs]), axis=0)
        reached = first_at_or_below(episodes, curve, target)
        trials = [first_at_or_below(r["episodes"], r["loss"], target) for r in runs]
        hits = [t for t in trials if t is not None]
        finals = np.array([r["loss"][-1] for r in runs])
        if selector == "uniform":
            own = reached
        rows.append(
            {
                "selector": selector,
                "trials": len(runs),
                "final_median": float(np.median(finals)),
                "final_mean": float(finals.mean()),
                "final_sd": float(finals.std(ddof=1)) if len(runs) > 1 else 0.0,
                "target": target,
                "episodes_to_target": reached,
                "trials_reaching": len(hits),
                "trial_episodes_mean": float(np.mean(hits)) if hits else None,
                "trial_episodes_sd": float(np.std(hits, ddof=1)) if len(hits) > 1 else None,
                "budget": episodes[-1],
            }
        )
    for row in rows:
        ok = own and row["episodes_to_target"] is not None
        row["ratio"] = row["episodes_to_target"] / own if ok else None
    return rows


def _number(value: float | None) -> str:
    return "–" if value is None else f"{value:.3g}"


def render(document: dict[str, Any]) -> str:
    """The markdown report of ``document`` (every task, optimiser and selector it holds)."""
    tasks = sorted({key.split("/")[0] for key in document["runs"]})
    selectors = ["uniform", "arcsine", "bandit", "progress"]
    optimizers = sorted({key.split("/")[1] for key in document["runs"]})
    versions = document.get("versions", {})
    lines = [
        f"# Context selection study, {document['mode']} mode",
        "",
        f"Measured on {document.get('cpu')} ({document.get('cpus')} CPUs); creps_gym "
        f"{versions.get('creps-gym')}, numpy {versions.get('numpy')}. Budgets (iterations, samples, eval "
        "every): "
        + ", ".join(f"{t} {tuple(document['budgets'][t])}" for t in tasks)
        + f"; {document['budgets']['trials']} trials (seeds 0 ..), {document['eval_contexts']} test "
        "contexts.",
        "",
        "Loss: mean regret (steep functions) or minus the mean return (reacher) of the mean policy on the "
        "env's test contexts; lower is better. Target: uniform's median final loss. Ratio: episodes of the "
        "median curve to the target over uniform's (<= 0.67 is the issue's target).",
    ]
    for task in tasks:
        for optimizer in optimizers:
            rows = summary(document, task, optimizer, selectors)
            if not rows:
                continue
            lines += [
                "",
                f"## {task}, {optimizer} (target {_number(rows[0]['target'])}, budget "
                f"{rows[0]['budget']} episodes)",
                "",
            ]
            lines += [
                "| selector | final loss median | final loss mean ± sd | episodes to target (median curve) "
                "| ratio to uniform | trials reaching | their episodes mean ± sd |",
                "|---|---|---|---|---|---|---|",
            ]
            for row in rows:
                spread = (
                    "–"
                    if row["trial_episodes_mean"] is None
                    else (f"{row['trial_episodes_mean']:.0f} ± {_number(row['trial_episodes_sd'])}")
                )
                lines.append(
                    f"| {row['selector']} | {_number(row['final_median'])} | {_number(row['final_mean'])} ± "
                    f"{_number(row['final_sd'])} | {row['episodes_to_target'] or '–'} | "
                    f"{_number(row['ratio'])} | {row['trials_reaching']}/{row['trials']} | {spread} |"
                )
    return "\n".join(lines) + "\n"


def headline(document: dict[str, Any]) -> str:
    """One row per task and optimiser: every selector's median final loss and ratio to uniform (docs)."""
    selectors = ["uniform", "arcsine", "bandit", "progress"]
    lines = [
        "| task | optimiser | " + " | ".join(selectors) + " |",
        "|---|---|" + "---|" * len(selectors),
    ]
    for task in sorted({key.split("/")[0] for key in document["runs"]}):
        for optimizer in sorted({key.split("/")[1] for key in document["runs"]}):
            rows = {row["selector"]: row for row in summary(document, task, optimizer, selectors)}
            cells = [
                f"{_number(rows[s]['final_median'])} ({_number(rows[s]['ratio'])})" if s in rows else "–"
                for s in selectors
            ]
            lines.append(f"| {task} | {optimizer} | " + " | ".join(cells) + " |")
    trials = document["budgets"]["trials"]
    note = (
        f"Median final loss over {trials} trials (lower is better) and, in brackets, the episodes the median "
        "curve needs to reach uniform training's median final loss over uniform's own (– : not reached "
        "within the budget)."
    )
    return "\n".join([note, "", *lines]) + "\n"


def with_headline(text: str, document: dict[str, Any]) -> str:
    """``text`` (a doc) with the block between :data:`DOC_START` and :data:`DOC_END` rendered anew."""
    head, start, rest = text.partition(DOC_START)
    _, end, tail = rest.partition(DOC_END)
    if not start or not end:
        raise ValueError(f"expected the markers {DOC_START} and {DOC_END} in the doc")
    return f"{head}{DOC_START}\n{headline(document)}{DOC_END}{tail}"
