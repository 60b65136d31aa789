"""The context-selection protocol and the selectors that adapt the fixed context samplers.

A :class:`ContextSelector` chooses the training contexts of every iteration of a run and is told what came
of them. The runner (:mod:`creps_gym.runner.contexts`) calls, in this order:

1. ``bind(low, high, env_sampler)`` once: the env's context box (finite, shape (z,)) and the env's own
   sampler ``env_sampler(rng, n) -> (n, z)``;
2. every iteration ``select(rng, n) -> contexts (n, z)``, inside the box, drawing every random number
   from ``rng`` (the run's selector stream), then ``tell(contexts, returns, diagnostics)`` with the
   episodes' returns (n,) and the optimiser's diagnostics (a plain ``{str: float}`` dict);
3. ``state_dict()`` at a checkpoint (JSON data only: numbers, strings, lists, dicts) and
   ``load_state_dict(state)`` on resume. A checkpoint is untrusted: ``load_state_dict`` validates
   ``state`` and raises ``ValueError``/``TypeError`` for anything ``state_dict`` cannot have written.

Optional: a selector whose class sets ``uses_context_utility = True`` is called
``select(rng, n, context_utility=f)`` instead, ``f`` being the optimiser's model hook
``context_utility(candidates (m, z), targets (r, z), pending (k, z) or None) -> (m,)`` (see
:mod:`creps_gym.optimizers.base`) as a plain callable, or None when the optimiser has none
(:class:`~creps_gym.selectors.active.ActiveContextSelector`).

Selectors never see the optimiser or the env: the dependency rule keeps them apart (they import numpy
and :mod:`creps_gym.wrappers.samplers` only).

Adapters of the fixed samplers
------------------------------
UniformSelector
    :class:`~creps_gym.wrappers.samplers.UniformContexts` over the box.
BetaSelector
    :class:`~creps_gym.wrappers.samplers.BetaContexts` over the box (``a = b = 0.5``: the arcsine law).
FixedSelector
    A fixed set, in a cycle over the run or at random (:class:`~creps_gym.wrappers.sources.FixedSource`).
EnvSelector
    The env's own ``sample_contexts`` (what the runner draws without a selector).
"""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from creps_gym._validation import as_float_array, check_in_box, check_positive_int, check_real
from creps_gym.wrappers.samplers import BetaContexts, UniformContexts
from creps_gym.wrappers.sources import FixedSource

__all__ = [
    "BetaSelector",
    "ContextSelector",
    "EnvSelector",
    "FixedSelector",
    "SamplerSelector",
    "UniformSelector",
    "check_state_keys",
    "finite_box",
    "select_for",
]

Array = NDArray[np.float64]


@runtime_checkable
class ContextSelector(Protocol):
    """Chooses an iteration's training contexts and learns from their outcome (see the module docstring)."""

    def bind(self, low: Array, high: Array, env_sampler: Any) -> None:
        """Receive the env's context box (z,) and its own sampler ``(rng, n) -> (n, z)``."""

    def select(self, rng: np.random.Generator, n: int) -> Array:
        """The next ``n`` training contexts, shape (n, z), inside the box."""

    def tell(self, contexts: Array, returns: Array, diagnostics: dict[str, float]) -> None:
        """The outcome of the contexts last selected: returns (n,), the optimiser's diagnostics."""

    def state_dict(self) -> dict[str, Any]:
        """The selector's learnt state as JSON data."""

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore :meth:`state_dict`'s output (validated: it comes from an untrusted checkpoint)."""


def select_for(selector: Any, rng: np.random.Generator, n: int, optimizer: Any = None) -> Array:
    """``selector``'s ``n`` contexts (n, z) from ``rng`` for ``optimizer``'s next batch: a selector that
    declares ``uses_context_utility`` also gets the optimiser's ``context_utility`` (None if it has none)."""
    if not getattr(selector, "uses_context_utility", False):
        return selector.select(rng, n)
    utility = getattr(optimizer, "context_utility", None)
    return selector.select(rng, n, context_utility=utility if callable(utility) else None)


def finite_box(low: Any, high: Any, user: str) -> tuple[Array, Array]:
    """``(low, high)`` as arrays (z,) if finite with ``low < high``, else ``ValueError`` naming ``user``."""
    low = as_float_array(low, f"{user}: context box low", (None,), finite=False)
    high = as_float_array(high, f"{user}: context box high", (low.shape[0],), finite=False)
    with np.errstate(over="ignore", invalid="ignore"):
        width = high - low
    if not (np.isfinite(low).all() and np.isfinite(high).all() and np.isfinite(width).all()):
        raise ValueError(
            f"{user}: expected an env whose context box is finite, got {low.tolist()} to {high.tolist()}"
        )
    if not (width > 0).all():
        raise ValueError(
            f"{user}: expected a context box with low < high, got {low.tolist()} to {high.tolist()}"
        )
    return low, high


def check_state_keys(state: Any, expected: set[str], user: str) -> dict[str, Any]:
    """``state`` if it is a dict with exactly the keys ``expected``; else a ``ValueError``/``TypeError``."""
    if not isinstance(state, dict):
        raise TypeError(f"{user} state: expected a dict, got {type(state).__name__}")
    if set(state) != expected:
        raise ValueError(f"{user} state: expected keys {sorted(expected)}, got {sorted(map(str, state))}")
    return state


