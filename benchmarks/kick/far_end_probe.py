"""Why does a precision run miss a target? Sample its final policy there, then search on from its mean alone.

For one finished precision run (``--run c-cma-es-trial1``, a checkpoint under ``--folder``) and one target
s (``--target``, default 12 m, the far end of the precision task's targets [3, 12] m):

1. whether the run's mean kick Aᵀϕ(s) falls, and its error (m, s + 1 for a fall); then ``--samples`` draws
   from the run's final π(θ|s): their fall rate and the quantiles of the standing kicks' distance (m);
2. pycma at that target alone, started at the run's mean policy Aᵀϕ(s) with the run's own search scale
   s_π = σ·√(mean diag C), minimising the distance to the target (a fall scores s + 1 m). Every 5
   generations it prints the fall rate of the generation, the error of pycma's mean kick and how far that
   mean has moved from the run's mean policy, in radii s_π·√p (a draw of the run's policy lies about one
   radius from its mean).

If pycma reaches the target from the end of the run's line, a standing kick for it lies close by, and the
contextual learner, not the robot, stops short. Each line of output is a JSON object.

    python benchmarks/kick/far_end_probe.py --run c-cma-es-trial1 --target 12
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

from benchmarks.kick.study import evaluate, load_run, make_env
from creps_gym.optimizers.registry import make_optimizer, recommended_samples

FOLDER = Path(__file__).resolve().parent / "results" / "full" / "runs" / "precision"


def target_errors(target: float, info: dict[str, np.ndarray]) -> np.ndarray:
    """Per episode (n,): distance (m) from the ball's rest point to the target, ``target + 1`` for a fall."""
    x, y = info["ball_displacement"].T
    return np.where(info["fell"], target + 1.0, np.hypot(x - target, y))


def probe(run: Path, target: float, samples: int, generations: int, seed: int) -> list[dict[str, float]]:
    """The report lines: the final policy's samples at ``target``, then pycma's progress from its mean."""
    env = make_env("precision", threads=1)
    learner = load_run(run)
    context = np.array([[target]])
    start = learner.recommend(context)[0]
    scale = float(np.sqrt(np.mean(np.diag(learner.cov))))  # σ·√(mean diag C)
    draws = np.repeat(context, samples, axis=0)
    _, info = evaluate(env, draws, learner.ask(draws))
    standing = info["ball_displacement"][~info["fell"], 0]
    quantiles = np.quantile(standing, [0.1, 0.5, 0.9, 1.0]).round(2).tolist() if standing.size else []
    fall_rate = float(info["fell"].mean())
    _, at_start = evaluate(env, context, start[None])
    lines = [{"run": run.name, "target_m": target, "mean_kick_fell": bool(at_start["fell"][0]),
              "mean_kick_error_m": float(target_errors(target, at_start)[0]), "search_scale": scale,
              "fall_rate": fall_rate, "standing_distance_q10_q50_q90_max_m": quantiles}]  # fmt: skip
    search = make_optimizer("cma", start.size, 1, seed, initial_mean=start, initial_cov=scale**2)
    population = recommended_samples("cma", start.size, 1)  # pycma's default
    batch = np.repeat(context, population, axis=0)
    radius = scale * np.sqrt(start.size)  # a draw of the run's policy lies about this far from its mean
    for generation in range(1, generations + 1):
        offsets = search.ask(batch)
        _, info = evaluate(env, batch, offsets)
        search.tell(batch, offsets, -target_errors(target, info))
        if generation % 5 == 0:
            mean = search.recommend(context)
            _, at_mean = evaluate(env, context, mean)
            lines.append({"episodes": search.evaluations, "fall_rate": float(info["fell"].mean()),
                          "mean_error_m": float(target_errors(target, at_mean)[0]),
                          "moved_in_radii": float(np.linalg.norm(mean[0] - start) / radius)})  # fmt: skip
    return lines


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--run", required=True, help="a finished run's stem, e.g. c-cma-es-trial1")
    parser.add_argument("--folder", type=Path, default=FOLDER)
    parser.add_argument("--target", type=float, default=12.0, help="the target distance s (m)")
    parser.add_argument("--samples", type=int, default=200)
    parser.add_argument("--generations", type=int, default=40)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    run = args.folder / args.run
    if not run.with_suffix(".npz").exists():
        parser.error(f"--run: expected a checkpoint {run.with_suffix('.npz')}, got none")
    for line in probe(run, args.target, args.samples, args.generations, args.seed):
        print(json.dumps(line), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
