"""The dual of Contextual REPS and the sample weights it defines (Eqs. 8–9).

Reference: A. Abdolmaleki et al., "Contextual Direct Policy Search With Regularized Covariance Matrix
Estimation", J. Intell. Robot. Syst. (2019), section 3.1 and Algorithm 2, steps 1–3.

g(η, w) = ηε + φ̂ᵀw + η log((1/N) Σ_k exp((R_k − φ(s_k)ᵀw)/η)) is minimised over η > 0 and w, and the weights
are d_k ∝ exp((R_k − φ(s_k)ᵀw)/η), normalised to sum to one.

Solving the dual. The weights are exactly invariant to R → aR + b (a > 0) and to adding any baseline
φ(s)ᵀv, so the returns are first replaced by the residual of their least-squares fit on φ, scaled to unit
standard deviation. This keeps η of order one for returns of any scale, including late in a run when the
context baseline explains nearly all of the return (the "η → 0 valley" of the raw problem). Writing
a = r − (φ − φ̂)ᵀw, g depends on w only through the convex log-sum-exp, so h(η) = min_w g(η, w) is
computed with a damped Newton solve in w, and the outer condition h′(η) = ε − KL(d ‖ uniform) = 0 is solved
by a safeguarded Newton iteration in log η, which is monotone, with a bracket that falls back to bisection.
The exact derivative uses the Schur complement of the Hessian: d KL / d log η = −(Var_d(a) − cᵀC⁻¹c)/η² with
C = Cov_d(φ) and c = Cov_d(φ, a). At the solution KL = ε up to ``DUAL_KL_TOL``, except where KL(η) stays
below ε for every η (several samples tie for the best return, or the baseline interpolates a small batch): the
constraint is then inactive, and the solution with the smallest η that could be solved at working precision
is returned, with KL < ε. η is bounded to [``ETA_MIN``, ``ETA_MAX``] in normalised return units.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray
from scipy import special
from scipy.linalg.lapack import dposv

from creps_gym._validation import as_float_array, check_positive_int, check_real, check_real_in_range

__all__ = ["DUAL_KL_TOL", "ETA_MAX", "ETA_MIN", "DualSolution", "kl_to_uniform", "solve_dual"]

Array = NDArray[np.float64]
ETA_MIN = 1e-10
ETA_MAX = 1e10
DUAL_KL_TOL = 1e-9
_DEGENERATE = 1e-13  # residual spread (normalised units) under which returns count as fully explained


class DualSolution(NamedTuple):
    """Result of :func:`solve_dual`.

    ``eta`` and ``w`` are in normalised units (``w`` on an orthonormal basis of the centred baseline
    features); η in return units is ``eta * return_scale``.
    """

    weights: Array  # (N,), >= 0, sums to 1
    eta: float
    w: Array  # (k',)
    kl: float  # KL(d || uniform)
    iterations: int
    return_scale: float = 1.0


def _solve_spd(matrix: Array, vector: Array) -> Array:
    """Solve a small SPD system with one LAPACK call (numpy's solve costs more in overhead than in work)."""
    _, solution, info = dposv(matrix, vector)
    return solution if info == 0 else np.full_like(vector, np.nan)


def _residual_softmax(r: Array, features: Array, eta: float, w: Array) -> tuple[Array, Array, float]:
    """Residuals a = r − Fw, weights d = softmax(a/η) and log-mean-exp(a/η)."""
    residual = r - features @ w if features.shape[1] else r
    scaled = residual / eta
    top = scaled.max()
    expo = np.exp(scaled - top)
    total = expo.sum()
    return residual, expo / total, float(top + np.log(total / r.shape[0]))


def _minimise_over_w(
    r: Array, features: Array, eta: float, w: Array
) -> tuple[Array, Array, Array, float, bool]:
    """Damped Newton on w ↦ η·logmeanexp((r − Fw)/η) (convex); returns w, residual, d, KL, converged."""
    residual, weights, lme = _residual_softmax(r, features, eta, w)
    converged = not features.shape[1]
    for _ in range(0 if converged else 50):
        mean_f = features.T @ weights  # the negative gradient −∂g/∂w
        centred = features - mean_f
        hessian = (centred.T * weights) @ centred / eta
        hessian.flat[:: hessian.shape[0] + 1] += 1e-12 * (hessian.trace() + 1e-300)
        step = _solve_spd(hessian, mean_f)
        if not np.isfinite(step).all():
            step = eta * mean_f  # a gradient step if the Hessian is numerically singular
        decrement = float(mean_f @ step)  # Newton decrement λ², in units of the objective
        if decrement <= 1e-20 * eta:
            converged = True
            break
        if decrement <= 1e-6 * eta:  # quadratic convergence region: the full step is safe
            res_c, d_c, lme_c = _residual_softmax(r, features, eta, w + step)
            if not np.isfinite(lme_c):
                break  # round-off at a tiny η: report "not converged" and let the outer loop back off
            w, residual, weights, lme = w + step, res_c, d_c, lme_c
            continue
        value = eta * lme
        for _ in range(30):  # Armijo backtracking keeps the convex objective decreasing
            candidate = w + step
            with np.errstate(over="ignore", invalid="ignore"):  # a rejected trial may overflow
                res_c, d_c, lme_c = _residual_softmax(r, features, eta, candidate)
            if np.isfinite(lme_c) and eta * lme_c <= value - 1e-4 * float(mean_f @ step):
                break
            step = step * 0.5
        else:
            break  # no decrease far from the optimum: η is too small to solve at working precision
        w, residual, weights, lme = candidate, res_c, d_c, lme_c
    return w, residual, weights, kl_to_uniform(weights), converged


def kl_to_uniform(weights: Array) -> float:
    """KL(d ‖ uniform) = log N + Σ_k d_k log d_k for normalised weights d, shape (N,)."""
    return max(float(np.log(weights.shape[0]) + special.xlogy(weights, weights).sum()), 0.0)


def _dkl_dlog_eta(features: Array, residual: Array, weights: Array, eta: float) -> float:
    """d KL / d log η along the inner optimum w*(η) (Schur complement of the dual's Hessian)."""
    centred_a = residual - residual @ weights
    variance = float((centred_a**2) @ weights)
    if features.shape[1]:
        centred_f = features - features.T @ weights
        cov_f = (centred_f.T * weights) @ centred_f
        cov_fa = centred_f.T @ (weights * centred_a)
        cov_f.flat[:: cov_f.shape[0] + 1] += 1e-12 * (cov_f.trace() + 1e-300)
        variance -= float(cov_fa @ _solve_spd(cov_f, cov_fa))
    return -max(variance, 0.0) / eta**2


def _normalise(returns: Array, baseline_features: Array) -> tuple[Array | None, Array, float]:
    """Normalise the returns and the baseline features; returns (r, F, scale) with R ≙ scale · r.

    The weights are exactly invariant to R → aR + b (a > 0), to R → R + φᵀv (w absorbs v) and to any
    invertible linear map of the centred features φ − φ̂, so this changes nothing but the units of η and w:

    * F is an orthonormal basis (columns of norm √N) of the centred features, with directions at round-off
      level dropped (a constant or offset context dimension then neither stalls nor biases the solve);
    * r is the residual of the returns' least-squares fit on F, shifted to max 0 and scaled to unit standard
      deviation. Then w = 0 is the optimum for η → ∞, and η is O(1) even when the baseline explains nearly all
      of the returns (the η → 0 valley of the raw problem).

    r is ``None`` when the residual vanishes (all-equal returns, or returns fully explained by the baseline).
    """
    n = returns.shape[0]
    raw_scale = float(np.abs(baseline_features).max()) if baseline_features.size else 0.0
    features = np.zeros((n, 0))
    if raw_scale > 0.0:
        basis, singular, _ = np.linalg.svd(
            baseline_features - baseline_features.mean(axis=0), full_matrices=False
        )
        features = basis[:, singular > 1e-12 * raw_scale * np.sqrt(n)] * np.sqrt(n)
    magnitude = float(np.abs(returns).max())
    if magnitude == 0.0:
        return None, features, 1.0
    centred = returns / magnitude  # divide first: returns near ±1e308 must not overflow
    centred = centred - centred.mean()
    spread = float(np.abs(centred).max())
    if spread == 0.0:
        return None, features, 1.0
    residual = centred / spread
    if features.shape[1]:
        residual = residual - features @ (features.T @ residual) / n
    deviation = float(residual.std())
    if deviation <= _DEGENERATE:
        return None, features, 1.0
    return (residual - residual.max()) / deviation, features, magnitude * spread * deviation


def solve_dual(
    returns: Array,
    baseline_features: Array,
    epsilon: float,
    eta0: float = 1.0,
    max_iter: int = 100,
) -> DualSolution:
    """Minimise the CREPS dual g(η, w) (Eq. 8) and return the sample weights (Eq. 9).

    Parameters
    ----------
    returns : ndarray, shape (N,)
        Returns R_k (maximised). Only their ranks and spacing matter: the result is invariant to R → aR + b.
    baseline_features : ndarray, shape (N, k)
        φ(s_k); centred on their batch mean φ̂ inside, so a constant feature is not needed (and a constant
        context dimension is harmless).
    epsilon : float
        KL bound ε, 0 < ε < log N.
    eta0 : float
        Warm start for η in normalised units, e.g. the previous iteration's ``DualSolution.eta``.

    Returns
    -------
    DualSolution
        Weights (N,) with KL(d ‖ uniform) = ε within ``DUAL_KL_TOL`` (or < ε at ``ETA_MIN``, see module
        docstring); all-equal returns, or returns fully explained by the baseline, give uniform weights.
    """
    returns = as_float_array(returns, "returns", (None,))
    baseline_features = as_float_array(baseline_features, "baseline_features", (returns.shape[0], None))
    if returns.shape[0] < 2:
        raise ValueError(f"returns: expected at least 2 samples, got {returns.shape[0]}")
    epsilon = check_real_in_range(epsilon, "epsilon", 0.0, math.log(returns.shape[0]), high_inclusive=False)
    eta0 = check_real(eta0, "eta0", strict=True)
    max_iter = check_positive_int(max_iter, "max_iter")
    with np.errstate(over="ignore", under="ignore", divide="ignore", invalid="ignore"):
        # Trial points near the non-smooth η → 0 limit may overflow; they are rejected by finiteness checks.
        return _solve_dual(returns, baseline_features, epsilon, eta0, max_iter)


def _solve_dual(
    returns: Array, baseline_features: Array, epsilon: float, eta0: float, max_iter: int
) -> DualSolution:
    n = baseline_features.shape[0]
    uniform = np.full(n, 1.0 / n)
    r, features, scale = _normalise(returns, baseline_features)
    if r is None:
        return DualSolution(uniform, np.inf, np.zeros(features.shape[1]), 0.0, 0, scale)
    w = np.zeros(features.shape[1])  # the exact large-η optimum after _normalise
    log_eta = float(np.log(np.clip(eta0, ETA_MIN, ETA_MAX))) if np.isfinite(eta0) else 0.0
    low, high = np.log(ETA_MIN), np.log(ETA_MAX)  # the root log η lies in (low, high)
    best = DualSolution(uniform, np.inf, w, 0.0, 0, scale)  # feasible (KL ≤ ε), with the smallest η
    for iteration in range(1, max_iter + 1):
        eta = float(np.exp(log_eta))
        w_eta, residual, weights, kl, converged = _minimise_over_w(r, features, eta, w)
        if not converged:  # too close to the non-smooth η → 0 limit: treat as the lower end
            low = log_eta
        else:
            w, gap = w_eta, kl - epsilon
            if gap <= DUAL_KL_TOL and eta < best.eta:
                best = DualSolution(weights, eta, w, kl, iteration, scale)
            if abs(gap) <= DUAL_KL_TOL:
                break
            low, high = (log_eta, high) if gap > 0 else (low, log_eta)
        if high - low < 1e-6:
            break  # KL(η) is flat below ε here (ties or a baseline that interpolates): keep the best
        slope = _dkl_dlog_eta(features, residual, weights, eta) if converged else 0.0
        if converged and slope < 0:
            step = -gap / slope
        else:
            step = 2.0 if (not converged or gap > 0) else -2.0
        proposal = log_eta + float(np.clip(step, -2.0, 2.0))
        log_eta = proposal if low < proposal < high else 0.5 * (low + high)
    return best._replace(iterations=iteration)
