"""The run's context selector: built from the configuration (or given), seeded, told, checkpointed.

A run with a selector (``RunConfig.context_selector``, a registered name, or a selector object given to
:class:`~creps_gym.runner.loop.Runner`) draws its training contexts with ``selector.select`` from its own
stream (:func:`selector_stream`) and tells the selector every iteration's
contexts, returns and the optimiser's diagnostics (a plain dict). The evaluation never uses it: the test
contexts come from the evaluation seed. A checkpoint holds the selector's stream and state (JSON data, under
``"selector_rng"`` and ``"selector"``), and only then: runs without a selector write the checkpoints they
wrote before.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from creps_gym._validation import check_generator_state
from creps_gym.runner.config import RunConfig
from creps_gym.runner.seeds import SeedPlan, seed_child
from creps_gym.selectors.base import ContextSelector, select_for
from creps_gym.selectors.registry import make_selector

__all__ = ["STATE_KEYS", "Selection", "selector_stream"]

#: The checkpoint keys of a run with a selector.
STATE_KEYS = ("selector_rng", "selector")


def selector_stream(seed: int) -> np.random.Generator:
    """The selector's Generator: the master seed's child :attr:`~creps_gym.runner.seeds.SeedPlan.SELECTOR`,
    a stream no other draw uses."""
    return np.random.default_rng(seed_child(seed, SeedPlan.SELECTOR))


class Selection:
    """The selector of a run (or none), its Generator and its checkpoint state.

    Parameters
    ----------
    config : RunConfig or None
        The run's configuration (None: no selector).
    selector : ContextSelector, optional
        An object instead of ``config.context_selector`` (not both).
    """

    def __init__(self, config: RunConfig | None, selector: Any = None) -> None:
        if config is None:
            self.selector = self.rng = None
            return
        if selector is not None and config.context_selector is not None:
            raise TypeError(
                f"context_selector: expected a registered name in the config or a selector object (not "
                f"both), got {config.context_selector!r} and {selector!r}"
            )
        if selector is not None and not isinstance(selector, ContextSelector):
            raise TypeError(
                "context_selector: expected an object with bind, select, tell, state_dict and "
                f"load_state_dict (creps_gym.selectors.ContextSelector), got {type(selector).__name__}"
            )
        if config.context_selector is not None:
            selector = make_selector(config.context_selector, config.context_selector_options)
        self.selector = selector
        self.rng = None if selector is None else selector_stream(config.seed)

    def select(self, n: int, optimizer: Any = None) -> Any:
        """The selector's ``n`` contexts from its stream; a selector that declares
        ``uses_context_utility`` also gets the optimiser's ``context_utility`` (None if it has none)."""
        return select_for(self.selector, self.rng, n, optimizer)

    def tell(self, contexts: np.ndarray, returns: np.ndarray, optimizer: Any) -> None:
        """Tell the selector the iteration's outcome and the optimiser's diagnostics (no-op without one)."""
        if self.selector is not None:
            diagnostics = {str(k): float(v) for k, v in dict(optimizer.diagnostics).items()}
            self.selector.tell(contexts.copy(), np.asarray(returns, np.float64).copy(), diagnostics)

    def state(self) -> dict[str, Any]:
        """The checkpoint entries (none without a selector)."""
        if self.selector is None:
            return {}
        return {"selector_rng": self.rng.bit_generator.state, "selector": self.selector.state_dict()}

    def load(self, state: dict[str, Any]) -> None:
        """Restore the entries of :meth:`state`; ``KeyError``/``ValueError`` if they do not match the run."""
        present = [key for key in STATE_KEYS if key in state]
        if self.selector is None:
            if present:
                raise ValueError(
                    "context_selector: the checkpoint holds a selector's state but the run has none (pass "
                    "the selector object the run was started with)"
                )
            return
        if len(present) != len(STATE_KEYS):
            raise KeyError(f"context_selector: expected {list(STATE_KEYS)} in the checkpoint, got {present}")
        self.rng.bit_generator.state = check_generator_state(state["selector_rng"], "selector_rng")
        self.selector.load_state_dict(state["selector"])
