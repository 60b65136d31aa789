"""Context selection study: uniform, arcsine, bandit and continuous selectors beside each other.

Every run is the generic runner (:func:`creps_gym.runner.run`) with a ``context_selector``; the mean policy
is evaluated every few iterations on the env's own 32 test contexts (from the run's evaluation seed, the
same for every selector of a trial), never on the selector's. Tasks:

* ``reacher``: ``creps_gym/PlanarReacher-v0`` (2-D via-points in [0, 2]² m), 50 samples per iteration,
  initial standard deviation 1 (as ``benchmarks/reacher``); loss = minus the mean return (m² + smoothness).
* ``steep-sphere`` and ``steep-rosenbrock``: :class:`benchmarks.contexts.tasks.SteepFunction` (p = 5,
  z = 1): the regret is scaled by ``100 ** u(s)``, so one end of the context box needs a 10x more precise
  policy (see its docstring for why the registered functions could not serve); loss = mean regret.

Per task and optimiser, the target is uniform training's final loss (mean over trials); a selector's
"episodes to target" is the first evaluation at which a trial's loss is at or below it, and the ratio is
that against uniform's own episodes to the same target (the issue's target: <= 0.67).

    python benchmarks/contexts/run.py --quick           # about a minute on 2 cores
    python benchmarks/contexts/run.py --full            # resumable: runs are cached in results/full.json
    python benchmarks/contexts/run.py --full --render-only
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

if not __package__:  # run by path: the repository root first on sys.path (see benchmarks/__init__.py)
    sys.path[0] = str(Path(__file__).resolve().parents[2])

from benchmarks.contexts.report import render, with_headline
from benchmarks.contexts.tasks import SteepFunction
from benchmarks.study_options import C3_PIN

RESULTS = Path(__file__).resolve().parent / "results"
DOC = Path(__file__).resolve().parents[2] / "docs" / "contexts.md"
SELECTORS = ("uniform", "arcsine", "bandit", "progress")
#: The study's optimisers: label -> (registry name, options). ``c-cma-es-cm0.5`` moves C-CMA-ES's mean half
#: way to each new fit (Eq. C3'): under a selector's moving draws a full step chases the batch's contexts
#: and the step size grows (docs/contexts.md, "A selector can break an optimiser"). ``c-cma-es-c3r`` is the
#: default since issue 45 (C3r, docs/algorithms.md), measured here before the default changed; the other two
#: keep C3, the default their runs were computed with (benchmarks/study_options.py).
OPTIMIZERS: dict[str, tuple[str, dict[str, Any]]] = {
    "c-cma-es": ("c-cma-es", dict(C3_PIN)),
    "c-cma-es-cm0.5": ("c-cma-es", {"c_m": 0.5, **dict(C3_PIN)}),
    "c-cma-es-c3r": ("c-cma-es", {"ridge_centre": "old"}),
    "creps-cma-old": ("creps-cma-old", {}),
}
#: Per mode: trials, and per task (iterations, samples or None for the optimiser's recommended batch,
#: evaluate every).
MODES: dict[str, dict[str, Any]] = {
    "quick": {
        "trials": 3,
        "reacher": (8, 30, 2),
        "steep-sphere": (20, None, 5),
        "steep-rosenbrock": (20, None, 5),
    },
    "full": {
        "trials": 5,
        "reacher": (60, 50, 5),
        "steep-sphere": (100, None, 5),
        "steep-rosenbrock": (150, None, 5),
    },
}
EVAL_CONTEXTS = 32


def make_task(task: str) -> tuple[Any, dict[str, Any]]:
    """The env (an id or an object) and the run options of ``task``."""
    if task == "reacher":
        return "creps_gym/PlanarReacher-v0", {"initial_std": 1.0}
    return SteepFunction(task.removeprefix("steep-").capitalize()), {}


def one_run(task: str, optimizer: str, selector: str, trial: int, mode: str) -> dict[str, Any]:
    """Train one run (``optimizer`` a label of :data:`OPTIMIZERS`); its learning curve (episodes, loss) at
    every evaluation."""
    from creps_gym.runner import run

    iterations, samples, every = MODES[mode][task]
    env, options = make_task(task)
    name, optimizer_options = OPTIMIZERS[optimizer]
    start = time.perf_counter()
    history = run(
        name,
        env,
        iterations,
        samples,
        trial,
        eval_every=every,
        eval_contexts=EVAL_CONTEXTS,
        context_selector=selector,
        optimizer_options=optimizer_options,
        **options,
    )
    evaluated = [r for r in history.records if r.iteration % every == 0 or r is history.records[-1]]
    regret = history.meta["metric"] == "regret"
    loss = [r.eval_regret if regret else -r.eval_return for r in evaluated]
    return {
        "episodes": [r.episodes for r in evaluated],
        "loss": loss,
        "budget": [iterations, history.meta["samples"]],
        "seconds": round(time.perf_counter() - start, 3),
    }


def machine() -> dict[str, Any]:
    """Package versions and the CPU the numbers were measured on."""
    from creps_gym.runner import package_versions

    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {"versions": package_versions(), "cpu": cpu, "cpus": os.cpu_count()}


def load(path: Path) -> dict[str, Any]:
    return json.loads(path.read_text()) if path.exists() else {"runs": {}}


def save(path: Path, document: dict[str, Any]) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(document, indent=1, sort_keys=True) + "\n")
    os.replace(tmp, path)


def compute(mode: str, path: Path, tasks: Sequence[str]) -> dict[str, Any]:
    """Every (task, optimiser, selector, trial) run of ``mode`` not in ``path`` yet; saved after each run."""
    document = load(path)
    document.update(mode=mode, budgets=MODES[mode], eval_contexts=EVAL_CONTEXTS, **machine())
    for task in tasks:
        for trial in range(MODES[mode]["trials"]):
            for optimizer in OPTIMIZERS:
                for selector in SELECTORS:
                    key = f"{task}/{optimizer}/{selector}/{trial}"
                    iterations = MODES[mode][task][0]
                    cached = document["runs"].get(key)
                    if cached is not None and cached["budget"][0] == iterations:
                        continue
                    document["runs"][key] = result = one_run(task, optimizer, selector, trial, mode)
                    print(f"{key}: loss {result['loss'][-1]:.4g} ({result['seconds']:.1f} s)", flush=True)
                    save(path, document)
    return document


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="Compare context selectors (uniform, arcsine, bandit, ...).")
    group = parser.add_mutually_exclusive_group()
    group.add_argument("--quick", action="store_true", help="small budgets (default)")
    group.add_argument("--full", action="store_true", help="the study's budgets")
    parser.add_argument("--render-only", action="store_true", help="compute nothing; render the results")
    parser.add_argument(
        "--tasks", nargs="+", default=None, choices=[t for t in MODES["full"] if t != "trials"]
    )
    args = parser.parse_args(argv)
    mode = "full" if args.full else "quick"
    path = RESULTS / f"{mode}.json"
    RESULTS.mkdir(exist_ok=True)
    tasks = args.tasks or [t for t in MODES[mode] if t != "trials"]
    document = load(path) if args.render_only else compute(mode, path, tasks)
    text = render(document)
    (RESULTS / f"{mode}.md").write_text(text)
    if mode == "full" and DOC.exists():  # the doc quotes the full study's headline table
        DOC.write_text(with_headline(DOC.read_text(), document))
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
