"""Shared machinery of the studies (``functions/``, ``scaling/``, ``ccmaes/``): runs and their cache.

One *run* is one (function, p, z, method, seed) with an episode budget. :func:`execute` runs it: a method
that is a registered optimiser (the paper's ``creps``, ``creps-cma-old``, ``creps-cma-current``, or any other
registry name) through :func:`creps_gym.runner.run`, a baseline through the runner the study passes in (a
mapping from method name to a callable, e.g. :data:`benchmarks.baselines.BASELINES`: this module imports no
baseline). Every run's result is a small JSON document cached on disk; :mod:`benchmarks.study_runner` skips
runs whose file exists (an interrupted study resumes) and computes the others in a process pool.

The metric is the paper's: the mean over a fixed set of test contexts of the regret of the mean policy, with
the target 1e-5; for the functions unbounded below (Plane, the ridges) it is the mean of f, with the target
f <= -1e4. Curves are stored at up to :data:`CURVE_POINTS` log-spaced iterations plus the last one.
"""

from __future__ import annotations

import fnmatch
import json
import math
import os
from collections.abc import Callable, Collection, Mapping, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from benchmarks.study_options import canonical_options, config_fields
from creps_gym.envs.functions import SPECS
from creps_gym.envs.functions.specs import UNBOUNDED_TARGET
from creps_gym.optimizers import optimizer_names
from creps_gym.runner import default_initial_distribution, resume, run
from creps_gym.runner.seeds import SeedPlan, seed_child

__all__ = [
    "CHECKPOINT_EVERY",
    "CURVE_POINTS",
    "DIVERGENCE_GROWTH",
    "EARLY_STOPS",
    "INITIALS",
    "MAX_CHECKPOINTS",
    "PAPER_METHODS",
    "Baselines",
    "RunSpec",
    "cached_result",
    "curve_indices",
    "ended_early",
    "execute",
    "function_spec",
    "initial_distribution",
    "is_bounded",
    "load_document",
    "result_document",
    "store_document",
    "write_text",
]

#: The paper's three algorithms (registry names).
PAPER_METHODS = ("creps", "creps-cma-old", "creps-cma-current")
#: Maximum number of curve points stored per run.
CURVE_POINTS = 300
#: Fewest iterations between the checkpoints of a run computed by ``run_all`` (seconds of work at p = 64).
CHECKPOINT_EVERY = 2000
#: Most checkpoints per run: each one rewrites the run's history, so a fixed interval would cost O(n²).
MAX_CHECKPOINTS = 20
#: A run of a paper method stops as diverged once √λ_max(Σ) exceeds this multiple of its initial value (the
#: optimiser's ``max_std_growth``); converging runs stay within a few times the initial value.
DIVERGENCE_GROWTH = 1000.0
#: CREPS-family runs never stop on stagnation (their ``tolstagnation``): the committed runs were computed
#: before that criterion existed, and a stalled paper method is reported by its budget running out.
NO_STAGNATION = 10**9
#: Initial search distributions of a run (see :func:`initial_distribution`).
INITIALS = ("centre", "uniform5")
#: Stop reasons of a run that ended before its budget ran out (besides the optimiser's ``"optimizer: ..."``).
EARLY_STOPS = ("target_regret", "callback", "target")


