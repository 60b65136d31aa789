"""The two kicks behind the low-dimensional kicks' v1 metaparameters ``power`` and ``reach``.

The v0 ids' six metaparameters cannot kick farther than 9.68 m or reach a ball at x_B = 0.30 m
(``results/reach.md``), while the full kick can. This script finds one kick for each in the full ids,
as the kick study's oracle does (``benchmarks/kick/oracle.py``): pycma from the env-declared start N(0, I)
of :class:`~creps_gym.wrappers.OffsetParams` at one context, restarted with twice the population whenever a
start stops (IPOP, :func:`benchmarks.kick.oracle.ipop_starts`), ``--episodes`` in all, the best final mean
over the starts kept:

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

from benchmarks.kick.oracle import SIGN, ipop_starts
from benchmarks.kick.study import evaluate, make_env
from benchmarks.provenance import provenance

#: name -> (the kick study's experiment, the context it is found at).
KICKS = {"power": ("precision", (12.0,)), "reach": ("flexibility", (0.30, 0.0))}


def strong_kick(experiment: str, context: Any, episodes: int, seed: int) -> dict[str, Any]:
    """pycma's best final mean over IPOP starts at ``context`` (start k's seed: ``seed`` plus the episodes
    spent before it; see the module docstring)."""
    env = make_env(experiment, 1)
    context = np.asarray(context, dtype=np.float64)
    starts = ipop_starts(env, experiment, context, episodes, lambda start, used: seed + used)
    record, offsets = max(starts, key=lambda start: SIGN[experiment] * start[0]["value"])  # the first best
    info = evaluate(env, context[None], offsets)[1]  # the episode that gave the record's value, again
    theta = env.to_env(offsets)[0]
    env.close()
    return {
        "experiment": experiment,
        "context": context.tolist(),
        "episodes": sum(start[0]["episodes"] for start in starts),
        "seed": seed,
        "metric": record["value"],
        "fell": bool(info["fell"][0]),
        "theta": theta.tolist(),
    }


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
