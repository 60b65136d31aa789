"""Context distributions for the context wrappers, and named, seeded train/test context sets.

A context sampler is any callable ``sampler(rng, n) -> contexts (n, z)`` that draws every random number
from the Generator it is given; the wrappers pass the env's ``np_random``, so a seeded reset gives the same
contexts bit for bit.

Samplers
--------
ContextSampler
    The protocol: ``__call__(rng, n) -> (n, z)``.
UniformContexts
    Uniform in a box ``[low, high]``.
BetaContexts
    Beta(a, b) in every dimension, scaled into a box; ``a = b < 1`` weights the box's ends.
GaussianContexts
    Gaussian ``N(mean, cov)``, optionally clipped into a box.

Functions
---------
context_splits
    Disjoint named context sets (``{"train": (m1, z), "test": (m2, z)}``) drawn from one seed.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from creps_gym._validation import as_float_array, check_positive_int, check_real

__all__ = ["BetaContexts", "ContextSampler", "GaussianContexts", "UniformContexts", "context_splits"]

Array = NDArray[np.float64]


@runtime_checkable
class ContextSampler(Protocol):
    """A context distribution: ``sampler(rng, n)`` returns ``n`` contexts of shape (n, z).

    It must draw all its randomness from ``rng`` (the env's ``np_random``).
    """

    def __call__(self, rng: np.random.Generator, n: int) -> Array:
        """Draw ``n`` contexts, shape (n, z)."""


def _check_box(low: Any, high: Any, name: str = "low/high") -> tuple[Array, Array]:
    low = as_float_array(low, "low", (None,))
    high = as_float_array(high, "high", (low.shape[0],))
    if (low > high).any():
        col = int(np.argmax(low > high))
        raise ValueError(
            f"{name}: expected low <= high in every dimension, got {low[col]} > {high[col]} at index {col}"
        )
    return low, high


class UniformContexts:
    """Contexts drawn uniformly in the box ``[low, high]``.

    Parameters
    ----------
    low, high : array_like, shape (z,)
        Finite bounds with ``low <= high``.
    """

    def __init__(self, low: Any, high: Any) -> None:
        self.low, self.high = _check_box(low, high)

    def __call__(self, rng: np.random.Generator, n: int) -> Array:
        """Draw ``n`` contexts, shape (n, z)."""
        n = check_positive_int(n, "n")
        return rng.uniform(self.low, self.high, size=(n, self.low.shape[0]))

    def __repr__(self) -> str:
        return f"UniformContexts(low={self.low.tolist()}, high={self.high.tolist()})"


class BetaContexts:
    """Contexts ``low + (high - low) · u`` with every coordinate of ``u`` drawn from Beta(a, b).

    ``a = b = 1`` is the uniform box. ``a = b = 0.5`` (the arcsine law) puts a third of the draws in each
    outer quarter of the range (uniform draws: a quarter), and 2.7 times as many as uniform draws in each
    outer eighteenth: the ends, where a policy that is affine in the context is least determined by the
    draws in between, are trained on more often.

    Parameters
    ----------
    low, high : array_like, shape (z,)
        Finite bounds with ``low <= high``.
    a : float
        First shape parameter, finite and > 0.
    b : float, optional
        Second shape parameter, finite and > 0; default ``a`` (symmetric about the box's centre).
    """

    def __init__(self, low: Any, high: Any, a: float, b: float | None = None) -> None:
        self.low, self.high = _check_box(low, high)
        with np.errstate(over="ignore"):
            self.width = self.high - self.low
        if not np.isfinite(self.width).all():
            raise ValueError(
                f"low/high: expected a box whose width high - low is finite, got {self.low.tolist()} to "
                f"{self.high.tolist()}"
            )
        self.a = check_real(a, "a", strict=True)
        self.b = self.a if b is None else check_real(b, "b", strict=True)

    def __call__(self, rng: np.random.Generator, n: int) -> Array:
        """Draw ``n`` contexts, shape (n, z)."""
        n = check_positive_int(n, "n")
        return self.low + self.width * rng.beta(self.a, self.b, size=(n, self.low.shape[0]))

    def __repr__(self) -> str:
        return f"BetaContexts(low={self.low.tolist()}, high={self.high.tolist()}, a={self.a}, b={self.b})"


def _covariance_factor(cov: Any, dim: int) -> Array:
    """A factor ``L`` with ``L Lᵀ = cov`` for a scalar, diagonal (z,) or full (z, z) covariance."""
    cov = as_float_array(cov, "cov")
    if cov.ndim == 0:
        cov = np.full(dim, float(cov))
    if cov.ndim == 1:
        if cov.shape != (dim,) or (cov < 0).any():
            raise ValueError(f"cov: expected non-negative variances of shape ({dim},), got {cov.tolist()}")
        return np.diag(np.sqrt(cov))
    if cov.shape != (dim, dim) or not np.allclose(cov, cov.T):
        raise ValueError(f"cov: expected a symmetric matrix of shape ({dim}, {dim}), got shape {cov.shape}")
    values, vectors = np.linalg.eigh(cov)
    if values.min() < -1e-10 * max(1.0, abs(values.max())):
        raise ValueError(
            f"cov: expected a positive semi-definite matrix, got smallest eigenvalue {values.min()}"
        )
    return vectors * np.sqrt(np.clip(values, 0.0, None))


class GaussianContexts:
    """Contexts drawn from ``N(mean, cov)``, clipped into ``[low, high]`` when bounds are given.

    Parameters
    ----------
    mean : array_like, shape (z,)
    cov : float or array_like, shape (z,) or (z, z)
        Isotropic variance, variances, or a positive semi-definite covariance matrix.
    low, high : array_like, shape (z,), optional
        Clip the samples into this box (both or neither), e.g. the env's context box.
    """

    def __init__(self, mean: Any, cov: Any, low: Any = None, high: Any = None) -> None:
        self.mean = as_float_array(mean, "mean", (None,))
        self.factor = _covariance_factor(cov, self.mean.shape[0])
        if (low is None) != (high is None):
            raise ValueError(f"low/high: expected both or neither, got low={low!r} and high={high!r}")
        self.bounds = None if low is None else _check_box(low, high)
        if self.bounds is not None and self.bounds[0].shape != self.mean.shape:
            raise ValueError(f"low/high: expected shape {self.mean.shape}, got {self.bounds[0].shape}")

    def __call__(self, rng: np.random.Generator, n: int) -> Array:
        """Draw ``n`` contexts, shape (n, z)."""
        n = check_positive_int(n, "n")
        noise = rng.standard_normal((n, self.mean.shape[0]))
        samples = self.mean + noise @ self.factor.T
        if self.bounds is not None:
            samples = np.clip(samples, *self.bounds)
        return samples

    def __repr__(self) -> str:
        return f"GaussianContexts(mean={self.mean.tolist()}, clipped={self.bounds is not None})"


def context_splits(source: Any, sizes: Mapping[str, int], seed: int) -> dict[str, Array]:
    """Draw named, disjoint context sets from one seed, e.g. for train and test splits.

    Parameters
    ----------
    source : ContextSampler or ContextualEpisodicEnv
        A sampler, or an env whose ``sample_contexts(rng, n)`` is used (its own context distribution).
    sizes : mapping of str to int
        Set name to number of contexts, e.g. ``{"train": 20, "test": 10}``; drawn in this order.
    seed : int
        Seed of the Generator all sets are drawn from (same seed, same sets).

    Returns
    -------
    dict of str to ndarray, shape (m_name, z)
        One independent draw per set; with a continuous distribution the sets share no context.
    """
    draw = getattr(source, "sample_contexts", None) or source
    if not callable(draw):
        raise TypeError(
            f"source: expected a context sampler or a contextual env, got {type(source).__name__}"
        )
    if not isinstance(sizes, Mapping) or not sizes:
        raise ValueError(f"sizes: expected a non-empty mapping of set name to size, got {sizes!r}")
    counts = {str(name): check_positive_int(count, f"sizes[{name!r}]") for name, count in sizes.items()}
    rng = np.random.default_rng(check_positive_int(seed, "seed", minimum=0))
    contexts = as_float_array(draw(rng, sum(counts.values())), "source output", (sum(counts.values()), None))
    splits, start = {}, 0
    for name, count in counts.items():
        splits[name] = contexts[start : start + count].copy()
        start += count
    return splits
