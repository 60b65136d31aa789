"""Probe: where in the context box does uniform training leave its loss? A selector can only save episodes
where some part of the box is harder than the rest (docs/contexts.md, "When a selector helps").

For each task of the study and C-CMA-ES and CREPS-CMA-old, it trains on uniform draws with the study's
full-mode budget and seeds (0-4), loads each run's final mean policy from its run folder
(``creps_gym.load_policy(folder, "final")``) and evaluates it on a grid over the context box (``POINTS``
points per dimension), grouped into ``CELLS`` cells per dimension (the grid of the bandit's arms). Per
task and optimiser it reports, as the median over trials, the worst cell's mean loss over the median
cell's and the share of the grid's total loss in the worst quarter of the cells (a quarter: 0.25 when
every cell is as hard as any other), and which cell is the worst in each trial (a region that is harder
for the task itself is the worst in every trial). The loss is the study's: the regret on the steep
functions, minus the return on the reacher (which has no regret, so its loss has a floor above 0).

    python benchmarks/contexts/difficulty_probe.py      # about 30 s; results/difficulty.json and .md
    python benchmarks/contexts/difficulty_probe.py --render-only
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

if not __package__:  # run by path: the repository root first on sys.path (see benchmarks/__init__.py)
    sys.path[0] = str(Path(__file__).resolve().parents[2])

from benchmarks.contexts.run import EVAL_CONTEXTS, MODES, RESULTS, machine, make_task, save
from benchmarks.study_options import pin_c3
from creps_gym.selectors import cell_index

OPTIMIZERS = ("c-cma-es", "creps-cma-old")
TASKS = ("reacher", "steep-sphere", "steep-rosenbrock")
CELLS, POINTS = 4, 40
PATH = RESULTS / "difficulty.json"
TABLE = RESULTS / "difficulty.md"


def grid(low: np.ndarray, high: np.ndarray, points: int) -> np.ndarray:
    """Cell-centred grid over the box [low, high], ``points`` per dimension, shape (points ** d, d)."""
    axes = [lo + (np.arange(points) + 0.5) * (hi - lo) / points for lo, hi in zip(low, high, strict=True)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, len(axes))


def cell_losses(
    contexts: np.ndarray, losses: np.ndarray, low: np.ndarray, high: np.ndarray, cells: int
) -> np.ndarray:
    """Mean loss per cell of a ``cells``-per-dimension partition of the box (the bandit's cells, row-major),
    shape (cells ** d,)."""
    flat = cell_index(contexts, low, high, (cells,) * contexts.shape[1])
    sums = np.bincount(flat, weights=losses, minlength=cells ** contexts.shape[1])
    counts = np.bincount(flat, minlength=cells ** contexts.shape[1])
    if np.any(counts == 0):
        raise ValueError(f"contexts: expected every one of the {len(counts)} cells covered, got empty cells")
    return sums / counts


def unevenness(per_cell: np.ndarray) -> dict[str, float]:
    """The worst cell's mean loss over the median cell's, and the worst quarter of the cells' share of the
    total loss (losses >= 0; a quarter rounded up, at least one cell)."""
    per_cell = np.asarray(per_cell, dtype=float)
    if per_cell.ndim != 1 or per_cell.size == 0 or np.any(per_cell < 0) or not np.all(np.isfinite(per_cell)):
        raise ValueError(f"per_cell: expected a non-empty 1-D array of finite losses >= 0, got {per_cell!r}")
    ordered = np.sort(per_cell)[::-1]
    quarter = max(1, -(-ordered.size // 4))
    total = ordered.sum()
    share = float(ordered[:quarter].sum() / total) if total > 0 else quarter / ordered.size
    median = float(np.median(ordered))
    if median <= 0:
        raise ValueError(f"per_cell: expected a positive median loss (else no ratio), got {median!r}")
    return {"worst_over_median": float(ordered[0] / median), "worst_quarter_share": share}


def one_probe(task: str, optimizer: str, trial: int) -> dict[str, Any]:
    """Train one uniform-draw run as the study does and measure its final mean policy per cell."""
    import gymnasium as gym

    from creps_gym import load_policy
    from creps_gym.envs import evaluate_policy
    from creps_gym.runner import run

    iterations, samples, every = MODES["full"][task]
    env, options = make_task(task)
    model = (gym.make(env) if isinstance(env, str) else env).unwrapped
    with tempfile.TemporaryDirectory() as folder:
        run(
            optimizer,
            env,
            iterations,
            samples,
            trial,
            run_dir=folder,
            eval_every=every,
            eval_contexts=EVAL_CONTEXTS,
            optimizer_options=dict(pin_c3(optimizer)),  # C3, with which difficulty.json was computed
            **options,
        )
        policy = load_policy(folder, "final")
    low, high = model.observation_space.low, model.observation_space.high
    contexts = grid(low, high, POINTS)
    result = evaluate_policy(model, policy, contexts)
    losses = result.regrets if result.regrets is not None else -result.returns
    per_cell = cell_losses(contexts, losses, low, high, CELLS)
    worst = np.unravel_index(int(np.argmax(per_cell)), (CELLS,) * len(low))
    return {"per_cell": per_cell.tolist(), "worst_cell": [int(i) for i in worst], **unevenness(per_cell)}


def render(document: dict[str, Any]) -> str:
    """The probe's table: per task and optimiser, the median over trials of each statistic."""
    lines = [
        f"Uniform draws, final mean policy on a {POINTS}-per-dimension grid in {CELLS}-per-dimension cells "
        f"(median over {len(document['trials'])} trials; a quarter's share is 0.25 when every cell is as "
        "hard as any other).",
        "",
        "| task | optimiser | worst cell / median cell | worst quarter's share of the loss "
        "| worst cell per trial (cell indices, 0 at the box's low end) |",
        "|---|---|---|---|---|",
    ]
    for task in TASKS:
        for optimizer in OPTIMIZERS:
            runs = [document["runs"][f"{task}/{optimizer}/{trial}"] for trial in document["trials"]]
            ratio = np.median([r["worst_over_median"] for r in runs])
            share = np.median([r["worst_quarter_share"] for r in runs])
            worst = ", ".join("(" + ", ".join(map(str, r["worst_cell"])) + ")" for r in runs)
            lines.append(f"| {task} | {optimizer} | {ratio:.3g} | {share:.2f} | {worst} |")
    return "\n".join(lines) + "\n"


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="Where uniform training leaves its loss in the box.")
    parser.add_argument("--render-only", action="store_true", help="compute nothing; print the table")
    args = parser.parse_args(argv)
    if args.render_only:
        document = json.loads(PATH.read_text())
    else:
        trials = list(range(MODES["full"]["trials"]))
        runs = {
            f"{task}/{optimizer}/{trial}": one_probe(task, optimizer, trial)
            for task in TASKS
            for optimizer in OPTIMIZERS
            for trial in trials
        }
        document = {"cells": CELLS, "points": POINTS, "trials": trials, "runs": runs, **machine()}
        save(PATH, document)
    text = render(document)
    TABLE.write_text(text)
    print(text, end="")
    return 0


if __name__ == "__main__":
    sys.exit(main())
