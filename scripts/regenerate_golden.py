"""Regenerate the golden numbers of the optimisers (tests/golden/optimizers.json).

Run ``python scripts/regenerate_golden.py`` after an intended change of the optimisers' numerics, check the
diff, and commit it with the change. ``tests/optimizers/test_golden.py`` recomputes the same numbers and
compares.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from creps_gym.optimizers import CREPS, CREPSCMA

GOLDEN_PATH = Path(__file__).resolve().parent.parent / "tests" / "golden" / "optimizers.json"
FACTORIES = {
    "creps": lambda: CREPS(5, 2, initial_mean=2.0, initial_cov=1.5, seed=0),
    "creps-cma-old": lambda: CREPSCMA(5, 2, variant="old", initial_mean=2.0, initial_cov=1.5, seed=0),
    "creps-cma-current": lambda: CREPSCMA(5, 2, variant="current", initial_mean=2.0, initial_cov=1.5, seed=0),
}


def golden_numbers() -> dict[str, dict[str, list[float] | float]]:
    """20 iterations of 25 samples on a contextual sphere x = θ + A·s, everything seeded with 0."""
    matrix = np.random.default_rng(0).uniform(-1, 1, (5, 2))
    results: dict[str, dict[str, list[float] | float]] = {}
    for name, factory in FACTORIES.items():
        rng = np.random.default_rng(0)
        optimizer = factory()
        first_ask = None
        for _ in range(20):
            contexts = rng.uniform(0, 3, (25, 2))
            params = optimizer.ask(contexts)
            first_ask = params[0].tolist() if first_ask is None else first_ask
            optimizer.tell(contexts, params, -((params + contexts @ matrix.T) ** 2).sum(axis=1))
        results[name] = {
            "first_ask": first_ask,
            "mean_at_1_2": optimizer.recommend([[1.0, 2.0]])[0].tolist(),
            "cov_diagonal": np.diag(optimizer.cov).tolist(),
            "eta": optimizer.diagnostics["eta"],
            "ess": optimizer.diagnostics["ess"],
        }
    return results


if __name__ == "__main__":
    GOLDEN_PATH.parent.mkdir(parents=True, exist_ok=True)
    GOLDEN_PATH.write_text(json.dumps(golden_numbers(), indent=2) + "\n")
    print(f"wrote {GOLDEN_PATH}")
