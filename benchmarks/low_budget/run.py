"""Issue 44's low-budget study: what each optimiser's recommended policy achieves after 50, 100, 200, 300
and 500 episodes, on contextual functions (p = 2, 4, 8; z = 1, 2) and the low-dimensional kick and reacher
ids.

One run per (task, method, seed) goes to the largest budget and records the recommended policy's metric on
fixed test contexts at every budget (:mod:`benchmarks.low_budget.study`), and the optimiser's own seconds
per asked episode. Runs are cached as JSON under ``--cache`` (a finished run is a file: the study resumes)
and computed in order, the issue's target cells first (p = 4, z = 1: the non-quadratic functions, then the
kick precision); the tables and the figure (``results.md``, ``curves.png``) are written from the cache only.

    python benchmarks/low_budget/run.py --quick     # p = 2, z = 1, Sphere, Rosenbrock, reacher; 100 episodes
    python benchmarks/low_budget/run.py --full --workers 1      # the whole study, 10 seeds, 500 episodes
    python benchmarks/low_budget/run.py --full --render-only    # redraw from the cached runs

(or ``python -m benchmarks.low_budget.run ...``, from the repository root).
"""

from __future__ import annotations

import argparse
import itertools
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

# Run by path: the repository root first on sys.path, as `python -m` puts it (see benchmarks/__init__.py).
if not __package__:
    sys.path[0] = str(Path(__file__).resolve().parents[2])

from benchmarks.low_budget.columns import METHODS, Method, method_by_name
from benchmarks.low_budget.report import (
    Cells,
    anchors_text,
    cells,
    completeness_text,
    cost_text,
    grouped_tasks,
    library_table,
    paired_table,
    plot_curves,
    targets_table,
    task_table,
    timing_table,
)
from benchmarks.low_budget.study import (
    BUDGETS,
    FUNCTIONS,
    NON_QUADRATIC,
    QUADRATIC,
    ROBOT_TASKS,
    LowBudgetSpec,
    function_task,
    one_run,
    task_by_name,
)
from benchmarks.study_cli import add_mode_options, add_output_options, resolve_outputs
from benchmarks.study_report import timing_text
from benchmarks.study_runner import run_study

HERE = Path(__file__).resolve().parent
ROBOTS = [t.name for t in ROBOT_TASKS]
PRESETS = {
    "quick": {
        "seeds": 2,
        "budget": 100,
        "functions": ["Sphere", "Rosenbrock"],
        "dims": [2],
        "context_dims": [1],
        "robots": ["PlanarReacherLowDim"],
    },
    "full": {
        "seeds": 10,
        "budget": BUDGETS[-1],
        "functions": list(FUNCTIONS),
        "dims": [2, 4, 8],
        "context_dims": [1, 2],
        "robots": ROBOTS,
    },
}
#: The issue's target cells, computed first: p = 4, z = 1 on the non-quadratic functions, then the kick
#: precision, then the quadratic functions at p = 4, z = 1 and the other robot tasks.
FIRST = [f"{f}-p4-z1" for f in NON_QUADRATIC]
FIRST += ["KickPrecisionLowDim", "KickPrecisionLowDim-v1", "KickPrecisionLowDim-v2"]
FIRST += [f"{f}-p4-z1" for f in QUADRATIC]
FIRST += ["KickFlexibilityLowDim", "KickFlexibilityLowDim-v1", "KickFlexibilityLowDim-v2"]
FIRST += ["PlanarReacherLowDim"]


def parse_args(argv: Sequence[str] | None = None) -> argparse.Namespace:
    """Command-line options; ``--quick``/``--full`` pick the defaults of the others."""
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    add_mode_options(parser, quick="p = 2, z = 1, 2 seeds, 100 episodes", full="the whole study")
    parser.add_argument(
        "--functions", nargs="*", choices=FUNCTIONS, help="contextual functions (none: only robots)"
    )
    parser.add_argument("--dims", nargs="+", type=int, help="parameter dimensions p")
    parser.add_argument("--context-dims", nargs="+", type=int, help="context dimensions z")
    parser.add_argument("--robots", nargs="*", choices=ROBOTS, help="low-dimensional robot tasks")
    names = [m.name for m in METHODS]
    parser.add_argument("--methods", nargs="+", choices=names, default=names, help="methods to run")
    parser.add_argument("--seeds", type=int, help="seeds per cell (0 .. n-1)")
    parser.add_argument("--budget", type=int, help="episodes per run (the largest budget)")
    add_output_options(parser, HERE, out="figure and tables (default docs/results/low_budget/<mode>)")
    args = parser.parse_args(argv)
    args.mode = args.mode or "full"
    resolve_outputs(args, argv, HERE, args.mode)
    for name, value in PRESETS[args.mode].items():
        setattr(args, name, getattr(args, name) if getattr(args, name) is not None else value)
    for name in ("seeds", "budget", "workers"):
        if getattr(args, name) < 1:
            parser.error(f"--{name}: expected a positive integer, got {getattr(args, name)}")
    if min(args.dims) < 1 or min(args.context_dims) < 1:
        parser.error(f"--dims/--context-dims: expected p, z >= 1, got {args.dims}, {args.context_dims}")
    return args


