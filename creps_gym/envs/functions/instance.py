"""Seeded problem instances: the context matrix A, the shift o and the rotation R of one function.

The paper contextualises each function with ``x = theta + A s``, where A is "a constant matrix that was chosen
randomly", but gives neither A's distribution nor the shift. This module fixes them, reproducibly, from the
non-negative integer ``instance`` seed:

* ``seeds = numpy.random.SeedSequence(instance).spawn(3)``; each quantity has its own stream, so A does not
  depend on whether the function is shifted or rotated, and is the same for every function of the suite.
* ``A = default_rng(seeds[0]).uniform(-1, 1, size=(p, z))``.
* ``o = default_rng(seeds[1]).uniform(-4, 4, size=p)`` for the shifted functions (zero otherwise).
* ``R``: a Haar-random orthogonal matrix for the rotated functions, the Q factor (with positive diagonal R
  factor) of ``default_rng(seeds[2]).standard_normal((p, p))``, computed with numpy's element-wise
  operations (classical Gram-Schmidt, applied twice) rather than LAPACK, so that one instance is the same
  problem, bit for bit, on every machine with the same numpy.

All batched maps here are row-independent: row k of a result depends only on row k of the inputs and is
bit-identical for any batch size, so the native vector env reproduces the scalar env exactly.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

__all__ = ["FunctionInstance", "haar_orthogonal", "make_instance"]

Array = NDArray[np.float64]

#: Half-width of the paper's initial search region, -5 <= theta_i <= 5.
SEARCH_HALF_WIDTH = 5.0
#: Margin added around the range of theta*(s) when it leaves the search region.
BOX_MARGIN = 1.0


def haar_orthogonal(rng: np.random.Generator, dim: int) -> Array:
    """A Haar-distributed orthogonal matrix, shape (dim, dim), by Gram-Schmidt on a Gaussian matrix."""
    gaussian = rng.standard_normal((dim, dim))
    basis = np.empty((dim, dim))
    for j in range(dim):
        column = gaussian[:, j].copy()
        done = basis[:, :j]
        for _ in range(2):  # classical Gram-Schmidt twice: orthogonal to machine precision
            coefficients = (done * column[:, None]).sum(axis=0)
            column -= (done * coefficients).sum(axis=1)
        basis[:, j] = column / np.sqrt((column * column).sum())
    return basis


@dataclass(frozen=True, eq=False)
class FunctionInstance:
    """One seeded instance of a contextual function.

    Attributes
    ----------
    matrix : ndarray, shape (p, z)
        The context matrix A of ``x = theta + A s``.
    shift : ndarray, shape (p,)
        The shift o (zeros for unshifted functions).
    rotation : ndarray, shape (p, p), or None
        The orthogonal R of the rotated functions.
    optimum : ndarray, shape (p,), or None
        The minimiser ``x*`` in x coordinates (``o`` for shifted functions, the kernel's own ``x*``
        otherwise), or None for a function unbounded below.
    canonical_optimum : ndarray, shape (p,), or None
        The kernel's minimiser in its own coordinates (zeros, or ones for Rosenbrock); ``None`` if unbounded.
    """

    matrix: Array
    shift: Array
    rotation: Array | None
    optimum: Array | None
    canonical_optimum: Array | None
    _negated_columns: tuple[Array, ...] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        columns = tuple(np.ascontiguousarray(-self.matrix[:, j]) for j in range(self.matrix.shape[1]))
        object.__setattr__(self, "_negated_columns", columns)

    @property
    def dim(self) -> int:
        """Number of parameters p."""
        return int(self.matrix.shape[0])

    @property
    def context_dim(self) -> int:
        """Number of context dimensions z."""
        return int(self.matrix.shape[1])

    def negative_offset(self, contexts: Array) -> Array:
        """``-A s`` for contexts (n, z): shape (n, p), computed without a BLAS product.

        A sum of element-wise products over the z columns, in a fixed order: row-independent, and IEEE
        rounding is symmetric, so negating A first gives exactly ``-(A s)`` with one pass fewer.
        """
        columns = self._negated_columns
        if not columns:  # z = 0: a non-contextual function, theta* is the same for every (empty) context
            return np.zeros((contexts.shape[0], self.dim))
        out = contexts[:, 0:1] * columns[0]
        for j in range(1, len(columns)):
            out += contexts[:, j : j + 1] * columns[j]
        return out

    def optimal_params(self, contexts: Array) -> Array:
        """``theta*(s) = x* - A s`` for contexts (n, z): shape (n, p)."""
        if self.optimum is None:
            raise ValueError("optimal_params: the function is unbounded below and has no optimum")
        theta = self.negative_offset(contexts)
        if self.optimum.any():
            theta += self.optimum
        return theta

    def kernel_argument(self, deviation: Array) -> Array:
        """The kernel's argument for ``deviation = theta - theta*(s)`` (= ``x - x*``), shape (n, p).

        Shifted functions see ``z = x - o`` (``R (x - o)`` if rotated); the others see ``x = x* + (x - x*)``.
        Going through the deviation makes ``theta = theta*(s)`` land exactly on ``x*``, so the regret at the
        optimum is exactly 0 in floating point. ``deviation`` (a temporary of the caller) may be overwritten.
        """
        if self.rotation is not None:
            # A stack of (1, p) @ (p, p) products: every row takes the same BLAS path whatever n is.
            rotated = np.matmul(np.ascontiguousarray(deviation)[:, None, :], self.rotation.T)
            return rotated[:, 0, :]
        if self.canonical_optimum is None or not self.canonical_optimum.any():
            return deviation
        deviation += self.canonical_optimum  # the caller hands over its temporary: no new array
        return deviation

    def param_bounds(self, context_low: Array, context_high: Array) -> tuple[Array, Array]:
        """Finite parameter bounds: the paper's [-5, 5]^p widened to contain theta*(s) for every s in the box.

        ``theta*_i(s) = x*_i - sum_j A_ij s_j`` is affine in s, so its range over the box is exact; the box is
        widened by :data:`BOX_MARGIN` wherever that range leaves [-5, 5].
        """
        low = np.full(self.dim, -SEARCH_HALF_WIDTH)
        high = np.full(self.dim, SEARCH_HALF_WIDTH)
        if self.optimum is None:
            return low, high
        at_low, at_high = self.matrix * context_low, self.matrix * context_high
        offset_min = np.minimum(at_low, at_high).sum(axis=1)
        offset_max = np.maximum(at_low, at_high).sum(axis=1)
        low = np.minimum(low, self.optimum - offset_max - BOX_MARGIN)
        high = np.maximum(high, self.optimum - offset_min + BOX_MARGIN)
        return low, high


def make_instance(
    dim: int,
    context_dim: int,
    instance: int,
    *,
    shifted: bool,
    rotated: bool,
    canonical_optimum: Array | None,
) -> FunctionInstance:
    """Draw the instance ``instance`` of a function of dimension p = ``dim`` with z = ``context_dim``.

    Parameters
    ----------
    dim, context_dim : int
        p >= 2 and z >= 1 (validated by the caller).
    instance : int
        Non-negative seed.
    shifted, rotated : bool
        Whether the function has a shift o and a rotation R.
    canonical_optimum : ndarray, shape (p,), or None
        The kernel's minimiser in its own coordinates, or None if unbounded below.

    Returns
    -------
    FunctionInstance
    """
    matrix_seed, shift_seed, rotation_seed = np.random.SeedSequence(instance).spawn(3)
    matrix = np.random.default_rng(matrix_seed).uniform(-1.0, 1.0, size=(dim, context_dim))
    shift = np.random.default_rng(shift_seed).uniform(-4.0, 4.0, size=dim) if shifted else np.zeros(dim)
    rotation = haar_orthogonal(np.random.default_rng(rotation_seed), dim) if rotated else None
    if canonical_optimum is None:
        optimum = None
    else:
        optimum = shift.copy() if shifted else np.asarray(canonical_optimum, dtype=np.float64).copy()
    for array in (matrix, shift, rotation, optimum, canonical_optimum):
        if array is not None:
            array.setflags(write=False)
    return FunctionInstance(matrix, shift, rotation, optimum, canonical_optimum)
