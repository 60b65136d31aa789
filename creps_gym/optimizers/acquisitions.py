"""Acquisition functions of contextual Bayesian optimisation and their maximisation over θ at a fixed s.

With μ and σ the GP's posterior mean and standard deviation (:mod:`creps_gym.optimizers.gp_model`):

* **UCB** (Srinivas et al., ICML 2010): α(x) = μ(x) + √β σ(x).                                       (A1)
* **Max-value entropy search** (MES; Wang & Jegelka, ICML 2017): the expected reduction of the entropy of the
  maximum value y* = max_θ f(s, θ) at the asked context s,

      α(x) = (1/K) Σ_k [γ_k φ(γ_k) / (2Φ(γ_k)) − log Φ(γ_k)],   γ_k = (y*_k − μ(x)) / σ(x),           (A2)

  with K samples y*_k of the maximum drawn from a Gumbel distribution fitted to
  P(y* < y) ≈ Π_i Φ((y − μ_i)/σ_i) over a candidate set at s (Wang & Jegelka's Gumbel sampling).   (A3)

The sampled maxima are raised to a floor, the least value the model allows the maximum at s:

      y*_k ≥ max(m + 10⁻⁶(1 + |m|), max_{x_j ∈ H(s)} μ(x_j) + 5 σ_n),   m = max_i μ_i,               (A4)

m over the candidates, H(s) the inputs the model holds at exactly the context s: the told episodes at s
and, in a batch, the earlier rows at s, which the kriging believer holds as observed with their posterior
means as returns (σ_n: the observation noise's standard deviation in μ's units). The maximum at s is at
least what was observed there, as in plain BO's rule (Wang & Jegelka's y* above the observations). The
second term matters at a context asked twice: a row's maximiser beats every random candidate (L-BFGS-B
improved on them), so the first term lies below its fantasy, where σ has shrunk to the noise; there γ is
very negative, α largest, and every later row at s returns to it. Five noise deviations above it, γ there
is at least 5 (σ ≤ σ_n) and MES leaves it (``mes_floor="observed"``, the default; ``"candidates"``: the
first term alone, the rule before 2026-11-30). Where no input is held at s (contexts drawn from a
continuous distribution never repeat), the floor is the first term, the former one bit for bit.

Each is maximised over θ in the parameter box (or a sub-box of it, e.g. the trust region of ``recommend``)
with s fixed: the acquisition is evaluated on many candidates (random draws and the observed θ) and
L-BFGS-B, with the analytic gradient, starts from the best few.
Everything is deterministic given the candidates and the Generator.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import special

from creps_gym.optimizers.gp_model import GPModel

__all__ = [
    "ACQUISITIONS",
    "MES_FLOORS",
    "AcquisitionMaximiser",
    "acquisition_at",
    "gumbel_max_values",
    "max_value_floor",
    "mes",
    "ucb",
]

Array = NDArray[np.float64]
#: An acquisition: (mean (m,), variance (m,)) -> (value (m,), ∂value/∂mean (m,), ∂value/∂variance (m,)).
Acquisition = Callable[[Array, Array], tuple[Array, Array, Array]]
ACQUISITIONS = ("ucb", "mes")
#: The rules of MES's floor (``mes_floor``): Eq. (A4) or the former one over the candidates alone.
MES_FLOORS = ("observed", "candidates")
_LOG_SQRT_2PI = 0.5 * math.log(2.0 * math.pi)


def ucb(mean: Array, variance: Array, beta: float) -> tuple[Array, Array, Array]:
    """Eq. (A1) and its derivatives with respect to μ and σ²."""
    std = np.sqrt(variance)
    root = math.sqrt(beta)
    return mean + root * std, np.ones_like(mean), root / (2.0 * std)


def mes(mean: Array, variance: Array, max_values: Array) -> tuple[Array, Array, Array]:
    """Eq. (A2) for K sampled maxima ``max_values`` (K,), and its derivatives with respect to μ and σ².

    Uses h = φ(γ)/Φ(γ) from ``log_ndtr`` (stable for very negative γ) and
    ∂/∂γ [γh/2 − log Φ(γ)] = −(h/2)(1 + γ² + γh).
    """
    std = np.sqrt(variance)
    gamma = (max_values[None, :] - mean[:, None]) / std[:, None]  # (m, K)
    log_cdf = special.log_ndtr(gamma)
    ratio = np.exp(-0.5 * gamma * gamma - _LOG_SQRT_2PI - log_cdf)
    value = (0.5 * gamma * ratio - log_cdf).mean(axis=1)
    slope = -0.5 * ratio * (1.0 + gamma * gamma + gamma * ratio)  # ∂/∂γ
    dmean = (slope * (-1.0 / std[:, None])).mean(axis=1)
    dvariance = (slope * (-gamma / (2.0 * variance[:, None]))).mean(axis=1)
    return value, dmean, dvariance


def gumbel_max_values(
    mean: Array,
    variance: Array,
    n_samples: int,
    rng: np.random.Generator,
    floor: float | None = None,
) -> Array:
    """K samples of max_θ f(s, θ), Eq. (A3): a Gumbel fitted to the quartiles of Π_i Φ((y − μ_i)/σ_i)
    over the candidates (m,), found by bisection, and raised to ``floor`` (Eq. A4, :func:`max_value_floor`;
    None: max μ_i + 1e-6·(1 + |max μ_i|), the maximum is at least the best mean's value, up to noise)."""
    std = np.sqrt(variance)
    top = float(mean.max())
    lowest = top + 1e-6 * (1.0 + abs(top)) if floor is None else floor
    low = top - 1e-9
    high = float((mean + 6.0 * std).max()) + 1e-9

    def log_cdf(y: Array) -> Array:
        return special.log_ndtr((y[:, None] - mean[None, :]) / std[None, :]).sum(axis=1)

    targets = np.log(np.array([0.25, 0.5, 0.75]))
    lows, highs = np.full(3, low), np.full(3, high)
    for _ in range(60):
        middle = 0.5 * (lows + highs)
        below = log_cdf(middle) < targets
        lows, highs = np.where(below, middle, lows), np.where(below, highs, middle)
    q25, q50, q75 = 0.5 * (lows + highs)
    scale = max((q75 - q25) / (math.log(-math.log(0.25)) - math.log(-math.log(0.75))), 1e-12)
    location = q50 + scale * math.log(-math.log(0.5))
    uniform = rng.uniform(1e-12, 1.0 - 1e-12, n_samples)
    samples = location - scale * np.log(-np.log(uniform))
    return np.maximum(samples, lowest)


def acquisition_at(
    name: str,
    mean: Array,
    variance: Array,
    rng: np.random.Generator,
    *,
    beta: float,
    samples: int,
    floor: float | None = None,
) -> Acquisition:
    """The acquisition ``name`` at one context, from its candidates' posterior mean and variance (m,):
    UCB, Eq. (A1), with ``beta``, or MES, Eq. (A2), over ``samples`` maxima drawn by Eq. (A3) (from
    ``rng``) and raised to ``floor`` (:func:`gumbel_max_values`)."""
    if name == "ucb":
        return lambda m, v: ucb(m, v, beta)
    maxima = gumbel_max_values(mean, variance, samples, rng, floor)
    return lambda m, v: mes(m, v, maxima)


def max_value_floor(model: Any, held: Array, mean: Array) -> float:
    """Eq. (A4)'s floor of the sampled maxima at a context: above the candidates' largest posterior mean
    (``mean`` (m,)) by 1e-6 of it, and above the posterior mean at the inputs ``held`` (k, d) that the model
    holds at that context by five standard deviations of ``model.observation_noise`` (a variance in μ's
    units)."""
    best = float(mean.max())
    floor = best + 1e-6 * (1.0 + abs(best))
    if held.shape[0]:
        floor = max(floor, float(model.predict(held)[0].max()) + 5.0 * math.sqrt(model.observation_noise))
    return floor


class AcquisitionMaximiser:
    """Maximise an acquisition (or the posterior mean) over θ in the unit box with s fixed.

    Parameters
    ----------
    n_starts : int
        L-BFGS-B runs, from the best distinct candidates.
    max_iter : int
        L-BFGS-B iterations per run.
    """

    def __init__(self, n_starts: int, max_iter: int = 50) -> None:
        self.n_starts = n_starts
        self.max_iter = max_iter

    def maximise(
        self,
        model: GPModel,
        context: Array,
        candidates: Array,
        acquisition: Acquisition | None,
        bounds: tuple[Array, Array] | None = None,
    ) -> tuple[Array, float]:
        """The best θ (q,) in [0, 1]^q (or in ``bounds``, (low (q,), high (q,)) inside it) found at the
        scaled context (c,) and its value.

        ``acquisition`` None maximises the posterior mean. ``candidates`` (m, q), which must lie within the
        bounds, are scored first; the best ``n_starts`` start L-BFGS-B; the result is the best of the runs
        and the candidates.
        """
        mean, variance = model.predict(self.inputs(context, candidates))
        return self.maximise_scored(model, context, candidates, mean, variance, acquisition, bounds)

    def maximise_scored(
        self,
        model: GPModel,
        context: Array,
        candidates: Array,
        mean: Array,
        variance: Array,
        acquisition: Acquisition | None,
        bounds: tuple[Array, Array] | None = None,
    ) -> tuple[Array, float]:
        """:meth:`maximise` with the posterior (``mean``, ``variance``, (m,)) at the candidates given."""
        values = mean if acquisition is None else acquisition(mean, variance)[0]
        order = np.argsort(-values, kind="stable")
        best, best_value = candidates[order[0]].copy(), float(values[order[0]])
        starts, seen = [], set()
        for index in order:
            key = candidates[index].tobytes()
            if key not in seen:
                seen.add(key)
                starts.append(candidates[index])
            if len(starts) == self.n_starts:
                break
        for start in starts:
            theta, value = self._local(model, context, start, acquisition, bounds)
            if value > best_value:
                best, best_value = theta, value
        return best, best_value

    @staticmethod
    def inputs(context: Array, thetas: Array) -> Array:
        return np.hstack([np.broadcast_to(context, (thetas.shape[0], context.shape[0])), thetas])

    def _local(
        self,
        model: GPModel,
        context: Array,
        start: Array,
        acquisition: Acquisition | None,
        bounds: tuple[Array, Array] | None,
    ) -> tuple[Array, float]:
        width = context.shape[0]

        def negative(theta: Array) -> tuple[float, Array]:
            x = np.concatenate([context, theta])[None, :]
            mean, variance, dmean, dvariance = model.predict_with_gradient(x)
            if acquisition is None:
                return -float(mean[0]), -dmean[0, width:]
            value, by_mean, by_variance = acquisition(mean, variance)
            gradient = by_mean[0] * dmean[0, width:] + by_variance[0] * dvariance[0, width:]
            return -float(value[0]), -gradient

        from scipy import optimize  # here: c-bo alone needs it, and it adds 0.2 s to every start-up

        low, high = (np.zeros(start.shape[0]), np.ones(start.shape[0])) if bounds is None else bounds
        options = {"maxiter": self.max_iter}
        result = optimize.minimize(
            negative,
            start,
            jac=True,
            method="L-BFGS-B",
            bounds=list(zip(low, high, strict=True)),
            options=options,
        )
        theta = np.clip(np.asarray(result.x, dtype=np.float64), low, high)
        value = -negative(theta)[0]
        return theta, value if math.isfinite(value) else -math.inf
