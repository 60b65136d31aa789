"""The kick study's data and rendering: ``results.json`` from the finished runs, then ``summary.md`` and the
figures from ``results.json`` alone (a test checks the committed summary against it).

``results.json``::

    {"mode": ..., "budgets": {...},
     "precision": {"<registry name>": {"trial_errors": [...], "target_errors": [[10 per trial]],
                                       "training_contexts": ["arcsine" per trial], ...},
                   "oracle": {"target_errors": [...]}},
     "flexibility": {"<registry name>": {"trial_distances": [...],
                                         "position_distances": [[28 per trial]], ...},
                     "oracle": {"position_distances": [...]}},
     "in_progress": {"<experiment>/<name>-trial<k>": iterations done},
     "selectors": {...},  # if a results/<mode>-<contexts> folder exists (:mod:`.selector_table`)
     "sweep": {...}}  # if a results/<mode>-opt-<slug> folder exists (:mod:`.sweep_table`)

A "±" in the summary is the standard deviation across trials (population, ddof = 0) unless it says otherwise.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.kick.figures import mean_curve, plot
from benchmarks.kick.oracle import read_oracle
from benchmarks.kick.selector_table import comparison, comparison_folders, comparison_section, oracle_mean
from benchmarks.kick.spread import COLUMNS, KEYS, LATE_BATCHES, final_spread, late_fall_rate, mean_and_std
from benchmarks.kick.study import ENV_IDS, EVAL_EVERY, GRID_X, GRID_Y, TARGETS, read_json, stored_setting
from benchmarks.kick.sweep_table import sweep, sweep_folders, sweep_section
from benchmarks.provenance import group_by_record, provenance_text

__all__ = ["collect", "render", "summary_text"]

PAPER = {
    "precision": "0.34 ± 0.11 m (CREPS-CMA, old mean, RBF features; the ± is not defined in the paper)",
    "flexibility": "CREPS-CMA 6.50 ± 2.95 m against CREPS 2.67 ± 2.69 m (10 trials)",
}
#: What the training-contexts column's names mean (``study.TRAINING_CONTEXTS``).
TRAINING_NOTE = (
    "Training targets: *uniform* in the env's context box (the paper's draw), or *arcsine*, Beta(½, ½) "
    "scaled into it (a third of the draws in each outer quarter of [3, 12] m)."
)
#: What the columns of :mod:`.spread`'s two quantities mean.
SPREAD_NOTE = (
    f"*Falls, last {LATE_BATCHES} it.*: the fraction of training samples that fell, averaged over each run's "
    f"last {LATE_BATCHES} batches (all of them in a shorter run). *Final spread*: the search distribution's "
    "standard deviation at the run's final checkpoint, σ·√(mean of diag(C)), in σ units of the offset "
    "parameters (every method starts at 1.00; an optimiser without step-size control keeps σ = 1). Both are "
    "mean ± std across trials."
)
METRIC = {
    "precision": ("trial_errors", "target_errors"),
    "flexibility": ("trial_distances", "position_distances"),
}


def _runs(folder: Path, experiment: str) -> list[dict[str, Any]]:
    """The finished runs under ``folder`` on the experiment's current env (a file of another env is stale),
    except those being computed again under another setting (:func:`_superseded`)."""
    paths = [p for p in sorted(folder.glob("*-trial*.json")) if not p.name.endswith(".history.json")]
    runs = [(p, read_json(p)) for p in paths]
    return [
        r
        for p, r in runs
        if stored_setting(r, experiment)["env"] == ENV_IDS[experiment] and not _superseded(p, r, experiment)
    ]


def _superseded(path: Path, result: dict[str, Any], experiment: str) -> bool:
    """Whether a finished run is being computed again under another setting: its history file, which a
    restarted run rewrites at its first checkpoint, holds a setting other than the result's."""
    history = path.with_name(path.name.removesuffix(".json") + ".history.json")
    if not history.exists():
        return False
    return stored_setting(read_json(history), experiment) != stored_setting(result, experiment)


