"""The kick study's comparison of training contexts and mean features (issue 32): the study's own folder
``results/<mode>`` and every ``results/<mode>-<contexts>`` and ``results/<mode>[-<contexts>]-features-<NAME>``
folder that ``run.py --contexts`` and ``--features`` wrote, in one table per experiment of
``results/<mode>/summary.md``, drawn from the ``"selectors"`` entry of its ``results.json``::

    {"folders": ["full", "full-bandit"],
     "precision": {"reference": "arcsine",
                   "rows": [{"folder": "full-bandit", "method": "creps-cma-old", "contexts": "bandit",
                             "features": "rbf", "samples": 20, "budget_iterations": 1000,
                             "trials": [...], "finals": [...], "iterations": [...],
                             "curves": [[[iteration, value], ...] per trial],
                             "late_fall_rate": [...], "final_spread": [...]}, ...],
                   "in_progress": {"full-bandit": {"creps-cma-old-trial1": 340}}},
     "flexibility": {...}}

A row is one method trained on one law of training contexts with one set of mean features in one folder.
``finals`` is each trial's metric at its end (precision: the mean policy's error averaged over the 10
targets; flexibility: its forward distance averaged over the 28 ball positions) and ``curves`` each trial's
metric every ``EVAL_EVERY`` iterations (the run's history) and at its end; ``late_fall_rate`` and
``final_spread`` are each trial's :mod:`.spread` quantities (None where it has none). The *reference* is
the study's own training law (``study.TRAINING``) in the study's own folder: every row says how many
episodes it needed to reach the reference row's final value of the same method.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.kick.figures import mean_curve
from benchmarks.kick.spread import COLUMNS, KEYS, mean_and_std
from benchmarks.kick.study import (
    EVAL_EVERY,
    FEATURES,
    GRID_X,
    GRID_Y,
    SELECTED_CONTEXTS,
    TRAINING,
    TRAINING_CONTEXTS,
    results_folder,
)

__all__ = [
    "LAWS",
    "SECTION",
    "comparison",
    "comparison_folders",
    "comparison_section",
    "episodes_to_reach",
    "episodes_to_stay",
    "oracle_mean",
    "peak_table",
    "same_features_table",
]

#: The laws of training contexts, in the tables' order (``run.py --contexts``).
LAWS = (*TRAINING_CONTEXTS, *SELECTED_CONTEXTS)
#: Laws whose runs are in git history only, not in any results folder: (experiment, law) -> where.
HISTORY_ONLY = {
    ("precision", "uniform"): (
        "the study's uniform-draw precision runs (the paper's draw) are in git history only: commit "
        '`bd108c5`, its `results/{mode}/summary.md` (README, "Where the precision error came from")'
    ),
}
#: The title of the summary's comparison section.
SECTION = "Training contexts (uniform, arcsine, the learning selectors) and mean features (issue 32)"
#: What each experiment's metric is, and which way is better.
METRICS = {
    "precision": {"value": "error", "unit": "m", "lower_is_better": True, "contexts": "training targets"},
    "flexibility": {
        "value": "forward distance",
        "unit": "m",
        "lower_is_better": False,
        "contexts": "training positions",
    },
}


def comparison_folders(out: Path) -> list[Path]:
    """The folders beside ``out`` that exist: ``<out.name>-<law>`` (``run.py --contexts``) in ``LAWS`` order,
    then ``<out.name>-features-<features>`` and ``<out.name>-<law>-features-<features>`` (``run.py
    --features``) in ``FEATURES`` order; a symbolic link is not followed."""
    names = [results_folder(out.name, law, None) for law in LAWS]
    for features in FEATURES:
        names += [results_folder(out.name, law, features) for law in (None, *LAWS)]
    candidates = [out.parent / name for name in names]
    return [path for path in candidates if path.is_dir() and not path.is_symlink()]


def _rows(folder: str, entries: dict[str, Any], per_trial: str) -> list[dict[str, Any]]:
    """One row per (method, training law) of one folder's collected entries (the oracle is not a row)."""
    rows: dict[tuple[str, str], dict[str, Any]] = {}
    for method, entry in entries.items():
        if method == "oracle":
            continue
        for k, law in enumerate(entry["training_contexts"]):
            row = rows.setdefault(
                (method, law),
                {
                    "folder": folder,
                    "method": method,
                    "contexts": law,
                    "features": entry["features"],
                    "samples": entry["samples"],
                    "budget_iterations": entry["budget_iterations"],
                    "trials": [],
                    "finals": [],
                    "iterations": [],
                    "curves": [],
                    "late_fall_rate": [],
                    "final_spread": [],
                },
            )
            final, iterations = entry[per_trial][k], entry["iterations"][k]
            curve = [[int(i), float(v)] for i, v in entry["curves"][k] if int(i) < iterations]
            row["trials"].append(entry["trials"][k])
            row["finals"].append(final)
            row["iterations"].append(iterations)
            for key in KEYS:  # (:mod:`.spread`) None where a run has none
                row[key].append(entry.get(key, [None] * len(entry["trials"]))[k])
            row["curves"].append([*curve, [iterations, final]])  # the end is one more evaluation
    return list(rows.values())


