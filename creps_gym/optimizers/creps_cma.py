"""CREPS with Covariance Matrix Adaptation (CREPS-CMA), old-mean and current-mean variants.

Reference: A. Abdolmaleki, D. Simões, N. Lau, L. P. Reis, G. Neumann, "Contextual Direct Policy Search With
Regularized Covariance Matrix Estimation", J. Intell. Robot. Syst. (2019), doi:10.1007/s10846-018-0968-4,
sections 3.2.2 and 4, read as in ``shared/notes/algorithm.md``.

The weights and the mean are those of CREPS (:mod:`creps_gym.optimizers.creps`). The covariance is a convex
combination of the old covariance and the weighted sample covariance, CMA-ES's rank-μ update:

    Σ = (1 − λ)·Σ_old + λ·S,     λ = min(1, φ_eff / n²),     φ_eff = 1 / Σ_k d_k²

where n = dim θ. ``variant="old"`` (CREPS-CMA_Old, the default and the paper's recommendation) computes S
around the *old* mean, the coefficients that generated the samples, so Σ learns the successful steps;
``variant="current"`` (CREPS-CMA_Curr) computes S around the new mean. CREPS is the special case λ = 1 with
the new mean. λ multiplies S as in Eqs. (13) and (16) (not Algorithm 2's last line): section 4 derives exactly
this form with λ = 1/(1 + γ), and γ = 0, plain maximum likelihood, gives CREPS.

``max_interpolation`` (default 1, the paper's Eq. (14) exactly) caps λ. With the paper's 50 samples per
iteration φ_eff ≈ 25–30, so Eq. (14) gives λ = 1 for n ≤ 5 and λ ≈ 0.4 for n = 8: the regularisation is
switched off (or nearly) and the old-mean variant can collapse like CREPS on small problems
(``benchmarks/scaling/`` measures it). A cap of 0.2 removes that failure there and changes nothing where
φ_eff/n² ≤ 0.2 already, e.g. for every n ≥ 16 with N ≤ 50 samples.

``divide_by_z=False`` leaves Z = 1 − Σ_k d_k² out of S. Z makes S unbiased around a mean *fitted* to the same
weighted samples (the new mean); around the old mean, which the samples did not estimate, S without Z is the
unbiased one (CMA-ES's rank-μ update has no Z). With Z, every direction the weights do not select grows by
1/Z ≈ φ_eff/(φ_eff − 1) per update, scaled by λ: negligible on small problems, but over the ~10⁵ updates of
p = 64 it makes the old-mean variant diverge with z = 5 (``benchmarks/scaling/``). The drift also guards
against collapse (without Z, Rosenbrock with p = 16, z = 5 converges prematurely), so the default keeps
Eq. (15) as published.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from creps_gym._validation import check_bool, check_real_in_range
from creps_gym.optimizers.creps import CREPS, CREPSConfig, weighted_sample_covariance

__all__ = ["CREPSCMA", "CREPSCMAConfig", "interpolation_factor", "regularised_covariance"]

Array = NDArray[np.float64]
VARIANTS = ("old", "current")


def interpolation_factor(weights: Array, n_params: int, maximum: float = 1.0) -> float:
    """λ = min(1, φ_eff / n²) with φ_eff = 1 / Σ_k d_k², Eq. (14); ``maximum`` < 1 caps it lower.

    Parameters
    ----------
    weights : ndarray, shape (N,)
        Normalised sample weights d_k.
    n_params : int
        n = dim θ.
    maximum : float
        Upper bound of λ, in (0, 1]; 1 is the paper's rule.
    """
    if not 0.0 < maximum <= 1.0:
        raise ValueError(f"maximum: expected a value in (0, 1], got {maximum!r}")
    effective_samples = 1.0 / float(weights @ weights)
    return min(maximum, effective_samples / n_params**2)


def regularised_covariance(old_cov: Array, sample_cov: Array, interpolation: float) -> Array:
    """Σ = (1 − λ)·Σ_old + λ·S, Eqs. (13) and (16).

    Parameters
    ----------
    old_cov, sample_cov : ndarray, shape (p, p)
    interpolation : float
        λ in [0, 1].
    """
    return (1.0 - interpolation) * old_cov + interpolation * sample_cov


@dataclass(frozen=True, eq=False)
class CREPSCMAConfig(CREPSConfig):
    """CREPSConfig plus the covariance update's options.

    Parameters
    ----------
    variant : str               ``"old"`` (default, Eqs. 15–16) or ``"current"`` (Eqs. 12–13).
    max_interpolation : float   cap of λ in (0, 1]; 1 (default) is Eq. (14) as published.
    divide_by_z : bool          divide S by Z = 1 − Σd² (default, Eqs. 12 and 15); see the module docstring.

    See :class:`~creps_gym.optimizers.creps.CREPSConfig` for the other fields.
    """

    variant: str = "old"
    max_interpolation: float = 1.0
    divide_by_z: bool = True

    def __post_init__(self) -> None:
        if self.variant not in VARIANTS:
            raise ValueError(f"variant: expected one of {VARIANTS}, got {self.variant!r}")
        cap = check_real_in_range(self.max_interpolation, "max_interpolation", 0.0, 1.0, low_inclusive=False)
        object.__setattr__(self, "max_interpolation", cap)
        object.__setattr__(self, "divide_by_z", check_bool(self.divide_by_z, "divide_by_z"))
        super().__post_init__()


class CREPSCMA(CREPS):
    """CREPS-CMA: CREPS weights and mean with the regularised covariance update.

    ``CREPSCMA(n_params, n_context_dims, variant="old", **options)``; see :class:`CREPSCMAConfig`.
    """

    kind: ClassVar[str] = "creps-cma"
    config_class: ClassVar[type[CREPSConfig]] = CREPSCMAConfig
    config: CREPSCMAConfig

    def __init__(self, n_params: int, n_context_dims: int, variant: str = "old", **options: Any) -> None:
        super().__init__(n_params, n_context_dims, variant=variant, **options)

    def _covariance_update(self, params: Array, old_means: Array, new_means: Array, weights: Array) -> tuple:
        centre = old_means if self.config.variant == "old" else new_means
        sample_cov = weighted_sample_covariance(  # Eq. (15) old / Eq. (12) current
            params, centre, weights, self.config.divide_by_z
        )
        interpolation = interpolation_factor(
            weights, self.n_params, self.config.max_interpolation
        )  # Eq. (14)
        return regularised_covariance(self.cov, sample_cov, interpolation), interpolation  # Eq. (16) / (13)
