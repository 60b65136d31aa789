"""CMA-ES's update rules as pure functions: weights, default learning rates, paths, covariance, step size.

N. Hansen, "The CMA Evolution Strategy: A Tutorial", arXiv:1604.00772, Appendix A (the algorithm summary and
its default parameters). Contextual CMA-ES (:mod:`creps_gym.optimizers.ccmaes`) and CREPS-CMA with step-size
control (:mod:`creps_gym.optimizers.creps_cma`) share them; the equation tags (C5)–(C9) are those of
``docs/algorithms.md``. Everything works in the coordinates of y = (θ − m_old(s))/σ ~ N(0, C).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "CMAConstants",
    "cma_constants",
    "csa_step",
    "distribution_stops",
    "expected_norm",
    "inverse_sqrt",
    "median",
    "population_size",
    "rank_weights",
    "record_mean_return",
    "restart_pays_off",
    "scaled_mean",
    "stagnated",
    "stagnation_window",
    "update_paths_and_cov",
]

Array = NDArray[np.float64]


class CMAConstants(NamedTuple):
    """Recombination weights and learning rates for one batch.

    ``weights`` are aligned with the raw weights given to :func:`cma_constants`: the positive ones sum to 1,
    the negative ones (active CMA) are scaled by the tutorial's α bounds, or set to 0 when inactive.
    """

    weights: Array
    mu_eff: float
    c_sigma: float
    d_sigma: float
    c_c: float
    c_1: float
    c_mu: float
    chi_n: float


def rank_weights(n_samples: int) -> Array:
    """Raw weights w'_i = ln((N + 1)/2) − ln i for ranks i = 1..N (best first), shape (N,)."""
    return math.log((n_samples + 1) / 2.0) - np.log(np.arange(1, n_samples + 1, dtype=np.float64))


def cma_constants(
    n: int,
    raw_weights: Array,
    active: bool = True,
    overrides: Mapping[str, float | None] | None = None,
) -> CMAConstants:
    """The tutorial's default weights and learning rates for dimension ``n`` and these raw weights.

    Parameters
    ----------
    n : int
        Dimension of θ.
    raw_weights : ndarray, shape (N,)
        Positive entries select and weight samples (normalised here to sum to 1); negative ones are the
        active update's, in any scale.
    active : bool
        Keep the negative weights (scaled so C stays positive definite in expectation) or zero them.
    overrides : mapping, optional
        ``c_sigma``, ``d_sigma``, ``c_c``, ``c_1``, ``c_mu`` values replacing the defaults (None keeps one).
        When only one of ``c_1`` and ``c_mu`` is given, the other's default is capped so that they sum to at
        most 1 (the active weights' scale needs 1 − c_1 − c_mu ≥ 0).
    """
    positive = raw_weights > 0
    weights = np.where(positive, raw_weights, 0.0) / raw_weights[positive].sum()
    mu_eff = 1.0 / float(weights @ weights)
    rates = {
        "c_sigma": (mu_eff + 2.0) / (n + mu_eff + 5.0),
        "c_c": (4.0 + mu_eff / n) / (n + 4.0 + 2.0 * mu_eff / n),
        "c_1": 2.0 / ((n + 1.3) ** 2 + mu_eff),
    }
    rates["c_mu"] = min(1.0 - rates["c_1"], 2.0 * (mu_eff - 2.0 + 1.0 / mu_eff) / ((n + 2.0) ** 2 + mu_eff))
    rates["d_sigma"] = 1.0 + 2.0 * max(0.0, math.sqrt((mu_eff - 1.0) / (n + 1.0)) - 1.0) + rates["c_sigma"]
    given = {k: float(v) for k, v in (overrides or {}).items() if v is not None}
    rates.update(given)
    for rate, other in (("c_1", "c_mu"), ("c_mu", "c_1")):  # a default yields to a given rate
        if rate in given and other not in given:
            rates[other] = min(rates[other], 1.0 - rates[rate])
    negative = raw_weights < 0
    if active and negative.any() and rates["c_mu"] > 0:
        raw_negative = raw_weights[negative]
        mu_eff_negative = float(raw_negative.sum() ** 2 / (raw_negative @ raw_negative))
        scale = min(
            1.0 + rates["c_1"] / rates["c_mu"],
            1.0 + 2.0 * mu_eff_negative / (mu_eff + 2.0),
            (1.0 - rates["c_1"] - rates["c_mu"]) / (n * rates["c_mu"]),
        )
        weights[negative] = scale * raw_negative / np.abs(raw_negative).sum()
    return CMAConstants(weights, mu_eff, chi_n=expected_norm(n), **rates)


