"""A Gaussian-process model of the return over inputs x = (s, θ) scaled to the unit box (numpy/scipy only).

The kernel is the ARD Matérn-5/2 kernel (Rasmussen & Williams 2006, Eq. 4.17)

    k(x, x') = σ_f² (1 + √5 r + 5r²/3) exp(−√5 r),   r² = Σ_j (x_j − x'_j)² / ℓ_j²,          (G1)

plus a noise term σ_n² on the diagonal. The targets are the returns after :func:`transformed_returns`
(an order-preserving transform, standardised to unit variance), so the hyperparameters
h = (log ℓ_1 … log ℓ_d, log σ_f², log σ_n²) live on a fixed scale and their bounds (:data:`LOG_BOUNDS`) do
not depend on the task. With K = k(X, X) + σ_n² I = LLᵀ and α = K⁻¹y:

    μ(x) = k(x, X) α,   σ²(x) = σ_f² − ‖L⁻¹ k(X, x)‖²                                         (G2)

(the latent function's variance, without the noise), and the log marginal likelihood is

    log p(y | h) = −½ yᵀα − Σ log L_ii − (n/2) log 2π,   ∂/∂h_k = ½ tr((ααᵀ − K⁻¹) ∂K/∂h_k).    (G3)

A fit costs O(m³) in the m episodes it sees, so it may see a subset of the n told ones (:func:`fit_subset`):
all of them while n ≤ m, and beyond either m episodes spread evenly over the whole history,

    i_j = ⌊j (n − 1) / (m − 1) + ½⌋,   j = 0 … m − 1,                                          (G3a)

(rounded half up in integer arithmetic; the first and the latest included, all distinct since the step
(n − 1)/(m − 1) exceeds 1) or the m most recent ones, n − m … n − 1.

A model is a pure function of (X, y, h): :func:`fit_gp` computes the same bits from the same arrays, so an
optimiser that stores its data and hyperparameters restores its model exactly, without pickle.
:meth:`GPModel.condition` appends one (fantasised) observation by a rank-one extension of L (the kriging
believer of batch acquisition), in O(n²). An optional quadratic prior mean, Eq. (G4), is in
:mod:`creps_gym.optimizers.gp_trend`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import linalg, special
from scipy.linalg.lapack import dtrtrs

from creps_gym.optimizers.gp_trend import LOG_QUANTILE, detrend, log_transform, trend_and_gradient

__all__ = [
    "FIT_SUBSETS",
    "LOG_BOUNDS",
    "GPModel",
    "default_start",
    "fit_gp",
    "fit_hyperparameters",
    "fit_subset",
    "hyper_bounds",
    "log_marginal_likelihood",
    "matern52",
    "mean_ranks",
    "transformed_returns",
]

Array = NDArray[np.float64]
SQRT5 = math.sqrt(5.0)
#: Bounds of the log hyperparameters on inputs in the unit box and standardised returns: lengthscales from
#: 0.01 to 20 box widths, signal variance from 0.01 to 100, noise variance from 1e-6 to 1 (the returns' own
#: variance: pure noise).
LOG_BOUNDS = {
    "lengthscale": (math.log(0.01), math.log(20.0)),
    "signal": (math.log(0.01), math.log(100.0)),
    "noise": (math.log(1e-6), 0.0),
}
_JITTER = 1e-10
#: The rules of :func:`fit_subset`: the episodes a refit sees once there are more than it may.
FIT_SUBSETS = ("spread", "recent")


def _scaled_differences(a: Array, b: Array, lengthscales: Array) -> Array:
    """(x_j − x'_j)/ℓ_j for every pair: shape (n, m, d)."""
    return (a[:, None, :] - b[None, :, :]) / lengthscales


def matern52(a: Array, b: Array, lengthscales: Array, signal: float) -> Array:
    """The Matérn-5/2 kernel matrix k(a_i, b_j), Eq. (G1).

    r² is computed as ‖a‖² + ‖b‖² − 2abᵀ on the scaled inputs (a matrix product; clipped at 0).

    Parameters
    ----------
    a : ndarray, shape (n, d)
    b : ndarray, shape (m, d)
    lengthscales : ndarray, shape (d,)
    signal : float
        σ_f².

    Returns
    -------
    ndarray, shape (n, m)
    """
    a, b = a / lengthscales, b / lengthscales
    squared = np.einsum("nd,nd->n", a, a)[:, None] + np.einsum("md,md->m", b, b)[None, :] - 2.0 * (a @ b.T)
    r = np.sqrt(np.maximum(squared, 0.0))
    return signal * (1.0 + SQRT5 * r + (5.0 / 3.0) * r * r) * np.exp(-SQRT5 * r)


def _kernel_and_slope(a: Array, b: Array, lengthscales: Array, signal: float) -> tuple[Array, Array, Array]:
    """k(a, b) (n, m), G = σ_f² (5/3)(1 + √5 r) exp(−√5 r) (n, m) and the scaled differences (n, m, d).

    ∂k/∂a_j = −G (a_j − b_j)/ℓ_j² and ∂k/∂log ℓ_j = G (a_j − b_j)²/ℓ_j².
    """
    scaled = _scaled_differences(a, b, lengthscales)
    r = np.sqrt(np.einsum("nmd,nmd->nm", scaled, scaled))
    decay = np.exp(-SQRT5 * r)
    kernel = signal * (1.0 + SQRT5 * r + (5.0 / 3.0) * r * r) * decay
    slope = signal * (5.0 / 3.0) * (1.0 + SQRT5 * r) * decay
    return kernel, slope, scaled


@dataclass(frozen=True, eq=False)
class GPModel:
    """A fitted GP (see the module docstring); build it with :func:`fit_gp`.

    Attributes
    ----------
    inputs : ndarray, shape (n, d)      X, scaled to the unit box.
    targets : ndarray, shape (n,)       standardised returns y (with a trend: the residuals / σ_r).
    log_hyper : ndarray, shape (d + 2,) h.
    chol : ndarray, shape (n, n)        L, lower.
    alpha : ndarray, shape (n,)         K⁻¹y.
    beta : ndarray, shape (q,) or None  the quadratic prior mean's coefficients, Eq. (G4); None: none.
    scale : float                       σ_r of Eq. (G4) (1 without a trend).

    With a trend, :meth:`predict` and :meth:`predict_with_gradient` give h(x)ᵀβ + σ_r μ(x) and σ_r² σ²(x);
    ``signal``, ``noise`` and :meth:`latent_variance` stay those of the GP of the standardised residuals.
    """

    inputs: Array
    targets: Array
    log_hyper: Array
    chol: Array
    alpha: Array
    beta: Array | None = None
    scale: float = 1.0

    @property
    def lengthscales(self) -> Array:
        """ℓ, shape (d,)."""
        return np.exp(self.log_hyper[:-2])

    @property
    def signal(self) -> float:
        """σ_f²."""
        return float(np.exp(self.log_hyper[-2]))

    @property
    def noise(self) -> float:
        """σ_n²."""
        return float(np.exp(self.log_hyper[-1]))

    @property
    def observation_noise(self) -> float:
        """σ_n² in the units of :meth:`predict` (σ_r² σ_n² with a trend)."""
        return self.scale**2 * self.noise

    def predict(self, x: Array) -> tuple[Array, Array]:
        """Posterior mean and latent variance at x (m, d), Eq. (G2) (and G4): two arrays of shape (m,)."""
        cross, variance = self._latent(x)
        if self.beta is None:
            return cross @ self.alpha, variance
        trend = trend_and_gradient(x, self.beta)[0]
        return trend + self.scale * (cross @ self.alpha), np.maximum(self.scale**2 * variance, 1e-300)

    def latent_variance(self, x: Array) -> Array:
        """σ²(x) of the GP of Eq. (G2) itself, in the units of ``signal`` and ``noise``: shape (m,)."""
        return self._latent(x)[1]

    def _latent(self, x: Array) -> tuple[Array, Array]:
        """k(x, X) (m, n) and the GP's own posterior variance σ²(x) (m,), Eq. (G2)."""
        cross = matern52(x, self.inputs, self.lengthscales, self.signal)
        v = _solve_lower(self.chol, cross.T)
        return cross, np.maximum(self.signal - np.einsum("nm,nm->m", v, v), 1e-300)

    def predict_with_gradient(self, x: Array) -> tuple[Array, Array, Array, Array]:
        """Mean (m,), variance (m,) and their gradients with respect to x, each of shape (m, d)."""
        cross, slope, scaled = _kernel_and_slope(x, self.inputs, self.lengthscales, self.signal)
        dcross = -(slope[:, :, None] * scaled) / self.lengthscales  # ∂k(x, X_i)/∂x, (m, n, d)
        v = _solve_lower(self.chol, cross.T)
        weights = _solve_lower(self.chol, v, transposed=True)  # K⁻¹k
        variance = np.maximum(self.signal - np.einsum("nm,nm->m", v, v), 1e-300)
        mean_gradient = np.einsum("mnd,n->md", dcross, self.alpha)
        variance_gradient = -2.0 * np.einsum("mnd,nm->md", dcross, weights)
        if self.beta is None:
            return cross @ self.alpha, variance, mean_gradient, variance_gradient
        trend, trend_gradient = trend_and_gradient(x, self.beta)
        squared = self.scale**2
        mean = trend + self.scale * (cross @ self.alpha)
        mean_gradient = trend_gradient + self.scale * mean_gradient
        return mean, np.maximum(squared * variance, 1e-300), mean_gradient, squared * variance_gradient

    def condition(self, x: Array, y: float) -> GPModel:
        """The model with one more observation (x (d,), y) and the same hyperparameters: L grows by one row
        (l = L⁻¹k(X, x), L_nn = √(k(x, x) + σ_n² − ‖l‖²)), in O(n²)."""
        row = x[None, :]
        if self.beta is not None:  # the GP holds the standardised residual
            y = (y - float(trend_and_gradient(row, self.beta)[0][0])) / self.scale
        cross = matern52(row, self.inputs, self.lengthscales, self.signal)[0]
        low = linalg.solve_triangular(self.chol, cross, lower=True, check_finite=False)
        corner = math.sqrt(max(self.signal + self.noise + _JITTER - float(low @ low), 1e-12))
        n = self.chol.shape[0]
        chol = np.zeros((n + 1, n + 1))
        chol[:n, :n], chol[n, :n], chol[n, n] = self.chol, low, corner
        inputs = np.vstack([self.inputs, row])
        targets = np.append(self.targets, y)
        alpha = linalg.cho_solve((chol, True), targets, check_finite=False)
        return GPModel(inputs, targets, self.log_hyper, chol, alpha, self.beta, self.scale)


def _solve_lower(chol: Array, rhs: Array, transposed: bool = False) -> Array:
    """L⁻¹ B (or L⁻ᵀ B) for the lower Cholesky factor ``chol`` (n, n) and ``rhs`` (n, m): the LAPACK
    ``trtrs`` call ``scipy.linalg.solve_triangular`` makes, bit for bit (a C-ordered L is passed as the
    Fortran-ordered Lᵀ), without its checks and batching, which cost more than the solve at these sizes."""
    if chol.flags.f_contiguous:
        solution, info = dtrtrs(chol, rhs, lower=1, trans=int(transposed))
    else:
        solution, info = dtrtrs(chol.T, rhs, lower=0, trans=int(not transposed))
    if info != 0:
        raise np.linalg.LinAlgError(f"chol: expected a nonsingular triangular factor, got a zero at {info}")
    return solution


def _factor(inputs: Array, log_hyper: Array) -> tuple[Array, Array]:
    """K (n, n) with the noise and a jitter on the diagonal, and its lower Cholesky factor."""
    lengthscales, signal, noise = np.exp(log_hyper[:-2]), math.exp(log_hyper[-2]), math.exp(log_hyper[-1])
    gram = matern52(inputs, inputs, lengthscales, signal)
    gram.flat[:: gram.shape[0] + 1] += noise + _JITTER
    return gram, linalg.cholesky(gram, lower=True, check_finite=False)


def fit_gp(inputs: Array, targets: Array, log_hyper: Array, trend: bool = False) -> GPModel:
    """The GP of Eq. (G2) on inputs (n, d) and standardised targets (n,) with hyperparameters h (d + 2,);
    with ``trend``, on the standardised residuals of the quadratic prior mean of Eq. (G4)
    (:func:`~creps_gym.optimizers.gp_trend.detrend`).

    A pure function: the same arrays give the same bits.
    """
    beta, scale = None, 1.0
    if trend:
        targets, beta, scale = detrend(inputs, targets)
    _, chol = _factor(inputs, log_hyper)
    alpha = linalg.cho_solve((chol, True), targets, check_finite=False)
    hyper = np.array(log_hyper, dtype=np.float64)
    return GPModel(inputs.copy(), targets.copy(), hyper, chol, alpha, beta, scale)


def log_marginal_likelihood(inputs: Array, targets: Array, log_hyper: Array) -> tuple[float, Array]:
    """log p(y | h) and its gradient with respect to h (d + 2,), Eq. (G3).

    ∂K/∂log ℓ_j = G ∘ D_j with D_j the squared scaled differences in dimension j; with V = W ∘ G (W = ααᵀ −
    K⁻¹, symmetric), Σ V ∘ D_j = 2 Σ_n u_nj² (V1)_n − 2 u_jᵀVu_j (u = x/ℓ): O(n²d) without an (n, n, d) array.
    """
    lengthscales, signal, noise = np.exp(log_hyper[:-2]), math.exp(log_hyper[-2]), math.exp(log_hyper[-1])
    scaled = inputs / lengthscales
    norms = np.einsum("nd,nd->n", scaled, scaled)
    r = np.sqrt(np.maximum(norms[:, None] + norms[None, :] - 2.0 * (scaled @ scaled.T), 0.0))
    decay = np.exp(-SQRT5 * r)
    kernel = signal * (1.0 + SQRT5 * r + (5.0 / 3.0) * r * r) * decay
    slope = signal * (5.0 / 3.0) * (1.0 + SQRT5 * r) * decay
    gram = kernel.copy()
    gram.flat[:: gram.shape[0] + 1] += noise + _JITTER
    chol = linalg.cholesky(gram, lower=True, check_finite=False)
    alpha = linalg.cho_solve((chol, True), targets, check_finite=False)
    n = targets.shape[0]
    value = -0.5 * float(targets @ alpha) - float(np.log(np.diag(chol)).sum())
    value -= 0.5 * n * math.log(2 * math.pi)
    inverse = linalg.cho_solve((chol, True), np.eye(n), check_finite=False)
    outer = np.outer(alpha, alpha) - inverse  # W = ααᵀ − K⁻¹
    weighted = outer * slope  # V
    gradient = np.empty(log_hyper.shape[0])
    row_sums = weighted.sum(axis=1)
    gradient[:-2] = (row_sums @ (scaled * scaled)) - np.einsum("nd,nd->d", scaled, weighted @ scaled)
    gradient[-2] = 0.5 * float(np.einsum("nm,nm->", outer, kernel))
    gradient[-1] = 0.5 * noise * float(np.trace(outer))
    return value, gradient


def default_start(n_inputs: int) -> Array:
    """The first fit's start: lengthscales 0.5 box widths, signal variance 1, noise variance 1e-3."""
    return np.array([math.log(0.5)] * n_inputs + [0.0, math.log(1e-3)])


def hyper_bounds(n_inputs: int) -> list[tuple[float, float]]:
    """The L-BFGS-B bounds of h for d inputs (:data:`LOG_BOUNDS`)."""
    return [LOG_BOUNDS["lengthscale"]] * n_inputs + [LOG_BOUNDS["signal"], LOG_BOUNDS["noise"]]


def fit_subset(n: int, points: int, rule: str) -> NDArray[np.int64]:
    """The episodes a refit sees (Eq. G3a).

    Fitting the hyperparameters on the most recent episodes alone fits them to where the search has
    converged, not to the data the model conditions on: with ``points`` = 256 and ``"recent"``, c-bo's
    default until 2026-11-30, its recommended policy got worse from 300 to 500 episodes on many tasks of
    issue 44's study (``benchmarks/low_budget/results/refit_data.md`` counts them, and measures the new
    default, which within those 500 episodes fits every one).

    Parameters
    ----------
    n : int         the episodes told (≥ 0).
    points : int    m, the most a refit sees (≥ 2).
    rule : str      ``"spread"`` (Eq. G3a) or ``"recent"`` (the last m), once n > m.

    Returns
    -------
    (min(n, m),) int64   the indices, in increasing order: all n while n ≤ m.
    """
    if rule not in FIT_SUBSETS:
        raise ValueError(f"rule: expected one of {FIT_SUBSETS}, got {rule!r}")
    if isinstance(points, bool) or not isinstance(points, (int, np.integer)) or points < 2:
        raise ValueError(f"points: expected an integer >= 2, got {points!r}")
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 0:
        raise ValueError(f"n: expected an integer >= 0, got {n!r}")
    if n <= points:
        return np.arange(n, dtype=np.int64)
    if rule == "recent":
        return np.arange(n - points, n, dtype=np.int64)
    j = np.arange(points, dtype=np.int64)
    return (2 * j * (n - 1) + (points - 1)) // (2 * (points - 1))  # G3a


def fit_hyperparameters(
    inputs: Array, targets: Array, start: Array, rng: np.random.Generator, restarts: int, max_iter: int = 60
) -> Array:
    """The maximum-likelihood h (Eq. G3): L-BFGS-B from ``start`` and from ``restarts`` uniform draws in the
    bounds (from ``rng``); a start whose factorisation fails is skipped. Returns ``start`` if all fail."""
    bounds = hyper_bounds(inputs.shape[1])
    low, high = np.array(bounds).T
    starts = [np.clip(start, low, high)] + [rng.uniform(low, high) for _ in range(restarts)]

    from scipy import optimize  # here: c-bo alone needs it, and it adds 0.2 s to every start-up

    def negative(h: Array) -> tuple[float, Array]:
        value, gradient = log_marginal_likelihood(inputs, targets, h)
        return -value, -gradient

    best, best_value = np.array(start, dtype=np.float64), math.inf
    for point in starts:
        try:
            result = optimize.minimize(
                negative, point, jac=True, method="L-BFGS-B", bounds=bounds, options={"maxiter": max_iter}
            )
        except (np.linalg.LinAlgError, linalg.LinAlgError, ValueError):
            continue
        if np.isfinite(result.fun) and result.fun < best_value:
            best, best_value = np.asarray(result.x, dtype=np.float64), float(result.fun)
    return best


def _standardised(values: Array, prior_mean: str) -> Array:
    """Values divided by their standard deviation and shifted so that the GP's zero prior mean is their
    mean (``"mean"``) or their minimum (``"min"``: far from the data the model expects the worst return seen,
    so neither the acquisition nor ``recommend`` is drawn to unexplored corners by the prior)."""
    values = values - values.max()  # finite (the protocol checks the spread), then scaled to [-1, 0], so
    width = -float(values.min())  # the squares below are too
    values = values / width if width > 0.0 else values
    spread = float(values.std())
    centre = float(values.min()) if prior_mean == "min" else float(values.mean())
    return (values - centre) / (spread if spread > 0.0 else 1.0)


def mean_ranks(values: Array) -> Array:
    """The ranks 1 … n of ``values`` (n,), ties sharing the mean of their ranks (as ``scipy.stats.rankdata``,
    whose module costs half a second to import)."""
    order = np.argsort(values, kind="stable")
    ordered = values[order]
    starts = np.flatnonzero(np.r_[True, ordered[1:] != ordered[:-1]])  # the first of each run of ties
    ends = np.r_[starts[1:], values.shape[0]]
    ranks = np.empty(values.shape[0])
    ranks[order] = np.repeat(0.5 * (starts + 1 + ends), ends - starts)  # mean of the ranks starts+1 … ends
    return ranks


def transformed_returns(
    returns: Array, transform: str, prior_mean: str = "min", quantile: float = LOG_QUANTILE
) -> Array:
    """The GP's targets: returns after ``transform``, standardised (see :func:`_standardised`).

    ``"none"``: the returns. ``"log"``: −log(1 + (R_max − R)/c) with c the ``quantile`` of R_max − R over
    the data (at least 1e-12 times their largest; Eq. G6 of :mod:`~creps_gym.optimizers.gp_trend`), which
    compresses a long tail of bad returns (Rosenbrock's valley walls) while keeping the order.
    ``"rank"``: Φ⁻¹((rank − 1/2)/n), the Gaussian copula of the ranks (ties share their mean rank).
    """
    if transform == "log":
        values = log_transform(returns, quantile)[0]
    elif transform == "rank":
        values = special.ndtri((mean_ranks(returns) - 0.5) / returns.shape[0])
    else:
        values = returns
    return _standardised(values, prior_mean)