def _method(run: str) -> str:
    """``"c-cma-es"`` of the run stem ``"c-cma-es-trial0"``."""
    return run.rsplit("-trial", 1)[0]


def comparison(documents: dict[str, dict[str, Any]], metrics: dict[str, tuple[str, str]]) -> dict[str, Any]:
    """The ``"selectors"`` entry from the collected results documents of the study's folder and of its
    ``--contexts`` folders (``{folder name: document}``, the study's own folder first); ``metrics`` maps each
    experiment to its (per-trial, per-point) keys (``report.METRIC``). Only the methods that a ``--contexts``
    folder holds (finished or in progress) have rows; the runs in progress are those of the ``--contexts``
    folders (the summary lists the study folder's own)."""
    names = list(documents)
    data: dict[str, Any] = {"folders": names}
    order = {law: k for k, law in enumerate(LAWS)}
    for experiment, (per_trial, _) in metrics.items():
        prefix = f"{experiment}/"
        in_progress = {
            name: {
                run.removeprefix(prefix): done
                for run, done in documents[name]["in_progress"].items()
                if run.startswith(prefix)
            }
            for name in names[1:]
        }
        in_progress = {name: runs for name, runs in in_progress.items() if runs}
        methods = {_method(run) for runs in in_progress.values() for run in runs}
        methods |= {method for name in names[1:] for method in documents[name][experiment]} - {"oracle"}
        rows = [
            row
            for name in names
            for row in _rows(name, documents[name][experiment], per_trial)
            if row["method"] in methods
        ]
        rows.sort(key=lambda r: (r["method"], order.get(r["contexts"], len(LAWS)), names.index(r["folder"])))
        data[experiment] = {"reference": TRAINING[experiment], "rows": rows, "in_progress": in_progress}
    data["flexibility"]["oracle_mean"] = oracle_mean(documents[names[0]]["flexibility"].get("oracle"))
    return data


def oracle_mean(oracle: dict[str, Any] | None) -> float | None:
    """The per-position oracle's forward distance averaged over the grid, or None until it has every
    position."""
    distances = [] if oracle is None else oracle["position_distances"]
    return float(np.mean(distances)) if len(distances) == len(GRID_X) * len(GRID_Y) else None


def _reached(value: float, target: float, lower_is_better: bool) -> bool:
    return value <= target if lower_is_better else value >= target


def episodes_to_reach(curve: list[Any], target: float, samples: int, lower_is_better: bool) -> int | None:
    """The episodes (iteration × ``samples``) at the first point ``[iteration, value]`` of ``curve`` whose
    value reaches ``target`` (at most it if ``lower_is_better``, else at least), or None if none does."""
    for iteration, value in curve:
        if _reached(value, target, lower_is_better):
            return int(iteration) * samples
    return None


def episodes_to_stay(curve: list[Any], target: float, samples: int, lower_is_better: bool) -> int | None:
    """The episodes at the first point of ``curve`` from which every later point reaches ``target`` too
    (the curves are not monotone), or None if its last point does not."""
    episodes = None
    for iteration, value in reversed(curve):
        if not _reached(value, target, lower_is_better):
            break
        episodes = int(iteration) * samples
    return episodes


def _mean_curve(curves: list[Any]) -> list[list[float]]:
    """``[[iteration, mean over trials], ...]`` at the iterations where every trial was evaluated."""
    return [[i, value] for i, value in mean_curve(curves).items()]


def _episodes(episodes: int | None) -> str:
    return "not reached" if episodes is None else f"{episodes:,}"


