"""c-bo's ``no_signal`` stop on noise and on the study's tasks, and two rules it did not get (issue 44).

c-bo's ``stop()`` reports ``no_signal`` from 50 told episodes on when the fitted noise variance holds at
least 95 % of the model's variance, σ_n²/(σ_f² + σ_n²) (with a quadratic trend that is signal, times the
share of the returns' variance the trend leaves). A GP can also fit noise with short lengthscales (each
episode its own bump of signal), and that share then stays small. This script measures how often the stop
fires, and how often two rules that look at what the model predicts instead would: with r_i the model's
leave-one-out error at episode i, r_i = α_i / [K⁻¹]_ii (Rasmussen & Williams 2006, Eq. 5.12), and c_i =
(y_i − ȳ) n/(n − 1) that of the other episodes' mean, the **sum** rule stops where Σ r_i² ≥ 0.95 Σ c_i²
and the **median** rule where median r_i² ≥ 0.95 median c_i² (each scaled by the trend's share too).

It runs c-bo columns with c-bo's current defaults on the study's tasks (the same start, batches, training
contexts and seeds as the study's runs, :func:`benchmarks.low_budget.study.start_run`) and, before every
batch from 50 episodes on and after the last, records the three statistics of the model ``stop()`` looks
at. With ``--noise`` the same runs are told standard normal returns instead of the task's (a Generator of
their own, seeded by the run's seed): there a stop should fire. A stop of the runner ends the run, so on
the tasks it should not. Writes one JSON document with provenance and a Markdown table next to it
(``--render-only`` redraws it).

    OPENBLAS_NUM_THREADS=1 python -m benchmarks.low_budget.stop_signal --seeds 3 --budget 200 --noise \\
        --tasks Sphere-p2-z1 Sphere-p2-z2 Sphere-p4-z1 Sphere-p4-z2 Sphere-p8-z1 Sphere-p8-z2 \\
        KickPrecisionLowDim KickFlexibilityLowDim KickPrecisionLowDim-v1 KickFlexibilityLowDim-v1 \\
        KickPrecisionLowDim-v2 KickFlexibilityLowDim-v2 PlanarReacherLowDim \\
        --out benchmarks/low_budget/results/stop_signal_noise.json
    OPENBLAS_NUM_THREADS=1 python -m benchmarks.low_budget.stop_signal --seeds 3 --budget 200 \\
        --out benchmarks/low_budget/results/stop_signal.json
"""

from __future__ import annotations

import sys
from pathlib import Path

if not __package__:  # run by path: the repository root first on sys.path, as `python -m` puts it
    sys.path[0] = str(Path(__file__).resolve().parents[2])

import argparse
import json
import math
from typing import Any

import numpy as np
from scipy import linalg

from benchmarks.low_budget import parse_runs_arguments, replay_command, run_and_write
from benchmarks.low_budget.recommenders import start_variant
from benchmarks.low_budget.study import FUNCTIONS, ROBOT_TASKS, Run, run_until
from creps_gym.optimizers.gp_trend import residual_share

__all__ = [
    "CURRENT",
    "RULES",
    "TASKS",
    "held_out_errors",
    "main",
    "one_run",
    "render",
    "statistics",
    "summary",
]

TASKS = tuple(f"{f}-p{p}-z{z}" for f in FUNCTIONS for p in (2, 4, 8) for z in (1, 2)) + tuple(
    task.name for task in ROBOT_TASKS
)
#: The options that make a study column c-bo's current defaults (with ``--unpinned``'s refit default).
CURRENT = {"log_quantile": 0.25, "mes_floor": "observed"}
#: ``stop()``'s threshold and first episode (``creps_gym/optimizers/cbo.py``).
THRESHOLD, FIRST = 0.95, 50
NOISE_STREAM = 20_261_130


class _WhiteNoise:
    """The task's env with standard normal returns: ``evaluate`` draws them, the rest is the env's."""

    def __init__(self, env: Any, seed: int) -> None:
        self.env, self.rng = env, np.random.default_rng([NOISE_STREAM, seed])

    def evaluate(self, contexts: np.ndarray, params: np.ndarray) -> tuple[np.ndarray, dict]:
        return self.rng.standard_normal(contexts.shape[0]), {}

    def __getattr__(self, name: str) -> Any:
        return getattr(self.env, name)


def held_out_errors(model: Any) -> tuple[np.ndarray, np.ndarray]:
    """(r, c), each of shape (n,): a fitted GP's leave-one-out errors r_i = α_i / [K⁻¹]_ii and those of the
    other targets' mean, c_i = (y_i − ȳ) n/(n − 1), in O(n³)."""
    n = model.targets.shape[0]
    inverse = linalg.solve_triangular(model.chol, np.eye(n), lower=True, check_finite=False)  # L⁻¹
    residuals = model.alpha / np.einsum("ij,ij->j", inverse, inverse)  # [K⁻¹]_ii: column i's squared norm
    return residuals, (model.targets - model.targets.mean()) * (n / (n - 1))


