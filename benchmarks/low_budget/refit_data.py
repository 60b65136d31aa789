"""c-bo's refit data before and after 2026-11-30: the study's pinned runs against the new default (issue 44).

Until 2026-11-30 c-bo fitted its hyperparameters on the 256 most recent episodes (``fit_points=256``,
``fit_subset="recent"``); now a refit sees every episode up to 1024, and beyond that a spread over the whole
history (Eq. G3a of ``creps_gym/optimizers/gp_model.py``). The low-budget study's c-bo columns keep the
former (``CBO_FIT_PIN`` of ``benchmarks/study_options.py``), so their committed runs stay the runs of their
specs. This script runs a column again without the pin (the same start, batches, training and test
contexts and seeds: :func:`benchmarks.low_budget.study.one_run` with the unpinned column) and sets each run
beside the study's committed run of the same task, column and seed. Both see the same data until the first
refit past 256 episodes, so their 50-, 100- and 200-episode values must agree bit for bit (the table says
in how many runs they do). Writes one JSON document with provenance and a Markdown table next to it
(``--render-only`` redraws the table from it).

    OPENBLAS_NUM_THREADS=1 python -m benchmarks.low_budget.refit_data --workers 2 \\
        --out benchmarks/low_budget/results/refit_data.json
    OPENBLAS_NUM_THREADS=1 python -m benchmarks.low_budget.refit_data --workers 2 --tasks \\
        Rosenbrock-p4-z1 DifferentPowers-p4-z1 Rastrigin-p4-z1 Sphere-p4-z1 ShiftedRotatedElliptic-p4-z1 \\
        Sphere-p8-z1 Rosenbrock-p8-z2 --out benchmarks/low_budget/results/refit_data_functions.json
    OPENBLAS_NUM_THREADS=1 python -m benchmarks.low_budget.refit_data --workers 2 --methods c-bo-ucb \\
        c-bo+quadratic --tasks KickFlexibilityLowDim-v2 KickPrecisionLowDim-v2 \\
        --out benchmarks/low_budget/results/refit_data_columns.json

Within the study's 500 episodes the new default fits every episode, so these runs measure "every episode"
against "the 256 most recent"; the spread beyond 1024 episodes is not measured here. Both keep the log
transform's former scale and MES's former floor (``CBO_KEPT_PINS``: the committed runs were measured
before they changed, and their documents do not name them); ``recommenders.py --options`` measures the
new ones.
"""

from __future__ import annotations

import sys
from pathlib import Path

if not __package__:  # run by path: the repository root first on sys.path, as `python -m` puts it
    sys.path[0] = str(Path(__file__).resolve().parents[2])

import json
from typing import Any

import numpy as np

from benchmarks.low_budget import column_replay_main, replay_command
from benchmarks.low_budget.columns import PINNED_FIT_POINTS, method_by_name, unpinned
from benchmarks.low_budget.recommenders import RUNS, committed_run
from benchmarks.low_budget.report import median_range
from benchmarks.low_budget.study import (
    BUDGETS,
    ROBOT_TASKS,
    LowBudgetSpec,
    one_run,
    task_by_name,
)

__all__ = ["main", "render", "study_document", "summary", "worse_later"]

#: Budgets at which both have seen the same data: no refit has seen more than the pin's ``fit_points``.
SHARED_BUDGETS = tuple(b for b in BUDGETS if b <= PINNED_FIT_POINTS)


def study_document(
    task: str, method: str, seed: int, samples: int, runs: Path = RUNS
) -> dict[str, Any] | None:
    """The study's committed run of ``task``, ``method``, ``seed`` and batch size, or None."""
    return committed_run(LowBudgetSpec(task, method, seed, samples=samples).key, runs)


def one(task: str, method: str, seed: int, budget: int) -> dict[str, Any]:
    """The run of ``method`` without the pin on ``task``: its values and seconds per budget."""
    document = one_run(LowBudgetSpec(task, method, seed, budget), unpinned(method_by_name(method)))
    keep = ("budgets", "episodes", "values", "optimizer_cpu_seconds", "last_batch_cpu_seconds_per_episode")
    run = {"task": task, "method": method, "seed": seed, "samples": document["spec"]["samples"]}
    return {**run, "options": document["method"]["options"], **{name: document[name] for name in keep}}


def _job(args: tuple[str, str, int, int]) -> dict[str, Any]:
    return one(*args)


