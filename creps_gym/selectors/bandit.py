"""Active context selection as a non-stationary bandit over the cells of the context box.

After Fabisch & Metzen, "Active Contextual Policy Search", JMLR 15:3371-3399 (2014): the learner picks the
tasks it practises, and a non-stationary multi-armed bandit whose reward is an intrinsic measure of
*learning progress* decides which. Here the arms are the cells of a regular grid over the context box
(``cells`` per dimension, boxes of 1 to 3 dimensions), an arm's contexts are drawn uniformly inside its
cell, and the bandit is discounted UCB (D-UCB; Garivier & Moulines, ALT 2011), which forgets old rewards
at rate ``discount`` per iteration, so it follows progress that moves across the box.

**Intrinsic reward** (learning progress of a cell, per iteration). A cell's episodes of this iteration have
the mean return ``m_i(t)``; its progress is ``|m_i(t) - m_i(t')|``, ``t'`` the cell's previous visit.
The progresses of the iteration are divided by their largest, so rewards lie in [0, 1] whatever the
return's scale (the first visit of a cell gives none: it has no previous mean).

**Exploration rule** (D-UCB). With discounted episode counts and reward sums per cell
``N_i = sum_s discount^(t-s) n_i(s)``, ``S_i = sum_s discount^(t-s) n_i(s) r_i(s)``, and ``N = sum_i N_i``,
the index of cell ``i`` is ::

    U_i = S_i / N_i + sqrt(exploration * log(max(N, e)) / N_i),    U_i = +inf if N_i = 0,

and each of an iteration's episodes goes to the cell with the largest index, counting the episodes
already placed in this iteration in ``N_i`` and ``N`` (ties broken at random with the run's selector
stream). A cell never rewarded (visited at most once) therefore keeps an infinite index and is visited
again; the square root is the confidence term of D-UCB with rewards bounded by 1.

A share ``uniform_share`` of every iteration's episodes is drawn uniformly in the whole box, so the
optimiser's policy always sees the whole range.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from creps_gym._validation import (
    MAX_COUNT,
    as_float_array,
    check_positive_int,
    check_real,
    check_real_in_range,
)
from creps_gym.selectors.base import check_state_keys, finite_box

__all__ = ["LearningProgressBandit", "cell_index", "ducb_index"]

Array = NDArray[np.float64]
MAX_CELLS = 4096


def ducb_index(sums: Array, counts: Array, exploration: float) -> Array:
    """D-UCB: ``S_i / N_i + sqrt(exploration log max(N, e) / N_i)`` per arm (+inf where N_i = 0)."""
    total = max(float(counts.sum()), math.e)
    index = np.full(counts.shape, np.inf)
    seen = counts > 0
    index[seen] = sums[seen] / counts[seen] + np.sqrt(exploration * math.log(total) / counts[seen])
    return index


def cell_index(contexts: Array, low: Array, high: Array, cells: tuple[int, ...]) -> NDArray[np.int64]:
    """The flat grid cell (row-major) of every context (n, z); contexts on a cell's upper edge go below."""
    grid = np.asarray(cells)
    position = np.floor((contexts - low) / (high - low) * grid).astype(np.int64)
    position = np.clip(position, 0, grid - 1)
    return np.ravel_multi_index(tuple(position.T), cells).astype(np.int64)


