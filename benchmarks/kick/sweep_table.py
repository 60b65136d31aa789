"""The kick study's sweep of optimiser options (issue 45): every ``results/<mode>[-...]-opt-<slug>`` folder
that ``run.py --opt`` wrote beside the study's ``results/<mode>``, in one section of its ``summary.md``,
drawn from the ``"sweep"`` entry of its ``results.json``::

    {"folders": ["full-opt-epsilon-1.0", ...],
     "precision": {"rows": [{"folder": "full", "method": "creps-cma-old", "options": {}, "features": "rbf",
                             "contexts": "arcsine", "samples": 20, "budget_iterations": 1000,
                             "trials": [...], "iterations": [...], "finals": [...],
                             "far_target": [...], "curves": [[[iteration, value], ...] per trial],
                             "study_same": [...], "late_fall_rate": [...], "final_spread": [...],
                             "final_ess": [...]}, ...],
                   "in_progress": {"full-opt-epsilon-1.0": {"creps-cma-old-trial0": 340}}},
     "flexibility": {...}}

A row is one method in one folder. ``options`` are the row's optimiser options that differ from the
study's own run of the method (``{}`` for the study's row, which comes first as the reference of every
method a sweep folder holds). ``finals`` is each trial's mean policy metric at its end (precision: the error
averaged over the 10 targets), ``far_target`` its value at the last evaluation context (precision: the 12 m
target), ``curves`` the metric every ``EVAL_EVERY`` iterations (the history), ``study_same`` the study's
run of the same method and trial evaluated at the same iteration (None where it has no evaluation there),
and ``late_fall_rate``, ``final_spread`` and ``final_ess`` the :mod:`.spread` quantities (the last: the
effective sample size of the final update's weights, from the checkpoint).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.kick.spread import COLUMNS, KEYS, final_ess, mean_and_std
from benchmarks.kick.study import EVAL_EVERY

__all__ = ["SWEEP_SECTION", "row_line", "sweep", "sweep_folders", "sweep_section"]

#: The title of the summary's sweep section.
SWEEP_SECTION = "Optimiser options (`run.py --opt`, issue 45)"
#: The metric's key per trial in a collected entry, and its unit, per experiment (``report.METRIC``).
PER_TRIAL = {
    "precision": ("trial_errors", "target_errors", "error"),
    "flexibility": ("trial_distances", "position_distances", "forward distance"),
}


def sweep_folders(out: Path) -> list[Path]:
    """The folders beside ``out`` named ``<out.name>-...-opt-<slug>`` (``run.py --opt``), sorted by name; a
    symbolic link is not followed."""
    candidates = sorted(out.parent.glob(f"{out.name}-*"))
    if "-opt-" in out.name:  # a sweep folder has no sweep of its own
        return []
    return [
        path
        for path in candidates
        if "-opt-" in path.name[len(out.name) :] and path.is_dir() and not path.is_symlink()
    ]


def _differences(options: dict[str, Any], reference: dict[str, Any] | None) -> dict[str, Any]:
    """The entries of ``options`` that ``reference`` (the study's options of the method) lacks or differs
    in."""
    if reference is None:
        return dict(options)
    return {k: v for k, v in options.items() if k not in reference or reference[k] != v}


def _study_at(study_entry: dict[str, Any] | None, trial: int, iteration: int) -> float | None:
    """The study's run of ``trial``: its mean policy metric at ``iteration`` (None if not evaluated there)."""
    if study_entry is None or trial not in study_entry["trials"]:
        return None
    curve = study_entry["curves"][study_entry["trials"].index(trial)]
    values = {int(i): v for i, v in curve}
    return values.get(iteration)


def _rows(
    experiment: str, folder: Path, entries: dict[str, Any], study: dict[str, Any], own: bool
) -> list[dict[str, Any]]:
    """One row per method of one folder's collected entries; ``study`` is the study folder's entries."""
    per_trial, per_point, _ = PER_TRIAL[experiment]
    rows = []
    for method, entry in entries.items():
        if method == "oracle":
            continue
        reference = study.get(method)
        options = (
            {} if own else _differences(entry["options"], None if reference is None else reference["options"])
        )
        rows.append(
            {
                "folder": folder.name,
                "method": method,
                "options": options,
                "features": entry["features"],
                "contexts": ", ".join(sorted(set(entry["training_contexts"]))),
                "samples": entry["samples"],
                "budget_iterations": entry["budget_iterations"],
                "trials": entry["trials"],
                "iterations": entry["iterations"],
                "finals": entry[per_trial],
                "far_target": [float(values[-1]) for values in entry[per_point]],
                "curves": entry["curves"],
                "study_same": [
                    _study_at(reference, t, i)
                    for t, i in zip(entry["trials"], entry["iterations"], strict=True)
                ],
                **{key: entry[key] for key in KEYS},
                "final_ess": [
                    final_ess(folder / "runs" / experiment / f"{method}-trial{t}.npz", i)
                    for t, i in zip(entry["trials"], entry["iterations"], strict=True)
                ],
            }
        )
    return rows


def sweep(out: Path, study: dict[str, Any], documents: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """The ``"sweep"`` entry from the study folder ``out``'s collected document ``study`` and the collected
    documents of its ``--opt`` folders (``{folder name: document}``, beside ``out``). Per experiment, the
    study's rows of every method a sweep folder holds (finished or in progress) come first."""
    data: dict[str, Any] = {"folders": list(documents)}
    for experiment in PER_TRIAL:
        prefix = f"{experiment}/"
        in_progress = {
            name: {
                run.removeprefix(prefix): done
                for run, done in document["in_progress"].items()
                if run.startswith(prefix)
            }
            for name, document in documents.items()
        }
        in_progress = {name: runs for name, runs in in_progress.items() if runs}
        methods = {run.rsplit("-trial", 1)[0] for runs in in_progress.values() for run in runs}
        methods |= {m for document in documents.values() for m in document[experiment]} - {"oracle"}
        own = {m: e for m, e in study[experiment].items() if m in methods}
        rows = _rows(experiment, out, own, study[experiment], own=True)
        for name, document in documents.items():
            rows += _rows(experiment, out.parent / name, document[experiment], study[experiment], own=False)
        data[experiment] = {"rows": rows, "in_progress": in_progress}
    return data


def _options_text(options: dict[str, Any]) -> str:
    return ", ".join(f"`{k}={v!r}`" if isinstance(v, str) else f"`{k}={v}`" for k, v in options.items()) or (
        "— (the study's)"
    )


def _best(curves: list[Any]) -> str:
    """The lowest value of the mean over the trials' curves (where all were evaluated) and its iteration."""
    by_iteration = [dict((int(i), v) for i, v in curve) for curve in curves]
    common = sorted(set.intersection(*(set(c) for c in by_iteration))) if by_iteration else []
    if not common:
        return "—"
    means = {i: float(np.mean([c[i] for c in by_iteration])) for i in common}
    best = min(means, key=lambda i: (means[i], i))
    return f"{means[best]:.2f} ({best})"


def _row_text(row: dict[str, Any], unit: str) -> str:
    finals = np.asarray(row["finals"], dtype=float)
    iterations = f"{min(row['iterations'])}–{max(row['iterations'])} of {row['budget_iterations']}"
    same = [v for v in row["study_same"] if v is not None]
    same_text = "—" if not same else ", ".join(f"{v:.2f}" for v in row["study_same"] if v is not None)
    cells = [row["method"], _options_text(row["options"]), row["features"], row["contexts"]]
    cells += [f"`results/{row['folder']}`", str(len(finals)), iterations]
    cells += [f"{finals.mean():.2f} ± {finals.std():.2f} {unit}", ", ".join(f"{v:.2f}" for v in finals)]
    cells += [", ".join(f"{v:.2f}" for v in row["far_target"]), same_text, _best(row["curves"])]
    cells += [mean_and_std(row[key]) for key in KEYS] + [mean_and_std(row["final_ess"], digits=1)]
    return "| " + " | ".join(cells) + " |"


def _numbers(values: list[float | None], digits: int = 2) -> str:
    return ", ".join("—" if v is None else f"{v:.{digits}f}" for v in values)


def row_line(row: dict[str, Any], unit: str = "m") -> str:
    """One row in words, the form the README quotes (a test checks each quote against the rendering)::

    - `epsilon=2.0` (`results/full-opt-epsilon-2.0`, 1 trial, 200 of 200 iterations): final 1.23 m
      (per trial 1.23; far point 3.45); the study's same trials at the same iteration 1.03 m; falls
      0.25, final spread 1.10, ESS 3.1
    """
    trials = len(row["finals"])
    iterations = f"{min(row['iterations'])}–{max(row['iterations'])}"
    if min(row["iterations"]) == max(row["iterations"]):
        iterations = str(row["iterations"][0])
    same = [v for v in row["study_same"] if v is not None]
    same_text = f"{np.mean(same):.2f} {unit}" if len(same) == trials else "—"
    digits = {**dict.fromkeys(KEYS, 2), "final_ess": 1}
    falls, spread_, ess = (mean_and_std(row[key], n).split(" ±")[0] for key, n in digits.items())
    options = _options_text(row["options"]) if row["options"] else "the study's own options"
    return (
        f"- {options} (`results/{row['folder']}`, {trials} trial{'s' * (trials > 1)}, "
        f"{iterations} of {row['budget_iterations']} iterations): final {np.mean(row['finals']):.2f} {unit} "
        f"(per trial {_numbers(row['finals'])}; far point {_numbers(row['far_target'])}); the study's same "
        f"trials at the same iteration {same_text}; falls {falls}, final spread {spread_}, ESS {ess}"
    )


def sweep_section(data: dict[str, Any]) -> list[str]:
    """The summary's section :data:`SWEEP_SECTION`."""
    lines = [
        f"## {SWEEP_SECTION}",
        "",
        "Each method of a `--opt` folder, with the options that differ from the study's run of it, beside "
        "the study's own row. A trial draws the study's seeds and training contexts, so trial k of a row "
        "and of the study differ in the options only. *Final*: the mean policy at the run's end (± across "
        "trials, then per trial); *far point*: at the last evaluation context (precision: 12 m); *study's "
        "same trials, same iteration*: the study's runs of those trials evaluated at the row's final "
        "iteration; *best of the mean curve*: the lowest mean over the trials of the evaluations every "
        f"{EVAL_EVERY} iterations (its iteration in brackets). Falls and final spread as in the tables "
        "above; *ESS*: the effective sample size 1/Σd² of the final update's weights (mean ± std across "
        "trials).",
        "",
    ]
    for experiment in PER_TRIAL:
        part = data[experiment]
        if not part["rows"] and not part["in_progress"]:
            continue
        _, _, what = PER_TRIAL[experiment]
        lines += [f"### {experiment.capitalize()}", ""]
        header = (
            "| method | options | mean features | training contexts | source | trials | iterations "
            f"| final {what} | per trial | far point per trial | study's same trials, same iteration "
            f"| best of the mean curve | {COLUMNS} | ESS, final update |"
        )
        lines += [header, "|---" * 15 + "|", *(_row_text(row, "m") for row in part["rows"]), ""]
        lines += ["The same rows in words (falls, spread and ESS: means over the trials):", ""]
        lines += [*(row_line(row) for row in part["rows"]), ""]
        for folder, runs in part["in_progress"].items():
            listed = ", ".join(f"{run} ({done} iterations)" for run, done in runs.items())
            lines += [f"In progress in `results/{folder}` (checkpoint, no result yet): {listed}.", ""]
    return lines