def _row(row: dict[str, Any], reference: dict[str, Any] | None, experiment: str) -> str:
    """One table row: method, law, source, trials, final value (± and per trial), episodes to reach the
    reference's final value (mean curve, per trial) and their ratio to the reference's budget episodes."""
    unit, lower = METRICS[experiment]["unit"], METRICS[experiment]["lower_is_better"]
    finals = np.asarray(row["finals"], dtype=float)
    cells = [row["method"], row["contexts"], row["features"], f"`results/{row['folder']}`", str(len(finals))]
    cells += [f"{finals.mean():.2f} ± {finals.std():.2f} {unit}", ", ".join(f"{v:.2f}" for v in finals)]
    spread = [mean_and_std(row.get(key, [None] * len(finals))) for key in KEYS]
    if reference is None:
        return "| " + " | ".join([*cells, "— (no reference run)", *["—"] * 4, *spread]) + " |"
    target = float(np.mean(reference["finals"]))
    reach, stay, budget = _reach_and_stay(row, reference, lower)
    per_trial = [episodes_to_reach(curve, target, row["samples"], lower) for curve in row["curves"]]
    cells += [_episodes(reach), ", ".join(_episodes(e) for e in per_trial), _ratio(reach, budget)]
    cells += [_episodes(stay), _ratio(stay, budget), *spread]
    return "| " + " | ".join(cells) + " |"


def _reach_and_stay(
    row: dict[str, Any], reference: dict[str, Any], lower_is_better: bool
) -> tuple[int | None, int | None, int]:
    """The episodes at which ``row``'s mean curve first reaches ``reference``'s final value (mean over its
    trials), those from which it stays there, and the reference's budget episodes (iterations × N)."""
    target, curve = float(np.mean(reference["finals"])), _mean_curve(row["curves"])
    reach = episodes_to_reach(curve, target, row["samples"], lower_is_better)
    stay = episodes_to_stay(curve, target, row["samples"], lower_is_better)
    return reach, stay, reference["budget_iterations"] * reference["samples"]


def _ratio(episodes: int | None, budget: int) -> str:
    return "—" if episodes is None else f"{episodes / budget:.2f}"


def _experiment_table(experiment: str, data: dict[str, Any], mode: str, study: str) -> list[str]:
    """The table of one experiment, its reference (each method's row of the reference law in the ``study``
    folder) and its notes (in progress, history only)."""
    rows, reference_law = data["rows"], data["reference"]
    what, unit = METRICS[experiment]["value"], METRICS[experiment]["unit"]
    references = {}
    for row in rows:
        if row["contexts"] == reference_law and row["folder"] == study:
            references.setdefault(row["method"], row)
    lines = [f"### {experiment.capitalize()}", ""]
    for samples in sorted({row["samples"] for row in rows}):
        lines += [
            f"Resolution: {EVAL_EVERY} iterations × {samples} episodes = {EVAL_EVERY * samples:,} episodes.",
            "",
        ]
    if references:
        targets = ", ".join(
            f"{m} {np.mean(r['finals']):.2f} {unit} (`results/{r['folder']}`)" for m, r in references.items()
        )
        lines += [f"Reference ({reference_law}, the study's training law), final {what}: {targets}.", ""]
    if rows:
        header = (
            f"| method | {METRICS[experiment]['contexts']} | mean features | source | trials | final {what} "
            "| per trial "
            f"| episodes to reach the {reference_law} final {what} (mean curve) | per trial "
            f"| × {reference_law}'s budget episodes | episodes from which the mean curve stays there "
            f"| × {reference_law}'s budget episodes | {COLUMNS} |"
        )
        lines += [header, "|---" * 14 + "|"]
        lines += [_row(row, references.get(row["method"]), experiment) for row in rows]
        lines.append("")
    shown = {row["contexts"] for row in rows}
    for (name, law), where in HISTORY_ONLY.items():
        if name == experiment and law not in shown:
            lines += [f"*{law.capitalize()} draws*: not in these folders; {where.format(mode=mode)}.", ""]
    for folder, runs in data["in_progress"].items():
        listed = ", ".join(f"{run} ({done} iterations)" for run, done in runs.items())
        lines += [f"In progress in `results/{folder}` (checkpoint, no result yet): {listed}.", ""]
    return lines


def comparison_section(data: dict[str, Any], mode: str) -> list[str]:
    """The summary's section :data:`SECTION`."""
    folders = ", ".join(f"`results/{name}`" for name in data["folders"])
    lines = [f"## {SECTION}", ""]
    lines += [
        f"The finished runs in {folders} of every method that a `--contexts` or `--features` folder holds: "
        "one row per method, law of training contexts (uniform, arcsine: fixed draws; bandit, progress: the "
        "learning selectors of `creps_gym.selectors`), mean features (affine [1, s], quadratic [1, s, s²] "
        "with element-wise squares, or normalised RBFs) and folder. The reference row of a method is its "
        "row in the study's own folder. The final "
        "value is the mean policy's at the end of each run (± across trials, then per trial). *Episodes to "
        "reach*: the first evaluation at which the mean over the row's trials (*mean curve*), or each "
        "trial's own value (*per trial*), reaches the reference row's final value of the same method; "
        "*stays*: the first evaluation from which the mean curve reaches it at every later one too. The "
        f"mean policy is evaluated every {EVAL_EVERY} iterations and at the run's end, so the resolution is "
        f"{EVAL_EVERY} iterations × N episodes (below). The × columns divide the mean curve's episodes by "
        "the reference row's budget (iterations × N), the episodes its final value cost. The curves are not "
        "monotone: a value once reached is not always kept, and the reference row itself may reach its "
        "final value before its end. The last two columns are the runs' late fall rate and final search "
        "spread (as in the study's tables above). Each folder's own `summary.md` has its runs' per-target "
        "values and provenance.",
        "",
    ]
    for experiment in METRICS:
        if data[experiment]["rows"] or data[experiment]["in_progress"]:
            lines += _experiment_table(experiment, data[experiment], mode, data["folders"][0])
            lines += same_features_table(experiment, data[experiment])
    if data["flexibility"]["rows"]:
        lines += peak_table(data["flexibility"])
    return lines


