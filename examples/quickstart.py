"""A short learning run: CREPS-CMA (old mean) on a contextual sphere, written as a plain ask/tell loop.

Usage: ``python examples/quickstart.py [--iterations N] [--out DIR]``. Prints progress and writes the learning
curve as CSV and PNG (the PNG needs the ``plot`` extra) to ``DIR`` (default ``runs/example-quickstart``, a
folder of its own: the README's main job writes ``runs/quickstart``).
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path

import numpy as np

from creps_gym.optimizers import CREPSCMA


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--iterations", type=int, default=300)
    parser.add_argument("--out", type=Path, default=Path("runs/example-quickstart"))
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    dim, context_dim, samples = 10, 1, 50
    shift = rng.uniform(-1, 1, (dim, context_dim))  # x = θ + A·s, so θ*(s) = −A·s
    test_contexts = rng.uniform(0, 3, (50, context_dim))
    optimizer = CREPSCMA(dim, context_dim, initial_mean=rng.uniform(-5, 5, dim), initial_cov=4.0, seed=0)
    rows = []
    for iteration in range(1, args.iterations + 1):
        contexts = rng.uniform(0, 3, (samples, context_dim))
        params = optimizer.ask(contexts)
        optimizer.tell(contexts, params, -((params + contexts @ shift.T) ** 2).sum(axis=1))
        regret = float(((optimizer.recommend(test_contexts) + test_contexts @ shift.T) ** 2).sum(1).mean())
        rows.append((iteration, iteration * samples, regret))
        if iteration % 25 == 0 or iteration == 1:
            print(
                f"iteration {iteration:4d}  episodes {iteration * samples:6d}  "
                f"mean-policy regret {regret:.3e}"
            )
    args.out.mkdir(parents=True, exist_ok=True)
    with open(args.out / "history.csv", "w", newline="") as stream:
        csv.writer(stream).writerows([("iteration", "episodes", "regret"), *rows])
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print(f"wrote {args.out / 'history.csv'} (install the 'plot' extra for the PNG)")
        return
    figure, axes = plt.subplots(figsize=(6, 4))
    axes.semilogy([r[1] for r in rows], [r[2] for r in rows])
    axes.set(xlabel="episodes", ylabel="mean-policy regret", title="CREPS-CMA (old mean), contextual sphere")
    figure.tight_layout()
    figure.savefig(args.out / "learning_curve.png", dpi=100)
    print(f"wrote {args.out / 'history.csv'} and {args.out / 'learning_curve.png'}")


if __name__ == "__main__":
    main()
