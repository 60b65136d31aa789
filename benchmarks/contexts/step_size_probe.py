"""Probe: C-CMA-ES's step size on the steep Rosenbrock under uniform draws, under the bandit's, and under a
fixed draw skewed towards the steep end like the bandit's (Beta(2, 1)): is it the skew or the moving
distribution that makes the step size grow?

Prints, for seeds 0-4 (the study's full-mode trials and budget), the step size (``diagnostics["step_size"]``)
at iterations 1, 50, 100 and 150, the final mean regret and the restarts (the runner's divergence rule
restarts a diverged search), per selector. ``docs/contexts.md`` quotes it.

    python benchmarks/contexts/step_size_probe.py
"""

from __future__ import annotations

import sys
from pathlib import Path

if not __package__:  # run by path: the repository root first on sys.path (see benchmarks/__init__.py)
    sys.path[0] = str(Path(__file__).resolve().parents[2])

from benchmarks.contexts.run import EVAL_CONTEXTS, MODES
from benchmarks.contexts.tasks import SteepFunction
from benchmarks.study_options import C3_PIN
from creps_gym.runner import run

CHECKPOINTS = (1, 50, 100, 150)


def main() -> int:
    iterations, samples, every = MODES["full"]["steep-rosenbrock"]
    for selector, options in (("uniform", {}), ("bandit", {}), ("beta", {"a": 2.0, "b": 1.0})):
        for seed in range(MODES["full"]["trials"]):
            task = SteepFunction("Rosenbrock")
            history = run(
                "c-cma-es",
                task,
                iterations,
                samples,
                seed,
                eval_every=every,
                eval_contexts=EVAL_CONTEXTS,
                context_selector=selector,
                context_selector_options=options,
                optimizer_options=dict(C3_PIN),  # C3, the default of docs/contexts.md's measurements
            )
            steps = {r.iteration: r.diagnostics["step_size"] for r in history.records}
            shown = ", ".join(f"{i}: {steps[i]:.3g}" for i in CHECKPOINTS if i in steps)
            final, restarts = history.records[-1].eval_regret, history.records[-1].diagnostics["restarts"]
            print(
                f"{selector} {options or ''} seed {seed}: step size {shown}; final regret {final:.3g}; "
                f"restarts {restarts:g}"
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
