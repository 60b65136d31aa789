r"""IPOP's population growth (C13) against today's restarts on the multimodal Rastrigin (issue 45, item 3).

The runner asks a fixed batch, so C13 (``restart_population_factor`` F > 1: N₀·F^r samples after r
restarts) cannot run through it (docs/algorithms.md, C13); this script drives ``c-cma-es`` by ask/tell as the
contextual BBO protocol does, asking ``wanted_batch_size(50)`` before each batch. The setting is the function
study's Rastrigin cell: p = 15, z ∈ {1, 3}, 50 samples per batch, a 200,000-episode budget (told to the
optimiser, so C12 gates its restarts), the env's own initial distribution and uniform contexts; the metric
is the mean policy's regret averaged over 16 test contexts, with the paper's target 1e−5. A run ends when the
optimiser stops (its restarts used up, or declined by C12) or the budget is spent.

    python benchmarks/functions/ipop.py             # 5 seeds x 2 context dims x 2 variants, ~10 CPU min
    python benchmarks/functions/ipop.py --render-only

Results: ``results/ipop.json`` (every run, with provenance) and ``results/ipop.md`` (rendered from it).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

if not __package__:  # run by path: the repository root first on sys.path (see benchmarks/__init__.py)
    sys.path[0] = str(Path(__file__).resolve().parents[2])

import gymnasium as gym
import numpy as np

from benchmarks.provenance import provenance, provenance_text
from benchmarks.study_tools import write_text
from creps_gym.envs.base import initial_distribution
from creps_gym.envs.evaluation import contextual_model
from creps_gym.optimizers import make_optimizer

__all__ = ["VARIANTS", "main", "one_run", "render"]

HERE = Path(__file__).resolve().parent
OUT = HERE / "results"
DIM, SAMPLES, BUDGET, TARGET, TEST_CONTEXTS = 15, 50, 200_000, 1e-5, 16
#: (label, options): today's restarts (F = 1) and IPOP's doubling population (F = 2).
VARIANTS = (("restarts, F = 1", {}), ("IPOP, F = 2", {"restart_population_factor": 2.0}))


def one_run(z: int, seed: int, options: dict[str, Any], budget: int = BUDGET) -> dict[str, Any]:
    """One run on the contextual Rastrigin (p = 15, context dimension ``z``, instance ``seed``)."""
    model = contextual_model(gym.make("creps_gym/Rastrigin-v0", dim=DIM, context_dim=z, instance=seed))
    low, high = model.observation_space.low, model.observation_space.high
    rng = np.random.default_rng([seed, z])
    test = rng.uniform(low, high, (TEST_CONTEXTS, z))
    mean, std = initial_distribution(model)
    optimizer = make_optimizer(
        "c-cma-es", DIM, z, seed, initial_mean=mean, initial_cov=std**2, budget=budget, **options
    )
    start, episodes, hit, batches, stop = time.process_time(), 0, None, [], "budget"
    regret = math.inf
    while episodes < budget:
        n = min(optimizer.wanted_batch_size(SAMPLES), budget - episodes)
        contexts = rng.uniform(low, high, (n, z))
        params = optimizer.ask(contexts)
        optimizer.tell(contexts, params, -model.objective(contexts, params))
        episodes += n
        batches.append(n)
        regret = float(model.regret(test, optimizer.recommend(test)).mean())
        if hit is None and regret <= TARGET:
            hit = episodes
        met = optimizer.stop()
        if met:
            stop = "optimizer: " + ", ".join(sorted(met))
            break
    return {
        "z": z,
        "seed": seed,
        "options": options,
        "hit": hit,
        "final": regret,
        "episodes": episodes,
        "restarts": int(optimizer.restarts_done),
        "largest_batch": max(batches),
        "stop_reason": stop,
        "cpu_seconds": round(time.process_time() - start, 2),
    }


def _median(values: list[float]) -> float:
    return float(np.median(values))


def render(document: dict[str, Any]) -> str:
    """The table of ``document`` (the JSON ``main`` writes)."""
    lines = [
        "# IPOP's population growth against today's restarts: contextual Rastrigin, p = 15",
        "",
        "Rendered by `benchmarks/functions/ipop.py --render-only` from `results/ipop.json`. Per context "
        f"dimension z and variant, over {document['seeds']} seeds: the mean policy's final regret (mean "
        f"over {TEST_CONTEXTS} test contexts; median, min and max over the seeds), runs that reached 1e−5, "
        "restarts made, the largest batch asked and the episodes used of the 200,000.",
        "",
        "| z | variant | median final regret | min | max | hit 1e−5 | restarts (median) | largest batch | "
        "episodes (median) |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for z in document["context_dims"]:
        for label, options in VARIANTS:
            runs = [r for r in document["runs"] if r["z"] == z and r["options"] == options]
            finals = [r["final"] for r in runs]
            lines.append(
                f"| {z} | {label} | {_median(finals):.3g} | {min(finals):.3g} | {max(finals):.3g} "
                f"| {sum(r['hit'] is not None for r in runs)}/{len(runs)} "
                f"| {_median([r['restarts'] for r in runs]):g} | {max(r['largest_batch'] for r in runs)} "
                f"| {_median([r['episodes'] for r in runs]):,.0f} |"
            )
    lines += ["", provenance_text([document["provenance"]] * len(document["runs"])), ""]
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    """Compute (or only render) the comparison."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--render-only", action="store_true", help="render results/ipop.json only")
    parser.add_argument("--seeds", type=int, default=5, help="seeds per cell (default 5)")
    parser.add_argument("--out", type=Path, default=OUT, help=f"folder (default {OUT})")
    args = parser.parse_args(argv)
    path = args.out / "ipop.json"
    if not args.render_only:
        runs = []
        for z in (1, 3):
            for seed in range(args.seeds):
                for label, options in VARIANTS:
                    runs.append(one_run(z, seed, options))
                    print(f"z={z} seed={seed} {label}: final {runs[-1]['final']:.3g}", flush=True)
        document = {"seeds": args.seeds, "context_dims": [1, 3], "runs": runs, "provenance": provenance()}
        args.out.mkdir(parents=True, exist_ok=True)
        write_text(path, json.dumps(document, indent=1, allow_nan=False) + "\n")
    document = json.loads(path.read_text(encoding="utf-8"))
    write_text(args.out / "ipop.md", render(document))
    print(f"wrote {args.out / 'ipop.md'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
