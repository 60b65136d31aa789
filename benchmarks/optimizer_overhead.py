"""Time per iteration of ask + tell: CREPS-CMA against pycma, in one run.

Both optimisers work on the same cheap contextual sphere (one vectorised numpy expression), so the figure is
the optimiser's own overhead. Each configuration alternates the two optimisers in short blocks and reports
the median block time, which keeps the ratio fair on a machine whose load changes.

Usage::

    python benchmarks/optimizer_overhead.py            # all configurations
    python benchmarks/optimizer_overhead.py --quick    # n = 15 only

Targets (issue 2): at n = 15, N = 50 the ratio CREPS-CMA / pycma is <= 1.0; at n = 256, N = 200 CREPS-CMA
stays under 50 ms per iteration.
"""

from __future__ import annotations

import argparse
import time
import warnings

import numpy as np

from creps_gym.optimizers import CREPSCMA

CONFIGS = [(15, 50, 1), (15, 50, 3), (64, 50, 1), (64, 200, 1), (256, 50, 1), (256, 200, 1)]


def creps_block(n: int, samples: int, z: int, iterations: int, state: dict) -> float:
    optimizer, rng, matrix = state["creps"], state["rng"], state["matrix"]
    start = time.perf_counter()
    for _ in range(iterations):
        contexts = rng.uniform(0, 3, (samples, z))
        params = optimizer.ask(contexts)
        optimizer.tell(contexts, params, -((params + contexts @ matrix.T) ** 2).sum(axis=1))
    return (time.perf_counter() - start) / iterations


def pycma_block(n: int, samples: int, iterations: int, state: dict) -> float:
    es = state["cma"]
    start = time.perf_counter()
    for _ in range(iterations):
        solutions = es.ask()
        es.tell(solutions, (np.asarray(solutions) ** 2).sum(axis=1).tolist())
    return (time.perf_counter() - start) / iterations


def measure(n: int, samples: int, z: int, blocks: int) -> tuple[float, float]:
    import cma

    rng = np.random.default_rng(0)
    state = {
        "rng": rng,
        "matrix": rng.uniform(-1, 1, (n, z)),
        "creps": CREPSCMA(n, z, initial_mean=rng.uniform(-5, 5, n), initial_cov=4.0, seed=0),
        "cma": cma.CMAEvolutionStrategy(np.zeros(n), 2.0, {"popsize": samples, "seed": 1, "verbose": -9}),
    }
    iterations = max(3, int(2000 / (n * samples) ** 0.75))
    ours, theirs = [], []
    for _ in range(blocks):
        ours.append(creps_block(n, samples, z, iterations, state))
        theirs.append(pycma_block(n, samples, iterations, state))
    return float(np.median(ours)), float(np.median(theirs))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="only n = 15")
    parser.add_argument("--blocks", type=int, default=15, help="alternating timing blocks per configuration")
    args = parser.parse_args()
    warnings.simplefilter("ignore")
    configs = [c for c in CONFIGS if c[0] == 15] if args.quick else CONFIGS
    print(f"{'n':>4} {'N':>4} {'z':>2} {'CREPS-CMA ms':>13} {'pycma ms':>9} {'ratio':>6}")
    for n, samples, z in configs:
        ours, theirs = measure(n, samples, z, args.blocks)
        print(f"{n:>4} {samples:>4} {z:>2} {ours * 1e3:>13.3f} {theirs * 1e3:>9.3f} {ours / theirs:>6.2f}")


if __name__ == "__main__":
    main()
