"""Low-dimensional views of a contextual episodic env: a fixed affine subspace of its parameters.

:class:`AffineSubspaceEnv` searches k parameters u ∈ [−1, 1]^k and evaluates the full env at

    θ = θ_ref + B u,   B = (b_1 … b_k) ∈ R^(p × k),

so u = 0 is the reference θ_ref and each column b_i is one movement metaparameter in the full parameters'
units (a swing amplitude, a duration, a set-point bump), as real-robot work searches a handful of them. It
wraps any :class:`~creps_gym.envs.base.ContextualEpisodicEnv` (contexts, context sampling and ``info`` are
the full env's; ``info["full_params"]`` holds θ). The registered low-dimensional ids are built by
:func:`make_low_dimensional` from the recipes (and entry points) of :mod:`creps_gym.envs.reacher.subspace`
and :mod:`creps_gym.envs.kick.subspace`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from creps_gym._validation import as_float_array, check_real
from creps_gym.envs.base import ContextualEpisodicEnv, InfoBatch

__all__ = ["AffineSubspaceEnv", "make_low_dimensional"]

Array = NDArray[np.float64]


class AffineSubspaceEnv(ContextualEpisodicEnv):
    """A fixed affine subspace θ = θ_ref + B u of a full env's parameters (see the module docstring).

    ## Description
    The full env's task, searched over k metaparameters u. Everything but the parameters is the full env's:
    contexts, their distribution, the return and ``info`` (plus ``full_params``, θ of shape (p,)).

    ## Context Space
    The full env's.

    ## Parameter Space
    ``Box(-1, 1, (k,), float64)``: u, one entry per column of ``basis``. Values outside the box are
    evaluated as given (θ = θ_ref + B u), as the full env evaluates its own parameters.

    ## Return
    The full env's return at θ = θ_ref + B u.

    ## Episode End
    One step, as the full env.

    ## Arguments
    ``AffineSubspaceEnv(env, reference, basis, names=None, initial_std=0.3, render_mode=None)``: ``env``
    the full env (unwrapped); ``reference`` θ_ref (p,); ``basis`` B (p, k), finite, 1 ≤ k ≤ p, full column
    rank; ``names`` k names of the metaparameters; ``initial_std`` (> 0) the declared start's σ around
    u = 0. ``render_mode`` is passed to the full env's ``render``.

    ## Version History
    * v0: initial version.
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["rgb_array", "rgb_array_list"], "render_fps": 4}

    def __init__(
        self,
        env: ContextualEpisodicEnv,
        reference: Any,
        basis: Any,
        names: Sequence[str] | None = None,
        initial_std: float = 0.3,
        render_mode: str | None = None,
    ) -> None:
        if not isinstance(env, ContextualEpisodicEnv):
            raise TypeError(f"env: expected a ContextualEpisodicEnv (unwrapped), got {type(env).__name__}")
        p = env.param_dim
        self.reference = as_float_array(reference, "reference", (p,)).copy()
        self.basis = as_float_array(basis, "basis", (p, None)).copy()
        k = self.basis.shape[1]
        if not 1 <= k <= p or np.linalg.matrix_rank(self.basis) < k:
            raise ValueError(
                f"basis: expected 1 to {p} linearly independent columns, got shape {self.basis.shape}"
            )
        names = [f"u{i}" for i in range(k)] if names is None else [str(name) for name in names]
        if len(names) != k:
            raise ValueError(f"names: expected {k} names (one per basis column), got {len(names)}")
        self.param_names = names
        self.initial_std = check_real(initial_std, "initial_std", strict=True)
        self.full_env = env
        self.metadata = {**type(self).metadata, "render_modes": list(env.metadata.get("render_modes", []))}
        space = env.observation_space
        super().__init__(space.low, space.high, np.full(k, -1.0), np.full(k, 1.0), render_mode=render_mode)

    def full_params(self, params: Any) -> Array:
        """θ = θ_ref + B u for u (n, k): shape (n, p), one row at a time (the same bits in any batch)."""
        params = self.check_params(params, "params")
        return self.reference + np.einsum("pk,nk->np", self.basis, params)

    def evaluate(self, contexts: Array, params: Array) -> tuple[Array, InfoBatch]:
        """The full env's returns and ``info`` at θ = θ_ref + B u, with ``info["full_params"]`` (n, p)."""
        full = self.full_params(params)
        with np.errstate(over="ignore", invalid="ignore"):
            returns, info = self.full_env.evaluate(contexts, full)
        return returns, {**info, "full_params": full}

    def initial_distribution(self) -> tuple[Array, Array]:
        """u = 0 (the reference) with ``initial_std`` per metaparameter."""
        return np.zeros(self.param_dim), np.full(self.param_dim, self.initial_std)

    def sample_contexts(self, rng: np.random.Generator, n: int) -> Array:
        """The full env's context distribution."""
        return self.full_env.sample_contexts(rng, n)

    def reset_info(self, contexts: Array) -> InfoBatch:
        """The full env's reset ``info``."""
        return self.full_env.reset_info(contexts)

    def render(self) -> Any:
        """The full env's rendering (its render modes) of the current context and the last motion, mapped to
        θ; None without a render mode."""
        if self.render_mode is None:
            return None
        self.full_env._context = self._context
        last = self._last_params
        self.full_env._last_params = None if last is None else self.full_params(last[None, :])[0]
        return self.full_env.render()

    def close(self) -> None:
        """Close the full env."""
        self.full_env.close()


def make_low_dimensional(
    recipe: Callable[[Any], tuple[Array, Array, list[str]]],
    full_id: str,
    initial_std: float = 0.3,
    render_mode: str | None = None,
    **kwargs: Any,
) -> AffineSubspaceEnv:
    """The full env ``full_id`` (made with ``render_mode`` and ``kwargs``) in the subspace ``recipe(env)``
    gives as (reference, basis, names): what the registered low-dimensional ids' entry points call."""
    full = gym.make(full_id, render_mode=render_mode, **kwargs).unwrapped
    reference, basis, names = recipe(full)
    return AffineSubspaceEnv(full, reference, basis, names, initial_std=initial_std, render_mode=render_mode)
