"""What the scalar and vector context wrappers share: fixed sets, checked samplers, parameter boxes."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np
from gymnasium import spaces
from numpy.typing import NDArray

from creps_gym._validation import as_float_array
from creps_gym.envs.base import ContextualEpisodicEnv

__all__ = ["ORDERS", "FixedSet", "FixedSource", "checked_samples", "param_bounds", "unchanged_on_error"]

Array = NDArray[np.float64]
ORDERS = ("cycle", "random")


class FixedSource:
    """A finite context set read in a cycle or at random; shared by the scalar and vector wrappers.

    Parameters
    ----------
    contexts : ndarray, shape (m, z)
        Already validated contexts.
    order : {"cycle", "random"}
    """

    def __init__(self, contexts: Array, order: str) -> None:
        if order not in ORDERS:
            raise ValueError(f"order: expected one of {ORDERS}, got {order!r}")
        if contexts.shape[0] == 0:
            raise ValueError("contexts: expected at least one context, got an empty set of shape (0, z)")
        self.contexts, self.order, self.position = contexts, order, 0

    def restart(self) -> None:
        """Start the cycle again at the first context."""
        self.position = 0

    def draw(self, rng: np.random.Generator, n: int) -> tuple[Array, NDArray[np.int64]]:
        """Return ``n`` contexts (n, z) and their indices in the set (n,)."""
        m = self.contexts.shape[0]
        if self.order == "random":
            index = rng.integers(0, m, size=n)
        else:
            index = (self.position + np.arange(n)) % m
            self.position = int((self.position + n) % m)
        return self.contexts[index].copy(), index.astype(np.int64)


class FixedSet:
    """What ``FixedContexts`` and ``FixedContextsVector`` share: the checked set, its label and its cycle.

    A mixin for a context-choosing wrapper whose ``model`` (the env's contextual model) is set.
    """

    model: Any
    source: FixedSource
    name: str | None

    def _hold(self, contexts: Any, order: str, name: str | None) -> None:
        """Check ``contexts`` (m, z) against the env's context box and keep them with ``order``."""
        self.source = FixedSource(self.model.check_contexts(contexts, "contexts"), order)
        self.name = name

    @property
    def contexts(self) -> Array:
        """The context set, shape (m, z)."""
        return self.source.contexts.copy()

    def _restart(self) -> None:
        self.source.restart()


def checked_samples(sampler: Any, rng: np.random.Generator, n: int, model: ContextualEpisodicEnv) -> Array:
    """Call ``sampler(rng, n)`` and check its output against the env's context box: shape (n, z)."""
    samples = sampler(rng, n)
    samples = as_float_array(samples, f"sampler {sampler!r} output", (n, model.context_dim))
    return model.check_contexts(samples, f"sampler {sampler!r} output")


def param_bounds(space: Any, wrapper: str) -> tuple[Array, Array]:
    """Finite ``(low, high)`` of a 1-D Box parameter space with ``low < high``, else a clear error."""
    if not isinstance(space, spaces.Box) or len(space.shape) != 1:
        raise TypeError(f"env.action_space: {wrapper} expected a 1-D Box, got {space}")
    low, high = space.low.astype(np.float64), space.high.astype(np.float64)
    if not (np.isfinite(low).all() and np.isfinite(high).all() and (low < high).all()):
        raise ValueError(f"env.action_space: {wrapper} expected finite bounds with low < high, got {space}")
    return low, high


@contextmanager
def unchanged_on_error(wrapper: Any) -> Iterator[None]:
    """Undo what a reset did to a context wrapper if the reset raises (a rejected call changes nothing).

    A reset may re-seed or draw from the wrapper's ``np_random`` and move a :class:`FixedSource` cycle
    (``wrapper.source``) before the wrapped env validates the options; on an exception the generator (its
    object and its bit state) and the cycle position are put back.
    """
    generator = wrapper.np_random
    state = generator.bit_generator.state
    source = getattr(wrapper, "source", None)
    position = None if source is None else source.position
    try:
        yield
    except BaseException:
        generator.bit_generator.state = state
        wrapper.np_random = generator
        if source is not None:
            source.position = position
        raise
