"""Active context choice against uniform draws for c-bo at a low budget (issue 44, item 2).

c-bo runs on a contextual function (``creps_gym/<Function>-v0`` with ``dim=p``, ``context_dim=z``), or
on ``Steep<Function>`` (the context study's function whose regret grows 100-fold across the box,
``benchmarks/contexts/tasks.py``), from the issue's start (mean 0, σ = 2), in batches of its recommended
size (4), with the training contexts of every batch chosen by the ``uniform`` or the ``active`` selector
(the latter given c-bo's ``context_utility``). After each budget the run records the mean regret of
``recommend`` on 100 uniform test contexts (seed 12345; the same for both selectors), and the seconds
the selector spent. Writes one JSON document with provenance and a Markdown table next to it
(``--render-only`` redraws the table).

    OPENBLAS_NUM_THREADS=1 python -m benchmarks.low_budget.active_contexts \\
        --out benchmarks/low_budget/results/active_contexts.json
    OPENBLAS_NUM_THREADS=1 python -m benchmarks.low_budget.active_contexts \\
        --tasks SteepSphere:2:1 SteepRosenbrock:2:1 --out benchmarks/low_budget/results/active_steep.json
"""

from __future__ import annotations

import sys
from pathlib import Path

if not __package__:  # run by path: the repository root first on sys.path, as `python -m` puts it
    sys.path[0] = str(Path(__file__).resolve().parents[2])

import argparse
import json
import time
from typing import Any

import gymnasium as gym
import numpy as np

import creps_gym  # noqa: F401  (registers the ids)
from benchmarks.low_budget import parse_runs_arguments, replay_command, run_and_write
from creps_gym.envs.evaluation import test_contexts
from creps_gym.optimizers import make_optimizer, recommended_samples
from creps_gym.selectors import make_selector

TEST_SEED, TEST_CONTEXTS = 12_345, 100
SELECTORS = ("uniform", "active")


def make_task(function: str, p: int, z: int) -> Any:
    """The env of ``creps_gym/<function>-v0``, or for ``Steep<function>`` the context study's
    :class:`~benchmarks.contexts.tasks.SteepFunction` (regret scaled by 100^u(s): the box's upper end of
    the first context coordinate is 100 times steeper)."""
    if function.startswith("Steep"):
        from benchmarks.contexts.tasks import SteepFunction

        return SteepFunction(function[len("Steep") :], dim=p, context_dim=z, steepness=100.0)
    return gym.make(f"creps_gym/{function}-v0", dim=p, context_dim=z).unwrapped


def one_run(
    function: str, p: int, z: int, selector_name: str, budgets: list[int], seed: int
) -> dict[str, Any]:
    """c-bo with ``selector_name``'s contexts on one function; its regret after each of ``budgets``."""
    env = make_task(function, p, z)
    optimizer = make_optimizer("c-bo", p, z, seed, initial_mean=0.0, initial_cov=4.0)
    selector = make_selector(selector_name)
    selector.bind(env.observation_space.low.astype(float), env.observation_space.high.astype(float), None)
    utility = {"context_utility": optimizer.context_utility} if selector_name == "active" else {}
    batch, rng = recommended_samples("c-bo", p, z), np.random.default_rng(seed + 1000)
    test = test_contexts(env, TEST_CONTEXTS, TEST_SEED)
    regrets, selector_seconds, episodes = {}, 0.0, 0
    for budget in sorted(budgets):
        while episodes + batch <= budget:
            start = time.perf_counter()
            contexts = selector.select(rng, batch, **utility)
            selector_seconds += time.perf_counter() - start
            params = optimizer.ask(contexts)
            optimizer.tell(contexts, params, env.evaluate(contexts, params)[0])
            episodes += batch
        regrets[str(budget)] = float(np.mean(env.regret(test, optimizer.recommend(test))))
    return {
        "function": function,
        "p": p,
        "z": z,
        "selector": selector_name,
        "seed": seed,
        "regret": regrets,
        "selector_seconds_per_episode": selector_seconds / max(episodes, 1),
    }


def summary(runs: list[dict[str, Any]]) -> str:
    """A Markdown table: per task and budget, the median regret (min–max over seeds) of each selector and
    the ratio of the medians (active / uniform), and the seeds on which active ended lower."""
    budgets = sorted({int(b) for r in runs for b in r["regret"]})
    lines = [
        "| function | p | z | budget | uniform: median (min–max over seeds) | active: median (min–max) "
        "| active / uniform (medians) | seeds where active is lower |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for function, p, z in sorted({(r["function"], r["p"], r["z"]) for r in runs}):
        task = [r for r in runs if (r["function"], r["p"], r["z"]) == (function, p, z)]
        for budget in budgets:
            cells, medians, by_seed = [], {}, {}
            for name in SELECTORS:
                group = sorted((r for r in task if r["selector"] == name), key=lambda r: r["seed"])
                values = np.array([r["regret"][str(budget)] for r in group])
                medians[name], by_seed[name] = (
                    float(np.median(values)),
                    dict(zip([r["seed"] for r in group], values, strict=True)),
                )
                cells.append(f"{medians[name]:.3g} ({values.min():.3g}–{values.max():.3g})")
            common = sorted(set(by_seed["uniform"]) & set(by_seed["active"]))
            lower = sum(by_seed["active"][s] < by_seed["uniform"][s] for s in common)
            ratio = medians["active"] / medians["uniform"]
            counts = f"{lower} of {len(common)}"
            lines.append(
                f"| {function} | {p} | {z} | {budget} | {cells[0]} | {cells[1]} | {ratio:.2f} | {counts} |"
            )
    seconds = np.median([r["selector_seconds_per_episode"] for r in runs if r["selector"] == "active"])
    lines.append("")
    lines.append(
        f"The active selector's own time: median {seconds:.3g} s per episode (over every active run)."
    )
    return "\n".join(lines)


def render(path: Path) -> str:
    """Write the table of the results at ``path`` (JSON) to the same name with ``.md``; returns it."""
    document = json.loads(path.read_text())
    command = replay_command("active_contexts", document)
    text = f"{summary(document['runs'])}\n\nCommand: `OPENBLAS_NUM_THREADS=1 {command}`.\n"
    path.with_suffix(".md").write_text(text)
    return text


def _job(args: tuple[str, int, int, str, list[int], int]) -> dict[str, Any]:
    return one_run(*args)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--tasks", nargs="+", default=["Sphere:2:2", "Rosenbrock:2:2", "Rosenbrock:4:1"], help="FUNCTION:P:Z"
    )
    parser.add_argument("--budgets", nargs="+", type=int, default=[100, 200])
    args = parse_runs_arguments(parser, argv, 5, render)
    if args is None:
        return
    jobs = []
    for task in args.tasks:
        function, p, z = task.split(":")
        for seed in range(args.seeds):
            for name in SELECTORS:
                jobs.append((function, int(p), int(z), name, args.budgets, seed))
    run_and_write(_job, jobs, args.workers, args.out, render)


if __name__ == "__main__":
    main()
