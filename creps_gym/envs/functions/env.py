"""Environment classes of the contextual test functions (the scalar families and the native vector env).

Two families, so that ``isinstance(env, SupportsRegret)`` is honest:

* :class:`BoundedFunctionEnv` (12 functions): the optimum is known, so it implements ``optimal_params`` and
  ``regret`` (the :class:`~creps_gym.envs.base.SupportsRegret` protocol).
* :class:`UnboundedFunctionEnv` (Plane, Sharp Ridge, Parabolic Ridge): unbounded below, so there is no
  optimum and no regret. It does not implement the protocol; ``isinstance(env, SupportsRegret)`` is False.

Both expose the paper's stopping target as a value of f (:attr:`ContextualFunctionEnv.target`), with
``objective`` (f), ``target_gap`` (f - target, <= 0 when reached) and ``solved``. The concrete classes, one
per function, are in :mod:`.suite`; their manuals come from :mod:`.manual`.

Bounded functions evaluate ``x = x* + (theta - theta*(s))`` (equal to ``theta + A s`` up to rounding), so
that ``theta = theta*(s)`` lands exactly on ``x*`` and the regret there is exactly 0 in floating point.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from creps_gym._validation import as_float_array, check_fits_in_memory, check_positive_int
from creps_gym.envs.base import Array, ContextualEpisodicEnv, ContextualEpisodicVectorEnv, InfoBatch
from creps_gym.envs.functions.instance import FunctionInstance, make_instance
from creps_gym.envs.functions.specs import FunctionSpec

__all__ = [
    "BoundedFunctionEnv",
    "ContextualFunctionEnv",
    "ContextualFunctionVectorEnv",
    "UnboundedFunctionEnv",
]

CONTEXT_LOW = 0.0
CONTEXT_HIGH = 3.0


class ContextualFunctionEnv(ContextualEpisodicEnv):
    """Common base of the contextual test-function envs; see a concrete class for the manual.

    Subclasses set the class attribute ``function`` (a :class:`FunctionSpec`).
    """

    function: ClassVar[FunctionSpec]

    def __init__(
        self, dim: int = 15, context_dim: int = 1, instance: int = 0, render_mode: str | None = None
    ) -> None:
        self.dim = check_positive_int(dim, "dim", minimum=2)
        context_dim = check_positive_int(context_dim, "context_dim", minimum=0)
        self.instance = check_positive_int(instance, "instance", minimum=0)
        spec = self.function
        rotation = 2 * self.dim**2 if spec.rotated else 0  # the Gaussian and the orthonormalised matrix
        arrays = "the instance's arrays (A, shift, bounds" + (
            ", 2 p x p rotation matrices)" if rotation else ")"
        )
        name, value = ("context_dim", context_dim) if context_dim > self.dim else ("dim", dim)  # the larger
        check_fits_in_memory(8.0 * (self.dim * (context_dim + 12) + rotation), name, value, arrays)
        #: The seeded A, o, R and x* of this instance.
        self.problem: FunctionInstance = make_instance(
            self.dim,
            context_dim,
            self.instance,
            shifted=spec.shifted,
            rotated=spec.rotated,
            canonical_optimum=spec.canonical_point(self.dim),
        )
        context_low, context_high = np.full(context_dim, CONTEXT_LOW), np.full(context_dim, CONTEXT_HIGH)
        param_low, param_high = self.problem.param_bounds(context_low, context_high)
        super().__init__(context_low, context_high, param_low, param_high, render_mode=render_mode)

    @property
    def target(self) -> float:
        """The paper's stopping target as a value of f: ``f_opt + 1e-5`` (bounded) or ``-1e4`` (unbounded)."""
        return self.function.target

    def sample_contexts(self, rng: np.random.Generator, n: int) -> Array:
        """``n`` contexts uniform in [0, 3]^z, shape (n, z): the numbers of ``rng.uniform(0, 3, (n, z))``."""
        return CONTEXT_HIGH * rng.random((n, self.context_dim))

    def _check_batch(self, contexts: Any, params: Any) -> tuple[Array, Array]:
        contexts = as_float_array(contexts, "contexts", (None, self.context_dim))
        params = as_float_array(params, "params", (None, self.param_dim))
        if contexts.shape[0] != params.shape[0]:
            raise ValueError(
                f"params: expected as many rows as contexts ({contexts.shape[0]}), got {params.shape[0]}"
            )
        return contexts, params

    def _objective(self, contexts: Array, params: Array) -> Array:
        raise NotImplementedError

    def objective(self, contexts: Any, params: Any) -> Array:
        """f(x) with ``x = theta + A s`` for contexts (n, z) and params (n, p): shape (n,). Returns are -f."""
        return self._objective(*self._check_batch(contexts, params))

    def target_gap(self, contexts: Any, params: Any) -> Array:
        """``f(x) - target`` for contexts (n, z) and params (n, p): shape (n,); <= 0 where the target is met.

        ``target`` is ``f_opt + 1e-5`` for the bounded functions and ``-1e4`` for the unbounded ones.
        """
        return self.objective(contexts, params) - self.target

    def solved(self, contexts: Any, params: Any) -> np.ndarray:
        """Whether the paper's stopping target is met, per row: bool array of shape (n,)."""
        return self.target_gap(contexts, params) <= 0.0