class LearningProgressBandit:
    """Practise where the mean return changes most: D-UCB over grid cells (see the module docstring).

    Parameters
    ----------
    cells : int or list of int
        Cells per dimension of the context box (>= 1 each; at most 4096 cells in all); default 8 in one
        dimension, 4 in two, 3 in three.
    discount : float
        Forgetting factor per iteration, in (0, 1].
    exploration : float
        The confidence term's coefficient ``exploration`` (>= 0; 0 is greedy).
    uniform_share : float
        Share of every iteration's episodes drawn uniformly in the whole box, in [0, 1].
    """

    name = "bandit"

    def __init__(
        self,
        cells: Any = None,
        discount: float = 0.9,
        exploration: float = 0.5,
        uniform_share: float = 0.5,
    ) -> None:
        if cells is not None and not isinstance(cells, int):
            if not isinstance(cells, (list, tuple)) or not cells:
                raise TypeError(f"cells: expected an int or a non-empty list of ints, got {cells!r}")
        self.requested = cells
        if cells is not None:
            for value in cells if isinstance(cells, (list, tuple)) else [cells]:
                check_positive_int(value, "cells")
        self.discount = check_real_in_range(discount, "discount", 0.0, 1.0)
        self.exploration = check_real(exploration, "exploration")
        self.uniform_share = check_real_in_range(uniform_share, "uniform_share", 0.0, 1.0, low_inclusive=True)
        self.cells: tuple[int, ...] = ()
        self.low = self.high = np.zeros(0)

    def bind(self, low: Array, high: Array, env_sampler: Any) -> None:
        """Lay the grid over the env's context box (1 to 3 dimensions)."""
        self.low, self.high = finite_box(low, high, "context_selector 'bandit'")
        z = self.low.shape[0]
        if not 1 <= z <= 3:
            raise ValueError(
                f"context_selector 'bandit': expected a context box of 1 to 3 dimensions, got {z}"
            )
        given = self.requested if self.requested is not None else {1: 8, 2: 4, 3: 3}[z]
        cells = tuple(int(c) for c in (given if isinstance(given, (list, tuple)) else [given] * z))
        if len(cells) != z:
            raise ValueError(f"cells: expected an int or {z} ints (one per context dimension), got {given!r}")
        if math.prod(cells) > MAX_CELLS:
            raise ValueError(f"cells: expected at most {MAX_CELLS} cells in all, got {cells}")
        self.cells = cells
        k = math.prod(cells)
        self.counts, self.sums = np.zeros(k), np.zeros(k)
        self.last_mean: list[float | None] = [None] * k

    @property
    def n_cells(self) -> int:
        """Number of arms (grid cells)."""
        return len(self.last_mean)

    def choose_cells(self, rng: np.random.Generator, m: int) -> NDArray[np.int64]:
        """The cells of ``m`` episodes: each to the largest index, the iteration's earlier picks counted."""
        pending = np.zeros(self.n_cells)
        chosen = np.empty(m, dtype=np.int64)
        for k in range(m):
            index = ducb_index(self.sums, self.counts + pending, self.exploration)
            best = np.flatnonzero(index == index.max())
            if len(best) > 1:  # unvisited cells first those with fewest picks, then at random
                best = best[pending[best] == pending[best].min()]
            chosen[k] = best[0] if len(best) == 1 else best[rng.integers(len(best))]
            pending[chosen[k]] += 1
        return chosen

    def select(self, rng: np.random.Generator, n: int) -> Array:
        """``n`` contexts (n, z): the bandit's share (uniform in the chosen cells), then the uniform share."""
        if not self.cells:
            raise RuntimeError("context_selector 'bandit': select() before bind()")
        n = check_positive_int(n, "n")
        uniform = round(self.uniform_share * n)
        chosen = self.choose_cells(rng, n - uniform)
        corner = np.array(np.unravel_index(chosen, self.cells)).T.reshape(len(chosen), len(self.cells))
        size = (self.high - self.low) / np.asarray(self.cells)
        inside = self.low + (corner + rng.random(corner.shape)) * size
        anywhere = self.low + (self.high - self.low) * rng.random((uniform, self.low.shape[0]))
        return np.clip(np.concatenate([inside, anywhere]), self.low, self.high)

    def tell(self, contexts: Array, returns: Array, diagnostics: dict[str, float]) -> None:
        """Reward every revisited cell by its normalised learning progress; discount the past."""
        contexts = as_float_array(contexts, "contexts", (None, self.low.shape[0]))
        returns = as_float_array(returns, "returns", (contexts.shape[0],))
        where = cell_index(contexts, self.low, self.high, self.cells)
        visited = np.unique(where)
        episodes = np.bincount(where, minlength=self.n_cells).astype(np.float64)
        progress = np.zeros(self.n_cells)
        rewarded = np.zeros(self.n_cells, dtype=bool)
        for cell in visited:
            mean = float(returns[where == cell].mean())
            previous = self.last_mean[cell]
            if previous is not None:
                progress[cell], rewarded[cell] = abs(mean - previous), True
            self.last_mean[cell] = mean
        top = progress.max()
        rewards = progress / top if top > 0 else progress
        self.counts *= self.discount
        self.sums *= self.discount
        self.counts[rewarded] += episodes[rewarded]
        self.sums[rewarded] += episodes[rewarded] * rewards[rewarded]

    def state_dict(self) -> dict[str, Any]:
        """The discounted counts and sums and each cell's last mean return (None: never visited)."""
        return {"counts": self.counts.tolist(), "sums": self.sums.tolist(), "last_mean": list(self.last_mean)}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore :meth:`state_dict`'s output, checked (finite, counts >= 0, sums in [0, counts])."""
        state = check_state_keys(state, {"counts", "sums", "last_mean"}, "context_selector 'bandit'")
        k = (self.n_cells,)
        counts = as_float_array(state["counts"], "context_selector 'bandit' state counts", k)
        sums = as_float_array(state["sums"], "context_selector 'bandit' state sums", k)
        if (counts < 0).any() or (sums < 0).any() or (sums > counts * (1 + 1e-12)).any():
            raise ValueError("context_selector 'bandit' state: expected 0 <= sums <= counts in every cell")
        with np.errstate(over="ignore"):
            total = float(counts.sum())
        if total > MAX_COUNT:  # discounted episode counts: no run comes near
            raise ValueError(
                f"context_selector 'bandit' state counts: expected a sum <= {MAX_COUNT}, got {total:g}"
            )
        last = state["last_mean"]
        if not isinstance(last, list) or len(last) != k[0]:
            raise ValueError(
                f"context_selector 'bandit' state last_mean: expected a list of {k[0]}, got {last!r}"
            )
        means = [None if v is None else check_real(v, "last_mean", minimum=-math.inf) for v in last]
        self.counts, self.sums, self.last_mean = counts.copy(), sums.copy(), means

    def __repr__(self) -> str:
        return (
            f"LearningProgressBandit(cells={list(self.cells) or self.requested}, discount={self.discount}, "
            f"exploration={self.exploration}, uniform_share={self.uniform_share})"
        )
