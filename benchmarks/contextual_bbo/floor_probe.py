"""Issue 45's probe of C-CMA-ES's floor on the GECCO 2019 protocol: runs of a column with options, and the
advantage estimate along one run.

    python benchmarks/contextual_bbo/floor_probe.py cells --functions Ellipsoidal Discus --seeds 3 \\
        --options '{"restarts": 0, "ridge_centre": "old"}' --out results/floor/c3r.json
    python benchmarks/contextual_bbo/floor_probe.py advantages --function DifferentPowers --seed 2 \\
        --options '{"restarts": 0, "ridge_centre": "old"}' --every 50

``cells`` runs :func:`~benchmarks.contextual_bbo.protocol.run_protocol` (the study's own runs) and prints one
JSON line per run (the protocol's measure, the mean policy's final test regret, the stop reason) and the
mean and median per function. ``advantages`` follows one run and, every ``--every`` generations, compares the
baseline V(s) (C1) with the true context effect E[R | s] = E_θ[−f_s(θ)] under the current search
distribution (Monte Carlo, ``--draws`` per context): the baseline's error (its rms over the batch, its
mean removed, since only differences between contexts rank), the spread of the part of R that θ decides
(R − E[R | s]), the spread of E[R | s] over the batch, and Kendall's τ between the advantages and that θ part
(1: the advantages rank θ as the returns do at a fixed context), the condition number of C and the rms of
the mean's error m(s) − θ*(s) over the batch (the mean regression's error across contexts). ``--out``
writes the rows with the provenance record (``benchmarks/provenance.py``). Nothing here changes the study's
cache. ``floor_table`` and ``restart_tables`` render docs/algorithms.md's tables from the committed
``results/floor`` and ``results/restarts`` files.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

# Run by path: the repository root first on sys.path, as `python -m` puts it (see benchmarks/__init__.py).
if not __package__:
    sys.path[0] = str(Path(__file__).resolve().parents[2])

import numpy as np
from scipy.stats import kendalltau

from benchmarks.contextual_bbo.problems import GENERATION, N_PARAMS, PROBLEMS, draw_run
from benchmarks.contextual_bbo.protocol import ProtocolSpec, run_protocol
from benchmarks.provenance import provenance
from benchmarks.study_cli import json_object
from creps_gym.optimizers import make_optimizer

__all__ = [
    "FLOOR_TABLE",
    "RESTART_TABLES",
    "advantage_rows",
    "cell_rows",
    "floor_table",
    "main",
    "restart_tables",
]

#: The rows of docs/algorithms.md's floor table: its label and the ``results/floor`` file it is read from.
FLOOR_TABLE = (
    ("defaults (C3, ridge 1e−8)", "c3.json"),
    ("`baseline_ridge=1e-16`", "c3-baseline-ridge1e-16.json"),
    ("`ridge=1e-14`", "c3-ridge1e-14.json"),
    ('`ridge_centre="old"` (C3r)', "c3r.json"),
    ("C3r, `baseline_ridge=0`", "c3r-baseline-ridge0.json"),
    ('`baseline_ridge_scale="unexplained"` (C1s)', "c1s.json"),
    ("C3r and C1s", "c3r-c1s.json"),
    ("C3r, `baseline_bandwidth=0.1` (C1″)", "c3r-bandwidth0.1.json"),
    ("C3r, `baseline_bandwidth=0.1, baseline_detrend=True` (C1d)", "c3r-c1d-bandwidth0.1.json"),
    (
        "`c-cma-es-surrogate`, C3r, C1d (h = 0.1), `max_condition=1e20`",
        "surrogate-c3r-c1d-bandwidth0.1-condition1e20.json",
    ),
    (
        "`c-cma-es-surrogate`, C3r, C1d (h = 0.3), `max_condition=1e20`",
        "surrogate-c3r-c1d-bandwidth0.3-condition1e20.json",
    ),
    (
        "`c-cma-es-surrogate`, C3r, C1d (h = 0.3), `max_condition=1e20`, `d_sigma=3`",
        "surrogate-c3r-c1d-bandwidth0.3-condition1e20-dsigma3.json",
    ),
)
FLOOR_FOLDER = Path(__file__).resolve().parent / "results" / "floor"
#: The restart tables of docs/algorithms.md (issue 45 item 3, C12 and C13): their functions and rows, read
#: from ``results/restarts`` (3 runs, then 20 runs per cell).
RESTART_TABLES = (
    (
        ("Ellipsoidal", "Discus", "Ackley"),
        (
            ("defaults, `budget=None` (the restarts before C12)", "c3-no-budget.json"),
            ("defaults (C12: the protocol's budget)", "c3-c12.json"),
            ("C12, `restart_population_factor=2` (C13)", "c3-c12-ipop2.json"),
            ('`ridge_centre="old"` (C3r), `budget=None`', "c3r-no-budget.json"),
            ("C3r, C12", "c3r-c12.json"),
            ("C3r, C12, C13 (F = 2)", "c3r-c12-ipop2.json"),
        ),
    ),
    (
        ("Ellipsoidal", "Discus", "DifferentPowers", "Ackley"),
        (
            ("defaults, `budget=None`", "c3-no-budget-20runs.json"),
            ("defaults (C12)", "c3-c12-20runs.json"),
            ("C12, C13 (F = 2)", "c3-c12-ipop2-20runs.json"),
            ("C3r, C12", "c3r-c12-20runs.json"),
        ),
    ),
)
RESTART_FOLDER = FLOOR_FOLDER.parent / "restarts"


def cell_rows(
    functions: Sequence[str], method: str, seeds: int, options: dict[str, Any], first_seed: int = 0
) -> list[dict]:
    """One row per (function, seed): the run's protocol measure, final test regret and stop reason, for
    the seeds ``first_seed`` .. ``first_seed + seeds − 1`` (seeds from 20 on are outside the study's)."""
    rows = []
    for function in functions:
        for seed in range(first_seed, first_seed + seeds):
            spec = ProtocolSpec(function, method, seed, tuple(sorted(options.items())), "probe")
            document = run_protocol(spec)
            row = {
                "function": function,
                "seed": seed,
                "protocol_last": document["protocol_last"],
                "final": document["final"],
                "stop_reason": document["stop_reason"],
                "generations_run": document["generations_run"],
            }
            print(json.dumps(row), flush=True)
            rows.append(row)
    return rows


def advantage_rows(
    function: str, seed: int, options: dict[str, Any], every: int, draws: int, method: str = "c-cma-es"
) -> list[dict]:
    """Every ``every`` generations of one run: the baseline's error against E[R | s] and the advantages' τ."""
    problem = PROBLEMS[function]
    draw = draw_run(problem, seed)
    optimizer = make_optimizer(
        method,
        N_PARAMS,
        problem.context_dim,
        seed=draw.optimizer_seed,
        initial_mean=draw.initial_mean,
        initial_cov=problem.sigma0**2,
        **options,
    )
    monte_carlo = np.random.default_rng(12345)
    rows = []
    for generation in range(problem.generations):
        contexts = draw.contexts(GENERATION)
        params = optimizer.ask(contexts)
        returns = -draw.evaluate(contexts, params)
        if generation % every == 0 or generation == problem.generations - 1:
            rows.append(_advantage_row(optimizer, draw, contexts, returns, generation, draws, monte_carlo))
            print(json.dumps(rows[-1]), flush=True)
        optimizer.tell(contexts, params, returns)
        if optimizer.stop():
            break
    return rows


def _advantage_row(optimizer, draw, contexts, returns, generation, draws, rng) -> dict[str, float]:
    advantages, explained = optimizer._advantages(contexts, returns)  # C1 as the update computes it
    mean = optimizer.policy.mean(contexts)
    factor = optimizer.step_size * optimizer.policy.chol
    noise = rng.standard_normal((draws, N_PARAMS)) @ factor.T
    expected = np.array(
        [
            -draw.evaluate(np.repeat(s[None], draws, 0), m + noise).mean()
            for s, m in zip(contexts, mean, strict=True)
        ]
    )
    error = (returns - advantages) - expected  # V(s_k) − E[R | s_k]
    error_of_mean = mean + contexts @ draw.shift.T - draw.problem.optimum  # m(s_k) − θ*(s_k)
    eigenvalues = np.linalg.eigvalsh(optimizer.policy.cov)  # C's condition: max_condition stops at 1e14
    theta_part = returns - expected
    regret = draw.regret(draw.test_contexts, optimizer.policy.mean(draw.test_contexts)).mean()
    return {
        "generation": generation,
        "mean_return": float(returns.mean()),
        "mean_policy_regret": float(regret),
        "step_size": optimizer.step_size,
        "baseline_error_rms": float(np.std(error)),
        "theta_part_std": float(np.std(theta_part)),
        "context_effect_std": float(np.std(expected)),
        "tau_advantages_theta": float(kendalltau(advantages, theta_part).statistic),
        "baseline_r2": explained,
        "condition": float(eigenvalues[-1] / eigenvalues[0]),
        "theta_error_rms": float(np.sqrt(np.mean(np.square(error_of_mean)))),
    }


def _cell(values: list[float]) -> str:
    """A mean as the docs print it: two significant digits, typographic minus signs (blank: no runs)."""
    if not values:
        return ""
    return f"{np.mean(values):.1e}".replace("-", "−").replace("e−0", "e−").replace("e+0", "e")


def _table_rows(rows: Sequence[tuple[str, str]], folder: Path, functions: Sequence[str]) -> str:
    """One line per (label, file): the mean protocol measure of the file's runs per function."""
    lines = []
    for label, name in rows:
        runs = json.loads((folder / name).read_text(encoding="utf-8"))["rows"]
        cells = [_cell([r["protocol_last"] for r in runs if r["function"] == f]) for f in functions]
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def floor_table(folder: Path = FLOOR_FOLDER) -> str:
    """The body rows of docs/algorithms.md's floor table (mean protocol measure over each file's runs, per
    function in the study's order), rendered from the committed ``results/floor`` files."""
    return _table_rows(FLOOR_TABLE, folder, list(PROBLEMS))


def restart_tables(folder: Path = RESTART_FOLDER) -> list[str]:
    """The body rows of docs/algorithms.md's restart tables (C12, C13), one text per table of
    :data:`RESTART_TABLES`, rendered from the committed ``results/restarts`` files."""
    return [_table_rows(rows, folder, functions) for functions, rows in RESTART_TABLES]


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("what", choices=("cells", "advantages"))
    parser.add_argument("--functions", nargs="+", default=list(PROBLEMS), choices=list(PROBLEMS))
    parser.add_argument("--function", default="DifferentPowers", choices=list(PROBLEMS))
    parser.add_argument("--method", default="c-cma-es")
    parser.add_argument("--seeds", type=int, default=3, help="cells: n seeds, from --first-seed on")
    parser.add_argument("--first-seed", type=int, default=0, help="cells: the first seed (default 0)")
    parser.add_argument("--seed", type=int, default=0, help="advantages: the run")
    parser.add_argument("--options", type=json_object, default={}, help="the optimiser's options (JSON)")
    parser.add_argument("--every", type=int, default=50, help="advantages: generations between rows")
    parser.add_argument("--draws", type=int, default=400, help="advantages: Monte Carlo draws per context")
    parser.add_argument("--out", type=Path, help="write the rows and the provenance here (JSON)")
    args = parser.parse_args(argv)
    if args.what == "cells":
        rows = cell_rows(args.functions, args.method, args.seeds, args.options, args.first_seed)
        for function in args.functions:
            values = [r["protocol_last"] for r in rows if r["function"] == function]
            print(
                f"{function}: mean {np.mean(values):.2e}, median {np.median(values):.2e} ({len(values)} runs)"
            )
    else:
        rows = advantage_rows(args.function, args.seed, args.options, args.every, args.draws, args.method)
    if args.out is not None:
        document = {
            "command": " ".join(["floor_probe.py", *(argv if argv is not None else sys.argv[1:])]),
            "options": args.options,
            "method": args.method,
            "rows": rows,
            "provenance": provenance(),
        }
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(document, indent=1) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
