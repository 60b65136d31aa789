"""Active context choice from the optimiser's model: practise where one episode teaches most about the
optimal policy (in the spirit of Active Contextual Entropy Search, Metzen 2015).

ACES chooses the context of the next trial so that the trial most reduces the entropy of the optimal
parameters' distribution over the whole context space. Only the optimiser's model can say that, and
selectors never see the optimiser (the dependency rule), so the model answers through an optional hook
of the optimiser protocol: ``context_utility(candidates (m, z), targets (r, z), pending (k, z) or None)
-> (m,)``, larger where one more episode at a candidate context would teach the model more about the
optimal parameters at the target contexts, after the episodes at the ``pending`` contexts of the same
batch (:meth:`creps_gym.optimizers.cbo.ContextualBO.context_utility` implements it with c-bo's GP,
:mod:`creps_gym.optimizers.context_value`). A selector that declares ``uses_context_utility = True``
receives it from the runner as ``select(rng, n, context_utility=...)``: a plain callable, or None when
the optimiser has no model.

Every iteration this selector draws ``targets`` contexts uniformly in the box (a Monte-Carlo stand-in
for the whole context space) and ``candidates`` more, and fills the batch greedily: each context is the
candidate of largest utility given the contexts already chosen (which leave the pool), the first on
ties. A share ``uniform_share`` of the batch is drawn uniformly in the whole box instead.

**Without a model** (``context_utility`` None: an optimiser without the hook, such as ``creps``, or a
direct ``select(rng, n)``) every context is a uniform draw, bit for bit the ``uniform`` selector's; so is
a utility that is equal everywhere (c-bo before its GP exists gives zeros: the first candidate is a
uniform draw). The selector learns nothing itself (its state is ``{}``): what it knows is in the
optimiser's model, which the optimiser checkpoints, so a resumed run chooses what an uninterrupted one
does.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from creps_gym._validation import check_positive_int, check_real_in_range
from creps_gym.selectors.base import check_state_keys, finite_box

__all__ = ["ActiveContextSelector"]

Array = NDArray[np.float64]
#: Largest candidate and target sets (each sizes the optimiser's work at every select).
MAX_POINTS = 1024


class ActiveContextSelector:
    """Choose the contexts where the optimiser's model expects to learn most (see the module docstring).

    Parameters
    ----------
    candidates : int
        Uniform candidate contexts scored per iteration (>= 1, at most 1024; at least the batch's
        active share are drawn).
    targets : int
        Uniform target contexts per iteration whose optimal parameters the utility values (>= 1, at
        most 1024).
    uniform_share : float
        Share of every iteration's episodes drawn uniformly in the whole box, in [0, 1].
    """

    name = "active"
    #: The runner passes the optimiser's ``context_utility`` (or None) to :meth:`select`.
    uses_context_utility = True

    def __init__(self, candidates: int = 32, targets: int = 16, uniform_share: float = 0.0) -> None:
        self.candidates = check_positive_int(candidates, "candidates")
        self.targets = check_positive_int(targets, "targets")
        for value, what in ((self.candidates, "candidates"), (self.targets, "targets")):
            if value > MAX_POINTS:
                raise ValueError(f"{what}: expected an integer of at most {MAX_POINTS}, got {value}")
        self.uniform_share = check_real_in_range(uniform_share, "uniform_share", 0.0, 1.0, low_inclusive=True)
        self.low = self.high = np.zeros(0)

    def bind(self, low: Array, high: Array, env_sampler: Any) -> None:
        """Take the env's context box."""
        self.low, self.high = finite_box(low, high, "context_selector 'active'")

    def select(self, rng: np.random.Generator, n: int, context_utility: Any = None) -> Array:
        """``n`` contexts (n, z): the greedy choices by ``context_utility``, then the uniform share.

        ``context_utility`` None: ``n`` uniform draws (what ``uniform`` draws from the same ``rng``).
        """
        if not self.low.shape[0]:
            raise RuntimeError("context_selector 'active': select() before bind()")
        n = check_positive_int(n, "n")
        if context_utility is None:
            return rng.uniform(self.low, self.high, size=(n, self.low.shape[0]))
        if not callable(context_utility):
            raise TypeError(
                f"context_utility: expected a callable (candidates, targets, pending) -> (m,) or None, "
                f"got {type(context_utility).__name__}"
            )
        uniform = round(self.uniform_share * n)
        z = self.low.shape[0]
        targets = rng.uniform(self.low, self.high, size=(self.targets, z))
        pool = rng.uniform(self.low, self.high, size=(max(self.candidates, n - uniform), z))
        chosen = np.zeros((0, z))
        for _ in range(n - uniform):
            scores = self._scores(context_utility, pool, targets, chosen)
            best = int(np.argmax(scores))  # the first on ties
            chosen = np.vstack([chosen, pool[best]])
            pool = np.delete(pool, best, axis=0)
        anywhere = rng.uniform(self.low, self.high, size=(uniform, z))
        return np.concatenate([chosen, anywhere])

    @staticmethod
    def _scores(utility: Any, pool: Array, targets: Array, chosen: Array) -> Array:
        """The utility of the pool (m,), checked: finite numbers, one per candidate."""
        scores = np.asarray(utility(pool.copy(), targets.copy(), chosen.copy() if len(chosen) else None))
        if scores.shape != (pool.shape[0],) or not np.issubdtype(scores.dtype, np.number):
            raise ValueError(
                f"context_utility: expected {pool.shape[0]} numbers (one per candidate), got an array of "
                f"shape {scores.shape} and dtype {scores.dtype}"
            )
        if not np.isfinite(scores).all():
            raise ValueError(f"context_utility: expected finite values, got {scores.tolist()}")
        return scores.astype(np.float64)

    def tell(self, contexts: Array, returns: Array, diagnostics: dict[str, float]) -> None:
        """Nothing to learn: the optimiser's model holds what is known."""

    def state_dict(self) -> dict[str, Any]:
        """No state: ``{}``."""
        return {}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Accept ``{}`` only."""
        check_state_keys(state, set(), "context_selector 'active'")

    def __repr__(self) -> str:
        return (
            f"ActiveContextSelector(candidates={self.candidates}, targets={self.targets}, "
            f"uniform_share={self.uniform_share})"
        )