def collect(out: Path, mode: str, budgets: dict[str, Any], selectors: bool = True) -> dict[str, Any]:
    """The results document from the finished run files under ``out/runs`` (trials in order) and, with
    ``selectors`` and if ``run.py --contexts`` wrote any ``<out>-<contexts>`` folder beside ``out``, the
    comparison of every such folder's runs with ``out``'s (``"selectors"``, :mod:`.selector_table`)."""
    document: dict[str, Any] = {"mode": mode, "budgets": budgets, "precision": {}, "flexibility": {}}
    sources: dict[str, Any] = {}  # run -> its provenance record
    for experiment, (per_trial, per_point) in METRIC.items():
        for run in sorted(
            _runs(out / "runs" / experiment, experiment), key=lambda r: (r["name"], r["trial"])
        ):
            entry = document[experiment].setdefault(
                run["name"],
                {
                    per_trial: [],
                    per_point: [],
                    "trials": [],
                    "iterations": [],
                    "stopped": [],
                    "curves": [],
                    "training_contexts": [],
                    "late_fall_rate": [],
                    "final_spread": [],
                    "features": run["features"],
                    "options": run["options"],
                    "samples": run["samples"],
                    "budget_iterations": run["budget_iterations"],
                },
            )
            sources[f"{experiment}/{run['name']}-trial{run['trial']}"] = run.get("provenance")
            entry[per_trial].append(float(np.mean(run["values"])))
            entry[per_point].append(run["values"])
            entry["trials"].append(run["trial"])
            entry["iterations"].append(run["iterations"])
            entry["stopped"].append(run["stopped"])
            entry["training_contexts"].append(stored_setting(run, experiment)["contexts"])
            entry["late_fall_rate"].append(late_fall_rate(run["history"]["batch"]))
            checkpoint = out / "runs" / experiment / f"{run['name']}-trial{run['trial']}.npz"
            entry["final_spread"].append(final_spread(checkpoint, run["iterations"]))
            entry["curves"].append([[i, float(np.mean(v))] for i, v in run["history"]["evaluations"]])
        paths = sorted((out / "runs" / experiment).glob("oracle-*.json"))
        records = {path.stem: read_oracle(path, experiment) for path in paths}
        current = {stem: r for stem, r in records.items() if r["env"] == ENV_IDS[experiment]}
        points = list(current.values())
        sources.update({f"{experiment}/{stem}": r.get("provenance") for stem, r in current.items()})
        if points:
            document[experiment]["oracle"] = {
                per_point: [r["value"] for r in points],
                "best": [r["best"] for r in points],
                "contexts": [r["context"] for r in points],
                "episodes": [r["episodes"] for r in points],
                "starts": [len(r["starts"]) for r in points],
                "optimizer": points[0]["optimizer"],
            }
    document["in_progress"] = _in_progress(out)
    document["provenance"] = group_by_record(sources)
    if selectors and (folders := comparison_folders(out)):
        others = {folder.name: collect(folder, mode, budgets, selectors=False) for folder in folders}
        document["selectors"] = comparison({out.name: document, **others}, METRIC)
    if selectors and (folders := sweep_folders(out)):
        others = {folder.name: collect(folder, mode, budgets, selectors=False) for folder in folders}
        document["sweep"] = sweep(out, document, others)
    return document


def _in_progress(out: Path) -> dict[str, int]:
    """Iterations done by every started but unfinished run (from its last checkpointed history)."""
    progress = {}
    for history in sorted((out / "runs").glob("*/*.history.json")):
        stem = history.name.removesuffix(".history.json")
        result = history.parent / f"{stem}.json"
        experiment = history.parent.name
        if not result.exists() or _superseded(result, read_json(result), experiment):
            progress[f"{experiment}/{stem}"] = len(read_json(history)["batch"])
    return progress


def _spread(values: list[float]) -> str:
    values_array = np.asarray(values, dtype=float)
    return f"{values_array.mean():.2f} ± {values_array.std():.2f} m"


def _method_rows(experiment: str, document: dict[str, Any]) -> list[str]:
    per_trial, _ = METRIC[experiment]
    oracle = oracle_mean(document["flexibility"].get("oracle"))
    rows = []
    for name, entry in document[experiment].items():
        if name == "oracle":
            continue
        values = entry[per_trial]
        trials = ", ".join(f"{v:.2f}" for v in values)
        stopped = sorted({k for s in entry["stopped"] for k in s}) or ["—"]
        budget = f"{entry['budget_iterations']} × {entry['samples']}"
        contexts = ", ".join(sorted(set(entry.get("training_contexts", ["uniform"]))))
        iterations = f"{min(entry['iterations'])}–{max(entry['iterations'])}"
        cells = [name, contexts, budget, str(len(values)), _spread(values), trials, iterations]
        cells.append(", ".join(stopped))
        if experiment == "flexibility":
            ratio = "— (oracle incomplete)" if oracle is None else f"{np.mean(values) / oracle:.2f}"
            at_far = np.asarray(entry["position_distances"])[:, -len(GRID_Y) :]
            cells += [ratio, f"{np.mean(at_far > 0.5):.0%}"]
        cells += [mean_and_std(entry.get(key, [None] * len(values))) for key in KEYS]
        rows.append("| " + " | ".join(cells) + " |")
    return rows


