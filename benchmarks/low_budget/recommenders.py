"""What c-bo should recommend on the robot tasks: Eqs. (R1), (R2) and (R3) on the same runs (issue 44).

``recommend`` draws nothing from the optimiser's Generator and changes none of its state, so one run
measures every rule of ``recommend_over`` (``creps_gym/optimizers/cbo_recommend.py``): ``trust_region``
(R1, the default: the posterior mean's maximiser within the box of the good neighbours' θ), ``observed``
(R2: the told θ with the largest posterior mean at s) and ``neighbours`` (R3: the same among the episodes
with the nearest contexts; documents written before it existed hold the first two). Each run is the
low-budget study's run of the same task, column and seed (the same start, batches, training and test
contexts), so its ``trust_region`` values are that study run's values bit for bit (the script checks it
where the study's document is in ``runs/``). After each budget, each rule's recommended policy is evaluated
on the task's test contexts: the study's metric and, on the kicks, how many of the test kicks fall. Writes
one JSON document with provenance and a Markdown table next to it (``--render-only`` redraws the table).

    OPENBLAS_NUM_THREADS=1 python -m benchmarks.low_budget.recommenders \\
        --out benchmarks/low_budget/results/recommenders.json

``--unpinned`` runs each column with c-bo's own defaults instead of the study's refit pin
(:func:`~benchmarks.low_budget.columns.unpinned`): the same runs until the first refit past the pin's 256
episodes, so their values must agree with the study's only up to there.

    OPENBLAS_NUM_THREADS=1 python -m benchmarks.low_budget.recommenders --unpinned --workers 2 \\
        --out benchmarks/low_budget/results/recommenders_defaults.json
"""

from __future__ import annotations

import sys
from pathlib import Path

if not __package__:  # run by path: the repository root first on sys.path, as `python -m` puts it
    sys.path[0] = str(Path(__file__).resolve().parents[2])

import dataclasses
import json
from typing import Any

import numpy as np

from benchmarks.low_budget import column_replay_main, replay_command, replay_results_path
from benchmarks.low_budget.columns import PINNED_FIT_POINTS, Method, method_by_name, unpinned
from benchmarks.low_budget.report import cells, median_at, median_range, ratio_text, values_by_seed
from benchmarks.low_budget.study import (
    LowBudgetSpec,
    Run,
    policy_evaluation,
    run_until,
    start_run,
    task_by_name,
)

RULES = ("trust_region", "observed", "neighbours")
#: The budget of issue 44's function target (c-bo ≤ 0.5 × the best other method's regret).
TARGET_BUDGET = 200
RUNS = Path(__file__).resolve().parent / "runs"


def recommend_with(optimizer: Any, rule: str, contexts: np.ndarray) -> np.ndarray:
    """``optimizer.recommend(contexts)`` with ``recommend_over=rule``; the optimiser is left as it was."""
    config = optimizer.config
    optimizer.config = dataclasses.replace(config, recommend_over=rule)
    try:
        return optimizer.recommend(contexts)
    finally:
        optimizer.config = config


def variant_column(method_name: str, unpinned_column: bool, options: dict[str, Any]) -> Method | None:
    """The c-bo column ``method_name``, unpinned and with ``options`` added where asked; None: the study's
    column as it is."""
    method = method_by_name(method_name)
    if method.optimizer != "c-bo":
        raise ValueError(f"method: expected a c-bo column, got {method_name!r} ({method.optimizer})")
    if not (unpinned_column or options):
        return None
    method = unpinned(method) if unpinned_column else method
    added = {name: tuple(v) if isinstance(v, list) else v for name, v in options.items()}
    kept = tuple((name, value) for name, value in method.options if name not in added)
    return dataclasses.replace(method, options=kept + tuple(sorted(added.items())))


def start_variant(
    task_name: str, method_name: str, seed: int, budget: int, unpinned_column: bool, options: dict[str, Any]
) -> Run:
    """The study's run of the c-bo column ``method_name`` before its first batch, as
    :func:`variant_column` varies it (the study's column as it is without ``unpinned_column`` or
    ``options``)."""
    spec = LowBudgetSpec(task_name, method_name, seed, budget)
    return start_run(spec, variant_column(method_name, unpinned_column, options))


def variant_fields(unpinned_column: bool, options: dict[str, Any]) -> dict[str, Any]:
    """What a replay's document records of the variant: ``unpinned`` and ``options``, each where set."""
    return ({"unpinned": True} if unpinned_column else {}) | ({"options": options} if options else {})


