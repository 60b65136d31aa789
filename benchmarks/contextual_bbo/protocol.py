"""One run of the IJCAI 2017 / GECCO 2019 protocol with a registered optimiser, and its result document.

A run asks its optimiser for N = 50 parameters per generation at fresh contexts s ~ U[1, 2)^{n_s}, tells it
the returns −f_s(θ), and records after every generation:

- the protocol's measure: the generation's average return, the mean of −f_s over its N episodes (the
  published tables give this at the last generation, averaged over the runs);
- ours: the mean over 100 fixed test contexts of the regret f_s(m(s)) of the optimiser's mean policy m(s)
  (its ``recommend``), and the episodes until that regret is ≤ 1e-5; beside it the same regret of the
  running search's mean (``policy.mean``), which differs from ``recommend`` only where a restart kept a
  better policy (``c-cma-es``'s ``keep_best``): it is what ``keep_best=False`` recommends on the same run.

Every episode counted is a true evaluation of f_s. A run that ends before its budget (the optimiser's stop
criteria fire with no restart left, or its update fails) keeps its last generation's values for the rest of
the budget, and its ``stop_reason`` says why.
"""

from __future__ import annotations

import math
import os
import platform
import sys
import time
from dataclasses import asdict, dataclass
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.contextual_bbo.problems import GENERATION, N_PARAMS, PROBLEMS, draw_run
from creps_gym.optimizers import make_optimizer

__all__ = ["CURVE_POINTS", "TARGET", "ProtocolSpec", "environment_record", "run_protocol"]

#: Regret target of our measure.
TARGET = 1e-5
#: Points of the stored curves (log-spaced generations plus the last).
CURVE_POINTS = 60


@dataclass(frozen=True)
class ProtocolSpec:
    """One run: a problem of :data:`PROBLEMS`, a registered optimiser with options, and a seed."""

    function: str
    method: str
    seed: int
    options: tuple[tuple[str, Any], ...] = ()
    label: str = ""  # the column's name when options are set (part of the key)

    def __post_init__(self) -> None:
        if self.function not in PROBLEMS:
            raise ValueError(f"function: expected one of {sorted(PROBLEMS)}, got {self.function!r}")
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or self.seed < 0:
            raise ValueError(f"seed: expected an integer >= 0, got {self.seed!r}")
        if self.options and not self.label.replace("-", "").isalnum():
            raise ValueError(f"label: expected a name of letters, digits and '-', got {self.label!r}")

    @property
    def samples(self) -> int:
        """N (``run_all`` groups a run's checkpoints by it)."""
        return GENERATION

    @property
    def column(self) -> str:
        """The table column: the label, or the method without options."""
        return self.label or self.method

    @property
    def prefix(self) -> str:
        """The key without the budget."""
        return f"{self.function}-{self.column}-s{self.seed}"

    @property
    def key(self) -> str:
        """File-name key of the run's document."""
        return f"{self.prefix}-b{PROBLEMS[self.function].episodes}-n{GENERATION}"


def environment_record() -> dict[str, str]:
    """Python, numpy, scipy and creps_gym versions, the platform and the CPU model the run computed on."""
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text(encoding="utf-8").splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    versions = {name: metadata.version(name) for name in ("numpy", "scipy", "creps_gym")}
    return {
        "python": sys.version.split()[0],
        **versions,
        "platform": platform.platform(),
        "cpu": cpu,
        "cores": str(os.cpu_count()),
    }


def _curve_indices(generations: int) -> list[int]:
    points = np.unique(np.geomspace(1, generations, CURVE_POINTS).astype(int)) - 1
    return sorted(set(points.tolist()) | {generations - 1})


def run_protocol(spec: ProtocolSpec, checkpoint_dir: Path | None = None) -> dict[str, Any]:
    """Run ``spec`` to its budget and return its result document (``checkpoint_dir`` is unused: a run takes
    seconds, the study resumes run by run)."""
    problem = PROBLEMS[spec.function]
    draw = draw_run(problem, spec.seed)
    start = time.perf_counter()
    optimizer = make_optimizer(
        spec.method,
        N_PARAMS,
        problem.context_dim,
        seed=draw.optimizer_seed,
        initial_mean=draw.initial_mean,
        initial_cov=problem.sigma0**2,
        **dict(spec.options),
    )
    averages, regrets, running, hit, stop_reason = [], [], [], None, "budget"
    for generation in range(problem.generations):
        contexts = draw.contexts(GENERATION)
        params = optimizer.ask(contexts)
        values = draw.evaluate(contexts, params)
        try:
            optimizer.tell(contexts, params, -values)
        except RuntimeError as error:
            stop_reason = f"error: {error}"
        averages.append(-float(values.mean()))
        recommended = optimizer.recommend(draw.test_contexts)
        regrets.append(float(draw.regret(draw.test_contexts, recommended).mean()))
        policy = getattr(optimizer, "policy", None)
        means = recommended if policy is None else policy.mean(draw.test_contexts)
        running.append(float(draw.regret(draw.test_contexts, means).mean()))
        if hit is None and regrets[-1] <= TARGET:
            hit = (generation + 1) * GENERATION
        met = optimizer.stop() if stop_reason == "budget" else {}
        if met:
            stop_reason = "optimizer: " + ", ".join(sorted(met))
        if stop_reason != "budget":
            break
    ran = len(averages)
    averages += [averages[-1]] * (problem.generations - ran)  # an early end keeps its last values
    regrets += [regrets[-1]] * (problem.generations - ran)
    running += [running[-1]] * (problem.generations - ran)
    indices = _curve_indices(problem.generations)
    return {
        "spec": {**asdict(spec), "options": dict(spec.options), "budget": problem.episodes},
        "key": spec.key,
        "hit": hit,
        "final": regrets[-1],
        "final_running": running[-1],
        "protocol_last": averages[-1],
        "generations_run": ran,
        "total_episodes": ran * GENERATION,
        "stop_reason": stop_reason,
        "restarts": float(getattr(optimizer, "restarts_done", 0)),
        "curve": {
            "generation": [i + 1 for i in indices],
            "average_return": [averages[i] for i in indices],
            "regret": [regrets[i] if math.isfinite(regrets[i]) else 1e300 for i in indices],
            "regret_running": [running[i] if math.isfinite(running[i]) else 1e300 for i in indices],
        },
        "seconds": round(time.perf_counter() - start, 3),
        "environment": environment_record(),
    }
