"""Contextual CMA-ES's restarts (:class:`~creps_gym.optimizers.ccmaes.CCMAES`): the kept best (C10), the
restart portfolio's loss (C11, in the config), the budget rule (C12) and IPOP's population growth (C13).

A search whose stop criterion fires restarts from the initial distribution while restarts are left (C10,
C11) and, with a known episode budget B, only while the episodes left can carry the new search as far as
the ended one went: B − E ≥ F · E_search (C12), E the episodes told so far, E_search those of the ended
search and F the population factor of C13. Otherwise the converged search goes on sampling: a restart near
the end of the budget would only replace a converged distribution by the broad initial one. After the r-th
restart the optimiser wants batches of N₀ · F^r samples (C13, IPOP-CMA-ES with F = 2); the caller chooses the
batch (``wanted_batch_size``), and the weights and learning rates follow the batch it tells.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from creps_gym._validation import check_positive_int
from creps_gym.optimizers.cma_rules import population_size, restart_pays_off

__all__ = ["BEST_WINDOW", "Restarts"]

Array = NDArray[np.float64]
#: Batches whose mean returns score a search's mean policy (C10): a few, to average the context draw's noise.
BEST_WINDOW = 3


class Restarts:
    """Mixin of :class:`~creps_gym.optimizers.ccmaes.CCMAES`: when and how a search restarts, and what a
    restart keeps. It reads the optimiser's ``config``, ``policy``, ``mean_returns``, ``restarts_done``,
    ``best_coefficients``, ``best_score``, ``search_start`` (the episodes told before the running search
    began) and the protocol's counters, and calls its ``_reset_search``."""

    config: Any
    policy: Any
    mean_returns: list[float]
    restarts_done: int
    best_coefficients: Array | None
    best_score: float
    search_start: int
    evaluations: int
    _pending: Any
    _diagnostics: dict[str, float]
    _told_rows: NDArray[np.int64]

    def wanted_batch_size(self, base: int) -> int:
        """The batch the running search wants when the caller's own batch is ``base`` (Eq. (C13)): ``base``
        · F^r after r restarts, F = ``restart_population_factor`` (``base`` with the default F = 1). A caller
        that grows its batch asks this before every ``ask``; one that keeps its batch may ignore it."""
        base = check_positive_int(base, "base")
        return population_size(base, self.config.restart_population_factor, self.restarts_done)

    def _restart_if_due(self) -> None:
        """Inside ``tell``: restart if a stop criterion is met, a restart is left and it can pay off (C12)."""
        config = self.config
        if self.restarts_done >= config.restarts or not self.stop():  # type: ignore[attr-defined]
            return
        told = self.evaluations + self._told_rows.shape[0]  # tell() counts the batch after _update
        factor = config.restart_population_factor
        if restart_pays_off(config.budget, told, told - self.search_start, factor):  # Eq. (C12)
            self._restart(told)

    def _restart(self, told: int) -> None:
        """Keep the ending search's mean policy if it scored best (C10), then start again from the initial
        distribution after ``told`` episodes; the searches after it fit the baseline with the restart loss
        (C11) and want the grown batch (C13)."""
        self._keep_if_best()
        self._reset_search()  # type: ignore[attr-defined]
        self.restarts_done += 1
        self.search_start = told
        for stale in ("cond_cov", "max_std", "search_scale"):  # they described the abandoned distribution
            self._diagnostics.pop(stale, None)
        if self._diagnostics:  # the new search's σ and (empty) path, not the abandoned search's
            self._diagnostics.update(step_size=self.policy.step_size, path_sigma_ratio=0.0)

    def restart(self) -> bool:
        """Restart now, as the stop criteria would (C10, C11, C13), if a restart is left; returns whether it
        did. The budget rule (C12) does not apply: the caller asks for it.

        The runner calls it when its divergence rule fires, so a diverging search is abandoned early
        instead of ending the run. Raises ``RuntimeError`` between ``ask`` and ``tell`` (the asked samples
        belong to the search it would abandon); with no restart left it returns False and changes nothing.
        """
        if self._pending is not None:
            raise RuntimeError("restart(): expected no pending ask(); tell() its samples first")
        if self.restarts_done >= self.config.restarts:
            return False
        self._restart(self.evaluations)
        self._diagnostics["restarts"] = float(self.restarts_done)
        return True

    def _search_score(self) -> float:
        """The running search's score (C10): the mean of its last ``BEST_WINDOW`` batch mean returns (−inf
        before it has told that many)."""
        recent = self.mean_returns[-BEST_WINDOW:]
        return float(np.mean(recent)) if len(recent) == BEST_WINDOW else -math.inf

    def _keep_if_best(self) -> None:
        """Eq. (C10): before a restart, keep the ending search's mean policy if it scores best so far."""
        score = self._search_score()
        if self.config.keep_best and score > self.best_score:
            self.best_coefficients, self.best_score = self.policy.coefficients.copy(), score

    def recommended_coefficients(self) -> Array:
        """The coefficients, shape (k, p), of the mean policy that ``recommend`` and ``mean_policy`` give:
        the running search's, or with ``keep_best`` the best one a restart left (C10) while the running
        search scores below it."""
        if self.best_coefficients is None or self._search_score() >= self.best_score:
            return self.policy.coefficients
        return self.best_coefficients  # Eq. (C10)