@dataclass(frozen=True)
class RunSpec:
    """One run of a study.

    Parameters
    ----------
    function : str
        Function name, as in ``creps_gym/<function>-v0``.
    dim, context_dim : int
        p and z.
    method : str
        A registered optimiser's name (run through the runner) or a baseline's name (run by the callable the
        study passes to :func:`execute`, see :mod:`benchmarks.baselines`).
    seed : int
        Master seed of the run; the function instance (A, shift, rotation) is ``instance = seed``.
    budget : int
        Maximum number of training episodes.
    samples : int
        Episodes per iteration (batch size N) of a registered optimiser, and of ``cma-fixed-batch``.
    max_interpolation : float
        CREPS-CMA's cap of λ (1: Eq. (14) as published). Since φ_eff <= N, a cap >= samples / dim² never
        binds: such a spec *is* the uncapped run and shares its key.
    divide_by_z : bool
        CREPS-CMA's ``divide_by_z`` (True: Eqs. (12) and (15) as published).
    eval_contexts : int
        Number of fixed test contexts of the metric (the runner's ``eval_contexts``).
    initial : str
        Initial search distribution (see :func:`initial_distribution`): ``"centre"`` (the runner's default)
        or ``"uniform5"`` (mean U[-5, 5]^p drawn from the seed, the same for every context, σ0 = 1).
    options : tuple of (name, value) pairs, or a mapping
        Further options of the registered optimiser ``method`` (names of its config fields; values bool,
        int, float or str), sorted by name. They end the key's prefix (``-name=value`` each); without them
        the key is the same as before the field existed.
    divergence : float or None
        The runner's divergence rule (``RunConfig.divergence``); None (the studies' default) turns it off, as
        for every run computed before the field existed. A factor ends the key's prefix (``-div<factor>``).
    """

    function: str
    dim: int
    context_dim: int
    method: str
    seed: int
    budget: int
    samples: int = 50
    max_interpolation: float = 1.0
    divide_by_z: bool = True
    eval_contexts: int = 16
    initial: str = "centre"
    options: tuple[tuple[str, Any], ...] = ()
    divergence: float | None = None

    def __post_init__(self) -> None:
        function_spec(self.function)  # raises for an unknown function
        if self.divergence is not None and not (
            isinstance(self.divergence, int | float)
            and not isinstance(self.divergence, bool)
            and 0.0 < self.divergence < math.inf
        ):
            got = self.divergence
            raise ValueError(f"divergence: expected None or a positive finite number, got {got!r}")
        object.__setattr__(self, "options", canonical_options(self.method, self.options))
        if not isinstance(self.method, str) or not self.method.replace("-", "").isalnum():
            raise ValueError(f"method: expected a name of letters, digits and '-', got {self.method!r}")
        if self.initial not in INITIALS:
            raise ValueError(f"initial: expected one of {list(INITIALS)}, got {self.initial!r}")
        minimum = {"dim": 2, "context_dim": 1, "seed": 0, "samples": 2, "budget": self.samples}
        minimum["eval_contexts"] = 1
        for name, low in minimum.items():
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < low:
                raise ValueError(f"{name}: expected an integer >= {low}, got {value!r}")
        if not 0.0 < self.max_interpolation <= 1.0:
            raise ValueError(f"max_interpolation: expected a value in (0, 1], got {self.max_interpolation!r}")
        variants = ("creps-cma-old", "creps-cma-current")
        if self.max_interpolation < 1.0 and self.method not in variants:
            raise ValueError(f"max_interpolation: expected 1 for method {self.method!r}, got a cap")
        if not self.divide_by_z and self.method not in variants:
            raise ValueError(f"divide_by_z: expected True for method {self.method!r}, got False")
        if self.max_interpolation >= self.samples / self.dim**2 * (1.0 + 1e-9):  # (rounding of φ_eff)
            object.__setattr__(self, "max_interpolation", 1.0)  # never binds: the same run as uncapped

    @property
    def prefix(self) -> str:
        """The key without the budget: the runs that differ only in their budget share it."""
        cap = "" if self.max_interpolation == 1.0 else f"-cap{self.max_interpolation!r}"
        cap += "" if self.divide_by_z else "-noz"
        cap += "" if self.eval_contexts == 16 else f"-e{self.eval_contexts}"
        cap += "" if self.initial == "centre" else f"-{self.initial}"
        cap += "".join(f"-{name}={value}" for name, value in self.options)
        cap += "" if self.divergence is None else f"-div{self.divergence:g}"
        return f"{self.function}-p{self.dim}-z{self.context_dim}-{self.method}{cap}-s{self.seed}"

    @property
    def key(self) -> str:
        """File-name key, unique per run (the budget is part of it: a new budget is a new run)."""
        return f"{self.prefix}-b{self.budget}-n{self.samples}"

    @property
    def env_id(self) -> str:
        """The registered id of the function."""
        return f"creps_gym/{self.function}-v0"

    @property
    def env_kwargs(self) -> dict[str, int]:
        """``gymnasium.make`` keyword arguments."""
        return {"dim": self.dim, "context_dim": self.context_dim, "instance": self.seed}