def one_run(
    task_name: str,
    method_name: str,
    seed: int,
    budget: int,
    unpinned_column: bool = False,
    options: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """The study's run of ``method_name`` (a c-bo column without a selector) on ``task_name``, or with
    ``unpinned_column`` the same run with c-bo's own defaults instead of the study's refit pin
    (:func:`~benchmarks.low_budget.columns.unpinned`), and with ``options`` (c-bo options the column adds,
    e.g. ``{"symmetric_contexts": [1]}``); at each of its budgets, each rule's metric and falls (None off
    the kicks) on the test contexts."""
    options = dict(options or {})
    run = start_variant(task_name, method_name, seed, budget, unpinned_column, options)
    values: dict[str, list[float]] = {rule: [] for rule in RULES}
    falls: dict[str, list[int | None]] = {rule: [] for rule in RULES}
    for target in run.spec.budgets:
        run_until(run, target)
        for rule in RULES:
            params = recommend_with(run.optimizer, rule, run.test)
            value, info = policy_evaluation(run.task, run.model, run.test, params)  # the metric and the falls
            values[rule].append(value)
            falls[rule].append(int(np.sum(info["fell"])) if "fell" in info else None)
    document = {"task": task_name, "method": method_name, "seed": seed, "budgets": list(run.spec.budgets)}
    document |= variant_fields(unpinned_column, options)
    return {**document, "key": run.spec.key, "values": values, "falls": falls, "test_contexts": len(run.test)}


def committed_run(key: str, runs: Path = RUNS) -> dict[str, Any] | None:
    """The study's committed document of the task, column, seed and batch of the run key ``key`` (a
    :attr:`~benchmarks.low_budget.study.LowBudgetSpec.key`; the largest budget's), or None."""
    prefix, samples = key.rsplit("-b", 1)[0], key.rsplit("-n", 1)[1]
    documents = sorted(runs.glob(f"{prefix}-b*-n{samples}.json"))
    return json.loads(documents[-1].read_text()) if documents else None


def check_against_study(run: dict[str, Any], runs: Path = RUNS) -> bool | None:
    """Whether the run's ``trust_region`` values equal the study's committed run of the same task, column,
    seed and batch bit for bit at every budget both record (an unpinned run: at those where both have
    fitted on the same episodes, up to the pin's ``fit_points``) (None: the study has no document of it,
    or the run added options to the column)."""
    study = committed_run(run["key"], runs)
    if study is None or run.get("options"):
        return None
    recorded = dict(zip(study["budgets"], study["values"], strict=True))
    own = dict(zip(run["budgets"], run["values"]["trust_region"], strict=True))
    shared = PINNED_FIT_POINTS if run.get("unpinned") else max(own)
    common = sorted(b for b in set(recorded) & set(own) if b <= shared)
    return bool(common) and all(recorded[b] == own[b] for b in common)


def _rules(runs: list[dict[str, Any]]) -> list[str]:
    """The rules the runs measured, in :data:`RULES`' order (a document written before ``neighbours``
    existed has the first two)."""
    return [rule for rule in RULES if not runs or rule in runs[0]["values"]]


def _header(rules: list[str]) -> list[str]:
    """The table's header: each rule's median, the seeds where each other rule beats ``trust_region``, the
    falls of each rule."""
    cells = [f"{rules[0]}: median (min–max over seeds)"] + [f"{rule}: median (min–max)" for rule in rules[1:]]
    cells += [f"seeds where {rule} is better" for rule in rules[1:]]
    cells.append(f"falls ({' / '.join(rules)}, summed over seeds)")
    return ["| task | column | budget | " + " | ".join(cells) + " |", "|---" * (len(cells) + 3) + "|"]


def _wins(values: np.ndarray, others: np.ndarray, larger_is_better: bool) -> str:
    """On how many of the n seeds ``values`` (n,) beat ``others`` (n,), seed by seed, as "k of n"."""
    sign = 1.0 if larger_is_better else -1.0
    return f"{int(np.sum(sign * (values - others) > 0))} of {values.shape[0]}"


def _row(group: list[dict[str, Any]], index: int, larger_is_better: bool, rules: list[str]) -> list[str]:
    """The cells of one budget's row: each rule's median (min–max over seeds), the seeds where each other
    rule is better than ``trust_region``, and the falls of each rule summed over seeds."""
    cells, values = [], {}
    for rule in rules:
        values[rule] = column = np.array([r["values"][rule][index] for r in group])
        cells.append(median_range(column))
    for rule in rules[1:]:
        cells.append(_wins(values[rule], values["trust_region"], larger_is_better))
    fell = [[r["falls"][rule][index] for r in group] for rule in rules]
    tests = len(group) * group[0]["test_contexts"]
    cells.append("—" if None in fell[0] else " / ".join(str(sum(f)) for f in fell) + f" of {tests}")
    return cells


def summary(runs: list[dict[str, Any]]) -> str:
    """A Markdown table per task and budget: each rule's median metric (min–max over seeds), the seeds on
    which each other rule is better than ``trust_region``, and the test kicks that fall (summed over
    seeds)."""
    rules = _rules(runs)
    lines = _header(rules)
    for task, method in sorted({(r["task"], r["method"]) for r in runs}):
        group = [r for r in runs if (r["task"], r["method"]) == (task, method)]
        group.sort(key=lambda r: r["seed"])
        larger_is_better = not task_by_name(task).lower_is_better
        for index, budget in enumerate(group[0]["budgets"]):
            cells = _row(group, index, larger_is_better, rules)
            lines.append(f"| {task} | {method} | {budget} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _agreement(runs: list[dict[str, Any]]) -> str:
    """The sentence on how many runs agree with the study's (:func:`check_against_study`); for runs of
    ``--unpinned``, what they are and at which budgets they must agree; for runs of ``--options``, which;
    for seeds the study does not have, that."""
    added = sorted({json.dumps(run["options"], sort_keys=True) for run in runs if run.get("options")})
    unpinned = any(run.get("unpinned") for run in runs)
    if added:
        pinned = "c-bo's defaults (`--unpinned`)" if unpinned else "the study's c-bo columns"
        return (
            f"The runs are {pinned} with the options {', '.join(f'`{a}`' for a in added)} added "
            "(`--options`): not the study's runs, so none is compared with them."
        )
    checked = [check_against_study(run) for run in runs]
    compared = sum(c is not None for c in checked)
    agree = f"{sum(c is True for c in checked)} of {compared}"
    points = PINNED_FIT_POINTS
    what = (
        "The runs are c-bo's defaults (`--unpinned`), not the study's c-bo columns: a refit sees every "
        f"episode where the study's saw the {points} most recent (`CBO_FIT_PIN`, "
        "`benchmarks/study_options.py`). "
    )
    if not compared:
        seeds = sorted({run["seed"] for run in runs})
        return f"{what if unpinned else ''}The study has no run of these seeds ({seeds[0]}–{seeds[-1]})."
    if not unpinned:
        return (
            f"The `trust_region` values equal the study's committed runs bit for bit in {agree} runs that "
            "the study has."
        )
    return (
        f"{what}Their `trust_region` values equal the study's committed runs bit for bit at the budgets up "
        f"to {points} episodes, where both have fitted on the same episodes, in {agree} runs that the study "
        "has."
    )


def versus(runs: list[dict[str, Any]], baseline: list[dict[str, Any]]) -> str:
    """A Markdown table per task, column, budget and rule: the median of ``runs`` and of ``baseline`` (another
    replay's runs) over the seeds both have, at the budgets both record, and on how many of those seeds
    ``runs`` is the better."""
    lines = [
        "| task | column | budget | rule | these runs: median | against: median | seeds where these are "
        "better |",
        "|---|---|---|---|---|---|---|",
    ]
    by_key = {(r["task"], r["method"], r["seed"]): r for r in baseline}
    for task, method in sorted({(r["task"], r["method"]) for r in runs}):
        mine = [r for r in runs if (r["task"], r["method"]) == (task, method)]
        pairs = [(r, by_key[k]) for r in mine if (k := (task, method, r["seed"])) in by_key]
        if not pairs:
            continue
        larger_is_better = not task_by_name(task).lower_is_better
        rules = [rule for rule in _rules([r for r, _ in pairs]) if rule in pairs[0][1]["values"]]
        for budget in pairs[0][0]["budgets"]:
            if not all(budget in r["budgets"] and budget in b["budgets"] for r, b in pairs):
                continue
            for rule in rules:
                own, other = (
                    np.array([d["values"][rule][d["budgets"].index(budget)] for d in side])
                    for side in zip(*pairs, strict=True)
                )
                cells = [
                    f"{np.median(own):.3g}",
                    f"{np.median(other):.3g}",
                    _wins(own, other, larger_is_better),
                ]
                lines.append(f"| {task} | {method} | {budget} | {rule} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _against(document: dict[str, Any]) -> str:
    """The paragraph comparing the runs with the replay the document names (``--against``), or ""."""
    if not document.get("against"):
        return ""
    baseline = json.loads(replay_results_path(document["against"]).read_text())["runs"]
    return (
        f"Seed by seed against `{document['against']}` (the same tasks and columns; the seeds and budgets "
        f"both have):\n\n{versus(document['runs'], baseline)}\n\n"
    )


def _study_cells(task: str, runs: Path) -> dict[str, list[dict[str, Any]]]:
    """The study's committed documents of ``task``, by column."""
    documents = [json.loads(path.read_text()) for path in sorted(runs.glob(f"{task}-*-s*-b*-n*.json"))]
    grouped = cells([d for d in documents if d["spec"]["task"] == task])
    return {method: docs for (_, method), docs in grouped.items()}


def _target_row(task: str, group: list[dict[str, Any]], budget: int, study: Path) -> tuple[str, list[bool]]:
    """One task's row of :func:`targets`, and whether the runs and the study's ``c-bo`` meet ≤ 0.5."""
    lower = task_by_name(task).lower_is_better
    columns = _study_cells(task, study)
    medians = {m: v for m, docs in columns.items() if (v := median_at(docs, budget)) is not None}
    rivals = {m: v for m, v in medians.items() if not m.startswith("c-bo")}
    best = (min if lower else max)(rivals, key=rivals.get) if rivals else None
    own = {r["seed"]: r["values"]["trust_region"][r["budgets"].index(budget)] for r in group}
    study_cbo = values_by_seed(columns.get("c-bo"), budget)
    seeds = sorted(set(own) & set(study_cbo))
    mine, theirs = (np.array([side[s] for s in seeds], dtype=float) for side in (own, study_cbo))
    ours = float(np.median(list(own.values())))
    ratios = [ratio_text(value, rivals.get(best), lower) for value in (ours, medians.get("c-bo"))]
    other = f"{rivals[best]:.3g} (`{best}`)" if best else "—"
    cbo = f"{medians['c-bo']:.3g}" if "c-bo" in medians else "—"
    cells_ = [f"{ours:.3g}", cbo, other, *ratios, _wins(mine, theirs, not lower)]
    row = f"| {task} | " + " | ".join(cells_) + " |"
    return row, [text != "—" and float(text) <= 0.5 for text in ratios]


def targets(runs: list[dict[str, Any]], budget: int = TARGET_BUDGET, study: Path = RUNS) -> str:
    """Issue 44's function target at ``budget``: per function task of ``runs``, their median (the default
    rule), the study's ``c-bo`` column's and its best column that is not c-bo's, each ratio to it (the
    target: ≤ 0.5), and on how many seeds the runs beat the study's ``c-bo`` run of the same seed; "" when
    no run is on a function or has the budget."""
    lines = [
        "| task | these runs | the study's `c-bo` | best other (method) | these ÷ best other "
        "| `c-bo` ÷ best other | seeds where these beat `c-bo` |",
        "|---|---|---|---|---|---|---|",
    ]
    met = np.zeros(2, dtype=int)
    for task in sorted({r["task"] for r in runs if not r["task"].startswith(("Kick", "Planar"))}):
        group = [r for r in runs if r["task"] == task and budget in r["budgets"]]
        if group:
            row, meets = _target_row(task, group, budget, study)
            lines.append(row)
            met += meets
    if len(lines) == 2:
        return ""
    return (
        f"At {budget} episodes against the study's committed columns (medians over seeds; the study's `c-bo` "
        "has the former log scale, and it has seen the same episodes as the unpinned column up to 256):\n\n"
        + "\n".join(lines)
        + f"\n\nThe target's ≤ 0.5 holds on {met[0]} of {len(lines) - 2} tasks for these runs and on "
        f"{met[1]} for the study's `c-bo`.\n\n"
    )


def render(path: Path) -> str:
    """Write the table of the results at ``path`` (JSON) to the same name with ``.md``; returns it."""
    document = json.loads(path.read_text())
    command = replay_command("recommenders", document)
    text = (
        f"{summary(document['runs'])}\n\nThe metric is the study's: the mean regret on a function and the "
        "kick precision's mean error in m (lower is better), the kick flexibility's mean distance in m "
        f"(higher is better). {_agreement(document['runs'])}\n\n{_against(document)}"
        f"{targets(document['runs']) if any(run.get('options') for run in document['runs']) else ''}"
        f"Command: `OPENBLAS_NUM_THREADS=1 {command}`.\n"
    )
    path.with_suffix(".md").write_text(text)
    return text


def _job(args: tuple[str, str, int, int, bool, dict[str, Any]]) -> dict[str, Any]:
    return one_run(*args)


def main(argv: list[str] | None = None) -> None:
    tasks = ["KickFlexibilityLowDim-v1", "KickPrecisionLowDim-v1"]  # the default tasks
    column_replay_main(__doc__.splitlines()[0], tasks, _job, render, argv, variant_flags=True)


if __name__ == "__main__":
    main()
