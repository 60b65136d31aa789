"""CREPS with Covariance Matrix Adaptation (CREPS-CMA), old-mean and current-mean variants.

Reference: A. Abdolmaleki, D. Simões, N. Lau, L. P. Reis, G. Neumann, "Contextual Direct Policy Search With
Regularized Covariance Matrix Estimation", J. Intell. Robot. Syst. (2019), doi:10.1007/s10846-018-0968-4,
sections 3.2.2 and 4, read as ``docs/algorithms.md`` explains.

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

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar, cast

import numpy as np
from numpy.typing import NDArray

from creps_gym._validation import as_float_array, check_bool, check_real_in_range
from creps_gym.optimizers.cma_rules import cma_constants, csa_step, inverse_sqrt, update_paths_and_cov
from creps_gym.optimizers.creps import CREPS, CREPSConfig, weighted_sample_covariance
from creps_gym.optimizers.policies import LinearGaussianPolicy

__all__ = ["CREPSCMA", "CREPSCMAConfig", "interpolation_factor", "regularised_covariance"]

Array = NDArray[np.float64]
VARIANTS = ("old", "current")
STEP_SIZE_RULES = ("none", "csa")


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
    step_size : str             ``"none"`` (default, the paper) or ``"csa"``: the paper's future work, a
        global step size σ by cumulative step-size adaptation, with CMA-ES's rank-one and rank-μ covariance
        update weighted by the CREPS weights d_k (Eqs. C4–C9 of ``docs/algorithms.md``, μ_eff = φ_eff). Then
        ``variant``, ``max_interpolation`` and ``divide_by_z`` do not apply.

    See :class:`~creps_gym.optimizers.creps.CREPSConfig` for the other fields.
    """

    variant: str = "old"
    max_interpolation: float = 1.0
    divide_by_z: bool = True
    step_size: str = "none"

    def __post_init__(self) -> None:
        if self.step_size not in STEP_SIZE_RULES:
            raise ValueError(f"step_size: expected one of {STEP_SIZE_RULES}, got {self.step_size!r}")
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

    def _init_from_config(self, config: CREPSConfig) -> None:
        super()._init_from_config(config)
        self.path_sigma = np.zeros((self.n_params, 1))
        self.path_cov = np.zeros(self.n_params)
        self._new_paths: tuple[Array, Array] | None = None

    def _update(self, contexts: Array, params: Array, returns: Array) -> None:
        super()._update(contexts, params, returns)
        if self._new_paths is not None:  # committed with the policy, after every check passed
            self.path_sigma, self.path_cov = self._new_paths
            self._new_paths = None
            self._diagnostics["step_size"] = self.policy.step_size

    def _covariance_update(
        self, policy: LinearGaussianPolicy, params: Array, old_means: Array, new_means: Array, weights: Array
    ) -> tuple[float, bool]:
        if self.config.step_size == "csa":
            return self._csa_update(policy, params, old_means, weights)
        centre = old_means if self.config.variant == "old" else new_means
        sample_cov = weighted_sample_covariance(  # Eq. (15) old / Eq. (12) current
            params, centre, weights, self.config.divide_by_z
        )
        interpolation = interpolation_factor(
            weights, self.n_params, self.config.max_interpolation
        )  # Eq. (14)
        cov = regularised_covariance(policy.cov, sample_cov, interpolation)  # Eq. (16) / (13)
        return interpolation, policy.set_cov(cov)

    def _csa_update(
        self, policy: LinearGaussianPolicy, params: Array, old_means: Array, weights: Array
    ) -> tuple[float, bool]:
        """CMA-ES's covariance and step-size update with the CREPS weights (Eqs. C4–C9)."""
        sigma = policy.step_size
        deviations = (params - old_means) / sigma  # y_k ~ N(0, C)
        constants = cma_constants(self.n_params, weights, active=False)
        shift = constants.weights @ deviations  # Eq. (C4)
        signal = np.sqrt(constants.mu_eff) * (inverse_sqrt(policy.cov) @ shift)[:, None]
        path_sigma, path_cov, cov, _ = update_paths_and_cov(  # Eqs. (C5)-(C8)
            policy.cov,
            self.path_sigma,
            self.path_cov,
            signal,
            shift,
            deviations,
            constants.weights,
            constants,
            self.iteration,
        )
        repaired = policy.set_cov(cov)
        policy.step_size = csa_step(sigma, path_sigma, constants)  # Eq. (C9)
        self._new_paths = (path_sigma, path_cov)
        return constants.c_mu, repaired

    def _state(self) -> dict[str, Any]:
        state = super()._state()
        state.update(path_sigma=self.path_sigma.copy(), path_cov=self.path_cov.copy())
        return state

    @classmethod
    def _from_state(cls, state: Mapping[str, Any]) -> CREPSCMA:
        optimizer = cast(CREPSCMA, super()._from_state(state))
        p = optimizer.n_params
        if "path_sigma" in state:  # checkpoints written before step-size control have none
            optimizer.path_sigma = as_float_array(state["path_sigma"], "state['path_sigma']", (p, 1)).copy()
            optimizer.path_cov = as_float_array(state["path_cov"], "state['path_cov']", (p,)).copy()
        return optimizer