class SamplerSelector:
    """Base of the selectors that draw from a fixed distribution: they learn nothing and hold no state.

    Subclasses build :attr:`sampler`, a callable ``(rng, n) -> (n, z)``, in :meth:`make_sampler`.
    """

    name = "sampler"

    def __init__(self) -> None:
        self.sampler: Any = None
        self.low = self.high = np.zeros(0)

    def make_sampler(self, low: Array, high: Array, env_sampler: Any) -> Any:
        """The sampler for the box (subclasses)."""
        raise NotImplementedError

    def bind(self, low: Array, high: Array, env_sampler: Any) -> None:
        """Build the sampler for the env's context box."""
        self.low, self.high = finite_box(low, high, f"context_selector {self.name!r}")
        self.sampler = self.make_sampler(self.low, self.high, env_sampler)

    def select(self, rng: np.random.Generator, n: int) -> Array:
        """``n`` contexts (n, z) from the sampler."""
        if self.sampler is None:
            raise RuntimeError(f"context_selector {self.name!r}: select() before bind()")
        return np.asarray(self.sampler(rng, check_positive_int(n, "n")), dtype=np.float64)

    def tell(self, contexts: Array, returns: Array, diagnostics: dict[str, float]) -> None:
        """Nothing to learn."""

    def state_dict(self) -> dict[str, Any]:
        """No state: ``{}``."""
        return {}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Accept ``{}`` only."""
        check_state_keys(state, set(), f"context_selector {self.name!r}")

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.sampler!r})"


class UniformSelector(SamplerSelector):
    """Uniform draws in the env's context box (:class:`~creps_gym.wrappers.samplers.UniformContexts`)."""

    name = "uniform"

    def make_sampler(self, low: Array, high: Array, env_sampler: Any) -> Any:
        """:class:`UniformContexts` over the box."""
        return UniformContexts(low, high)


class BetaSelector(SamplerSelector):
    """Beta(a, b) draws scaled into the box (:class:`~creps_gym.wrappers.samplers.BetaContexts`).

    Parameters
    ----------
    a : float
        First shape parameter (> 0); 0.5 with ``b = a`` is the arcsine law, which trains the ends of the
        range more often.
    b : float, optional
        Second shape parameter (> 0), default ``a``.
    """

    name = "beta"

    def __init__(self, a: float = 0.5, b: float | None = None) -> None:
        super().__init__()
        self.a = check_real(a, "a", strict=True)
        self.b = self.a if b is None else check_real(b, "b", strict=True)

    def make_sampler(self, low: Array, high: Array, env_sampler: Any) -> Any:
        """:class:`BetaContexts` over the box."""
        return BetaContexts(low, high, self.a, self.b)


class EnvSelector(SamplerSelector):
    """The env's own context distribution (its ``sample_contexts``): the runner's draws without a selector."""

    name = "env"

    def make_sampler(self, low: Array, high: Array, env_sampler: Any) -> Any:
        """The env's sampler as given."""
        if not callable(env_sampler):
            raise TypeError(f"context_selector 'env': expected the env's sampler, got {env_sampler!r}")
        return env_sampler


class FixedSelector:
    """Contexts from a fixed set: in one cycle over the whole run, or drawn at random (with replacement).

    Parameters
    ----------
    contexts : array_like, shape (n, z), or (n,) where z = 1
        The set (inside the env's context box); its shape is checked against the env's z by :meth:`bind`.
    order : {"cycle", "random"}
    """

    name = "fixed"

    def __init__(self, contexts: Any, order: str = "cycle") -> None:
        array = as_float_array(contexts, "contexts")
        if array.ndim not in (1, 2):
            raise ValueError(
                f"contexts: expected shape (n, z), one row of z numbers per context, got {array.shape}"
            )
        self._given_shape = array.shape  # a flat list is one context per number: right only where z = 1
        self.source = FixedSource(array if array.ndim == 2 else array[:, None], order)

    def bind(self, low: Array, high: Array, env_sampler: Any) -> None:
        """Check the set against the env's context box (z = its length)."""
        low, high = finite_box(low, high, "context_selector 'fixed'")
        z = low.shape[0]
        flat = len(self._given_shape) == 1
        if (flat and z != 1) or (not flat and self._given_shape[1] != z):
            raise ValueError(
                f"contexts: expected shape (n, {z}), one row of {z} numbers per context, "
                f"got {self._given_shape}"
            )
        check_in_box(self.source.contexts, low, high, "contexts")

    def select(self, rng: np.random.Generator, n: int) -> Array:
        """The next ``n`` contexts (n, z) of the cycle, or ``n`` drawn at random with ``rng``."""
        return self.source.draw(rng, check_positive_int(n, "n"))[0]

    def tell(self, contexts: Array, returns: Array, diagnostics: dict[str, float]) -> None:
        """Nothing to learn."""

    def state_dict(self) -> dict[str, Any]:
        """The cycle's position."""
        return {"position": self.source.position}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore the cycle's position (an int in [0, m))."""
        state = check_state_keys(state, {"position"}, "context_selector 'fixed'")
        position = check_positive_int(state["position"], "context_selector 'fixed' state position", 0)
        if position >= self.source.contexts.shape[0]:
            raise ValueError(
                f"context_selector 'fixed' state position: expected < {self.source.contexts.shape[0]}, "
                f"got {position}"
            )
        self.source.position = position
