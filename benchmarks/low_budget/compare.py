"""A quick low-budget comparison (issue 44): regret of the recommended policy after a fixed episode budget.

Every method starts from the same distribution (mean 0, σ = 2, the issue's setting) on a contextual function
(``creps_gym/<Function>-v0`` with ``dim=p``, ``context_dim=z``) and runs whole batches of its recommended
size until the next batch would pass the budget. The result of a run is the mean regret of ``recommend`` on
100 test contexts (seed 12345) and the optimiser's own seconds per episode (ask, tell and the final
recommend; the env's time excluded). Writes one JSON document with provenance and prints medians over seeds.

    OPENBLAS_NUM_THREADS=1 python -m benchmarks.low_budget.compare --out results.json

This is the quick measurement of issue 44's first item, not the study of its item 5 (``run.py`` in this
folder).
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
from benchmarks.low_budget import add_output_arguments, replay_command
from benchmarks.provenance import provenance
from creps_gym.envs.evaluation import test_contexts
from creps_gym.optimizers import make_optimizer, recommended_samples

TEST_SEED, TEST_CONTEXTS = 12_345, 100


def parse_method(method: str) -> tuple[str, dict[str, Any]]:
    """``name`` or ``name:option=value,option=value`` (values read as JSON, else kept as strings)."""
    name, _, rest = method.partition(":")
    options = {}
    for item in filter(None, rest.split(",")):
        key, _, text = item.partition("=")
        try:
            options[key] = json.loads(text)
        except json.JSONDecodeError:
            options[key] = text
    return name, options


def one_run(method: str, function: str, p: int, z: int, budget: int, seed: int) -> dict[str, Any]:
    """Run ``method`` (see :func:`parse_method`) on one function for ``budget`` episodes; its regret and
    timing."""
    env = gym.make(f"creps_gym/{function}-v0", dim=p, context_dim=z).unwrapped
    name, options = parse_method(method)
    optimizer = make_optimizer(name, p, z, seed, initial_mean=0.0, initial_cov=4.0, **options)
    batch = recommended_samples(name, p, z)
    rng = np.random.default_rng(seed + 1000)
    spent, episodes = 0.0, 0
    while episodes + batch <= budget:
        contexts = env.sample_contexts(rng, batch)
        start = time.perf_counter()
        params = optimizer.ask(contexts)
        spent += time.perf_counter() - start
        returns = env.evaluate(contexts, params)[0]
        start = time.perf_counter()
        optimizer.tell(contexts, params, returns)
        spent += time.perf_counter() - start
        episodes += batch
    test = test_contexts(env, TEST_CONTEXTS, TEST_SEED)
    start = time.perf_counter()
    recommended = optimizer.recommend(test)
    spent += time.perf_counter() - start
    regret = float(np.mean(env.regret(test, recommended)))
    return {
        "method": method,
        "function": function,
        "p": p,
        "z": z,
        "budget": budget,
        "seed": seed,
        "episodes": episodes,
        "batch": batch,
        "regret": regret,
        "seconds_per_episode": spent / max(episodes, 1),
    }


def summary(runs: list[dict[str, Any]]) -> str:
    """A Markdown table: median regret (min–max over seeds) and median seconds per episode."""
    lines = [
        "| function | method | episodes | regret: median (min–max over seeds) | s per episode |",
        "|---|---|---|---|---|",
    ]
    keys = sorted({(r["function"], r["method"]) for r in runs})
    for function, method in keys:
        group = [r for r in runs if (r["function"], r["method"]) == (function, method)]
        regrets = np.array([r["regret"] for r in group])
        seconds = float(np.median([r["seconds_per_episode"] for r in group]))
        lines.append(
            f"| {function} | `{method}` | {group[0]['episodes']} | {np.median(regrets):.3g} "
            f"({regrets.min():.3g}–{regrets.max():.3g}) | {seconds:.3g} |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--functions", nargs="+", default=["Sphere", "Rosenbrock"])
    parser.add_argument("--methods", nargs="+", default=["c-bo", "creps-cma-old", "c-cma-es"])
    parser.add_argument("--p", type=int, default=4)
    parser.add_argument("--z", type=int, default=1)
    parser.add_argument("--budget", type=int, default=200)
    parser.add_argument("--seeds", type=int, default=3)
    add_output_arguments(parser)
    args = parser.parse_args(argv)
    if args.render_only:
        render(args.out)
        return
    runs = []
    for function in args.functions:
        for method in args.methods:
            for seed in range(args.seeds):
                runs.append(one_run(method, function, args.p, args.z, args.budget, seed))
                print(json.dumps(runs[-1]), flush=True)
    document = {"command": sys.argv, "runs": runs, "provenance": provenance()}
    args.out.write_text(json.dumps(document, indent=1) + "\n")
    print(render(args.out))


def render(path: Path) -> str:
    """Write the table of the results at ``path`` (JSON) to the same name with ``.md``; returns it."""
    document = json.loads(path.read_text())
    command = replay_command("compare", document)
    text = f"{summary(document['runs'])}\n\nCommand: `OPENBLAS_NUM_THREADS=1 {command}`.\n"
    path.with_suffix(".md").write_text(text)
    return text


if __name__ == "__main__":
    main()