class BoundedFunctionEnv(ContextualFunctionEnv):
    """A test function with a known minimum: implements ``optimal_params`` and ``regret`` (SupportsRegret)."""

    @property
    def f_opt(self) -> float:
        """The minimum value of f (0 for every function of the suite)."""
        return float(self.function.f_opt)  # type: ignore[arg-type]

    def _optimum_and_objective(self, contexts: Array, params: Array) -> tuple[Array, Array]:
        optimum = self.problem.optimal_params(contexts)
        return optimum, self.function.kernel(self.problem.kernel_argument(params - optimum))

    def _objective(self, contexts: Array, params: Array) -> Array:
        return self._optimum_and_objective(contexts, params)[1]

    def evaluate(self, contexts: Array, params: Array) -> tuple[Array, InfoBatch]:
        """Returns ``-f(x)`` (n,); info ``regret`` (n,) and ``optimal_params`` theta*(s) (n, p)."""
        contexts, params = self._check_batch(contexts, params)
        optimum, values = self._optimum_and_objective(contexts, params)
        return 0.0 - values, {"regret": values - self.f_opt, "optimal_params": optimum}  # +0.0 at f = 0

    def reset_info(self, contexts: Array) -> InfoBatch:
        """Reset info: ``optimal_params`` theta*(s), shape (n, p)."""
        return {"optimal_params": self.problem.optimal_params(contexts)}

    def optimal_params(self, contexts: Any) -> Array:
        """theta*(s) = x* - A s for contexts of shape (n, z): shape (n, p). Any finite context is accepted."""
        contexts = as_float_array(contexts, "contexts", (None, self.context_dim))
        return self.problem.optimal_params(contexts)

    def regret(self, contexts: Any, params: Any) -> Array:
        """``f(x) - f_opt`` (>= 0, exactly 0 at theta*(s)) for contexts (n, z), params (n, p): shape (n,)."""
        return self.objective(contexts, params) - self.f_opt


class UnboundedFunctionEnv(ContextualFunctionEnv):
    """A test function unbounded below: no optimum and no regret; the target is ``f <= -1e4``."""

    def _objective(self, contexts: Array, params: Array) -> Array:
        # theta - (-A s) is bit-identical to theta + A s, one pass cheaper.
        return self.function.kernel(params - self.problem.negative_offset(contexts))

    def evaluate(self, contexts: Array, params: Array) -> tuple[Array, InfoBatch]:
        """Returns ``-f(x)`` (n,); info ``target_gap`` = f(x) + 1e4 (n,), <= 0 once the target is met."""
        values = self._objective(*self._check_batch(contexts, params))
        return 0.0 - values, {"target_gap": values - self.target}  # +0.0, not -0.0, at f = 0


class ContextualFunctionVectorEnv(ContextualEpisodicVectorEnv):
    """Native vector env of a test function: ``make_vec(id, num_envs=n)`` evaluates the batch in one call.

    See :class:`~creps_gym.envs.base.ContextualEpisodicVectorEnv` for per-env contexts
    (``reset(options={"context": array (n, z)})``) and the ``SAME_STEP`` / ``DISABLED`` autoreset modes.
    The model (the single env, with its ``optimal_params``, ``regret`` and ``target``) is ``self.model``.
    """
