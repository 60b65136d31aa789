"""The weighted ridge maximum-likelihood fit of a linear-Gaussian policy's mean coefficients.

Eq. (7) of Abdolmaleki et al. (2019), "Contextual Direct Policy Search With Regularized Covariance Matrix
Estimation": A = (ΦᵀDΦ + λI)⁻¹ΦᵀDU, the mean update of CREPS and CREPS-CMA, which contextual CMA-ES's
mean update (Eq. C3) and robust refit reuse. ``docs/algorithms.md`` states how the ridge is scaled.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.linalg.lapack import dposv

__all__ = ["weighted_ml_fit"]

Array = NDArray[np.float64]


def weighted_ml_fit(
    mean_features: Array, params: Array, weights: Array, ridge: float, constant_column: int | None = None
) -> Array:
    """Weighted ridge maximum-likelihood fit of the mean coefficients, Eq. (7).

    Parameters
    ----------
    mean_features : ndarray, shape (N, m)   ϕ(s_k)
    params : ndarray, shape (N, p)          θ_k
    weights : ndarray, shape (N,)           d_k ≥ 0, summing to one
    ridge : float
        Ridge of the regularised normal equations (ΦᵀDΦ + ridge·I)A = ΦᵀDU, relative to the features' scale.
    constant_column : int, optional
        Index of a constant feature (the 1 of ϕ(s) = [1, s]). The ridge then acts on the other columns after
        weighted centring and standardising, and the intercept is not shrunk, so the fit does not depend on
        where the context box lies (contexts in [1000, 1003] fit like contexts in [0, 3]), and the weighted
        residuals sum to zero: Σ_k d_k (θ_k − Aᵀϕ(s_k)) = 0. Without it, the ridge is relative to the mean
        diagonal of ΦᵀDΦ.

    Returns
    -------
    ndarray, shape (m, p)
        The coefficients A; Aᵀϕ(s) is the new mean.
    """
    if constant_column is None:
        weighted = mean_features.T * weights
        gram = weighted @ mean_features
        gram.flat[:: gram.shape[0] + 1] += ridge * max(gram.trace() / gram.shape[0], 1e-300)
        return _solve_pos(gram, weighted @ params)
    others = [i for i in range(mean_features.shape[1]) if i != constant_column]
    columns = mean_features[:, others]
    centre = weights @ columns
    centred = columns - centre
    spread = np.sqrt(weights @ centred**2)
    informative = spread > 1e-12 * (np.abs(centre) + spread)  # constant context dimensions carry nothing
    standardised = np.where(informative, centred / np.where(informative, spread, 1.0), 0.0)
    mean_params = weights @ params
    weighted = standardised.T * weights
    gram = weighted @ standardised
    gram.flat[:: gram.shape[0] + 1] += ridge + (~informative)
    slopes = _solve_pos(gram, weighted @ (params - mean_params))
    slopes /= np.where(informative, spread, 1.0)[:, None]
    coefficients = np.empty((mean_features.shape[1], params.shape[1]))
    coefficients[others] = slopes
    coefficients[constant_column] = mean_params - centre @ slopes
    return coefficients


def _solve_pos(gram: Array, rhs: Array) -> Array:
    """Solve the SPD normal equations with one LAPACK ``posv`` call on the upper triangle.

    It is what ``scipy.linalg.solve(..., assume_a="pos")`` computes, bit for bit (a 1 × 1 system is a
    division there too), without its argument checks, which cost ten times the work at these sizes (the
    robust refit solves up to 50 per update). A matrix that is not positive definite raises
    ``numpy.linalg.LinAlgError``, as there.
    """
    if rhs.size == 0:
        return np.zeros(rhs.shape)
    if gram.size == 1 and gram[0, 0] > 0:  # one feature: a division, as scipy's solve does
        return rhs / gram
    _, solution, info = dposv(gram, rhs, lower=0)
    if info != 0:
        raise np.linalg.LinAlgError(f"gram: expected a positive definite matrix, got a zero pivot at {info}")
    return solution.copy(order="C")  # LAPACK's is Fortran-ordered: later products' bits follow the strides