def summary_text(document: dict[str, Any]) -> str:
    """The whole ``summary.md``, drawn from the results document only."""
    lines = [f"# Kick study ({document['mode']} mode): rendered from `results.json`", ""]
    lines += [f"Budgets: {json.dumps(document['budgets'])}. A ± is the standard deviation across trials.", ""]
    lines += _precision_section(document) + _flexibility_section(document)
    if "selectors" in document:
        lines += comparison_section(document["selectors"], document["mode"])
    if "sweep" in document:
        lines += sweep_section(document["sweep"])
    if document["in_progress"]:
        lines += ["## Runs in progress (iterations done at the last checkpoint)", ""]
        lines += [f"- {run}: {done}" for run, done in document["in_progress"].items()] + [""]
    groups = document.get("provenance", [])
    records = [group["record"] for group in groups for _ in group["runs"]]
    lines += ["## Provenance (the runs and the oracles)", "", provenance_text(records, "runs"), ""]
    return "\n".join(lines)


def _precision_section(document: dict[str, Any]) -> list[str]:
    lines = ["## Precision (Fig. 5c)", "", f"Paper: {PAPER['precision']}.", "", TRAINING_NOTE, ""]
    lines += [SPREAD_NOTE, ""]
    header = (
        "| method | training targets | budget (it. × N) | trials | mean error | per trial | iterations "
        f"| stopped by | {COLUMNS} |"
    )
    lines += [header, "|---" * 10 + "|", *_method_rows("precision", document), ""]
    columns = {  # the oracle once it has every target
        name: np.asarray(entry["target_errors"]).reshape(-1, len(TARGETS))
        for name, entry in document["precision"].items()
        if name != "oracle" or len(entry["target_errors"]) == len(TARGETS)
    }
    if columns:
        title = "Error (m) per target, mean over trials and (in brackets) the largest trial's error"
        lines += [f"{title} (oracle: pycma on that target alone):", ""]
        lines += ["| target (m) | " + " | ".join(columns) + " |", "|---" * (len(columns) + 1) + "|"]
        for i, target in enumerate(TARGETS):
            cells = [_mean_and_largest(errors[:, i]) for errors in columns.values()]
            lines.append(f"| {target:.0f} | " + " | ".join(cells) + " |")
        lines.append("")
    title = "Mean policy's error (m) while learning, mean over trials (— once a trial has stopped)"
    lines += _curve_table(document["precision"], title)
    oracle = document["precision"].get("oracle")
    if oracle:
        errors = np.asarray(oracle["target_errors"])
        lines += [
            _oracle_intro(oracle, "target", len(errors), len(TARGETS))
            + f"{errors.mean():.2f} m mean error; reachable within 0.34 m: "
            + (", ".join(f"{TARGETS[i]:.0f}" for i in np.flatnonzero(errors <= 0.34)) or "none")
            + " m.",
            "",
        ]
    return lines


def _mean_and_largest(values: np.ndarray) -> str:
    """``"0.64 (1.61)"``: the mean and, over several trials, the largest value; ``"0.07"`` for one."""
    return f"{values.mean():.2f}" + (f" ({values.max():.2f})" if len(values) > 1 else "")


def _curve_table(entries: dict[str, Any], title: str, every: int = 2 * EVAL_EVERY) -> list[str]:
    """Learning curves as a table: one row per method, the mean over its trials every ``every`` iterations
    at which every trial was evaluated ("—" after a trial stopped)."""
    rows = {}
    for name, entry in entries.items():
        if entry.get("curves"):  # not the oracle
            rows[name] = {i: v for i, v in mean_curve(entry["curves"]).items() if i % every == 0}
    iterations = sorted(set().union(*rows.values())) if rows else []
    if not iterations:
        return []
    lines = [f"{title}:", "", "| method | " + " | ".join(str(i) for i in iterations) + " |"]
    lines.append("|---" * (len(iterations) + 1) + "|")
    for name, row in rows.items():
        cells = [f"{row[i]:.2f}" if i in row else "—" for i in iterations]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return [*lines, ""]