def statistics(optimizer: Any) -> tuple[float, float, float]:
    """(stop's, sum, median) no-signal statistics of a c-bo optimiser's model: the fitted noise share,
    Σ r_i² / Σ c_i² and median r_i² / median c_i² (:func:`held_out_errors`), each times the share the trend
    leaves where it is signal."""
    model = optimizer.model
    noise, signal = math.exp(optimizer.log_hyper[-1]), math.exp(optimizer.log_hyper[-2])
    factor = 1.0
    if model.beta is not None:
        factor = residual_share(model.scale, model.beta, optimizer._targets(optimizer.returns))
    errors, others = held_out_errors(model)
    total = float(np.sum(others**2)) or 1.0
    typical = float(np.median(others**2)) or 1.0
    held_out = (float(np.sum(errors**2)) / total, float(np.median(errors**2)) / typical)
    return noise / (noise + signal) * factor, held_out[0] * factor, held_out[1] * factor


def one_run(task_name: str, method_name: str, seed: int, budget: int, noise: bool = False) -> dict[str, Any]:
    """The c-bo column ``method_name`` with c-bo's current defaults on ``task_name`` (its returns white noise
    with ``noise``), both statistics before every batch from :data:`FIRST` episodes and at the end."""
    run = start_variant(task_name, method_name, seed, budget, True, CURRENT)
    if noise:
        run.model = _WhiteNoise(run.model, seed)
    records: list[list[float]] = []

    def record(run: Run) -> None:
        if run.state["episodes"] >= FIRST:
            records.append([run.state["episodes"], *statistics(run.optimizer)])

    run_until(run, budget, record)
    record(run)
    document = {"task": task_name, "method": method_name, "seed": seed, "key": run.spec.key, "noise": noise}
    return {**document, "options": CURRENT, "records": records}


def _cells(runs: list[dict[str, Any]], column: int) -> list[str]:
    """The runs' count that reach :data:`THRESHOLD`, the earliest episode they do, the largest value."""
    stopped = [next((r[0] for r in run["records"] if r[column] >= THRESHOLD), None) for run in runs]
    hits = [e for e in stopped if e is not None]
    largest = max(r[column] for run in runs for r in run["records"])
    return [f"{len(hits)} of {len(runs)}", f"{min(hits):.0f}" if hits else "—", f"{largest:.3g}"]


RULES = ("noise share (stop)", "held out, sum", "held out, median")


def summary(runs: list[dict[str, Any]]) -> str:
    """The Markdown table: per task and column, the runs where each statistic stops."""
    head = ["runs that stop", "first episode", "largest value"]
    lines = [
        "| task | column | " + " | ".join(f"{h}: {rule}" for rule in RULES for h in head) + " |",
        "|---" * (2 + len(RULES) * len(head)) + "|",
    ]
    for cell in dict.fromkeys((r["task"], r["method"]) for r in runs):
        these = [r for r in runs if (r["task"], r["method"]) == cell]
        cells = [c for column in range(1, len(RULES) + 1) for c in _cells(these, column)]
        lines.append(f"| {cell[0]} | `{cell[1]}` | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _totals(runs: list[dict[str, Any]]) -> str:
    """How many runs each statistic stops, at any look and at the first."""
    columns = range(1, len(RULES) + 1)
    anywhere = [sum(any(r[c] >= THRESHOLD for r in run["records"]) for run in runs) for c in columns]
    first = [sum(run["records"][0][c] >= THRESHOLD for run in runs) for c in columns]
    counts = ", ".join(f"{n} ({rule})" for n, rule in zip(anywhere, RULES, strict=True))
    return f"{counts} of {len(runs)} runs stop; at the first look, {', '.join(map(str, first))}"


def render(path: Path) -> str:
    """Write the table of the results at ``path`` (JSON) to the same name with ``.md``; returns it."""
    document = json.loads(path.read_text())
    runs = document["runs"]
    command = replay_command("stop_signal", document)
    seeds = sorted({run["seed"] for run in runs})
    returns = "standard normal returns instead of the task's" if runs[0]["noise"] else "the task's returns"
    text = (
        f"{summary(runs)}\n\nSeeds {seeds[0]}–{seeds[-1]}, c-bo's current defaults, {returns}; each "
        f"statistic before every batch from {FIRST} episodes on and at the end, a stop where it is at least "
        f"{THRESHOLD}. In all, {_totals(runs)}.\n\nCommand: `OPENBLAS_NUM_THREADS=1 {command}`.\n"
    )
    path.with_suffix(".md").write_text(text)
    return text


def _job(args: tuple[Any, ...]) -> dict[str, Any]:
    return one_run(*args)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tasks", nargs="+", default=list(TASKS), help="study task names (default: all)")
    parser.add_argument("--methods", nargs="+", default=["c-bo", "c-bo+quadratic"], help="c-bo columns")
    parser.add_argument("--budget", type=int, default=200)
    parser.add_argument("--noise", action="store_true", help="tell standard normal returns instead")
    args = parse_runs_arguments(parser, argv, 3, render)
    if args is None:
        return
    jobs = [
        (t, m, s, args.budget, args.noise)
        for t in args.tasks
        for m in args.methods
        for s in range(args.seeds)
    ]
    run_and_write(_job, jobs, args.workers, args.out, render)


if __name__ == "__main__":
    main()
