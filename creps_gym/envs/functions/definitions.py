"""The 15 test functions of the paper's Table 1 as pure, batched numpy kernels.

Abdolmaleki et al. (2019), section 5.1, Table 1. The extracted table is garbled, so the kernels follow the
standard definitions of the CMA-ES test-function literature (Hansen's ``cmaes.m`` / ``purecma`` test suite,
Hansen & Ostermeier 2001, and the CEC 2005 benchmark of Suganthan et al. for the shifted, rotated functions),
as settled in ``docs/algorithms.md``. Indices in the formulas are 1-based, ``p >= 2`` is the dimension.

Every kernel maps points ``x`` of shape (n, p) to values of shape (n,) and is *row-independent*: row ``k`` of
the result depends only on row ``k`` of ``x`` and is bit-identical whatever ``n`` is (only element-wise
operations and reductions along the last axis are used, never a BLAS product across rows). The shift and the
rotation of the "shifted" functions are applied by the environment (:mod:`.instance`) before the kernel is
called, so here every kernel is in its own canonical coordinates.

Stopping targets (the paper's "Stop" column): a regret ``f(x) - f_opt <= 1e-5`` for the 12 bounded
functions, and ``f(x) <= -1e4`` for Plane, Sharp Ridge and Parabolic Ridge, which are unbounded below.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "cigar",
    "cigtab",
    "different_powers",
    "elliptic",
    "parabolic_ridge",
    "plane",
    "rastrigin",
    "rosenbrock",
    "schwefel_1_2",
    "sharp_ridge",
    "sphere",
    "tablet",
    "two_axes",
]

Array = NDArray[np.float64]


def _square_sum(x: Array) -> Array:
    return np.square(x).sum(axis=1)


def rosenbrock(x: Array) -> Array:
    """Rosenbrock: ``f(x) = sum_{i=1}^{p-1} [100 (x_{i+1} - x_i^2)^2 + (1 - x_i)^2]``.

    Reference: Rosenbrock (1960); Hansen's ``frosen``. ``x* = (1, ..., 1)``, ``f_opt = 0``; stop target
    regret 1e-5. For ``p >= 4`` there is also a local minimum near ``x_1 = -1``.

    Parameters
    ----------
    x : ndarray, shape (n, p)

    Returns
    -------
    ndarray, shape (n,)
    """
    head, tail = x[:, :-1], x[:, 1:]
    valley = head * head  # in-place steps: fewer large temporaries
    np.subtract(tail, valley, out=valley)
    valley *= valley
    valley *= 100.0
    gap = 1.0 - head
    gap *= gap
    valley += gap
    return valley.sum(axis=1)


def sphere(x: Array) -> Array:
    """Sphere: ``f(x) = sum_i x_i^2``.

    Reference: De Jong (1975); Hansen's ``fsphere``. ``x* = 0``, ``f_opt = 0``; stop target regret 1e-5.
    The "Shifted Sphere" is ``sphere(x - o)`` (CEC 2005 F1 without its bias).

    Parameters
    ----------
    x : ndarray, shape (n, p)

    Returns
    -------
    ndarray, shape (n,)
    """
    return _square_sum(x)


def schwefel_1_2(x: Array) -> Array:
    """Schwefel's problem 1.2 (double sum): ``f(x) = sum_{i=1}^{p} (sum_{j=1}^{i} x_j)^2``.

    Reference: Schwefel (1995), problem 1.2; Hansen's ``fschwefel``; CEC 2005 F2. ``x* = 0``, ``f_opt = 0``;
    stop target regret 1e-5. The paper uses the shifted version ``schwefel_1_2(x - o)``.

    Parameters
    ----------
    x : ndarray, shape (n, p)

    Returns
    -------
    ndarray, shape (n,)
    """
    return _square_sum(np.cumsum(x, axis=1))


def cigtab(x: Array) -> Array:
    """CigTab: ``f(x) = x_1^2 + 1e8 x_p^2 + 1e4 sum_{i=2}^{p-1} x_i^2``.

    Reference: Hansen's ``fcigtab`` (cigar-tablet). ``x* = 0``, ``f_opt = 0``; stop target regret 1e-5.
    Condition number 1e8. For ``p = 2`` the middle sum is empty.

    Parameters
    ----------
    x : ndarray, shape (n, p)

    Returns
    -------
    ndarray, shape (n,)
    """
    return x[:, 0] ** 2 + 1e8 * x[:, -1] ** 2 + 1e4 * _square_sum(x[:, 1:-1])


def tablet(x: Array) -> Array:
    """Tablet: ``f(x) = 1e6 x_1^2 + sum_{i=2}^{p} x_i^2``.

    Reference: Hansen's ``ftablet``. ``x* = 0``, ``f_opt = 0``; stop target regret 1e-5. Condition number 1e6.

    Parameters
    ----------
    x : ndarray, shape (n, p)

    Returns
    -------
    ndarray, shape (n,)
    """
    return 1e6 * x[:, 0] ** 2 + _square_sum(x[:, 1:])


def elliptic(x: Array, condition: float = 1e6) -> Array:
    """High-conditioned elliptic: ``f(x) = sum_{i=1}^{p} condition^((i-1)/(p-1)) x_i^2``.

    Reference: Hansen's ``felli``; CEC 2005 F3 ("shifted rotated high conditioned elliptic", condition 1e6).
    ``x* = 0``, ``f_opt = 0``; stop target regret 1e-5. The paper uses it shifted and rotated,
    ``elliptic(R (x - o))``, with condition 1e6 and a variant with condition 1e4.

    Parameters
    ----------
    x : ndarray, shape (n, p)
    condition : float
        Ratio of the largest to the smallest axis weight.

    Returns
    -------
    ndarray, shape (n,)
    """
    p = x.shape[1]
    weights = condition ** (np.arange(p) / (p - 1))
    terms = np.square(x)
    terms *= weights
    return terms.sum(axis=1)


def different_powers(x: Array) -> Array:
    """Different powers: ``f(x) = sum_{i=1}^{p} |x_i|^(2 + 10 (i-1)/(p-1))``.

    Reference: Hansen's ``fdiffpow`` (exponents from 2 to 12). ``x* = 0``, ``f_opt = 0``; stop target
    regret 1e-5.

    Parameters
    ----------
    x : ndarray, shape (n, p)

    Returns
    -------
    ndarray, shape (n,)
    """
    p = x.shape[1]
    exponents = 2.0 + 10.0 * np.arange(p) / (p - 1)
    terms = np.abs(x)
    np.power(terms, exponents, out=terms)
    return terms.sum(axis=1)


def plane(x: Array) -> Array:
    """Plane (linear function): ``f(x) = x_1``.

    Reference: Hansen's ``fplane``. Unbounded below: no ``x*`` and no ``f_opt``; stop target ``f <= -1e4``.

    Parameters
    ----------
    x : ndarray, shape (n, p)

    Returns
    -------
    ndarray, shape (n,)
    """
    return x[:, 0].copy()


def two_axes(x: Array) -> Array:
    """Two axes: ``f(x) = 1e6 sum_{i=1}^{floor(p/2)} x_i^2 + sum_{i=floor(p/2)+1}^{p} x_i^2``.

    Reference: Hansen's ``ftwoaxes`` (which weights the second half instead: the same function up to an
    axis permutation). ``x* = 0``, ``f_opt = 0``; stop target regret 1e-5.

    Parameters
    ----------
    x : ndarray, shape (n, p)

    Returns
    -------
    ndarray, shape (n,)
    """
    half = x.shape[1] // 2
    return 1e6 * _square_sum(x[:, :half]) + _square_sum(x[:, half:])


def cigar(x: Array) -> Array:
    """Cigar: ``f(x) = x_1^2 + 1e6 sum_{i=2}^{p} x_i^2``.

    Reference: Hansen's ``fcigar``. ``x* = 0``, ``f_opt = 0``; stop target regret 1e-5.

    Parameters
    ----------
    x : ndarray, shape (n, p)

    Returns
    -------
    ndarray, shape (n,)
    """
    return x[:, 0] ** 2 + 1e6 * _square_sum(x[:, 1:])


def rastrigin(x: Array) -> Array:
    """Rastrigin: ``f(x) = 10 p + sum_{i=1}^{p} [x_i^2 - 10 cos(2 pi x_i)]``.

    Reference: Rastrigin (1974); Hansen's ``frastrigin10`` without scaling. ``x* = 0``, ``f_opt = 0``; stop
    target regret 1e-5. Multimodal (about 10^p local minima): a Gaussian search distribution with a small
    population is not expected to reach the global optimum.

    Parameters
    ----------
    x : ndarray, shape (n, p)

    Returns
    -------
    ndarray, shape (n,)
    """
    waves = np.multiply(x, 2.0 * np.pi)
    np.cos(waves, out=waves)
    waves *= -10.0
    waves += np.square(x)
    return 10.0 * x.shape[1] + waves.sum(axis=1)


def sharp_ridge(x: Array) -> Array:
    """Sharp ridge: ``f(x) = x_1 + 100 sqrt(sum_{i=2}^{p} x_i^2)``.

    Reference: Hansen's ``fsharpR`` (with ``-x_1``: the mirror image). Unbounded below along ``-x_1``; stop
    target ``f <= -1e4``.

    Parameters
    ----------
    x : ndarray, shape (n, p)

    Returns
    -------
    ndarray, shape (n,)
    """
    return x[:, 0] + 100.0 * np.sqrt(_square_sum(x[:, 1:]))


def parabolic_ridge(x: Array) -> Array:
    """Parabolic ridge: ``f(x) = x_1 + 100 sum_{i=2}^{p} x_i^2``, Hansen's ``fparabR``: the sharp ridge
    (:func:`sharp_ridge`, mirrored and unbounded below in the same way) with the squared norm.

    Parameters
    ----------
    x : ndarray, shape (n, p)

    Returns
    -------
    ndarray, shape (n,)
    """
    return x[:, 0] + 100.0 * _square_sum(x[:, 1:])
