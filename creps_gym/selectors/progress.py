"""A continuous learning-progress selector: no partition, a kernel estimate over recent episodes.

The bandit (:mod:`creps_gym.selectors.bandit`) measures learning progress per grid cell; here it is a
function of the context. The selector keeps the episodes of the last ``2 window`` iterations. At a context
``c`` the Gaussian-kernel means of the returns (bandwidth ``bandwidth`` times the box's width per
dimension) over the recent episodes (the last ``window`` iterations) and over the older ones (the
``window`` before) give the progress estimate ::

    LP(c) = | m_recent(c) - m_older(c) |,

and a context with too little kernel weight on either side (less than one episode's worth) gets the
largest LP of the others: where nothing is known, practise (optimism). Every iteration draws
``candidates`` points uniformly in the box and picks the iteration's contexts among them (without
replacement) with probabilities proportional to ``LP``; a share ``uniform_share`` is drawn uniformly in the
whole box, and until two windows have been seen every context is.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from creps_gym._validation import (
    as_float_array,
    check_count,
    check_fits_in_memory,
    check_positive_int,
    check_real_in_range,
)
from creps_gym.selectors.base import check_state_keys, finite_box

__all__ = ["KernelProgressSelector"]

Array = NDArray[np.float64]
#: Largest (points x kept episodes x z) block :meth:`KernelProgressSelector.progress` computes at once; a
#: larger one (many candidates or kept episodes) is computed in blocks of rows, so its memory stays bounded.
BLOCK = 2**22


class KernelProgressSelector:
    """Practise where a kernel estimate of the mean return changed most (see the module docstring).

    Parameters
    ----------
    bandwidth : float
        Kernel width as a share of the box's width per dimension, in (0, 1].
    window : int
        Iterations per window (>= 1): progress compares the last ``window`` with the ``window`` before.
    candidates : int
        Uniform candidate contexts per iteration (>= 2).
    uniform_share : float
        Share of every iteration's episodes drawn uniformly in the whole box, in [0, 1].
    """

    name = "progress"

    def __init__(
        self, bandwidth: float = 0.15, window: int = 3, candidates: int = 256, uniform_share: float = 0.5
    ) -> None:
        self.bandwidth = check_real_in_range(bandwidth, "bandwidth", 0.0, 1.0)
        self.window = check_positive_int(window, "window")
        self.candidates = check_positive_int(candidates, "candidates", minimum=2)
        self.uniform_share = check_real_in_range(uniform_share, "uniform_share", 0.0, 1.0, low_inclusive=True)
        self.low = self.high = np.zeros(0)
        self.iteration = 0
        self.contexts, self.returns, self.ages = np.zeros((0, 0)), np.zeros(0), np.zeros(0, dtype=np.int64)

    def bind(self, low: Array, high: Array, env_sampler: Any) -> None:
        """Take the env's context box."""
        self.low, self.high = finite_box(low, high, "context_selector 'progress'")
        z = self.low.shape[0]
        what = f"the candidate contexts and their progress (candidates x (z + 4) floats, z = {z})"
        check_fits_in_memory(
            8.0 * self.candidates * (z + 4) + 8.0 * BLOCK * 3, "candidates", self.candidates, what
        )
        self.contexts = np.zeros((0, z))

    def progress(self, points: Array) -> Array:
        """The estimate ``LP`` at ``points`` (m, z), shape (m,) (see the module docstring)."""
        rows = max(1, BLOCK // max(1, self.contexts.size))
        if points.shape[0] <= rows:
            new, new_mass, old, old_mass = self._sides(points)
        else:  # in blocks of rows: the kernel matrices of many points would not fit in memory
            blocks = [self._sides(points[i : i + rows]) for i in range(0, points.shape[0], rows)]
            new, new_mass, old, old_mass = (np.concatenate(parts) for parts in zip(*blocks, strict=True))
        estimate = np.abs(new - old)
        known = (new_mass >= 1.0) & (old_mass >= 1.0)
        if not known.any():
            return np.ones(points.shape[0])
        return np.where(known, estimate, estimate[known].max())

    def _sides(self, points: Array) -> tuple[Array, Array, Array, Array]:
        """Kernel means and masses of the recent and the older episodes at ``points`` (m, z)."""
        scale = self.bandwidth * (self.high - self.low)
        gaps = (points[:, None, :] - self.contexts[None, :, :]) / scale
        weights = np.exp(-0.5 * np.einsum("mkz,mkz->mk", gaps, gaps))
        recent = self.ages < self.window
        sides = []
        for mask in (recent, ~recent):
            mass = weights[:, mask].sum(axis=1)
            total = np.einsum("mk,k->m", weights[:, mask], self.returns[mask])
            sides.extend((total / np.maximum(mass, 1e-300), mass))
        new, new_mass, old, old_mass = sides
        return new, new_mass, old, old_mass

    def select(self, rng: np.random.Generator, n: int) -> Array:
        """``n`` contexts (n, z): candidates picked by ``LP``, then the uniform share."""
        if self.contexts.shape[1:] != self.low.shape or not self.low.shape[0]:
            raise RuntimeError("context_selector 'progress': select() before bind()")
        n = check_positive_int(n, "n")
        width, z = self.high - self.low, self.low.shape[0]
        ready = self.iteration >= 2 * self.window
        uniform = n if not ready else round(self.uniform_share * n)
        picked = np.zeros((0, z))
        if n - uniform:
            pool = self.low + width * rng.random((max(self.candidates, n), z))
            weights = self.progress(pool)
            total = weights.sum()
            p = weights / total if total > 0 and np.isfinite(total) else None
            index = rng.choice(pool.shape[0], size=n - uniform, replace=False, p=p)
            picked = pool[index]
        anywhere = self.low + width * rng.random((uniform, z))
        return np.concatenate([picked, anywhere])

    def tell(self, contexts: Array, returns: Array, diagnostics: dict[str, float]) -> None:
        """Keep the iteration's episodes; forget those older than two windows."""
        contexts = as_float_array(contexts, "contexts", (None, self.low.shape[0]))
        returns = as_float_array(returns, "returns", (contexts.shape[0],))
        keep = self.ages + 1 < 2 * self.window
        self.contexts = np.concatenate([contexts, self.contexts[keep]])
        self.returns = np.concatenate([returns, self.returns[keep]])
        self.ages = np.concatenate([np.zeros(len(returns), dtype=np.int64), self.ages[keep] + 1])
        self.iteration += 1

    def state_dict(self) -> dict[str, Any]:
        """The kept episodes (contexts, returns, ages in iterations) and the iteration count."""
        return {
            "iteration": self.iteration,
            "contexts": self.contexts.tolist(),
            "returns": self.returns.tolist(),
            "ages": self.ages.tolist(),
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore :meth:`state_dict`'s output, checked (shapes, finite values, ages < 2 window)."""
        user = "context_selector 'progress' state"
        state = check_state_keys(state, {"iteration", "contexts", "returns", "ages"}, user)
        iteration = check_count(state["iteration"], f"{user} iteration")
        if not isinstance(state["returns"], list):
            raise TypeError(
                f"{user} returns: expected a list of numbers, got {type(state['returns']).__name__}"
            )
        k, z = len(state["returns"]), self.low.shape[0]
        check_fits_in_memory(8.0 * k * (z + 3), f"{user} returns", f"{k} kept episodes", "the kept episodes")
        returns = as_float_array(state["returns"], f"{user} returns", (None,))
        contexts = as_float_array(state["contexts"], f"{user} contexts", (k, z)) if k else np.zeros((0, z))
        ages = state["ages"]
        if not isinstance(ages, list) or len(ages) != k:
            raise ValueError(f"{user} ages: expected a list of {k} ints, got {ages!r}")
        ages = np.array([check_positive_int(a, f"{user} ages", 0) for a in ages], dtype=np.int64)
        if (ages >= 2 * self.window).any() or (ages >= max(iteration, 1)).any():
            raise ValueError(f"{user} ages: expected ages below 2 windows and the iteration count")
        self.iteration, self.contexts, self.returns, self.ages = iteration, contexts, returns, ages

    def __repr__(self) -> str:
        return (
            f"KernelProgressSelector(bandwidth={self.bandwidth}, window={self.window}, "
            f"candidates={self.candidates}, uniform_share={self.uniform_share})"
        )
