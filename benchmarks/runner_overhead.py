"""The runner's own cost: the runner with its default backend against a plain ask/tell loop, in one run.

Both run CREPS-CMA (``creps-cma-old``) on the contextual Sphere with the same seed, the same batch size and
the same evaluation schedule (the mean policy on 16 test contexts after every iteration). The plain loop is
what a user would write by hand over the native vector env: one batched context draw, ``ask``, one
``reset(options={"context": ...})`` and one ``step`` of the vector env, ``tell``, and
:func:`~creps_gym.envs.evaluation.evaluate_policy`. The runner adds its backend, its records and its stop
checks (no run directory). Runner and loop alternate in short blocks and the script reports the median
block time per iteration and the ratio, which keeps the ratio fair on a machine whose load changes.

The second table is the cost of one checkpoint (runner state + optimiser state, written atomically) after
100, 1,000 and 10,000 iterations of a run with a run directory: it must not grow with the run.

Usage::

    python benchmarks/runner_overhead.py            # p = 15, N = 50, z = 1 and 3; checkpoints at 1e2..1e4
    python benchmarks/runner_overhead.py --quick    # z = 1 only, few blocks, checkpoints at 10 and 100

Targets (issue 14): runner / loop <= 1.3 at p = 15, N = 50 (z = 1 and z = 3); the checkpoint cost is flat
from 100 to 10,000 iterations.
"""

from __future__ import annotations

import argparse
import tempfile
import time
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np

from creps_gym.envs.evaluation import contextual_model, evaluate_policy, test_contexts
from creps_gym.optimizers import make_optimizer
from creps_gym.runner import RunConfig, Runner, split_seed

ENV = "creps_gym/Sphere-v0"
OPTIMIZER = "creps-cma-old"
CONFIGS = [(15, 50, 1), (15, 50, 3)]


class PlainLoop:
    """A hand-written ask/tell loop over the native vector env, seeded like the runner."""

    def __init__(self, p: int, samples: int, z: int, seed: int, eval_contexts: int = 16) -> None:
        kwargs = {"dim": p, "context_dim": z}
        self.vec = gym.make_vec(ENV, samples, vectorization_mode="vector_entry_point", **kwargs)
        self.model = contextual_model(self.vec)
        self.rng, optimizer_seed, eval_seed = split_seed(seed)
        mean, std = self.model.initial_distribution()
        self.optimizer = make_optimizer(
            OPTIMIZER, p, z, optimizer_seed, initial_mean=mean, initial_cov=std**2
        )
        self.test = test_contexts(self.model, eval_contexts, eval_seed)
        self.samples = samples

    def iterate(self, iterations: int) -> None:
        """``iterations`` iterations, each evaluated on the test contexts."""
        for _ in range(iterations):
            contexts = self.model.sample_contexts(self.rng, self.samples)
            params = self.optimizer.ask(contexts)
            self.vec.reset(options={"context": contexts})
            _, returns, _, _, _ = self.vec.step(params)
            self.optimizer.tell(contexts, params, returns)
            evaluate_policy(self.model, self.optimizer.recommend, self.test)


class RunnerLoop:
    """The runner with its default backend, stepped one iteration at a time."""

    def __init__(self, p: int, samples: int, z: int, seed: int) -> None:
        config = RunConfig(ENV, OPTIMIZER, 10**9, samples, seed, env_kwargs={"dim": p, "context_dim": z})
        self.runner = Runner(config)
        self.backend = self.runner.make_backend()

    def iterate(self, iterations: int) -> None:
        """``iterations`` iterations of :meth:`Runner.step` (records kept, as in a run)."""
        for _ in range(iterations):
            record, _ = self.runner.step(self.backend)
            self.runner.history.append(record)


def block(loop: PlainLoop | RunnerLoop, iterations: int) -> float:
    start = time.perf_counter()
    loop.iterate(iterations)
    return (time.perf_counter() - start) / iterations


def overhead(p: int, samples: int, z: int, blocks: int, iterations: int) -> tuple[float, float]:
    """Median seconds per iteration of the runner and of the plain loop (alternating blocks)."""
    loops = {"runner": RunnerLoop(p, samples, z, 0), "plain": PlainLoop(p, samples, z, 0)}
    times: dict[str, list[float]] = {name: [] for name in loops}
    for _ in range(blocks):
        for name, loop in loops.items():
            times[name].append(block(loop, iterations))
    loops["runner"].backend.close()
    return float(np.median(times["runner"])), float(np.median(times["plain"]))


def checkpoint_cost(lengths: list[int], repeats: int) -> dict[int, float]:
    """Median seconds of one checkpoint after each number of iterations (one run grown step by step)."""
    with tempfile.TemporaryDirectory() as folder:
        config = RunConfig(ENV, OPTIMIZER, 10**9, 50, 0, env_kwargs={"dim": 15}, checkpoint_every=10**9)
        runner = Runner(config, run_dir=Path(folder) / "run")
        backend = runner.make_backend()
        costs = {}
        try:
            for length in lengths:
                while runner.iteration < length:
                    record, _ = runner.step(backend)
                    runner.history.append(record)
                    runner.log_record(record)
                times = []
                for _ in range(repeats):
                    start = time.perf_counter()
                    runner.checkpoint()
                    times.append(time.perf_counter() - start)
                costs[length] = float(np.median(times))
        finally:
            backend.close()
            runner.run_dir.lock.release()
    return costs


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="z = 1 only, few blocks, short checkpoint runs")
    parser.add_argument("--blocks", type=int, default=15, help="alternating timing blocks per configuration")
    args = parser.parse_args()
    warnings.simplefilter("ignore")
    configs = CONFIGS[:1] if args.quick else CONFIGS
    blocks, iterations = (3, 5) if args.quick else (args.blocks, 40)
    print(f"{'p':>3} {'N':>3} {'z':>2} {'runner ms':>10} {'loop ms':>8} {'ratio':>6}")
    for p, samples, z in configs:
        runner, plain = overhead(p, samples, z, blocks, iterations)
        print(f"{p:>3} {samples:>3} {z:>2} {runner * 1e3:>10.3f} {plain * 1e3:>8.3f} {runner / plain:>6.2f}")
    lengths = [10, 100] if args.quick else [100, 1000, 10000]
    costs = checkpoint_cost(lengths, repeats=3 if args.quick else 15)
    print(f"{'iterations':>10} {'checkpoint ms':>14} {'/ first':>8}")
    first = costs[lengths[0]]
    for length, seconds in costs.items():
        print(f"{length:>10} {seconds * 1e3:>14.3f} {seconds / first:>8.2f}")


if __name__ == "__main__":
    main()
