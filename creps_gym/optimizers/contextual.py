"""The contextual parts of contextual CMA-ES as pure functions: the context baseline, the regression mean and
the step-size signal of every mean coefficient.

A. Abdolmaleki, B. Price, N. Lau, L. P. Reis, G. Neumann, "Contextual Covariance Matrix Adaptation
Evolutionary Strategies", IJCAI 2017; the equation tags (C1)–(C4') are those of ``docs/algorithms.md``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from creps_gym.optimizers.cma_rules import inverse_sqrt
from creps_gym.optimizers.features import FeatureMap, PolynomialFeatures
from creps_gym.optimizers.policies import weighted_ml_fit

__all__ = ["baseline_features", "coefficient_shift", "context_advantages", "contextual_mean"]

Array = NDArray[np.float64]


def baseline_features(n_samples: int, context_dim: int, degree: int) -> PolynomialFeatures:
    """The richest polynomial of degree ≤ ``degree`` with k features and N ≥ 2k + 2 (at least degree 0)."""
    for order in range(degree, 0, -1):
        features = PolynomialFeatures(context_dim, order)
        if n_samples >= 2 * features.n_features + 2:
            return features
    return PolynomialFeatures(context_dim, 0)


def context_advantages(contexts: Array, returns: Array, degree: int, ridge: float) -> tuple[Array, float]:
    """a_k = R_k − V(s_k), Eq. (C1), and the fraction of the returns' variance that V explains.

    V is a ridge least-squares fit of the returns on a polynomial in s with cross terms (a full quadratic for
    ``degree=2``); a batch too small for it uses the richest lower degree it can fit
    (:func:`baseline_features`). Contexts are standardised first, which leaves the span of the features, and
    so V, unchanged but keeps the fit well conditioned.

    Parameters
    ----------
    contexts : ndarray, shape (N, z)
    returns : ndarray, shape (N,)
    degree : int
        Highest degree of the baseline polynomial.
    ridge : float
        Ridge on the standardised non-constant features.
    """
    n, z = contexts.shape
    features = baseline_features(n, z, degree)
    if features.degree == 0:
        return returns - returns.mean(), 0.0
    spread = contexts.std(axis=0)
    phi = features((contexts - contexts.mean(axis=0)) / np.where(spread > 0, spread, 1.0))
    uniform = np.full(n, 1.0 / n)
    scale = float(np.abs(returns).max()) or 1.0  # the fit is linear in R; scaling keeps it in range
    fit = weighted_ml_fit(phi, returns[:, None] / scale, uniform, ridge, features.constant_column)
    advantages = returns - (phi @ fit)[:, 0] * scale
    total = float(np.sum((returns - returns.mean()) ** 2))
    explained = 1.0 - float(advantages @ advantages) / total if total > 0 else 0.0
    return advantages, explained


def contextual_mean(
    mean_map: FeatureMap, contexts: Array, params: Array, weights: Array, ridge: float
) -> Array:
    """New coefficients A (k, p): weighted least squares of θ on ϕ(s) over the positive weights, Eq. (C3)."""
    selected = weights > 0
    positive = weights[selected] / weights[selected].sum()
    return weighted_ml_fit(
        mean_map(contexts[selected]), params[selected], positive, ridge, mean_map.constant_column
    )


def coefficient_shift(mean_map: FeatureMap, contexts: Array, deviations: Array, weights: Array) -> Array:
    """The shift of every mean coefficient, normalised to N(0, C) columns under random selection, Eq. (C4').

    With Φ the selected samples' features (non-constant columns centred on their weighted mean), W = diag(w)
    and G = ΦᵀWΦ, the unridged regression moves the coefficients by ΔA/σ = MᵀY with M = WΦG⁻¹, where the
    rows y_k of Y are N(0, C) when selection ignores θ. Then (ΔA/σ)ᵀ(MᵀM)^(−1/2) has k independent
    N(0, C) columns; the first is, up to the mixing by (MᵀM)^(−1/2), √μ_eff·y_w.

    Parameters
    ----------
    mean_map : FeatureMap
    contexts : ndarray, shape (μ, z)     the positively weighted samples' contexts
    deviations : ndarray, shape (μ, p)   their y_k
    weights : ndarray, shape (μ,)        their positive weights, summing to one

    Returns
    -------
    ndarray, shape (p, k)
    """
    phi = mean_map(contexts)
    if mean_map.constant_column is not None:
        others = np.arange(phi.shape[1]) != mean_map.constant_column
        phi[:, others] -= weights @ phi[:, others]
    gram = (phi.T * weights) @ phi
    values, vectors = np.linalg.eigh(gram)
    keep = values > 1e-12 * values[-1]  # directions the selected contexts do not span carry no signal
    inverse = (vectors[:, keep] / values[keep]) @ vectors[:, keep].T
    hat = (phi * weights[:, None]) @ inverse  # M, shape (μ, k)
    return deviations.T @ hat @ inverse_sqrt(hat.T @ hat)