def study_tasks(args: argparse.Namespace) -> list[str]:
    """The task names of the study, the target cells (:data:`FIRST`) first."""
    functions = [
        function_task(f, p, z).name
        for p, z, f in itertools.product(args.dims, args.context_dims, args.functions)
    ]
    tasks = functions + list(args.robots)
    return sorted(tasks, key=lambda t: (FIRST.index(t) if t in FIRST else len(FIRST), tasks.index(t)))


def study_specs(args: argparse.Namespace) -> list[LowBudgetSpec]:
    """Every run, in the order computed: task by task (:func:`study_tasks`), seed by seed, every method."""
    return [
        LowBudgetSpec(task, method, seed, args.budget)
        for task in study_tasks(args)
        for seed in range(args.seeds)
        for method in args.methods
    ]


def write_report(args: argparse.Namespace, documents: list[dict[str, Any]], timing: dict[str, Any]) -> Path:
    """Write ``results.md`` and ``curves.png`` into ``args.out``; returns the table's path."""
    args.out.mkdir(parents=True, exist_ok=True)
    methods = [m for m in METHODS if m.name in args.methods]
    grouped, tasks = cells(documents), study_tasks(args)
    budgets = [b for b in BUDGETS if b < args.budget] + [args.budget]
    figure = plot_curves(grouped, tasks, methods, args.out / "curves.png").name
    text = [
        *_header(args, documents, timing, budgets),
        *_target_sections(grouped, tasks, methods, budgets),
        *_paired_sections(grouped, tasks, budgets),
        *_library_and_cost_sections(args, documents, grouped, tasks, methods, budgets),
        *_per_task_sections(grouped, tasks, methods, args.seeds, budgets),
        *_failures(documents),
        "## Figures",
        "",
        f"![curves]({figure})",
        "",
    ]
    path = args.out / "results.md"
    path.write_text("\n".join(text), encoding="utf-8")
    return path


def _header(
    args: argparse.Namespace, documents: list[dict[str, Any]], timing: dict[str, Any], budgets: list[int]
) -> list[str]:
    """The report's title, command, setting, timing and provenance, completeness and the anchors."""
    return [
        f"# Low-budget study ({args.mode}): generated by `benchmarks/low_budget/run.py`",
        "",
        f"Command: `python benchmarks/low_budget/run.py {args.flags}`. {args.seeds} seed(s) per cell, "
        f"{args.budget} episodes per run, the recommended policy evaluated at {', '.join(map(str, budgets))} "
        "episodes (whole batches: a cell's episodes are the budget rounded down to the method's batch). "
        "Every method starts from mean 0, σ = 2 on the functions (instance = seed, 100 test contexts) and "
        "from the robot id's declared initial distribution (kick: the paper's 10 targets or 28 ball "
        "positions; reacher: 16 test contexts).",
        timing_text(timing, documents),
        "",
        "Cells: median over seeds (min–max); `[k/n]`: only k of the n seeds have finished; `—`: not run yet.",
        "",
        completeness_text(documents, args.specs),
        anchors_text(),
    ]


def _target_sections(
    grouped: Cells, tasks: list[str], methods: list[Method], budgets: list[int]
) -> list[str]:
    """c-bo against the best other method at 200 and 300 episodes (or the largest budget)."""
    text = []
    for budget in [b for b in (200, 300) if b in budgets] or budgets[-1:]:
        text += [
            f"## c-bo against the best other method at {budget} episodes (medians over seeds)",
            "",
            targets_table(grouped, tasks, methods, budget),
        ]
    return text


