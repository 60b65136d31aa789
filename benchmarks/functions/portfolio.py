"""The restart portfolio of ``c-cma-es`` (C11, ``restart_baseline_loss``) on the function study's protocol.

Different Powers at z = 3 is the function study's failure cell for ``c-cma-es``: every search diverges until
its stop criteria restart it, and with the former defaults the restarts repeated the same search. Since issue
33 the searches after a restart fit the context baseline with the other loss (Huber's) and keep the best
policy (C10). The first search does not depend on either, so only the runs that restarted differ from the
former defaults; this script measures the failure cell and the function study's other headline cells of
``c-cma-es`` with both, over 20 seeds, with the function study's settings (p = 15, N = 50, budget 200,000, 16
test contexts, target regret 1e-5), and the failure cell once more through the runner's divergence rule (on
by default in ``creps_gym.runner.run`` and the CLI; the studies turn it off), which restarts a diverged search
at once.

    python benchmarks/functions/portfolio.py                 # compute the missing runs, render the table
    python benchmarks/functions/portfolio.py --render-only   # render from the committed runs only

The runs are the function study's documents (``benchmarks/functions/runs/``; the default's seeds 0-4 are the
full study's own runs); the table goes into ``benchmarks/functions/README.md`` (block ``restart-portfolio``).
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

# Run by path: the repository root first on sys.path, as `python -m` puts it (see benchmarks/__init__.py).
if not __package__:
    sys.path[0] = str(Path(__file__).resolve().parents[2])

import numpy as np

from benchmarks.provenance import provenance_text
from benchmarks.study_options import RESTART_PIN, pin_c3
from benchmarks.study_report import update_block
from benchmarks.study_runner import run_all
from benchmarks.study_tools import RunSpec

HERE = Path(__file__).resolve().parent
#: (function, z): the failure cell first, then the headline cells of ``c-cma-es`` it must not lose.
CELLS = (("DifferentPowers", 3), ("Rosenbrock", 3), ("ShiftedRotatedElliptic", 3), ("Sphere", 1))
#: (label, options, the runner's divergence factor, cells or None for all) of ``c-cma-es``; the first is the
#: default as the studies run it (the divergence rule off), the others are compared with it. The rule fires
#: on the failure cell only (``tests/runner/test_divergence.py``), so elsewhere it would change nothing.
Cells = tuple[tuple[str, int], ...]
VARIANTS: tuple[tuple[str, tuple[tuple[str, Any], ...], float | None, Cells | None], ...] = (
    ("default", (), None, None),
    ("former restarts", RESTART_PIN, None, None),
    ("default, runner's divergence rule", (), 1000.0, (("DifferentPowers", 3),)),
)
SEEDS, BUDGET, DIM, SAMPLES = 20, 200_000, 15, 50
BLOCK = "restart-portfolio"


def parse_args(argv: Sequence[str] | None = None) -> argparse.Namespace:
    """Command-line options."""
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--render-only", action="store_true", help="compute nothing, render the cache")
    parser.add_argument("--workers", type=int, default=1, help="processes (default 1)")
    parser.add_argument("--cache", type=Path, default=HERE / "runs", help="the run documents' folder")
    parser.add_argument("--readme", type=Path, default=HERE / "README.md", help="the file of the table")
    args = parser.parse_args(argv)
    if args.workers < 1:
        parser.error(f"--workers: expected a positive integer, got {args.workers}")
    return args


def make_specs() -> list[RunSpec]:
    """Every run: each cell, variant and seed."""
    return [
        _spec(function, z, seed, options, divergence)
        for function, z in CELLS
        for _, options, divergence, cells in VARIANTS
        if cells is None or (function, z) in cells
        for seed in range(SEEDS)
    ]


def _spec(function: str, z: int, seed: int, options: Any, divergence: float | None) -> RunSpec:
    """The run of a cell, seed and variant (its options and the runner's divergence factor)."""
    options = pin_c3("c-cma-es", options)  # the committed runs' C3 (benchmarks/study_options.py)
    return RunSpec(
        function, DIM, z, "c-cma-es", seed, BUDGET, SAMPLES, options=options, divergence=divergence
    )


def _row(label: str, runs: list[dict[str, Any]], default: list[dict[str, Any]] | None) -> str:
    hits = [d["hit"] for d in runs if d["hit"] is not None]
    median = f"{np.median(hits):,.0f}" if hits else "–"
    worst = max(d["final"] if d["final"] is not None else np.inf for d in runs)
    missed = [d["total_episodes"] for d in runs if d["hit"] is None]
    if default is None:
        differ = "–"
    else:  # the first search is the default's: a run differs only where it restarted
        differ = str(sum(a["values"] != b["values"] for a, b in zip(runs, default, strict=True)))
    spent = f"{np.median(missed):,.0f}" if missed else "–"
    return f"| {label} | {len(hits)}/{len(runs)} | {median} | {spent} | {worst:.3g} | {differ} |"


def table(documents: list[dict[str, Any]]) -> str:
    """The Markdown block: per cell and variant, the seeds that met the target and their median episodes."""
    by_key = {RunSpec(**d["spec"]).prefix: d for d in documents}  # a run that ended early: any budget
    lines = [
        "Command: `python benchmarks/functions/portfolio.py`. `c-cma-es` with the function study's settings "
        f"(p = {DIM}, N = {SAMPLES}, budget {BUDGET:,} episodes, 16 test contexts), seeds 0–{SEEDS - 1}. "
        "Met: seeds whose mean policy's mean regret reached 1e-5; episodes: their median; missed: the median "
        "episodes of the others when they stopped (the budget, or the stop criteria with no restart left); "
        "worst final: the largest final regret; differ: seeds whose regret curve is not the default's "
        "(the restart options act only from a restart on, and the divergence rule only where it fires, so "
        "these are the runs that restarted).",
        "",
        "| cell | variant | met | episodes | missed after | worst final | differ |",
        "|---|---|---|---|---|---|---|",
    ]
    for function, z in CELLS:
        default = None
        for label, options, divergence, cells in VARIANTS:
            if cells is not None and (function, z) not in cells:
                continue
            keys = [_spec(function, z, s, options, divergence).prefix for s in range(SEEDS)]
            if not all(key in by_key for key in keys):
                lines.append(f"| {function}, z = {z} | {label} | not computed yet | | | | |")
                continue
            runs = [by_key[key] for key in keys]
            lines.append(_row(f"{function}, z = {z} | {label}", runs, default))
            default = runs if default is None else default
    lines += ["", provenance_text(d.get("provenance") for d in documents)]
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    """Compute the missing runs (unless ``--render-only``) and write the table into the README."""
    args = parse_args(argv)
    documents = run_all(make_specs(), args.cache, workers=args.workers, compute=not args.render_only)
    update_block(args.readme, BLOCK, table(documents))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