def inverse_sqrt(matrix: Array, eigen: tuple[Array, Array] | None = None) -> Array:
    """M^(−1/2) = B D⁻¹ Bᵀ from the eigendecomposition M = B D² Bᵀ of a symmetric PSD matrix.

    ``eigen`` is ``numpy.linalg.eigh(matrix)`` if the caller has it already.
    """
    values, vectors = np.linalg.eigh(matrix) if eigen is None else eigen
    return (vectors / np.sqrt(np.maximum(values, 1e-300 * max(values[-1], 1e-300)))) @ vectors.T


def expected_norm(dimension: int) -> float:
    """E‖N(0, I_d)‖ ≈ √d (1 − 1/(4d) + 1/(21d²))."""
    return math.sqrt(dimension) * (1.0 - 1.0 / (4.0 * dimension) + 1.0 / (21.0 * dimension**2))


def update_paths_and_cov(
    cov: Array,
    path_sigma: Array,
    path_cov: Array,
    signal: Array,
    shift: Array,
    deviations: Array,
    weights: Array,
    constants: CMAConstants,
    iteration: int,
    inv_sqrt: Array | None = None,
) -> tuple[Array, Array, Array, bool]:
    """One generation of the evolution paths and the covariance, Eqs. (C5)–(C8).

    Parameters
    ----------
    cov : ndarray, shape (p, p)          C before the update.
    path_sigma : ndarray, shape (p, m)   p_σ before the update (m = 1: CMA-ES's path).
    path_cov : ndarray, shape (p,)       p_c before the update.
    signal : ndarray, shape (p, m)       the step-size signal, i.i.d. N(0, 1) entries without selection.
    shift : ndarray, shape (p,)          y_w = Σ_{w_k>0} w_k y_k, N(0, C/μ_eff) without selection.
    deviations : ndarray, shape (N, p)   y_k = (θ_k − m_old(s_k))/σ.
    weights : ndarray, shape (N,)        aligned with ``deviations``'s rows (negative: active update).
    constants : CMAConstants
    iteration : int                      generations done before this one (for h_σ's bias correction).
    inv_sqrt : ndarray, shape (p, p), optional   C^(−1/2), if the caller has it already.

    Returns
    -------
    (p_σ, p_c, C, h_σ)
    """
    n = cov.shape[0]
    c_s, c_c, c_1, c_mu = constants.c_sigma, constants.c_c, constants.c_1, constants.c_mu
    path_sigma = (1.0 - c_s) * path_sigma + math.sqrt(c_s * (2.0 - c_s)) * signal  # Eq. (C5)
    correction = math.sqrt(1.0 - (1.0 - c_s) ** (2 * (iteration + 1)))
    threshold = (1.4 + 2.0 / (n + 1.0)) * expected_norm(path_sigma.size)
    hsig = float(np.linalg.norm(path_sigma)) / correction < threshold
    path_cov = (1.0 - c_c) * path_cov + hsig * math.sqrt(c_c * (2.0 - c_c) * constants.mu_eff) * shift  # (C6)
    adjusted = weights.copy()
    negative = weights < 0
    if negative.any():  # Eq. (C7): negative weights act on whitened lengths, so C stays positive definite
        whitened = deviations[negative] @ (inverse_sqrt(cov) if inv_sqrt is None else inv_sqrt)
        adjusted[negative] *= n / np.maximum(np.einsum("ij,ij->i", whitened, whitened), 1e-300)
    lost = (1.0 - hsig) * c_c * (2.0 - c_c)
    cov = (
        (1.0 + c_1 * lost - c_1 - c_mu * float(weights.sum())) * cov
        + c_1 * np.outer(path_cov, path_cov)
        + c_mu * (deviations.T * adjusted) @ deviations
    )  # Eq. (C8)
    return path_sigma, path_cov, cov, hsig


def csa_step(sigma: float, path_sigma: Array, constants: CMAConstants) -> float:
    """σ ← σ·exp(min(1, (c_σ/d_σ)(‖p_σ‖/E‖N(0, I)‖ − 1))), Eq. (C9) (the cap at e is pycma's safeguard).

    The norm is Frobenius's and the expectation is over ``path_sigma.size`` dimensions.
    """
    ratio = float(np.linalg.norm(path_sigma)) / expected_norm(path_sigma.size)
    return sigma * math.exp(min(1.0, constants.c_sigma / constants.d_sigma * (ratio - 1.0)))


