"""A quadratic prior mean for c-bo's Gaussian process: the GP models what a quadratic leaves unexplained.

With h(x) = [1, x_1 … x_d, x_i x_j (i ≤ j)], q = 1 + d + d(d + 1)/2 basis functions of the scaled inputs
x = (s, θ) ∈ [0, 1]^d, the return model is

    f(x) = h(x)ᵀβ + σ_r g(x),   g ~ GP(0, k),                                                      (G4)

with β the least-squares fit of the targets y on H = h(X) (a plug-in estimate, as in universal kriging with
the trend fitted first; Rasmussen & Williams 2006, Sec. 2.7) and σ_r the root mean square of the residuals
y − Hβ, which the GP of Eq. (G2) then fits at unit scale (its hyperparameter bounds stay those of
standardised targets). Where the returns are quadratic in (s, θ), as on a contextual sphere with an affine
optimum, the trend is exact and the posterior mean's maximiser is the optimum whatever the GP's lengthscales;
elsewhere the GP carries what the quadratic misses. The trend is used from 2q episodes on (fewer would let
it interpolate noise); before, the GP has its constant prior mean alone.

A quadratic is exact only on untransformed returns, while c-bo's default log transform is what keeps long
tails of bad returns from swamping the model. :func:`chosen_transform` chooses between them at every tell
by the Box–Cox profile likelihood of the prior mean's fit in the returns' own units, Eq. (G5).

The log transform itself, with R_max the best return told and c a low quantile of the gaps,

    T(R) = −log(1 + (R_max − R)/c),   c = Q_q({R_max − R_k}),                                        (G6)

is near linear in the gaps below c and logarithmic above: it resolves the returns within about c of the best
and compresses the rest. q = 1/4 (:data:`LOG_QUANTILE`, c-bo's ``log_quantile``). The median (q = 1/2),
the default until 2026-11-30, lets a run's bad early episodes set c where most are far worse than the
best, and the differences among the good ones then shrink below the GP's noise: on Different Powers at
p = 8, z = 1 c-bo's regret at 200 episodes was 28 times ``creps``' in the low-budget study, and is 0.015
times it with the lower quartile (``benchmarks/low_budget/README.md``, "c-bo's log scale").
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import special

__all__ = [
    "LOG_QUANTILE",
    "TREND_RATIO",
    "chosen_transform",
    "detrend",
    "log_transform",
    "quadratic_basis",
    "residual_share",
    "trend_and_gradient",
    "trend_maximiser",
    "trend_p_value",
    "with_trend_maximiser",
]

Array = NDArray[np.float64]
#: q of Eq. (G6): the log transform's scale c is this quantile of the gaps to the best return.
LOG_QUANTILE = 0.25
#: The trend is fitted once there are at least this many episodes per basis function.
TREND_RATIO = 2
#: A trend counts as signal (:func:`residual_share`) when noise would fit as well less often than this.
TREND_P = 0.01


def quadratic_basis(x: Array) -> Array:
    """h(x) of Eq. (G4) at inputs x (m, d): shape (m, q), q = 1 + d + d(d + 1)/2."""
    i, j = np.triu_indices(x.shape[1])
    return np.hstack([np.ones((x.shape[0], 1)), x, x[:, i] * x[:, j]])


def _fits_a_trend(basis: Array) -> bool:
    """Whether the rows of ``basis`` (n, q) are at least :data:`TREND_RATIO` · q episodes."""
    return basis.shape[0] >= TREND_RATIO * basis.shape[1]


def _hessian(beta: Array, d: int) -> Array:
    """Q = U + Uᵀ (d, d), U the upper triangle of β's quadratic coefficients: h(x)ᵀβ's Hessian."""
    i, j = np.triu_indices(d)
    upper = np.zeros((d, d))
    upper[i, j] = beta[d + 1 :]
    return upper + upper.T


def trend_and_gradient(x: Array, beta: Array) -> tuple[Array, Array]:
    """h(x)ᵀβ (m,) and its gradient with respect to x (m, d): β_lin + Qx (:func:`_hessian`)."""
    d = x.shape[1]
    return quadratic_basis(x) @ beta, beta[1 : d + 1] + x @ _hessian(beta, d)


def detrend(inputs: Array, targets: Array) -> tuple[Array, Array | None, float]:
    """(residuals / σ_r, β, σ_r) of Eq. (G4) on inputs (n, d) and targets (n,); the targets, None and 1.0
    while n < :data:`TREND_RATIO` · q. σ_r is floored at 1e-12 times the targets' root mean square, so
    residuals that vanish (an exact quadratic) stay finite."""
    basis = quadratic_basis(inputs)
    if not _fits_a_trend(basis):
        return targets, None, 1.0
    beta = np.linalg.lstsq(basis, targets, rcond=None)[0]  # Eq. (G4)
    residuals = targets - basis @ beta
    size = float(np.sqrt(np.mean(targets**2)))
    scale = max(float(np.sqrt(np.mean(residuals**2))), 1e-12 * size, 1e-300)
    return residuals / scale, beta, scale


def trend_p_value(n: int, q: int, explained: float) -> float:
    """The F-test's p-value of a least-squares fit with q coefficients (an intercept among them) that
    explains the share ``explained`` (R²) of n targets' variance: how likely pure noise explains as much.

    F = (R²/(q − 1)) / ((1 − R²)/(n − q)), p = P(F_{q−1, n−q} ≥ F); 1.0 when n ≤ q or q < 2."""
    if n <= q or q < 2:
        return 1.0
    if explained >= 1.0:
        return 0.0
    statistic = (max(explained, 0.0) / (q - 1)) / ((1.0 - explained) / (n - q))
    return float(special.fdtrc(q - 1, n - q, statistic))


def trend_maximiser(beta: Array, context: Array, low: Array, high: Array) -> Array | None:
    """The maximiser over θ of the trend h(s, θ)ᵀβ at a fixed scaled context s (c,), clipped to the box
    [low, high] (q,), or None where the trend is not strictly concave in θ.

    Setting the θ-gradient to zero: Q_θθ θ = −(b_θ + Q_θs s), with b the linear and Q = U + Uᵀ the quadratic
    coefficients. A candidate for the acquisition's and the posterior mean's maximisation: on an
    ill-conditioned quadratic, L-BFGS-B stops once the value no longer changes in its ninth digit, far from
    the maximiser along the flat directions."""
    c, d = context.shape[0], context.shape[0] + low.shape[0]
    hessian = _hessian(beta, d)
    block = hessian[c:, c:]
    try:
        np.linalg.cholesky(-block)
    except np.linalg.LinAlgError:
        return None
    theta = np.linalg.solve(block, -(beta[1 + c : 1 + d] + hessian[c:, :c] @ context))
    return np.clip(theta, low, high)


def with_trend_maximiser(
    candidates: Array, beta: Array | None, context: Array, bounds: tuple[Any, Any]
) -> Array:
    """The candidate θ (m, q) and, with a trend ``beta``, its :func:`trend_maximiser` at ``context`` in
    ``bounds`` (low, high: scalars or (q,)) as one more row."""
    if beta is None:
        return candidates
    q = candidates.shape[1]
    best = trend_maximiser(beta, context, *(np.broadcast_to(b, (q,)) for b in bounds))
    return candidates if best is None else np.vstack([candidates, best[None, :]])


def log_transform(returns: Array, quantile: float = LOG_QUANTILE) -> tuple[Array, float]:
    """c-bo's log transform of the returns (n,), −log(1 + (R_max − R)/c), and its scale c: the ``quantile``
    of the gaps R_max − R (at least 1e-12 times their largest), Eq. (G6). Its derivative in R is
    1/(c + R_max − R)."""
    gaps = returns.max() - returns
    # 0.5 is numpy's median, whose midpoint of an even count can differ from quantile's in the last bit:
    # the runs computed with the former default stay bit-identical
    level = float(np.median(gaps)) if quantile == 0.5 else float(np.quantile(gaps, quantile))
    scale = max(level, 1e-12 * float(gaps.max()), 1e-300)
    return -np.log1p(gaps / scale), scale


def _profile_log_likelihood(inputs: Array, values: Array, log_jacobian: float, trend: bool) -> float:
    """−(n/2) log σ̂² + log |dT/dR| of a least-squares model of transformed returns ``values`` (n,): a
    quadratic in the inputs (n, d) with ``trend`` and at least :data:`TREND_RATIO` · q episodes, else a
    constant (Box & Cox 1964: the transform's profile likelihood in the returns' own units)."""
    basis = quadratic_basis(inputs)
    if not (trend and _fits_a_trend(basis)):
        basis = basis[:, :1]
    residuals = values - basis @ np.linalg.lstsq(basis, values, rcond=None)[0]
    variance = max(float(np.mean(residuals**2)), 1e-300)
    return -0.5 * values.shape[0] * float(np.log(variance)) + log_jacobian  # Eq. (G5)


def chosen_transform(inputs: Array, returns: Array, trend: bool, quantile: float = LOG_QUANTILE) -> str:
    """``"none"`` or ``"log"``, whichever gives the returns (n,) the larger profile likelihood under the GP's
    prior mean (the quadratic of Eq. G4 with ``trend``, else a constant), Eq. (G5):

        ℓ(T) = −(n/2) log σ̂²_T + Σ_k log T′(R_k),   T_none(R) = R,   T_log(R) = −log(1 + (R_max − R)/c),

    with σ̂²_T the mean squared residual of the least-squares fit of T(R) and c the log transform's scale
    (:func:`log_transform` at ``quantile``, Eq. G6); ties keep ``"log"``. Returns that are quadratic in
    (s, θ) choose ``"none"`` (σ̂² vanishes), long tails of bad returns ``"log"``."""
    logged, scale = log_transform(returns, quantile)
    jacobian = -float(np.log(scale + (returns.max() - returns)).sum())
    plain = _profile_log_likelihood(inputs, returns, 0.0, trend)
    return "none" if plain > _profile_log_likelihood(inputs, logged, jacobian, trend) else "log"


def residual_share(scale: float, beta: Array, targets: Array) -> float:
    """The share σ_r²/Var(y) of the targets y (n,) that the trend (q coefficients ``beta``) leaves to the
    GP, if an F-test says pure noise fits as well less often than :data:`TREND_P` (the trend is signal);
    1.0 otherwise. c-bo's ``no_signal`` stop multiplies the GP's noise share by it."""
    unexplained = scale**2 / max(float(np.var(targets)), 1e-300)
    significant = trend_p_value(targets.shape[0], beta.shape[0], 1.0 - unexplained) < TREND_P
    return unexplained if significant else 1.0
