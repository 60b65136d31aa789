"""The low-budget study's methods, tasks and runs (issue 44, item 5): one run is one (task, method, seed).

A run asks its optimiser for whole batches of its recommended size until the next batch would pass the run's
budget (500 episodes in the study). Before the first batch that would pass each of the curve's budgets
(:data:`BUDGETS`: 50, 100, 200, 300, 500) it evaluates ``optimizer.recommend`` on the task's fixed test
contexts, so one run gives the whole curve. It also times the optimiser's own work (``ask`` and ``tell``; the
env's episodes and the evaluations excluded) per asked episode. Every method starts from the same
distribution: on the contextual functions mean 0 and σ = 2 (the issue's setting, that of ``compare.py``: the
box of ±3σ holds every context's optimum), on the low-dimensional robot ids their declared
``initial_distribution()``.

Methods are the rows of :data:`benchmarks.low_budget.columns.METHODS` (``columns.Method``: a registered
optimiser, its options and an optional context selector), so a variant, e.g. c-bo with an active context
selector, is one more entry.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

import creps_gym  # noqa: F401  (registers the ids)
from benchmarks.low_budget.columns import Method, method_by_name
from creps_gym.envs.evaluation import contextual_model, test_contexts
from creps_gym.optimizers import recommended_samples
from creps_gym.selectors import make_selector
from creps_gym.selectors.base import select_for

__all__ = [
    "BUDGETS",
    "FUNCTIONS",
    "NON_QUADRATIC",
    "ROBOT_TASKS",
    "LowBudgetSpec",
    "Run",
    "Task",
    "one_run",
    "run_until",
    "start_run",
    "task_by_name",
]

Array = NDArray[np.float64]
#: The curve's budgets (episodes): the recommended policy is evaluated at each (the issue's 50, 100, 200 and
#: 500, and 300, where its kick targets are set).
BUDGETS = (50, 100, 200, 300, 500)
#: The contextual functions' test contexts (``compare.py``'s: 100, seed 12345) and the robot ids' seed.
TEST_SEED, FUNCTION_TEST_CONTEXTS, ROBOT_TEST_CONTEXTS = 12_345, 100, 16
#: The functions' initial distribution: mean 0, σ = 2 (the issue's setting).
FUNCTION_MEAN, FUNCTION_STD = 0.0, 2.0
#: The quadratic functions and the non-quadratic ones of the suite (Rastrigin: multimodal).
QUADRATIC = ("Sphere", "ShiftedRotatedElliptic")
NON_QUADRATIC = ("Rosenbrock", "DifferentPowers", "Rastrigin")
FUNCTIONS = NON_QUADRATIC + QUADRATIC


@dataclass(frozen=True)
class Task:
    """A row of the study: a registered env id, its keyword arguments, and the metric of a policy.

    ``metric``: ``"regret"`` (the functions' mean regret), ``"error"`` (the kick precision's distance (m)
    from the ball's rest point to the target), ``"distance"`` (the kick flexibility's forward distance (m),
    0 after a fall; higher is better) or ``"cost"`` (minus the mean return, the reacher's).
    """

    name: str
    env_id: str
    metric: str
    env_kwargs: tuple[tuple[str, Any], ...] = ()
    function: str | None = None

    @property
    def lower_is_better(self) -> bool:
        """Whether a smaller metric is better (all but the kick flexibility's distance)."""
        return self.metric != "distance"

    @property
    def kick_experiment(self) -> str:
        """The kick study's experiment for a kick task: `"precision"` (error) or `"flexibility"`."""
        return "precision" if self.metric == "error" else "flexibility"

    def make_env(self, seed: int) -> Any:
        """The env's model (a function's instance is the run's seed, as in the other function studies)."""
        kwargs = dict(self.env_kwargs)
        if self.function is not None:
            kwargs["instance"] = seed
        return contextual_model(gym.make(self.env_id, **kwargs))


def function_task(function: str, dim: int, context_dim: int) -> Task:
    """The contextual function ``creps_gym/<function>-v0`` with p = ``dim``, z = ``context_dim``."""
    kwargs = (("context_dim", context_dim), ("dim", dim))
    return Task(f"{function}-p{dim}-z{context_dim}", f"creps_gym/{function}-v0", "regret", kwargs, function)


#: The low-dimensional robot tasks.
ROBOT_TASKS = (
    Task("KickPrecisionLowDim", "creps_gym/KickPrecisionLowDim-v0", "error"),
    Task("KickFlexibilityLowDim", "creps_gym/KickFlexibilityLowDim-v0", "distance"),
    Task("KickPrecisionLowDim-v1", "creps_gym/KickPrecisionLowDim-v1", "error"),
    Task("KickFlexibilityLowDim-v1", "creps_gym/KickFlexibilityLowDim-v1", "distance"),
    Task("KickPrecisionLowDim-v2", "creps_gym/KickPrecisionLowDim-v2", "error"),
    Task("KickFlexibilityLowDim-v2", "creps_gym/KickFlexibilityLowDim-v2", "distance"),
    Task("PlanarReacherLowDim", "creps_gym/PlanarReacherLowDim-v0", "cost"),
)


def task_by_name(name: str) -> Task:
    """The task called ``name``: a robot task's, or ``<Function>-p<p>-z<z>``."""
    for task in ROBOT_TASKS:
        if task.name == name:
            return task
    function, _, rest = name.partition("-p")
    dim, _, context_dim = rest.partition("-z")
    if function not in FUNCTIONS or not (dim.isdigit() and context_dim.isdigit()):
        robots = [t.name for t in ROBOT_TASKS]
        raise ValueError(
            f"task: expected one of {robots} or '<Function>-p<p>-z<z>' of {FUNCTIONS}, got {name!r}"
        )
    return function_task(function, int(dim), int(context_dim))


@dataclass(frozen=True)
class LowBudgetSpec:
    """One run: ``task`` and ``method`` (names) with ``seed``, up to ``budget`` episodes.

    ``samples`` is the method's batch size (its optimiser's recommended one for the task's dimensions, set
    on construction). The fields ``key``, ``prefix``, ``samples`` and ``method`` are those
    :func:`benchmarks.study_runner.run_all` uses (the cache's file names).
    """

    task: str
    method: str
    seed: int
    budget: int = BUDGETS[-1]
    samples: int = field(default=0)

    def __post_init__(self) -> None:
        task, method = task_by_name(self.task), method_by_name(self.method)
        for name, low in (("seed", 0), ("budget", 1)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < low:
                raise ValueError(f"{name}: expected an integer >= {low}, got {value!r}")
        if self.samples == 0:
            dim, context_dim = _dimensions(task)
            object.__setattr__(self, "samples", int(recommended_samples(method.optimizer, dim, context_dim)))

    @property
    def prefix(self) -> str:
        """The key without the budget."""
        return f"{self.task}-{self.method}-s{self.seed}"

    @property
    def key(self) -> str:
        """The cache file's name (without ``.json``)."""
        return f"{self.prefix}-b{self.budget}-n{self.samples}"

    @property
    def budgets(self) -> tuple[int, ...]:
        """The budgets the run records: those of :data:`BUDGETS` below its budget, and its budget."""
        return (*(b for b in BUDGETS if b < self.budget), self.budget)


_DIMENSIONS: dict[str, tuple[int, int]] = {}


def _dimensions(task: Task) -> tuple[int, int]:
    """(p, z) of a task (a robot id's are read from its env once)."""
    if task.function is not None:
        kwargs = dict(task.env_kwargs)
        return kwargs["dim"], kwargs["context_dim"]
    if task.name not in _DIMENSIONS:
        model = task.make_env(0)
        _DIMENSIONS[task.name] = (model.param_dim, model.context_dim)
    return _DIMENSIONS[task.name]


def evaluation_contexts(task: Task, model: Any) -> Array:
    """The fixed test contexts: the kick precision's 10 targets 3, 4, ..., 12 m, the kick flexibility's 28
    ball positions (the paper's, as ``benchmarks/kick``), else ``test_contexts`` with seed 12345."""
    if task.name.startswith("Kick"):
        from benchmarks.kick.study import evaluation_contexts as kick_contexts

        return kick_contexts(task.kick_experiment)
    count = FUNCTION_TEST_CONTEXTS if task.function is not None else ROBOT_TEST_CONTEXTS
    return test_contexts(model, count, TEST_SEED)


def policy_metric(task: Task, model: Any, contexts: Array, params: Array) -> float:
    """The task's metric of the parameters ``params`` (n, p) at ``contexts`` (n, z), a mean over them."""
    return policy_evaluation(task, model, contexts, params)[0]


def policy_evaluation(task: Task, model: Any, contexts: Array, params: Array) -> tuple[float, dict]:
    """:func:`policy_metric` and the episodes' ``info`` it came from (empty for a function's regret)."""
    if task.metric == "regret":
        return float(np.mean(model.regret(contexts, params))), {}
    returns, info = model.evaluate(contexts, params)
    if task.metric == "cost":
        return -float(np.mean(returns)), info
    from benchmarks.kick.study import episode_metric

    return float(np.mean(episode_metric(task.kick_experiment, contexts, info))), info


def initial_distribution(task: Task, model: Any) -> tuple[Array, Array]:
    """Mean and standard deviations (p,) every method starts from (see the module docstring)."""
    if task.function is not None:
        return np.full(model.param_dim, FUNCTION_MEAN), np.full(model.param_dim, FUNCTION_STD)
    mean, std = model.initial_distribution()
    return np.asarray(mean, dtype=np.float64), np.asarray(std, dtype=np.float64)


def make_run_selector(method: Method, model: Any) -> Any:
    """The method's context selector bound to the env's context box, or None."""
    if method.selector is None:
        return None
    selector = make_selector(method.selector, dict(method.selector_options))
    space = model.observation_space  # the context box
    selector.bind(
        np.asarray(space.low, np.float64), np.asarray(space.high, np.float64), model.sample_contexts
    )
    return selector


#: What a run's curve records at each budget: the state's entries (see :func:`run_batch`) and the value.
CURVE_FIELDS = ("episodes", "values", "spent", "spent_cpu", "last", "last_cpu")


@dataclass
class Run:
    """A run's parts (:func:`start_run`): its spec, task and method, the env, the optimiser, the context
    selector (or None), the training contexts' Generator, the test contexts and ``state`` (the episodes told
    and the optimiser's seconds, see :func:`run_batch`)."""

    spec: LowBudgetSpec
    task: Task
    method: Method
    model: Any
    optimizer: Any
    selector: Any
    rng: np.random.Generator
    test: Array
    state: dict[str, Any]


def start_run(spec: LowBudgetSpec, method: Method | None = None) -> Run:
    """``spec``'s run before its first batch: every method from :func:`initial_distribution`, the training
    contexts from ``default_rng([seed, 1])`` (or the selector's stream). ``method`` replaces the column of
    ``spec.method`` (a replay's variant of it, e.g. ``benchmarks/low_budget/refit_data.py``)."""
    task, method = task_by_name(spec.task), method or method_by_name(spec.method)
    model = task.make_env(spec.seed)
    mean, std = initial_distribution(task, model)
    start_options = {"initial_mean": mean, "initial_cov": std**2, **dict(method.options)}
    optimizer = method.build(model.param_dim, model.context_dim, spec.seed, **start_options)
    selector = make_run_selector(method, model)
    rng = np.random.default_rng([spec.seed, 1])
    test = evaluation_contexts(task, model)
    state: dict[str, Any] = {"episodes": 0, "spent": 0.0, "spent_cpu": 0.0, "last": None, "last_cpu": None}
    return Run(spec, task, method, model, optimizer, selector, rng, test, state)


def run_until(run: Run, budget: int, before_batch: Callable[[Run], None] | None = None) -> None:
    """Whole batches while the next one stays within ``budget`` episodes; ``before_batch(run)`` before each
    (a replay's measurement; it must leave the optimiser as it was)."""
    while run.state["episodes"] + run.spec.samples <= budget:
        if before_batch is not None:
            before_batch(run)
        run_batch(run.spec, run.model, run.optimizer, run.selector, run.rng, run.state)


def one_run(spec: LowBudgetSpec, method: Method | None = None) -> dict[str, Any]:
    """Run ``spec`` and return its result document (see the module docstring and :func:`_document`);
    ``method`` as in :func:`start_run` (its document then records that column's options under ``spec``'s
    key: a replay's, never to be cached in the study's ``runs/``)."""
    start, start_cpu = time.perf_counter(), time.process_time()
    run = start_run(spec, method)
    curve: dict[str, list[Any]] = {name: [] for name in CURVE_FIELDS}
    recorded, stop_reason = 0, "budget"
    try:
        for budget in spec.budgets:
            run_until(run, budget)
            value = policy_metric(run.task, run.model, run.test, run.optimizer.recommend(run.test))
            _record(curve, run.state, value)
            recorded += 1
    except (ArithmeticError, ValueError, RuntimeError, np.linalg.LinAlgError) as error:
        stop_reason = f"error: {type(error).__name__}: {error}"  # the budgets left are recorded as None
        for _ in spec.budgets[recorded:]:
            _record(curve, {**run.state, "last": None, "last_cpu": None}, None)
    seconds = (time.perf_counter() - start, time.process_time() - start_cpu)
    return _document(spec, run.task, run.method, curve, stop_reason, seconds, len(run.test))


def _record(curve: dict[str, list[Any]], state: dict[str, Any], value: float | None) -> None:
    """Append one budget's entries: the state's (episodes, optimiser seconds) and the policy's value."""
    for name in CURVE_FIELDS:
        curve[name].append(value if name == "values" else state[name])


def run_batch(
    spec: LowBudgetSpec, model: Any, optimizer: Any, selector: Any, rng: np.random.Generator, state: dict
) -> None:
    """Ask, evaluate and tell one batch; ``state`` gains its episodes and the optimiser's seconds (wall:
    ``spent``, ``last``; this process's CPU: ``spent_cpu``, ``last_cpu``; ``last*`` per episode)."""
    contexts = (
        model.sample_contexts(rng, spec.samples)
        if selector is None
        else select_for(selector, rng, spec.samples, optimizer)
    )
    clock, cpu = time.perf_counter(), time.process_time()
    params = optimizer.ask(contexts)
    seconds, cpu_seconds = time.perf_counter() - clock, time.process_time() - cpu
    returns = np.asarray(model.evaluate(contexts, params)[0], dtype=np.float64)
    clock, cpu = time.perf_counter(), time.process_time()
    optimizer.tell(contexts, params, returns)
    seconds, cpu_seconds = seconds + time.perf_counter() - clock, cpu_seconds + time.process_time() - cpu
    if selector is not None:
        diagnostics = {str(k): float(v) for k, v in dict(optimizer.diagnostics).items()}
        selector.tell(contexts, returns, diagnostics)
    state["episodes"] += spec.samples
    state["spent"] += seconds
    state["spent_cpu"] += cpu_seconds
    state["last"], state["last_cpu"] = seconds / spec.samples, cpu_seconds / spec.samples


def _document(
    spec: LowBudgetSpec,
    task: Task,
    method: Method,
    curve: dict[str, list[Any]],
    stop_reason: str,
    seconds: tuple[float, float],
    test_count: int,
) -> dict[str, Any]:
    """A run's JSON document.

    ``budgets``, and per budget: ``episodes`` (those spent: whole batches), ``values`` (the task's metric of
    ``recommend`` on the test contexts), ``optimizer_seconds`` and ``optimizer_cpu_seconds`` (its ask and
    tell so far: wall, and this process's CPU time) and ``last_batch_seconds_per_episode`` and
    ``last_batch_cpu_seconds_per_episode`` (the last batch's ask and tell per episode: what a robot waits
    for at that budget). ``seconds`` and ``cpu_seconds`` are the whole run's (env and evaluations
    included). ``final`` is the value at the largest budget; ``hit`` is None (the study has no target;
    :func:`benchmarks.study_runner.run_all` logs it).
    """
    values = [v if v is None or np.isfinite(v) else None for v in curve["values"]]
    rounded = {
        name: [None if v is None else round(v, digits) for v in curve[field]]
        for name, field, digits in (
            ("optimizer_seconds", "spent", 4),
            ("optimizer_cpu_seconds", "spent_cpu", 4),
            ("last_batch_seconds_per_episode", "last", 5),
            ("last_batch_cpu_seconds_per_episode", "last_cpu", 5),
        )
    }
    return {
        "spec": asdict(spec),
        "task": task.name,
        "env_id": task.env_id,
        "env_kwargs": dict(task.env_kwargs),
        "method": {
            "optimizer": method.optimizer,
            "options": dict(method.options),
            "selector": method.selector,
            **({} if method.factory is None else {"factory": method.factory}),
        },
        "metric": task.metric,
        "test_contexts": test_count,
        "budgets": list(spec.budgets),
        "episodes": curve["episodes"],
        "values": values,
        **rounded,
        "hit": None,
        "final": values[-1],
        "total_episodes": curve["episodes"][-1],
        "stop_reason": stop_reason,
        "seconds": round(seconds[0], 3),
        "cpu_seconds": round(seconds[1], 3),
    }