def distribution_stops(
    step_size: float,
    initial_step_size: float,
    diagonal: Array,
    eigenvalues: Array,
    path_cov: Array,
    tolx: float,
    tolupsigma: float,
    max_condition: float,
) -> dict[str, float]:
    """pycma's criteria on the search distribution σ²C that are met.

    Parameters
    ----------
    step_size, initial_step_size : float        σ and σ0.
    diagonal : ndarray, shape (p,)              C's diagonal.
    eigenvalues : ndarray, shape (p,)           C's eigenvalues, ascending.
    path_cov : ndarray, shape (p,)              the evolution path p_c.
    tolx, tolupsigma, max_condition : float     the thresholds.

    Returns
    -------
    dict
        Each criterion met, with its value: ``"tolx"`` (the largest σ·√C_ii, when it and every σ·|p_c,i| are
        below ``tolx``), ``"tolupsigma"`` (σ/σ0, when it exceeds tolupsigma·√λ_max(C)) and
        ``"max_condition"`` (λ_max/λ_min, when it exceeds ``max_condition``).
    """
    met: dict[str, float] = {}
    largest_std = step_size * math.sqrt(float(diagonal.max()))
    if largest_std < tolx and step_size * float(np.abs(path_cov).max()) < tolx:
        met["tolx"] = largest_std
    growth = step_size / initial_step_size
    if growth > tolupsigma * math.sqrt(float(eigenvalues[-1])):
        met["tolupsigma"] = growth
    condition = float(eigenvalues[-1] / max(eigenvalues[0], 1e-300))
    if condition > max_condition:
        met["max_condition"] = condition
    return met


def stagnation_window(n_params: int, n_samples: int, configured: int | None) -> int:
    """Iterations the stagnation criterion looks back: ``configured``, or pycma's 100 + 100·p^1.5/N."""
    return configured if configured is not None else int(100 + 100 * n_params**1.5 / n_samples)


def record_mean_return(history: Sequence[float], returns: Array, window: int) -> list[float]:
    """The batch's mean return appended to ``history``, which keeps only the last ``window`` entries."""
    return [*history, scaled_mean(returns)][-window:]


def scaled_mean(returns: Array) -> float:
    """The mean of ``returns`` taken in units of their largest magnitude, so that finite returns near the
    float limit (whose sum overflows) still give a finite mean; 0 for all-zero returns."""
    magnitude = float(np.abs(returns).max())
    return float(np.mean(returns / magnitude) * magnitude) if magnitude > 0 else 0.0


def median(values: Array) -> float:
    """The median of ``values`` (n,), as ``np.median`` gives it, at a fifth of its cost (robust refits take
    several an update) and without overflowing near the float limit: the two middle values are halved before
    they are added (halving is exact, so this is ``np.median``'s (a + b)/2 bit for bit wherever that does not
    overflow or underflow)."""
    n = values.size
    middle = np.partition(values, [(n - 1) // 2, n // 2])
    return float(middle[(n - 1) // 2] / 2 + middle[n // 2] / 2)


def stagnated(mean_returns: Sequence[float], window: int) -> bool:
    """True when, over the last ``window`` iterations, the median mean return of the latest fifth is no
    better than that of the earliest fifth (pycma's ``tolstagnation``, on the batch mean return)."""
    if len(mean_returns) < window:
        return False
    recent = np.asarray(mean_returns[-window:], dtype=np.float64)
    fifth = max(window // 5, 1)
    return bool(np.median(recent[-fifth:]) <= np.median(recent[:fifth]))


def restart_pays_off(budget: int | None, used: int, search_episodes: int, factor: float) -> bool:
    """Whether a restart can pay off (Eq. (C12)): the ``budget`` − ``used`` episodes left carry a new search
    at least as far as the ended one went, ``factor`` (its population's growth, C13) times its
    ``search_episodes``; always True with no known ``budget`` (None)."""
    if budget is None:
        return True
    return budget - used >= factor * search_episodes  # Eq. (C12)


def population_size(base: int, factor: float, restarts: int) -> int:
    """The batch a search wants after ``restarts`` restarts (Eq. (C13), IPOP): ``base`` · ``factor``^r,
    rounded to the nearest integer (``base`` itself with ``factor`` = 1 or before the first restart)."""
    return max(base, round(base * factor**restarts))  # Eq. (C13)
