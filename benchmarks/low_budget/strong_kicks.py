"""The two kicks behind the low-dimensional kicks' v1 metaparameters ``power`` and ``reach``.

The v0 ids' six metaparameters cannot kick farther than 9.68 m or reach a ball at x_B = 0.30 m
(``results/reach.md``), while the full kick can. This script finds one kick for each in the full ids,
as the kick study's oracle does (``benchmarks/kick/oracle.py``): pycma from the env-declared start N(0, I)
of :class:`~creps_gym.wrappers.OffsetParams` at one context, restarted with twice the population whenever a
start stops (IPOP), ``--episodes`` in all, the best final mean over the starts kept:

- ``power``: the precision task (``creps_gym/KickPrecision-v1``) at the 12 m target;
- ``reach``: the flexibility task (``creps_gym/KickFlexibility-v2``) with the ball at x_B = 0.30 m, y_B = 0.

It writes their θ (normalised units, as ``reference_params()``), their metric and whether they stand, with
provenance, to ``--out``; :mod:`creps_gym.envs.kick.subspace` holds the same θ rounded to 6 decimals
(a test compares them).

    OPENBLAS_NUM_THREADS=1 python -m benchmarks.low_budget.strong_kicks \\
        --out benchmarks/low_budget/results/strong_kicks.json
"""

from __future__ import annotations

import sys
from pathlib import Path

if not __package__:  # run by path: the repository root first on sys.path, as `python -m` puts it
    sys.path[0] = str(Path(__file__).resolve().parents[2])

import argparse
import json
from typing import Any

import numpy as np

from benchmarks.kick.study import episode_metric, evaluate, make_env
from benchmarks.provenance import provenance
from creps_gym.envs.base import initial_distribution
from creps_gym.optimizers.registry import make_optimizer, recommended_samples

#: name -> (the kick study's experiment, the context it is found at).
KICKS = {"power": ("precision", (12.0,)), "reach": ("flexibility", (0.30, 0.0))}


def strong_kick(experiment: str, context: Any, episodes: int, seed: int) -> dict[str, Any]:
    """pycma's best final mean over IPOP starts at ``context`` (see the module docstring)."""
    env = make_env(experiment, 1)
    p, z = env.action_space.shape[0], env.unwrapped.context_dim
    mean, std = initial_distribution(env)
    context = np.asarray(context, dtype=np.float64)
    population, used, best = recommended_samples("cma", p, 0), 0, None
    sign = 1.0 if experiment == "precision" else -1.0  # lower is better: the error, minus the distance
    while used + population <= episodes:
        opt = make_optimizer("cma", p, z, seed + used, initial_mean=mean, initial_cov=std**2)
        contexts, stop = np.tile(context, (population, 1)), {}
        while opt.evaluations + population <= episodes - used and not stop:
            offsets = opt.ask(contexts)
            opt.tell(contexts, offsets, evaluate(env, contexts, offsets)[0])
            stop = opt.stop()
        used += opt.evaluations
        offsets = opt.recommend(context[None])
        info = evaluate(env, context[None], offsets)[1]
        metric = float(episode_metric(experiment, context[None], info)[0])
        if best is None or sign * metric < sign * best["metric"]:
            theta = env.to_env(offsets)[0]
            best = {"metric": metric, "fell": bool(info["fell"][0]), "theta": theta.tolist()}
        population *= 2
    env.close()
    return {"experiment": experiment, "context": context.tolist(), "episodes": used, "seed": seed, **best}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=3000, help="episodes per kick (all starts)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, required=True, help="the results' JSON")
    args = parser.parse_args(argv)
    kicks = {}
    for name, (experiment, context) in KICKS.items():
        kicks[name] = strong_kick(experiment, context, args.episodes, args.seed)
        print(name, json.dumps({k: v for k, v in kicks[name].items() if k != "theta"}), flush=True)
    document = {"command": sys.argv, "kicks": kicks, "provenance": provenance(["cma", "mujoco"])}
    args.out.write_text(json.dumps(document, indent=1) + "\n", encoding="utf-8")


if __name__ == "__main__":
    main()
