"""The context-selection study's contextual functions whose difficulty depends on the context.

The registered function envs (``creps_gym/<Function>-v0``) evaluate ``f(θ + A s)``: the optimum
``θ*(s) = x* − A s`` is affine in ``s`` and the landscape around it is the same translate of ``f`` for every
context, so no region of their context box is harder than another (only the starting policy's error
varies with ``s``). A context selector has nothing to find there. :class:`SteepFunction` makes the
difficulty depend on the context: its regret at ``s`` is the function's regret times
``w(s) = steepness ** u(s)``, ``u(s) in [0, 1]`` the first context coordinate's position in the box. With
``steepness = 100`` the same parameter error costs 100 times more regret at the box's upper end than at its
lower end, so a policy must be 10 times more precise there (for a quadratic ``f``) to reach the same
regret, and the mean regret over uniform test contexts is dominated by the steep end.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

import creps_gym  # noqa: F401  (registers the ids)
from creps_gym.envs.base import ContextualEpisodicEnv, initial_distribution

__all__ = ["SteepFunction"]

Array = NDArray[np.float64]


class SteepFunction(ContextualEpisodicEnv):
    """A registered contextual function whose regret is scaled by ``steepness ** u(s)`` (module docstring).

    Parameters
    ----------
    function : str
        A bounded registered function, e.g. ``"Sphere"`` or ``"Rosenbrock"``.
    dim, context_dim : int
        The function env's keywords.
    steepness : float
        ``w`` at the box's upper end of the first context coordinate (1 at its lower end), >= 1.
    """

    def __init__(self, function: str, dim: int = 5, context_dim: int = 1, steepness: float = 100.0) -> None:
        self.model = gym.make(f"creps_gym/{function}-v0", dim=dim, context_dim=context_dim).unwrapped
        if not steepness >= 1.0:
            raise ValueError(f"steepness: expected a number >= 1, got {steepness!r}")
        self.steepness = float(steepness)
        box, params = self.model.observation_space, self.model.action_space
        super().__init__(box.low, box.high, params.low, params.high)

    def weight(self, contexts: Array) -> Array:
        """``w(s) = steepness ** u(s)``, shape (n,)."""
        low, high = self.observation_space.low[0], self.observation_space.high[0]
        return self.steepness ** ((contexts[:, 0] - low) / (high - low))

    def evaluate(self, contexts: Array, params: Array) -> tuple[Array, dict[str, Any]]:
        """Returns ``-w(s) · regret_f(s, θ)`` (n,)."""
        return -self.regret(contexts, params), {}

    def regret(self, contexts: Any, params: Any) -> Array:
        """``w(s) · (f(θ + A s) − f_opt)``, shape (n,)."""
        contexts = np.asarray(contexts, np.float64)
        return self.weight(contexts) * self.model.regret(contexts, params)

    def optimal_params(self, contexts: Any) -> Array:
        """The function's optimum ``θ*(s)`` (the weight does not move it)."""
        return self.model.optimal_params(contexts)

    def initial_distribution(self) -> tuple[Array, Array]:
        """The function env's declared start."""
        return initial_distribution(self.model)
