"""Why max-value entropy search ties with UCB on the kicks: both choices from the same model (issue 44).

The issue asks that the information-based acquisition beat UCB on the robot tasks, "or the measured reason it
does not". The study counts the seeds where `c-bo` (MES) beats `c-bo-ucb`; this script looks at the choices
themselves. It replays the study's `c-bo` run of a task and seed (the same start, batches and contexts) and,
before each batch once the initial design is told, draws one probe context s from its own stream and
computes each acquisition's proposal at s from the same state: the same GP, the optimiser's Generator set to
the same state before each proposal and restored after both, so the run goes on exactly as the study's (its
values at the budgets equal the study's committed run bit for bit; the rendering says in how many runs).

Per ask it records the distance between the two proposals in θ's unit box (the root mean square over the p
coordinates, so 1 is the box's width) and each proposal's posterior mean and standard deviation (the GP's
units). The table gives, per task and window of episodes, the median distance, the share of asks where the
proposals are within 0.05 of each other, and the median ratio of MES's posterior standard deviation to
UCB's (below 1: MES asks where the model is surer than where UCB asks, it exploits more). Writes one JSON
document with provenance and a Markdown table next to it (``--render-only`` redraws the table).

    OPENBLAS_NUM_THREADS=1 python -m benchmarks.low_budget.acquisition_choices \\
        --out benchmarks/low_budget/results/acquisition_choices.json
"""

from __future__ import annotations

import sys
from pathlib import Path

if not __package__:  # run by path: the repository root first on sys.path, as `python -m` puts it
    sys.path[0] = str(Path(__file__).resolve().parents[2])

import argparse
import dataclasses
import json
from typing import Any

import numpy as np

from benchmarks.low_budget import parse_runs_arguments, replay_command, run_and_write
from benchmarks.low_budget.recommenders import check_against_study
from benchmarks.low_budget.study import ROBOT_TASKS, LowBudgetSpec, Run, policy_metric, run_until, start_run

ACQUISITIONS = ("mes", "ucb")
#: The probe contexts' stream (apart from the study's training and test contexts).
PROBE_SEED = 20_151_001
WINDOWS = ((0, 100), (100, 200), (200, 300), (300, 500))
NEAR = 0.05


def proposals(optimizer: Any, context: np.ndarray) -> dict[str, np.ndarray]:
    """Each acquisition's proposal (p,) in θ's unit box at one scaled context, from the same state; the
    optimiser's configuration and Generator are left as they were."""
    config, state = optimizer.config, optimizer.rng.bit_generator.state
    chosen = {}
    try:
        for acquisition in ACQUISITIONS:
            optimizer.rng.bit_generator.state = state
            optimizer.config = dataclasses.replace(config, acquisition=acquisition)
            chosen[acquisition] = optimizer._propose(optimizer.model, context)
    finally:
        optimizer.config, optimizer.rng.bit_generator.state = config, state
    return chosen


def _ask_record(optimizer: Any, context: np.ndarray, episodes: int) -> list[float]:
    """[episodes, distance, mean (MES), mean (UCB), sd (MES), sd (UCB)] of one probe context (z,)."""
    scaled = optimizer._scaled_contexts(context[None, :])[0]
    chosen = proposals(optimizer, scaled)
    units = np.array([chosen[a] for a in ACQUISITIONS])
    mean, variance = optimizer.model.predict(np.hstack([np.tile(scaled, (2, 1)), units]))
    distance = float(np.sqrt(np.mean((units[0] - units[1]) ** 2)))
    return [episodes, distance, *map(float, mean), *map(float, np.sqrt(variance))]


def one_run(task_name: str, seed: int, budget: int) -> dict[str, Any]:
    """The study's `c-bo` run on ``task_name`` with both acquisitions' proposals at a probe context before
    each batch after the initial design, and the study's metric at each budget."""
    run = start_run(LowBudgetSpec(task_name, "c-bo", seed, budget))  # the study's run
    probes = np.random.default_rng([PROBE_SEED, seed])
    asks, values = [], []

    def probe(run: Run) -> None:
        optimizer = run.optimizer
        if optimizer.model is not None and optimizer.returns.shape[0] >= optimizer.config.n_initial:
            context = run.model.sample_contexts(probes, 1)[0]
            asks.append(_ask_record(optimizer, context, run.state["episodes"]))

    for target in run.spec.budgets:
        run_until(run, target, probe)
        values.append(policy_metric(run.task, run.model, run.test, run.optimizer.recommend(run.test)))
    document = {"task": task_name, "seed": seed, "key": run.spec.key, "budgets": list(run.spec.budgets)}
    return {**document, "values": {"trust_region": values}, "asks": asks}


def _window_cells(asks: np.ndarray) -> list[str]:
    """Asks (m, 6) of one window: their count, the median distance, the share within :data:`NEAR` and the
    median ratio of MES's posterior sd to UCB's."""
    if not asks.shape[0]:
        return ["0", "—", "—", "—"]
    ratio = asks[:, 4] / np.maximum(asks[:, 5], np.finfo(float).tiny)
    share = float(np.mean(asks[:, 1] < NEAR))
    return [str(asks.shape[0]), f"{np.median(asks[:, 1]):.3g}", f"{share:.2f}", f"{np.median(ratio):.3g}"]


def summary(runs: list[dict[str, Any]]) -> str:
    """The Markdown table: per task and window of episodes, over every seed's asks."""
    lines = [
        "| task | episodes | asks (all seeds) | median distance of the proposals (θ's unit box) "
        f"| share within {NEAR} | median sd(MES) / sd(UCB) |",
        "|---|---|---|---|---|---|",
    ]
    for task in sorted({r["task"] for r in runs}):
        asks = np.array([ask for r in runs if r["task"] == task for ask in r["asks"]], dtype=np.float64)
        last = max(r["budgets"][-1] for r in runs if r["task"] == task)
        for low, high in WINDOWS:
            if low < last:
                window = asks[(asks[:, 0] >= low) & (asks[:, 0] < high)]
                lines.append(f"| {task} | {low}–{high} | " + " | ".join(_window_cells(window)) + " |")
    return "\n".join(lines)


def render(path: Path) -> str:
    """Write the table of the results at ``path`` (JSON) to the same name with ``.md``; returns it."""
    document = json.loads(path.read_text())
    command = replay_command("acquisition_choices", document)
    checked = [check_against_study(run) for run in document["runs"]]
    seeds = sorted({run["seed"] for run in document["runs"]})
    agree = f"{sum(c is True for c in checked)} of {sum(c is not None for c in checked)}"
    text = (
        f"{summary(document['runs'])}\n\nSeeds {seeds[0]}–{seeds[-1]} of the study's `c-bo` column "
        "(max-value entropy search), one probe context per batch after the initial design. The replayed "
        f"runs' values equal the study's committed runs bit for bit in {agree} runs that the study has.\n\n"
        f"Command: `OPENBLAS_NUM_THREADS=1 {command}`.\n"
    )
    path.with_suffix(".md").write_text(text)
    return text


def _job(args: tuple[str, int, int]) -> dict[str, Any]:
    return one_run(*args)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    robots = [task.name for task in ROBOT_TASKS]
    parser.add_argument("--tasks", nargs="+", default=robots, help="study task names (default: the robots)")
    parser.add_argument("--budget", type=int, default=300)
    args = parse_runs_arguments(parser, argv, 10, render)
    if args is None:
        return
    jobs = [(task, seed, args.budget) for task in args.tasks for seed in range(args.seeds)]
    run_and_write(_job, jobs, args.workers, args.out, render)


if __name__ == "__main__":
    main()
