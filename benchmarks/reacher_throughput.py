"""Planar reacher throughput: one batched evaluation of 100 rollouts against a loop of 100 single rollouts.

Both paths call the same ``PlanarReacherEnv.evaluate`` (the batched one with ``n = 100``, the loop with
``n = 1``), on the same seeded contexts and parameters, in the same run; the script checks that they give
identical returns and prints rollouts per second and the speed-up ratio. A third line times the Gymnasium
API path (``reset`` + ``step`` per episode) for reference.

Usage::

    python benchmarks/reacher_throughput.py [--batch 100] [--repeats 20]
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable

import gymnasium as gym
import numpy as np

import creps_gym  # noqa: F401  (registers the ids)
from creps_gym.envs.reacher import PlanarReacherEnv


def best_time(run: Callable[[], object], repeats: int) -> float:
    """Fastest of ``repeats`` wall-clock timings of ``run()`` (s), after one warm-up call."""
    run()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        run()
        times.append(time.perf_counter() - start)
    return min(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--batch", type=int, default=100, help="rollouts per batch (default 100)")
    parser.add_argument("--repeats", type=int, default=20, help="timings per path; the best is kept")
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    env = PlanarReacherEnv()
    contexts = rng.uniform(0.0, 2.0, size=(args.batch, 2))
    params = rng.normal(scale=2.0, size=(args.batch, 25))

    batched = env.evaluate(contexts, params)[0]
    looped = np.array([env.evaluate(contexts[i : i + 1], params[i : i + 1])[0][0] for i in range(args.batch)])
    if not np.array_equal(batched, looped):
        raise RuntimeError("batched and looped returns differ: the benchmark would compare different work")

    gym_env = gym.make("creps_gym/PlanarReacher-v0")

    def gym_loop() -> None:
        for i in range(args.batch):
            gym_env.reset(options={"context": contexts[i]})
            gym_env.step(params[i])

    t_batch = best_time(lambda: env.evaluate(contexts, params), args.repeats)
    t_loop = best_time(
        lambda: [env.evaluate(contexts[i : i + 1], params[i : i + 1]) for i in range(args.batch)],
        max(3, args.repeats // 4),
    )
    t_gym = best_time(gym_loop, max(3, args.repeats // 4))
    print(
        f"batch of {args.batch} (one evaluate call): {args.batch / t_batch:12.0f} rollouts/s "
        f"({t_batch * 1e3:.2f} ms per batch)"
    )
    print(f"loop of {args.batch} single evaluate calls: {args.batch / t_loop:12.0f} rollouts/s")
    print(f"loop of {args.batch} gymnasium reset+step:   {args.batch / t_gym:12.0f} rollouts/s")
    print(f"speed-up batch / single loop: {t_loop / t_batch:.1f}x")
    print(f"speed-up batch / gymnasium loop: {t_gym / t_batch:.1f}x")


if __name__ == "__main__":
    main()
