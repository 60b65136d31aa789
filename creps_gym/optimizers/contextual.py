"""The contextual parts of contextual CMA-ES as pure functions: the context baseline, the regression mean and
the step-size signal of every mean coefficient.

A. Abdolmaleki, B. Price, N. Lau, L. P. Reis, G. Neumann, "Contextual Covariance Matrix Adaptation
Evolutionary Strategies", IJCAI 2017; the equation tags (C1)–(C4') are those of ``docs/algorithms.md``.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray

from creps_gym.optimizers.cma_rules import inverse_sqrt, median
from creps_gym.optimizers.features import FeatureMap, PolynomialFeatures
from creps_gym.optimizers.mean_fit import weighted_ml_fit

__all__ = [
    "BASELINE_RIDGE_SCALES",
    "MIN_BANDWIDTH",
    "MIN_UNEXPLAINED",
    "baseline_features",
    "check_local_baseline",
    "coefficient_shift",
    "context_advantages",
    "contextual_mean",
    "detrended_local_advantages",
    "local_advantages",
    "recent_samples",
    "robust_refit",
    "scaled_ridge",
]

LOSSES = ("squared", "huber")
#: How the baseline's ridge scales: ``"fixed"`` (C1) or ``"unexplained"`` (C1s, :func:`scaled_ridge`).
BASELINE_RIDGE_SCALES = ("fixed", "unexplained")
MIN_UNEXPLAINED = 1e-6  # the smallest factor of C1s: the ridge stays >= 1e-6 of its value (conditioning)
MIN_BANDWIDTH = 1e-3  # the local baseline's smallest bandwidth: below it the kernel weighs nothing but s_k
HUBER_K = 1.345  # the Huber threshold in robust standard deviations: 95 % efficiency for Gaussian residuals

Array = NDArray[np.float64]


@functools.lru_cache(maxsize=64)
def baseline_features(n_samples: int, context_dim: int, degree: int) -> PolynomialFeatures:
    """The richest polynomial of degree ≤ ``degree`` with k features and N ≥ 2k + 2 (at least degree 0).

    Cached: the maps are frozen, and building one checks the memory its fit needs (reading ``/proc``), which
    cost about a fifth of a C-CMA-ES update at p = 20, N = 50."""
    for order in range(degree, 0, -1):
        features = PolynomialFeatures(context_dim, order)
        if n_samples >= 2 * features.n_features + 2:
            return features
    return PolynomialFeatures(context_dim, 0)


def _with_past(
    contexts: Array, returns: Array, past_contexts: Array | None, past_returns: Array | None
) -> tuple[Array, Array]:
    """The reused samples followed by the batch: contexts (M + N, z) and returns (M + N,)."""
    if past_returns is None or not past_returns.size:
        return contexts, returns
    return np.concatenate([past_contexts, contexts]), np.concatenate([past_returns, returns])


def _explained(scaled_returns: Array, scaled_residuals: Array) -> float:
    """1 − Σ r_k² / Σ (R_k − R̄)², both in units of the largest |R| (squares of returns near 1e155 would
    overflow); 0 for flat returns."""
    total = float(np.sum((scaled_returns - scaled_returns.mean()) ** 2))
    return 1.0 - float(scaled_residuals @ scaled_residuals) / total if total > 0 else 0.0


def context_advantages(
    contexts: Array,
    returns: Array,
    degree: int,
    ridge: float,
    past_contexts: Array | None = None,
    past_returns: Array | None = None,
    standardise: bool = False,
    loss: str = "squared",
    ridge_scale: str = "fixed",
) -> tuple[Array, float]:
    """a_k = R_k − V(s_k), Eq. (C1), and the fraction of the batch returns' variance that V explains.

    V is a ridge least-squares fit of the returns on a polynomial in s with cross terms (a full quadratic for
    ``degree=2``); too few samples for it give the richest lower degree they can fit
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
    past_contexts, past_returns : ndarray, shape (M, z) and (M,), optional
        Samples of earlier batches that the fit of V reuses (the advantages are the current batch's only).
    standardise : bool
        Divide each advantage by a context-dependent scale √v(s), with v a least-squares fit of the squared
        advantages on the same features (floored at 1 % of their mean), so that contexts where the returns
        spread widely do not take all the top and bottom ranks.
    loss : str
        ``"squared"`` (least squares) or ``"huber"`` (:func:`robust_refit`).
    ridge_scale : str
        ``"fixed"``: the ridge as given. ``"unexplained"``, Eq. (C1s): see :func:`scaled_ridge`.
    """
    if loss not in LOSSES:
        raise ValueError(f"loss: expected one of {LOSSES}, got {loss!r}")
    if ridge_scale not in BASELINE_RIDGE_SCALES:
        raise ValueError(f"ridge_scale: expected one of {BASELINE_RIDGE_SCALES}, got {ridge_scale!r}")
    n, z = contexts.shape
    all_contexts, all_returns = _with_past(contexts, returns, past_contexts, past_returns)
    features = baseline_features(all_returns.shape[0], z, degree)
    if features.degree == 0:
        return returns - all_returns.mean(), 0.0
    spread = all_contexts.std(axis=0)
    centre, spread = all_contexts.mean(axis=0), np.where(spread > 0, spread, 1.0)
    phi = features((all_contexts - centre) / spread)
    uniform = np.full(all_returns.shape[0], 1.0 / all_returns.shape[0])
    scale = float(np.abs(all_returns).max()) or 1.0  # the fit is linear in R; scaling keeps it in range
    fit = weighted_ml_fit(phi, all_returns[:, None] / scale, uniform, ridge, features.constant_column)
    if ridge_scale == "unexplained" and ridge > 0.0:  # Eq. (C1s): the ridge shrinks with the unexplained part
        ridge = scaled_ridge(ridge, all_returns / scale, (phi @ fit)[:, 0])
        fit = weighted_ml_fit(phi, all_returns[:, None] / scale, uniform, ridge, features.constant_column)
    if loss == "huber":
        fit = robust_refit(phi, all_returns / scale, fit, ridge, features.constant_column)
    residuals = all_returns / scale - (phi @ fit)[:, 0]
    advantages = residuals[-n:] * scale
    explained = _explained(returns / scale, residuals[-n:])
    if standardise and residuals.any():  # all zero (flat returns): nothing to rank, nothing to scale
        squares = residuals**2
        variance = (phi @ weighted_ml_fit(phi, squares[:, None], uniform, ridge, features.constant_column))[
            :, 0
        ]
        advantages = advantages / np.sqrt(np.maximum(variance[-n:], 0.01 * squares.mean()))
    return advantages, explained


def scaled_ridge(ridge: float, targets: Array, fitted: Array) -> float:
    """The baseline's ridge of Eq. (C1s): ``ridge`` times the fraction 1 − R² of the targets' variance that a
    first fit leaves unexplained, clipped to [:data:`MIN_UNEXPLAINED`, 1].

    A ridge on the standardised features shrinks V's slopes by about ``ridge`` of their size, an error of
    ``ridge`` times the context's effect on the returns. Where that effect does not vanish at the optimum
    (a best return that depends on s), a fixed ridge floors the ranking once the part of the returns that θ
    decides falls below it; scaled by 1 − R², the error is about ``ridge`` times that part squared over the
    context's effect, so it shrinks with the search. Scaling or shifting the returns does not change it.

    Parameters
    ----------
    ridge : float
    targets, fitted : ndarray, shape (M,)
        The returns the baseline is fitted on and the first fit's values at them.
    """
    unexplained = 1.0 - _explained(targets, targets - fitted)
    return ridge * min(max(unexplained, MIN_UNEXPLAINED), 1.0)


def check_local_baseline(bandwidth: float, polynomial_options: Mapping[str, tuple[Any, Any]]) -> None:
    """Raise ``ValueError`` for a ``bandwidth`` in (0, :data:`MIN_BANDWIDTH`), and for a local V (C1'',
    ``bandwidth`` > 0) when an option of the polynomial fit (name -> (value, default)) is not at its default:
    the local V ignores them, so another value would silently have no effect. The caller checks that
    ``bandwidth`` is finite and >= 0."""
    if 0.0 < bandwidth < MIN_BANDWIDTH:
        raise ValueError(f"baseline_bandwidth: expected 0 or >= {MIN_BANDWIDTH}, got {bandwidth}")
    names = ", ".join(polynomial_options)
    given = tuple(value for value, _ in polynomial_options.values())
    expected = tuple(default for _, default in polynomial_options.values())
    if bandwidth > 0.0 and given != expected:
        raise ValueError(f"{names}: expected {expected} with baseline_bandwidth > 0, got {given}")


def local_advantages(
    contexts: Array,
    returns: Array,
    bandwidth: float,
    past_contexts: Array | None = None,
    past_returns: Array | None = None,
) -> tuple[Array, float]:
    """a_k = R_k − V(s_k) with a local V, Eq. (C1''), and the fraction of the returns' variance V explains.

    V(s_k) is the lower weighted median of the returns of the batch (and of the reused earlier samples), each
    weighted by the Gaussian kernel exp(−‖(s_k − s_j)/d‖² / (2h²)), with d the contexts' standard deviations
    and h the ``bandwidth``. A median follows a cliff in the returns over the contexts (a region where every
    sample falls) that a polynomial cannot, and a few outlying returns do not move it. V shifts with the
    returns and scales with a positive factor, and a strictly increasing transformation of the returns
    transforms it alike (it is always one of the returns).

    Each sample is in its own median with weight 1, the kernel's largest, which shrinks its advantage
    towards 0. A sample with little kernel weight from others (h small against the spacing of the
    contexts, as for z ≥ 2 with few samples) is its own median: its advantage is exactly 0, ties are
    ranked in batch order and the R² is inflated, so choose h to give each sample many neighbours. The
    kernel matrix takes N·(M + N)·z floats.

    Parameters
    ----------
    contexts : ndarray, shape (N, z)
    returns : ndarray, shape (N,)
    bandwidth : float
        h ≥ :data:`MIN_BANDWIDTH`, in context standard deviations.
    past_contexts, past_returns : ndarray, shape (M, z) and (M,), optional
        Samples of earlier batches that V also weighs (the advantages are the current batch's only).

    Returns
    -------
    advantages : ndarray, shape (N,)
    explained : float
        1 − Σ a_k² / Σ (R_k − R̄)² over the batch.

    Raises
    ------
    ValueError
        If ``bandwidth`` is not finite and ≥ :data:`MIN_BANDWIDTH`, or if an advantage overflows (returns of
        opposite signs near the largest float): rescale the returns.
    """
    if not (np.isfinite(bandwidth) and bandwidth >= MIN_BANDWIDTH):
        raise ValueError(f"bandwidth: expected a finite value >= {MIN_BANDWIDTH}, got {bandwidth}")
    n = returns.shape[0]
    all_contexts, all_returns = _with_past(contexts, returns, past_contexts, past_returns)
    spread = all_contexts.std(axis=0)
    scaled = all_contexts / np.where(spread > 0, spread, 1.0)
    squared_distances = ((scaled[-n:, None, :] - scaled[None, :, :]) ** 2).sum(axis=2)
    kernel = np.exp(-0.5 * squared_distances / bandwidth**2)  # (N, M + N); each sample weighs itself 1
    order = np.argsort(all_returns, kind="stable")
    cumulative = np.cumsum(kernel[:, order], axis=1)
    median_rank = (cumulative < 0.5 * cumulative[:, -1:]).sum(axis=1)
    scale = float(np.abs(all_returns).max()) or 1.0  # differences of returns near 1e308 would overflow
    residuals = returns / scale - all_returns[order][median_rank] / scale
    explained = _explained(returns / scale, residuals)
    with np.errstate(over="ignore"):
        advantages = residuals * scale
    if not np.isfinite(advantages).all():
        raise ValueError(
            "returns: expected advantages R_k - V(s_k) within the float range, got an overflow (returns near"
            f" ±{scale:.3g} against a local baseline of the opposite sign); rescale the returns"
        )
    return advantages, explained


def detrended_local_advantages(
    contexts: Array,
    returns: Array,
    bandwidth: float,
    degree: int,
    ridge: float,
    past_contexts: Array | None = None,
    past_returns: Array | None = None,
    ridge_scale: str = "fixed",
) -> tuple[Array, float]:
    """a_k = R_k − V(s_k) with V the polynomial fit of Eq. (C1) plus the local median (C1'') of its residuals,
    Eq. (C1d), and the fraction of the batch returns' variance V explains.

    The polynomial takes the trend of the returns over the contexts, which a local median follows only to
    about its slope times the bandwidth (more at the ends of the context range, where the kernel is
    one-sided); the median of the residuals follows what the polynomial cannot, such as the kink of a
    cone-shaped optimum's E[R | s] (issue 45: GECCO 2019's Different Powers). Both are fitted on the batch
    and the reused samples, whose residuals are those of this batch's polynomial.

    Parameters
    ----------
    contexts, returns, past_contexts, past_returns
        As in :func:`context_advantages`.
    bandwidth : float
        The local median's h, as in :func:`local_advantages`.
    degree, ridge, ridge_scale
        The polynomial fit's, as in :func:`context_advantages`.
    """
    all_contexts, all_returns = _with_past(contexts, returns, past_contexts, past_returns)
    residuals, _ = context_advantages(all_contexts, all_returns, degree, ridge, ridge_scale=ridge_scale)
    reused = all_returns.shape[0] - returns.shape[0]
    advantages, _ = local_advantages(
        contexts, residuals[reused:], bandwidth, all_contexts[:reused], residuals[:reused]
    )
    scale = float(np.abs(all_returns).max()) or 1.0
    return advantages, _explained(returns / scale, advantages / scale)


def robust_refit(
    phi: Array, targets: Array, fit: Array, ridge: float, constant_column: int | None, iterations: int = 50
) -> Array:
    """Huber's M-estimate of a linear fit by iteratively reweighted least squares, started from ``fit``.

    Each pass weighs sample k by min(1, c·σ̂/|r_k|), with r the residuals of the current fit, σ̂ = 1.4826 ×
    their median absolute deviation and c = :data:`HUBER_K`, and refits. Since σ̂ scales with the
    targets, the estimate keeps the least-squares fit's equivariance: adding a function in the span of
    ``phi`` to the targets, or scaling them by a positive factor, changes the fit and leaves the
    (scaled) residuals unchanged.

    Parameters
    ----------
    phi : ndarray, shape (n, k)      features
    targets : ndarray, shape (n,)
    fit : ndarray, shape (k, 1)      the starting fit (least squares)
    ridge : float
    constant_column : int or None    as in :func:`~creps_gym.optimizers.mean_fit.weighted_ml_fit`
    iterations : int                 at most this many passes (it stops once the fit no longer moves)

    Returns
    -------
    ndarray, shape (k, 1)
    """
    for _ in range(iterations):
        residuals = targets - (phi @ fit)[:, 0]
        deviation = np.abs(residuals - median(residuals))
        sigma = 1.4826 * median(deviation)
        if sigma <= 1e-12 * float(np.abs(targets).max(initial=0.0)):  # half the fit is exact: keep it
            return fit
        weights = np.minimum(1.0, HUBER_K * sigma / np.maximum(np.abs(residuals), 1e-300))
        refit = weighted_ml_fit(phi, targets[:, None], weights / weights.sum(), ridge, constant_column)
        moved = float(np.abs(refit - fit).max())
        fit = refit
        if moved <= 1e-12 * max(float(np.abs(fit).max()), 1e-300):
            break
    return fit


def contextual_mean(
    mean_map: FeatureMap,
    contexts: Array,
    params: Array,
    weights: Array,
    ridge: float,
    old_coefficients: Array | None = None,
    repulsion: float = 0.0,
    ridge_centre: str = "zero",
) -> Array:
    """New coefficients A (k, p): weighted least squares of θ on ϕ(s) over the positive weights, Eq. (C3).

    With ``ridge_centre="old"``, Eq. (C3r): the same fit of the shifts θ_k − A_oldᵀϕ(s_k), added to
    ``old_coefficients``, so the ridge shrinks the step instead of the coefficients. Without a ridge both
    are the same least-squares fit; with one, C3 biases the slopes by about ``ridge`` times their size,
    which does not shrink as the search converges, and C3r by ``ridge`` times the step, which does.

    With ``repulsion`` α > 0, Eq. (C3''): minus α times the same fit of the negatively weighted samples'
    shifts θ_k − A_oldᵀϕ(s_k) (``old_coefficients`` A_old, weights |w_k| normalised to one), so that the
    mean also moves away from the worst samples: antisymmetric recombination weights (docs/algorithms.md).
    """
    selected = weights > 0
    positive = weights[selected] / weights[selected].sum()
    features = mean_map(contexts[selected])
    if ridge_centre == "old" and old_coefficients is not None:  # Eq. (C3r): the ridge shrinks the step
        shifts = params[selected] - features @ old_coefficients
        step = weighted_ml_fit(features, shifts, positive, ridge, mean_map.constant_column)
        fitted = old_coefficients + step
    else:  # Eq. (C3)
        fitted = weighted_ml_fit(features, params[selected], positive, ridge, mean_map.constant_column)
    if repulsion == 0.0 or old_coefficients is None:
        return fitted
    rejected = weights < 0
    features = mean_map(contexts[rejected])
    shifts = params[rejected] - features @ old_coefficients
    negative = weights[rejected] / weights[rejected].sum()
    return fitted - repulsion * weighted_ml_fit(features, shifts, negative, ridge, mean_map.constant_column)


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


def recent_samples(
    past_contexts: Array, past_returns: Array, contexts: Array, returns: Array, batches: int
) -> tuple[Array, Array]:
    """The last ``batches``·N samples, N the newest batch's size (its samples included)."""
    kept = batches * returns.shape[0]
    contexts = np.concatenate([past_contexts, contexts])[-kept:]
    returns = np.concatenate([past_returns, returns])[-kept:]
    return contexts, returns