def same_features_table(experiment: str, data: dict[str, Any]) -> list[str]:
    """Each selector's row (a law of training contexts other than uniform) against uniform draws of the same
    method with the same mean features, in whichever folder they are: the episodes its mean curve needed to
    reach that uniform row's final value, and their ratio to that row's budget (issue 32's target compares
    a selector with uniform training); empty when no selector row has such a uniform row."""
    unit, lower = METRICS[experiment]["unit"], METRICS[experiment]["lower_is_better"]
    uniform = {}
    for row in data["rows"]:
        if row["contexts"] == "uniform":
            uniform.setdefault((row["method"], row["features"]), row)
    pairs = [
        (row, uniform[(row["method"], row["features"])])
        for row in data["rows"]
        if row["contexts"] != "uniform" and (row["method"], row["features"]) in uniform
    ]
    if not pairs:
        return []
    lines = [
        f"{experiment.capitalize()}: each selector against uniform draws with the same mean features (the "
        "episodes its mean curve needed to reach the uniform row's final value; × that row's budget "
        "episodes).",
        "",
        "| method | contexts | mean features | source | uniform final (source) | selector final "
        "| episodes to reach (mean curve) | × uniform's budget | episodes from which it stays "
        "| × uniform's budget |",
        "|---" * 10 + "|",
    ]
    for row, reference in pairs:
        reach, stay, budget = _reach_and_stay(row, reference, lower)
        target, final = float(np.mean(reference["finals"])), float(np.mean(row["finals"]))
        cells = [row["method"], row["contexts"], row["features"], f"`results/{row['folder']}`"]
        cells += [f"{target:.2f} {unit} (`results/{reference['folder']}`)", f"{final:.2f} {unit}"]
        cells += [_episodes(reach), _ratio(reach, budget), _episodes(stay), _ratio(stay, budget)]
        lines.append("| " + " | ".join(cells) + " |")
    return [*lines, ""]


def peak_table(data: dict[str, Any]) -> list[str]:
    """Issue 32's flexibility targets per row: each trial's peak along its curve, how far its end is below
    that peak, and the final and best peak distances as fractions of the per-position oracle."""
    oracle = data.get("oracle_mean")
    where = "incomplete: no fraction" if oracle is None else f"{oracle:.2f} m averaged over the grid"
    lines = [
        "Flexibility targets (issue 32: a final mean of at least 6.5 m over at least 3 trials, no trial "
        "ending more than 1 m below its own peak, and the fraction of the per-position oracle). *Peak*: "
        "the largest value of a trial's curve (the evaluations every "
        f"{EVAL_EVERY} iterations and its end); *drop*: peak minus final. Oracle: {where}.",
        "",
        "| method | training positions | mean features | trials | final (mean ± std) | peak per trial "
        "| drop per trial | largest drop | final / oracle | best peak / oracle |",
        "|---" * 10 + "|",
    ]
    for row in data["rows"]:
        finals = np.asarray(row["finals"], dtype=float)
        peaks = np.asarray([max(value for _, value in curve) for curve in row["curves"]])
        drops = peaks - finals
        fractions = ["—", "—"]
        if oracle is not None:
            fractions = [f"{finals.mean() / oracle:.2f}", f"{peaks.max() / oracle:.2f}"]
        cells = [row["method"], row["contexts"], row["features"], str(len(finals))]
        cells.append(f"{finals.mean():.2f} ± {finals.std():.2f} m")
        cells += [", ".join(f"{v:.2f}" for v in peaks), ", ".join(f"{v:.2f}" for v in drops)]
        cells += [f"{drops.max():.2f} m", *fractions]
        lines.append("| " + " | ".join(cells) + " |")
    return [*lines, ""]
