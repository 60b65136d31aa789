"""What a user would do instead of a contextual optimiser, measured with the same metric and test contexts.

* ``cma-fixed``: pycma's CMA-ES (through the registry's ``cma`` adapter, default population size
  4 + floor(3 ln p)) on **one** fixed context, the first of the run's test contexts. It measures the cost of
  solving a single task: the episodes until the regret at that context meets the paper's target (f <= -1e4
  for the functions unbounded below).
* ``cma-fixed-batch``: the same with the population size of the contextual methods, ``spec.samples``.
* ``cma-regression``: the naive contextual approach of the paper's related work. CMA-ES runs independently on
  K training contexts (z = 1: 5 points evenly spaced over [0, 3]; z > 1: the 2^z corners of [0, 3]^z and the
  centre), each until its own regret is at most a tenth of the target (f <= -1e4 for the unbounded ones) or
  its share of the budget is spent; then a linear least-squares map from [1, s] to theta is fitted to the K
  solutions and evaluated, like the contextual methods, as the mean regret (or mean f) on the run's test
  contexts. The total episodes over the K runs are reported.

All use the runner's seed split (:func:`creps_gym.runner.split_seed`), so the test contexts
(``spec.eval_contexts`` of them) and the initial search distribution
(:func:`benchmarks.study_tools.initial_distribution`) are those of the contextual methods' runs with the same
seed. Only the public API is used.
"""

from __future__ import annotations

import itertools
import math
import time
from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from benchmarks.study_tools import RunSpec, function_spec, initial_distribution, is_bounded, result_document
from creps_gym.envs.evaluation import contextual_model, test_contexts
from creps_gym.optimizers import make_optimizer
from creps_gym.runner import split_seed

__all__ = ["BASELINES", "fixed_context_cma", "training_contexts"]

Array = NDArray[np.float64]


def training_contexts(context_dim: int, low: float = 0.0, high: float = 3.0) -> Array:
    """The K training contexts of ``cma-regression``, shape (K, z) (see the module docstring)."""
    if context_dim == 1:
        return np.linspace(low, high, 5)[:, None]
    corners = np.array(list(itertools.product((low, high), repeat=context_dim)), dtype=np.float64)
    return np.vstack([corners, np.full((1, context_dim), (low + high) / 2.0)])


def _metric(model: Any, bounded: bool, contexts: Array, params: Array) -> Array:
    """Regret (bounded functions) or f (unbounded ones) per row."""
    return model.regret(contexts, params) if bounded else model.objective(contexts, params)


def fixed_context_cma(
    model: Any,
    context: Array,
    budget: int,
    seed: int,
    target: float,
    start: tuple[Array, Array],
    popsize: int | None = None,
) -> tuple[list[int], list[float], Array, str]:
    """CMA-ES on one context until the metric at it is <= ``target`` or the budget is spent.

    Parameters
    ----------
    model : creps_gym function env (unwrapped)
    context : ndarray, shape (z,)
    budget : int
        Maximum number of episodes.
    seed : int
        Seed of the adapter.
    target : float
        Stop when the metric (regret, or f for unbounded functions) of the mean is at most this.
    start : (ndarray, ndarray), shapes (p,) and (p,)
        Initial mean and standard deviations.
    popsize : int, optional
        Population size (default: pycma's 4 + floor(3 ln p)).

    Returns
    -------
    episodes, values : lists
        Episodes used and the metric of the recommended mean after each iteration.
    params : ndarray, shape (p,)
        The final recommendation.
    stop_reason : str
    """
    bounded = hasattr(model, "regret")
    mean, std = start
    p = model.param_dim
    optimizer = make_optimizer("cma", p, model.context_dim, seed, initial_mean=mean, initial_cov=std**2)
    popsize = popsize or 4 + math.floor(3 * math.log(p))
    contexts = np.repeat(context[None, :], popsize, axis=0)
    episodes: list[int] = []
    values: list[float] = []
    used, reason = 0, "max_episodes"
    while used + popsize <= budget:
        params = optimizer.ask(contexts)
        returns, _ = model.evaluate(contexts, params)
        optimizer.tell(contexts, params, returns)
        used += popsize
        recommended = optimizer.recommend(contexts[:1])
        episodes.append(used)
        values.append(float(_metric(model, bounded, contexts[:1], recommended)[0]))
        if values[-1] <= target:
            reason = "target"
            break
        met = optimizer.stop()
        if met:
            reason = "optimizer: " + ", ".join(sorted(met))
            break
    return episodes, values, np.asarray(optimizer.recommend(contexts[:1]))[0], reason


def _setup(spec: RunSpec) -> tuple[Any, Array, int, tuple[Array, Array]]:
    env = gym.make(spec.env_id, **spec.env_kwargs)
    model = contextual_model(env)
    _, optimizer_seed, eval_seed = split_seed(spec.seed)
    start = initial_distribution(spec, env.action_space)
    return model, test_contexts(model, spec.eval_contexts, eval_seed), optimizer_seed, start


def _fixed(spec: RunSpec, popsize: int | None = None) -> dict[str, Any]:
    clock = time.perf_counter()
    model, tests, seed, start = _setup(spec)
    target = function_spec(spec.function).target
    episodes, values, _, reason = fixed_context_cma(
        model, tests[0], spec.budget, seed, target, start, popsize
    )
    return result_document(spec, episodes, values, reason, time.perf_counter() - clock)


def _fixed_batch(spec: RunSpec) -> dict[str, Any]:
    return _fixed(spec, popsize=spec.samples)


def _regression(spec: RunSpec) -> dict[str, Any]:
    clock = time.perf_counter()
    model, tests, seed, start = _setup(spec)
    bounded = is_bounded(spec.function)
    target = function_spec(spec.function).target
    per_context_target = target / 10.0 if bounded else target
    train = training_contexts(spec.context_dim)
    seeds = np.random.SeedSequence(seed).generate_state(len(train))
    solutions, used, solved = [], 0, 0
    for context, context_seed in zip(train, seeds, strict=True):
        budget = spec.budget // len(train)
        episodes, values, params, _ = fixed_context_cma(
            model, context, budget, int(context_seed), per_context_target, start
        )
        solutions.append(params)
        used += episodes[-1] if episodes else 0
        solved += bool(values and values[-1] <= per_context_target)
    features = np.hstack([np.ones((len(train), 1)), train])
    coefficients, *_ = np.linalg.lstsq(features, np.array(solutions), rcond=None)
    test_params = np.hstack([np.ones((len(tests), 1)), tests]) @ coefficients
    value = float(_metric(model, bounded, tests, test_params).mean())
    return result_document(
        spec,
        [used],
        [value],
        "regression",
        time.perf_counter() - clock,
        training_contexts=len(train),
        contexts_solved=solved,
    )


#: The baselines' runners by method name (the ``method`` of a :class:`~benchmarks.study_tools.RunSpec`), as
#: the studies pass them to :func:`benchmarks.study_tools.run_study`.
BASELINES = {"cma-fixed": _fixed, "cma-fixed-batch": _fixed_batch, "cma-regression": _regression}