def initial_distribution(
    spec: RunSpec, action_space: Any = None
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Initial mean and standard deviations (p,) of a run: for ``"centre"`` the runner's default, the centre
    and a quarter of the width of ``action_space`` (the env's, required then); for ``"uniform5"`` a mean drawn
    from U[-5, 5]^p (the seed's ``SeedSequence`` child ``SeedPlan.INITIAL_MEAN``, the runner's stream for
    initial means) and σ0 = 1."""
    if spec.initial == "centre":
        if action_space is None:
            raise ValueError("action_space: expected the env's action space for initial 'centre', got None")
        return default_initial_distribution(action_space)
    stream = seed_child(spec.seed, SeedPlan.INITIAL_MEAN)
    return np.random.default_rng(stream).uniform(-5.0, 5.0, spec.dim), np.ones(spec.dim)


def function_spec(name: str) -> Any:
    """The :class:`~creps_gym.envs.functions.FunctionSpec` called ``name``."""
    for spec in SPECS:
        if spec.name == name:
            return spec
    raise ValueError(f"function: expected one of {[s.name for s in SPECS]}, got {name!r}")


def is_bounded(name: str) -> bool:
    """Whether the function has a minimum (regret metric) rather than the f <= -1e4 target."""
    return bool(function_spec(name).bounded)


def curve_indices(n: int, points: int = CURVE_POINTS) -> NDArray[np.int64]:
    """Up to ``points`` log-spaced indices into a length-``n`` curve, always with the first and last."""
    if n <= points:
        return np.arange(n)
    raw = np.unique(np.round(np.geomspace(1, n, points)).astype(np.int64) - 1)
    return np.union1d(raw, [0, n - 1])


def result_document(
    spec: RunSpec,
    episodes: Sequence[float],
    values: Sequence[float],
    stop_reason: str | None,
    seconds: float,
    **extra: Any,
) -> dict[str, Any]:
    """The cached JSON document of a run: its spec, the (thinned) curve, the hit and the final value.

    ``values`` are the metric (regret, or f for unbounded functions) after each entry of ``episodes``;
    ``hit`` is the first episode count at which the metric met the paper's target (None if never).
    """
    episodes_arr = np.asarray(episodes, dtype=np.float64)
    values_arr = np.asarray(values, dtype=np.float64)
    target = function_spec(spec.function).target
    met = np.flatnonzero(values_arr <= target)
    keep = curve_indices(len(values_arr))
    # Without options or a divergence rule, the spec is described as before those fields existed.
    unset = {"options": (), "divergence": None}
    described = {name: v for name, v in asdict(spec).items() if name not in unset or v != unset[name]}
    return {
        "spec": described,
        "metric": "regret" if is_bounded(spec.function) else "f",
        "target": target,
        "episodes": [int(e) for e in episodes_arr[keep]],
        "values": [_finite_or_none(v) for v in values_arr[keep]],
        "hit": int(episodes_arr[met[0]]) if met.size else None,
        "final": _finite_or_none(values_arr[-1]) if values_arr.size else None,
        "total_episodes": int(episodes_arr[-1]) if episodes_arr.size else 0,
        "stop_reason": stop_reason,
        "seconds": round(float(seconds), 3),
        **extra,
    }


def _finite_or_none(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None


def _reached_f_target(record: Any, history: Any) -> bool:
    """Callback: stop an unbounded function's run once the mean f on the test contexts is <= -1e4."""
    return bool(-record.eval_return <= UNBOUNDED_TARGET)


def optimizer_result(spec: RunSpec, checkpoint_dir: Path | None = None) -> dict[str, Any]:
    """Run a registered optimiser (``spec.method``) through the runner and return its result document.

    Episodes run on the functions' native vector env (bit-identical to one env per episode, and about
    twice as fast). Contexts are read from one seeded reset per episode (``context_draws="reset"``, the
    runner's stream before issue 14), so every cached document stays what this code computes. An
    optimiser with a ``max_std_growth`` option stops a diverging run (:data:`DIVERGENCE_GROWTH`) and never
    stops on stagnation (:data:`NO_STAGNATION`). The runner's ``divergence`` stop is off unless
    ``spec.divergence`` sets it: 14 committed
    runs diverge, and the tables report how far they went before their optimiser stopped them. With
    ``checkpoint_dir``, the run checkpoints there (at
    most :data:`MAX_CHECKPOINTS` times, at least :data:`CHECKPOINT_EVERY` iterations apart) and a run
    interrupted earlier continues from its last checkpoint instead of restarting.
    """
    bounded = is_bounded(spec.function)
    callbacks = () if bounded else (_reached_f_target,)
    if checkpoint_dir is not None and (checkpoint_dir / "config.json").exists():
        history = resume(checkpoint_dir, callbacks=callbacks)
    else:
        iterations = max(1, spec.budget // spec.samples)
        options: dict[str, Any] = {}
        start: dict[str, Any] = {}
        if "max_std_growth" in config_fields(spec.method):
            options["max_std_growth"] = DIVERGENCE_GROWTH
            options["tolstagnation"] = NO_STAGNATION
        if spec.max_interpolation < 1.0:
            options["max_interpolation"] = spec.max_interpolation
        if not spec.divide_by_z:
            options["divide_by_z"] = False
        options.update(spec.options)
        if spec.initial != "centre":  # else the runner's default, the same
            mean, std = initial_distribution(spec)
            start = {"initial_mean": mean.tolist(), "initial_std": std.tolist()}
        history = run(
            spec.method,
            spec.env_id,
            iterations=iterations,
            samples_per_iteration=spec.samples,
            seed=spec.seed,
            env_kwargs=spec.env_kwargs,
            optimizer_options=options,
            target_regret=function_spec(spec.function).target if bounded else None,
            callbacks=callbacks,
            eval_every=1,
            eval_contexts=spec.eval_contexts,
            backend="vector",
            vector_mode="native",
            context_draws="reset",  # the stream the committed run caches were computed with (see below)
            divergence=spec.divergence,  # None: the committed caches predate the runner's divergence stop
            run_dir=checkpoint_dir,
            checkpoint_every=max(CHECKPOINT_EVERY, iterations // MAX_CHECKPOINTS),
            **start,
        )
    values = history.column("eval_regret") if bounded else -history.column("eval_return")
    seconds = history.records[-1].wall_time if history.records else 0.0  # summed over resumes
    return result_document(spec, history.column("episodes"), values, history.stop_reason, seconds)


#: Baseline runners: method name -> ``f(spec) -> result document`` (module-level functions, so a process
#: pool can send them).
Baselines = Mapping[str, Callable[[RunSpec], dict[str, Any]]]


def execute(
    spec: RunSpec, checkpoint_dir: Path | None = None, baselines: Baselines | None = None
) -> dict[str, Any]:
    """Run one spec and return its result document.

    ``spec.method`` is looked up first in ``baselines`` (name -> runner), then in the optimiser registry.
    ``checkpoint_dir`` makes a registered optimiser's run resumable (see :func:`optimizer_result`); the
    baselines are short and ignore it.
    """
    baselines = baselines or {}
    if spec.method in baselines:
        return baselines[spec.method](spec)
    if spec.method in optimizer_names():
        return optimizer_result(spec, checkpoint_dir)
    raise ValueError(
        f"method: expected a registered optimiser {optimizer_names()} or a baseline {sorted(baselines)}, "
        f"got {spec.method!r}"
    )


def cached_result(cache: Path, spec: RunSpec, names: Collection[str] | None = None) -> dict[str, Any] | None:
    """The cached document of ``spec``, or of the same run with a smaller budget that did not use it up.

    A run is deterministic and its budget only sets where it is cut off, so a run that ended before its
    budget ran out (it met the target, or the optimiser stopped) is the same run under any larger budget.
    Raising the budget of a study therefore recomputes only its censored runs. ``names`` is the folder's
    listing (``os.listdir(cache)``) from a caller that looks up many specs, so the folder of thousands of
    runs is not listed again for each.
    """
    exact = load_document(cache / f"{spec.key}.json")
    if exact is not None:
        return exact
    pattern = f"{spec.prefix}-b*-n{spec.samples}.json"
    for name in sorted(fnmatch.filter(os.listdir(cache) if names is None else names, pattern)):
        document = load_document(cache / name)
        if document is not None and document["spec"]["budget"] <= spec.budget and ended_early(document):
            return document
    return None


def ended_early(document: dict[str, Any]) -> bool:
    """Whether a run's document would be the same under any larger budget: it met its target or its
    optimiser stopped (its stop reason is in :data:`EARLY_STOPS` or starts with ``optimizer``). A baseline
    whose result depends on the budget reports another stop reason (``cma-regression``: ``"regression"``)."""
    reason = str(document["stop_reason"])
    return reason in EARLY_STOPS or reason.startswith("optimizer")


def load_document(path: Path) -> dict[str, Any] | None:
    """The JSON document at ``path``, or None if it is missing or partly written."""
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError):
        return None  # missing or a partial write: recompute


def store_document(path: Path, document: dict[str, Any]) -> None:
    """Write a run's document to ``path`` (JSON, atomically)."""
    write_text(path, json.dumps(document, allow_nan=False) + "\n")


def write_text(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` atomically (a temporary file, then renamed)."""
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)