def _paired_sections(grouped: Cells, tasks: list[str], budgets: list[int]) -> list[str]:
    """MES against UCB, and each acquisition with active contexts against uniform draws, seed by seed."""
    return [
        "## Max-value entropy search against UCB, seed by seed",
        "",
        "Seeds where `c-bo` (MES) ends better than `c-bo-ucb`, of the seeds both finished, and the sign "
        "test's two-sided p-value (the same seed starts both from the same initial design).",
        "",
        paired_table(grouped, tasks, budgets, "c-bo", "c-bo-ucb"),
        "## Active contexts against uniform draws, seed by seed",
        "",
        "Seeds where the acquisition with the `active` context selector (issue 44, item 2) ends better than "
        "the same acquisition on the env's uniform draws, of the seeds both finished, and the sign test's "
        "two-sided p-value (the same seed starts both from the same initial design).",
        "",
        "`c-bo+active` against `c-bo` (max-value entropy search):",
        "",
        paired_table(grouped, tasks, budgets, "c-bo+active", "c-bo"),
        "`c-bo-ucb+active` against `c-bo-ucb` (GP-UCB):",
        "",
        paired_table(grouped, tasks, budgets, "c-bo-ucb+active", "c-bo-ucb"),
    ]


def _library_and_cost_sections(
    args: argparse.Namespace,
    documents: list[dict[str, Any]],
    grouped: Cells,
    tasks: list[str],
    methods: list[Method],
    budgets: list[int],
) -> list[str]:
    """c-bo on the libraries' GPs, the optimiser's own seconds per episode, and each run's cost."""
    return [
        "## c-bo on its own GP and on the libraries' (BoTorch, scikit-learn)",
        "",
        "The same c-bo with BoTorch's model and optimiser (`c-bo-botorch`) or scikit-learn's "
        "`GaussianProcessRegressor` (`c-bo-sklearn`) in place of its own GP (`library_gp.py`), on the tasks "
        "where they have runs: medians over seeds (regret or the kicks' metric, as in the tables per task).",
        "",
        library_table(grouped, tasks, args.seeds, budgets),
        f"## The optimiser's own seconds per asked episode at {budgets[-1]} episodes",
        "",
        "The last batch's ask + tell per episode in CPU seconds (median over seeds, and the largest), its "
        "wall seconds (median; on a shared machine under `nice`, so larger), and the run's mean CPU seconds "
        "per asked episode.",
        "",
        timing_table(grouped, tasks, methods, budgets[-1]),
        "## Cost of a run (CPU seconds: the optimiser's, the env's and the evaluations')",
        "",
        cost_text(documents, args.specs),
    ]


def _per_task_sections(
    grouped: Cells, tasks: list[str], methods: list[Method], seeds: int, budgets: list[int]
) -> list[str]:
    """One table per task, under its group's heading."""
    text = [
        "## Per task",
        "",
        "Median over seeds (min–max) of the recommended policy's metric per budget.",
        "",
    ]
    for section, names in grouped_tasks(tasks).items():
        text += [f"## {section}", ""]
        for task in names:
            text += [f"### {task}", "", task_table(grouped, task, methods, seeds, budgets)]
    return text


def _failures(documents: list[dict[str, Any]]) -> list[str]:
    """The runs that stopped on an error, or nothing."""
    failed = sorted(
        f"`{d['spec']['task']}` `{d['spec']['method']}` seed {d['spec']['seed']}: {d['stop_reason']}"
        for d in documents
        if d["stop_reason"] != "budget"
    )
    if not failed:
        return []
    return [
        "## Runs that stopped on an error (their later budgets are missing)",
        "",
        *[f"- {f}" for f in failed],
        "",
    ]


def run_packages(spec: LowBudgetSpec) -> tuple[str, ...]:
    """The distributions whose versions a run's provenance records besides the core ones: pycma (as every
    study's), MuJoCo for a kick, and its column's GP library (:attr:`~columns.Method.packages`)."""
    kick = ("mujoco",) if task_by_name(spec.task).env_id.startswith("creps_gym/Kick") else ()
    return ("cma", *kick, *method_by_name(spec.method).packages)


def main(argv: Sequence[str] | None = None) -> int:
    """Run (or resume) the study and write its report."""
    args = parse_args(argv)
    specs = args.specs = study_specs(args)
    return run_study(
        args,
        specs,
        write_report,
        baselines={m.name: one_run for m in METHODS},
        title="Low-budget study (issue 44)",
        script="benchmarks/low_budget/run.py",
        figures_marker="\n## Per task",
        readme=HERE / "README.md",
        packages=run_packages,
    )


if __name__ == "__main__":
    raise SystemExit(main())
