"""The runner's ``divergence`` stop: the evaluation got worse than the run's start by orders of magnitude.

Optimisers see only sample returns; the runner sees the evaluation of the recommended (mean) policy on the
fixed test contexts, the same quantity at every iteration. Its *loss* is the mean regret where the env has
one, else minus the mean return. Let L₀ be the loss of the run's first evaluation. The run stops with the
reason ``"divergence"`` once :data:`WINDOW` consecutive evaluations all have

    L − L₀ > factor · |L₀|

(``RunConfig.divergence``, 1000 by default: three orders of magnitude), unless the optimiser has a restart
left: then the runner calls its ``restart()`` (``c-cma-es``: the restart its stop criteria would make later,
C10 and C11), the count starts again and the run goes on. A run whose first loss is exactly 0 has no scale to
measure by and is never stopped this way. A restart back to the initial distribution stays near L₀, and a
single bad evaluation is not enough; the factor and the window were chosen against every
committed study run (``docs/optimizers.md``, *Divergence*): no run that reached its target or its budget
would have been stopped.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Any

__all__ = ["WINDOW", "DivergenceWatch", "evaluation_loss"]

#: Consecutive evaluations that must all be beyond the factor.
WINDOW = 10


def evaluation_loss(eval_return: float, eval_regret: float) -> float:
    """The loss the rule watches: the regret if it is a number, else minus the return (NaN: none)."""
    return eval_regret if not math.isnan(eval_regret) else -eval_return


class DivergenceWatch:
    """Counts consecutive diverged evaluations; rebuilt from a history's records on resume.

    Parameters
    ----------
    factor : float or None
        The factor of the rule (None: never stop).
    """

    def __init__(self, factor: float | None) -> None:
        self.factor = factor
        self.first: float | None = None
        self.run_length = 0

    def observe(self, loss: float) -> bool:
        """Record one evaluation's loss (NaN: no evaluation at this iteration); True once diverged."""
        if self.factor is None or math.isnan(loss):
            return False
        if self.first is None:
            self.first = loss
            return False
        worse = self.first != 0.0 and loss - self.first > self.factor * abs(self.first)
        self.run_length = self.run_length + 1 if worse else 0
        return self.run_length >= WINDOW

    def restarted(self) -> None:
        """The optimiser restarted its search when the rule fired: count the next :data:`WINDOW` again."""
        self.run_length = 0

    def restarts(self, optimizer: Any) -> bool:
        """The rule fired: True if ``optimizer`` restarted its search (its optional ``restart()``), and then
        the count starts again; False if it has no restart left (the run stops)."""
        restart = getattr(optimizer, "restart", None)
        if not (callable(restart) and restart()):
            return False
        self.restarted()
        return True

    @classmethod
    def of_history(cls, factor: float | None, records: Iterable[Any]) -> DivergenceWatch:
        """A watch that has observed the evaluations of ``records`` (a resumed run's history)."""
        return cls(factor).replay(evaluation_loss(r.eval_return, r.eval_regret) for r in records)

    def replay(self, losses: Iterable[float]) -> DivergenceWatch:
        """Observe ``losses`` in order (a resumed run's history); returns self. A history that goes on after
        the rule fired had its optimiser restart there, so the count starts again as it did."""
        for loss in losses:
            if self.observe(loss):
                self.restarted()
        return self