def _count(n: int, noun: str) -> str:
    """``"1 start"``, ``"3 starts"``."""
    return f"{n} {noun}{'' if n == 1 else 's'}"


def _oracle_intro(oracle: dict[str, Any], point: str, done: int, total: int) -> str:
    """``Oracle (<optimizer> per <point>, <episodes> episodes each, <done> of <total> <point>s): ``."""
    plural = "targets" if point == "target" else "positions"
    return (
        f"Oracle ({oracle['optimizer']} per {point} with IPOP restarts, {max(oracle['episodes'])} episodes "
        f"each at most, {_count(max(oracle['starts']), 'start')} at most, "
        f"{done} of {total} {plural}): "
    )


def _flexibility_section(document: dict[str, Any]) -> list[str]:
    lines = [
        f"## Flexibility (Fig. 7), `{ENV_IDS['flexibility']}`",
        "",
        f"Paper: {PAPER['flexibility']}.",
        "",
        SPREAD_NOTE,
        "",
    ]
    header = (
        "| method | training positions | budget (it. × N) | trials | mean forward distance | per trial "
        "| iterations | stopped by | fraction of the oracle | balls at x_B = 0.30 m kicked > 0.5 m "
        f"| {COLUMNS} |"
    )
    lines += [header, "|---" * 12 + "|", *_method_rows("flexibility", document), ""]
    lines += _row_table(document["flexibility"])
    title = "Mean policy's forward distance (m) while learning, mean over trials (— once a trial has stopped)"
    lines += _curve_table(document["flexibility"], title)
    oracle = document["flexibility"].get("oracle")
    if oracle:
        distances = np.asarray(oracle["position_distances"])
        lines += [
            _oracle_intro(oracle, "ball position", len(distances), len(GRID_X) * len(GRID_Y))
            + f"{distances.mean():.2f} ± {distances.std():.2f} m "
            "(± over positions); farthest sample kick per position "
            f"{np.mean([b or 0.0 for b in oracle['best']]):.2f} m on average.",
            "",
        ]
    return lines


def _row_table(entries: dict[str, Any]) -> list[str]:
    """Per method, the final mean policy's forward distance per row of balls (x_B), mean over trials, and
    per trial how many of the 28 positions end at 0 m (a fall, or a kick that misses the ball)."""
    header = " | ".join(f"x_B = {x:.2f} m" for x in GRID_X)
    title = (
        "Final mean policy per row of balls (forward distance, mean over trials; positions at 0 m: a fall or "
        "a miss, per trial):"
    )
    lines = [title, "", f"| method | {header} | positions at 0 m |", "|---" * 6 + "|"]
    for name, entry in entries.items():
        if name != "oracle":
            distances = np.asarray(entry["position_distances"]).reshape(-1, len(GRID_X), len(GRID_Y))
            rows = [f"{v:.2f}" for v in distances.mean(axis=(0, 2))]
            zeros = ", ".join(str(int(n)) for n in (distances == 0).sum(axis=(1, 2)))
            lines.append(f"| {name} | " + " | ".join(rows) + f" | {zeros} |")
    return [*lines, ""]


def render(out: Path, mode: str, budgets: dict[str, Any]) -> str:
    """Rebuild ``results.json`` from the finished runs, then ``summary.md`` and the figures from it; the
    ``--contexts``, ``--features`` and ``--opt`` folders beside ``out``
    (:func:`.selector_table.comparison_folders`, :func:`.sweep_table.sweep_folders`) are rendered again too,
    so that their files and ``out``'s tables come from the same run files. Returns ``out``'s summary."""
    out.mkdir(parents=True, exist_ok=True)
    document = collect(out, mode, budgets)
    tmp = out / "results.json.tmp"
    tmp.write_text(json.dumps(document, indent=1) + "\n")
    os.replace(tmp, out / "results.json")
    text = summary_text(read_json(out / "results.json"))
    (out / "summary.md").write_text(text)
    plot(document, out)
    for folder in [*comparison_folders(out), *sweep_folders(out)]:
        render(folder, mode, budgets)
    return text
