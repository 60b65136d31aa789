"""Can the robot reach a ball at all? CMA-ES on a shaped objective at one flexibility ball position.

The flexibility return is flat (0) for every kick that misses the ball, so near the reference kick a far ball
gives a search no signal. This probe asks the physical question instead: pycma minimises the smallest
foot-to-ball distance during the swing (``info["min_foot_ball_distance"]``, m), plus 1 for a fall, minus
0.1 × the forward distance once the ball is hit, from the env-declared start N(0, I) of
:class:`~creps_gym.wrappers.OffsetParams`. It prints one JSON line per 10 generations and a final one.

    python benchmarks/kick/reach_probe.py --index 23 --episodes 1200   # ball at (0.30, -0.05) m
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np

if __package__ in (None, ""):  # run as a script: make ``benchmarks`` importable
    sys.path[0] = str(Path(__file__).resolve().parents[2])

from benchmarks.kick.study import evaluate, grid_contexts, make_env
from creps_gym.optimizers.registry import make_optimizer


def shaped_loss(info: dict[str, np.ndarray]) -> np.ndarray:
    """Per episode (n,): foot-ball distance (m) + 1 for a fall − 0.1 × forward distance without a fall."""
    fell = info["fell"]
    forward = np.where(fell, 0.0, info["ball_displacement"][:, 0])
    return info["min_foot_ball_distance"] + fell - 0.1 * forward


def probe(index: int, episodes: int, seed: int, population: int) -> dict[str, float]:
    """Run the probe at ball position ``grid_contexts()[index]``; return its final summary."""
    env = make_env("flexibility", threads=1)
    context = grid_contexts()[index]
    opt = make_optimizer("cma", 25, 2, seed)  # N(0, I) in OffsetParams units: the env-declared start
    contexts = np.tile(context, (population, 1))
    closest, farthest = np.inf, 0.0
    while opt.evaluations + population <= episodes:
        offsets = opt.ask(contexts)
        _, info = evaluate(env, contexts, offsets)
        opt.tell(contexts, offsets, -shaped_loss(info))
        standing = ~info["fell"]
        if standing.any():
            closest = min(closest, float(info["min_foot_ball_distance"][standing].min()))
            farthest = max(farthest, float(info["ball_displacement"][standing, 0].max()))
        if opt.iteration % 10 == 0:
            line = {"episodes": opt.evaluations, "fall_rate": float(info["fell"].mean())}
            print(json.dumps({**line, "closest_standing_m": closest, "farthest_standing_m": farthest}))
    return {"context": context.tolist(), "episodes": opt.evaluations, "closest_standing_m": closest,
            "farthest_standing_m": farthest}  # fmt: skip


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--index", type=int, default=23, help="ball position: index into the 4 x 7 grid")
    parser.add_argument("--episodes", type=int, default=1200)
    parser.add_argument("--population", type=int, default=16)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    if not 0 <= args.index < len(grid_contexts()):
        parser.error(f"--index: expected 0 <= index < {len(grid_contexts())}, got {args.index}")
    print(json.dumps(probe(args.index, args.episodes, args.seed, args.population)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