def _rows(group: list[dict[str, Any]], studies: list[dict[str, Any]], lower_is_better: bool) -> list[str]:
    """One table row per budget of a (task, column): the study's median, the new default's, the seeds where
    the new default is better, and the new default's optimiser CPU seconds per asked episode so far and in
    the last batch before the budget (what a robot waits for; the study's runs ran beside other processes,
    so their seconds are not compared)."""
    rows, sign = [], -1.0 if lower_is_better else 1.0
    task, method = group[0]["task"], group[0]["method"]
    for index, budget in enumerate(group[0]["budgets"]):
        old = np.array([d["values"][index] for d in studies], dtype=float)
        new = np.array([r["values"][index] for r in group], dtype=float)
        better = int(np.sum(sign * (new - old) > 0))
        cpu = np.median([r["optimizer_cpu_seconds"][index] / r["episodes"][index] for r in group])
        last = np.array([r["last_batch_cpu_seconds_per_episode"][index] for r in group], dtype=float)
        cells = [median_range(old), median_range(new), f"{better} of {len(group)}", f"{cpu:.3g}"]
        cells.append(f"{np.median(last):.3g} ({last.max():.3g})")
        rows.append(f"| {task} | {method} | {budget} | " + " | ".join(cells) + " |")
    return rows


def summary(runs: list[dict[str, Any]], runs_dir: Path = RUNS) -> tuple[str, int, int]:
    """The Markdown table per task and budget, and (runs whose shared budgets agree bit for bit with the
    study's, runs the study has)."""
    lines = [
        "| task | column | budget | study (256 most recent): median (min–max over seeds) | new default: "
        "median (min–max) | seeds where the new default is better | new default: the optimiser's CPU s "
        "per asked episode so far (median) | new default: its last batch's CPU s per episode (median, "
        "largest) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    agree = compared = 0
    for task, method in sorted({(r["task"], r["method"]) for r in runs}):
        group = sorted(
            (r for r in runs if (r["task"], r["method"]) == (task, method)), key=lambda r: r["seed"]
        )
        studies = [study_document(task, method, r["seed"], r["samples"], runs_dir) for r in group]
        pairs = [(r, d) for r, d in zip(group, studies, strict=True) if d is not None]
        for run, study in pairs:
            shared = [i for i, b in enumerate(run["budgets"]) if b in SHARED_BUDGETS]
            agree += all(run["values"][i] == study["values"][i] for i in shared)
        compared += len(pairs)
        if pairs:
            lower_is_better = task_by_name(task).lower_is_better
            lines += _rows([r for r, _ in pairs], [d for _, d in pairs], lower_is_better)
    return "\n".join(lines), agree, compared


def worse_later(method: str = "c-bo", runs: Path = RUNS) -> tuple[list[str], int]:
    """The tasks on which the study's committed runs of ``method`` have a worse median at 500 episodes than
    at 300, and the number of tasks with runs of it."""
    values: dict[str, list[list[float]]] = {}
    for path in sorted(runs.glob(f"*-{method}-s*-b500-n*.json")):
        document = json.loads(path.read_text())
        if document["spec"]["method"] == method:
            values.setdefault(document["task"], []).append(document["values"])
    worse = []
    for task, rows in sorted(values.items()):
        medians = np.median(np.array(rows, dtype=float), axis=0)
        at = dict(zip(BUDGETS, medians, strict=True))
        sign = -1.0 if task_by_name(task).lower_is_better else 1.0
        if sign * (at[500] - at[300]) < 0:
            worse.append(task)
    return worse, len(values)


def render(path: Path) -> str:
    """Write the table of the results at ``path`` (JSON) to the same name with ``.md``; returns it."""
    document = json.loads(path.read_text())
    command = replay_command("refit_data", document)
    table, agree, compared = summary(document["runs"])
    worse, tasks = worse_later()
    text = (
        f"{table}\n\nThe metric is the study's: the mean regret on a function, the kick precision's mean "
        "error in m and the reacher's cost (lower is better), the kick flexibility's mean distance in m "
        "(higher is better). "
        "\"Better\" compares each seed's run with the study's committed run of the same seed. The values at "
        f"{', '.join(map(str, SHARED_BUDGETS))} episodes, where both have fitted on the same episodes, agree "
        f"bit for bit in {agree} of {compared} runs.\n\n"
        f"The study's committed `c-bo` runs (the former default) have a worse median at 500 episodes than at "
        f"300 on {len(worse)} of the {tasks} tasks: {', '.join(worse)}.\n\n"
        f"Command: `OPENBLAS_NUM_THREADS=1 {command}`.\n"
    )
    path.with_suffix(".md").write_text(text)
    return text


def main(argv: list[str] | None = None) -> None:
    robots = [task.name for task in ROBOT_TASKS]  # the default tasks
    column_replay_main(__doc__.splitlines()[0], robots, _job, render, argv)


if __name__ == "__main__":
    main()
