"""Why c-bo misses issue 44's function target on Rastrigin: where its recommendations land (issue 44).

Rastrigin, ``f(x) = 10 p + Σ [x_i² − 10 cos(2π x_i)]`` with ``x = θ + A s``, is a bowl with a ripple of
period 1 in every coordinate: a local minimum near every point of the integer lattice, the global one at
x = 0. The study starts every method at σ = 2, so c-bo's parameter box is 12 wide, twelve ripples per
coordinate. This script replays the study's `c-bo` runs on Rastrigin (the same start, batches, training and
test contexts; with ``--unpinned --options`` the column with c-bo's current defaults, compared bit for bit
with a replay of it, ``--against``) and, at each budget, splits where the recommended θ lands at the test
contexts into:

* the **basin** share: the test contexts whose deviation x = θ − θ*(s) has every |x_i| < 1/2 (the
  recommendation is in the global minimum's basin; outside it, it sits at least near another local minimum);
* the **lattice** regret: Σ round(x_i)², the regret of the bottom of the basin the recommendation is in;
* the ripple term per coordinate, the mean of 10 (1 − cos 2π x_i): 0 at a basin's bottom, 20 at its
  rim, and 10 on average where x_i's phase within the ripple is uniformly random;
* the regret itself (the study's metric; the script checks that the formula above gives it);

and records the GP's fitted hyperparameters: the lengthscales of θ's coordinates in ripple periods (the
box's width over 1) and the noise share σ_n² / (σ_f² + σ_n²) of the model's variance. A lengthscale of
several periods makes the ripples too fast for the model: it sees the bowl and treats the ripples as noise.
Writes one JSON document with provenance and a Markdown table next to it (``--render-only`` redraws it).

    OPENBLAS_NUM_THREADS=1 python -m benchmarks.low_budget.rastrigin_ripples --unpinned \\
        --options '{"log_quantile": 0.25}' --budget 200 --workers 2 \\
        --against benchmarks/low_budget/results/recommenders_log_quantile.json \\
        --out benchmarks/low_budget/results/rastrigin_ripples.json
"""

from __future__ import annotations

import sys
from pathlib import Path

if not __package__:  # run by path: the repository root first on sys.path, as `python -m` puts it
    sys.path[0] = str(Path(__file__).resolve().parents[2])

import json
import math
from typing import Any

import numpy as np

from benchmarks.low_budget import column_replay_main, replay_command, replay_results_path
from benchmarks.low_budget.recommenders import start_variant, variant_fields
from benchmarks.low_budget.study import policy_metric, run_until

__all__ = ["landing", "main", "one_run", "render", "summary"]

TASKS = tuple(f"Rastrigin-p{p}-z{z}" for p in (2, 4, 8) for z in (1, 2))
#: Rastrigin's ripple period in x (and so in θ).
PERIOD = 1.0


def landing(deviation: np.ndarray) -> dict[str, float]:
    """Where recommendations with deviations ``deviation`` (n, p) from the optimum land: the mean regret
    (Rastrigin's formula), the share in the optimum's basin, the mean regret of their basins' bottoms and
    the mean ripple term per coordinate."""
    ripple = 10.0 * (1.0 - np.cos(2.0 * np.pi * deviation))
    nearest = np.round(deviation / PERIOD) * PERIOD
    return {
        "regret": float(np.mean(np.sum(deviation**2 + ripple, axis=1))),
        "basin_share": float(np.mean(np.all(np.abs(deviation) < PERIOD / 2, axis=1))),
        "lattice_regret": float(np.mean(np.sum(nearest**2, axis=1))),
        "ripple_per_coordinate": float(np.mean(ripple)),
    }


def _model_record(optimizer: Any) -> dict[str, Any]:
    """The fitted GP's θ lengthscales in ripple periods and its noise share."""
    z = optimizer.n_context_dims
    low, high = optimizer.config.param_box
    periods = np.exp(optimizer.log_hyper[z:-2]) * (high - low) / PERIOD
    signal, noise = math.exp(optimizer.log_hyper[-2]), math.exp(optimizer.log_hyper[-1])
    return {"lengthscale_periods": periods.tolist(), "noise_share": noise / (signal + noise)}


