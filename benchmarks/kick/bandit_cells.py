"""Where the bandit practised at the end of a flexibility run (issue 32): per row of ball distance x_B, its
share of the bandit's discounted episode counts and its discounted mean learning-progress reward, from each
finished run's last selector state (``<name>-trial<k>.selector.json``, D-UCB with discount 0.9: about the
last ten iterations). The bandit's 4 × 4 cells are row-major over (x_B, y_B), so cells 4i to 4i + 3 are the
i-th quarter of [0.15, 0.30] m in x_B. Uniform draws give every row a share of 0.25 (the bandit draws half
of each batch uniformly, the other half by its index). ``docs/contexts.md`` quotes it.

    python benchmarks/kick/bandit_cells.py [--folder benchmarks/kick/results/full-bandit]
"""

from __future__ import annotations

import argparse
import itertools
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

if not __package__:  # run by path: the repository root first on sys.path (see benchmarks/__init__.py)
    sys.path[0] = str(Path(__file__).resolve().parents[2])

from benchmarks.kick.study import GRID_X, read_json

__all__ = ["row_shares"]

FOLDER = Path(__file__).resolve().parent / "results" / "full-bandit"


def row_shares(state: dict[str, Any], rows: int = len(GRID_X)) -> tuple[np.ndarray, np.ndarray]:
    """Per x_B row of a bandit state (``counts``, ``sums`` over row-major cells): the share of the
    discounted episode counts, shape (rows,), and the discounted mean reward (sums over counts; NaN for a
    row without episodes), shape (rows,)."""
    counts = np.asarray(state["counts"], dtype=float).reshape(rows, -1).sum(axis=1)
    sums = np.asarray(state["sums"], dtype=float).reshape(rows, -1).sum(axis=1)
    total = counts.sum()
    if total <= 0:
        raise ValueError(f"state: expected positive episode counts, got a total of {total}")
    with np.errstate(invalid="ignore", divide="ignore"):
        return counts / total, np.where(counts > 0, sums / counts, np.nan)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--folder", type=Path, default=FOLDER)
    args = parser.parse_args(argv)
    runs = sorted((args.folder / "runs" / "flexibility").glob("*-trial*.selector.json"))
    edges = np.linspace(GRID_X[0], GRID_X[-1], len(GRID_X) + 1)
    header = ", ".join(f"[{a:.4g}, {b:.4g}]" for a, b in itertools.pairwise(edges))
    print(f"x_B rows (m): {header}")
    for path in runs:
        name = path.name.removesuffix(".selector.json")
        if not path.with_name(f"{name}.json").exists():
            continue  # in progress
        states = read_json(path)
        last = max(states, key=int)
        shares, rewards = row_shares(states[last])
        print(
            f"{name} at iteration {last}: shares {', '.join(f'{s:.2f}' for s in shares)}; "
            f"mean reward {', '.join(f'{r:.3g}' for r in rewards)}"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