def one_run(
    task_name: str,
    method_name: str,
    seed: int,
    budget: int,
    unpinned_column: bool = False,
    options: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """The study's run of ``method_name`` (a c-bo column) on the Rastrigin task ``task_name`` (or its
    variant, as :func:`benchmarks.low_budget.recommenders.one_run`), with its recommendation's landing and
    the fitted model at each budget."""
    if not task_name.startswith("Rastrigin-"):
        raise ValueError(f"task_name: expected a Rastrigin task of the study, got {task_name!r}")
    options = dict(options or {})
    run = start_variant(task_name, method_name, seed, budget, unpinned_column, options)
    records = []
    for target in run.spec.budgets:
        run_until(run, target)
        params = run.optimizer.recommend(run.test)
        value = policy_metric(run.task, run.model, run.test, params)
        record = landing(params - run.model.optimal_params(run.test))
        if not math.isclose(record["regret"], value, rel_tol=1e-9, abs_tol=1e-9):
            message = f"Rastrigin's regret {record['regret']} is not the study's {value}"
            raise RuntimeError(f"{run.spec.key}: {message}")
        records.append({"episodes": target, "value": value, **record, **_model_record(run.optimizer)})
    document = {"task": task_name, "method": method_name, "seed": seed, "key": run.spec.key}
    document |= variant_fields(unpinned_column, options)
    return {**document, "budgets": list(run.spec.budgets), "records": records}


def _median(values: list[float], digits: int = 3) -> str:
    return f"{np.median(values):.{digits}g}"


def _row(task: str, budget: int, at: list[dict[str, Any]]) -> str:
    """One row of :func:`summary`: the seeds' records ``at`` one budget."""
    scales = [np.sort(r["lengthscale_periods"]) for r in at]
    cells = [_median([r[name] for r in at]) for name in ("regret", "lattice_regret", "ripple_per_coordinate")]
    cells.append(_median([r["basin_share"] for r in at], 2))
    cells.append(f"{_median([s[0] for s in scales], 2)}, {_median([np.median(s) for s in scales], 2)}")
    cells.append(_median([r["noise_share"] for r in at], 2))
    return f"| {task} | {budget} | " + " | ".join(cells) + " |"


def summary(runs: list[dict[str, Any]]) -> str:
    """The Markdown table: per task and budget, medians over seeds."""
    lines = [
        "| task | episodes | regret | lattice regret (the basin's bottom) | ripple term per coordinate "
        "| share in the optimum's basin | θ lengthscales (ripple periods: smallest, median) | noise share |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for task in sorted({r["task"] for r in runs}, key=TASKS.index):
        records = [r["records"] for r in runs if r["task"] == task]
        for i, budget in enumerate(runs[0]["budgets"]):
            lines.append(
                _row(task, budget, [seed_records[i] for seed_records in records if len(seed_records) > i])
            )
    return "\n".join(lines)


def _agreement(document: dict[str, Any]) -> str:
    """How many runs equal the ``against`` replay's runs (their ``trust_region`` values) bit for bit."""
    if "against" not in document:
        return "No replay to compare with was given."
    against = json.loads(replay_results_path(document["against"]).read_text())
    theirs = {(r["task"], r["method"], r["seed"]): r for r in against["runs"]}
    same = total = 0
    for run in document["runs"]:
        other = theirs.get((run["task"], run["method"], run["seed"]))
        if other is not None:
            recorded = dict(zip(other["budgets"], other["values"]["trust_region"], strict=True))
            total += 1
            same += all(recorded.get(r["episodes"]) == r["value"] for r in run["records"])
    return f"The runs' values equal those of `{document['against']}` bit for bit in {same} of {total} runs."


def render(path: Path) -> str:
    """Write the table of the results at ``path`` (JSON) to the same name with ``.md``; returns it."""
    document = json.loads(path.read_text())
    command = replay_command("rastrigin_ripples", document)
    seeds = sorted({run["seed"] for run in document["runs"]})
    text = (
        f"{summary(document['runs'])}\n\nMedians over seeds {seeds[0]}–{seeds[-1]} of the `c-bo` column's "
        f"recommendation at the task's 100 test contexts. {_agreement(document)}\n\n"
        f"Command: `OPENBLAS_NUM_THREADS=1 {command}`.\n"
    )
    path.with_suffix(".md").write_text(text)
    return text


def _job(args: tuple[Any, ...]) -> dict[str, Any]:
    return one_run(*args)


def main(argv: list[str] | None = None) -> None:
    column_replay_main(__doc__.splitlines()[0], TASKS, _job, render, argv, variant_flags=True)


if __name__ == "__main__":
    main()
