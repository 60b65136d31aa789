"""Contextual Relative Entropy Policy Search (CREPS).

Reference: A. Abdolmaleki, D. Simões, N. Lau, L. P. Reis, G. Neumann, "Contextual Direct Policy Search With
Regularized Covariance Matrix Estimation", J. Intell. Robot. Syst. (2019), doi:10.1007/s10846-018-0968-4,
Algorithm 2 with Σ = S; the places where the text is ambiguous are read as ``docs/algorithms.md`` explains.

One iteration, for a batch of N samples (s_k, θ_k, R_k) drawn from π(θ|s) = N(Aᵀϕ(s), Σ):

1. Weights (Eqs. 8–9): minimise the dual g(η, w) = ηε + φ̂ᵀw + η log((1/N) Σ_k exp((R_k − φ(s_k)ᵀw)/η)) over
   η > 0 and w, with baseline features φ(s) = [s, s²]; then d_k ∝ exp((R_k − φ(s_k)ᵀw)/η), Σ_k d_k = 1.
2. Mean (Eq. 7): A = (ΦᵀDΦ + ridge·I)⁻¹ΦᵀDU with mean features ϕ(s) (affine [1, s] by default).
3. Covariance (Eq. 12): S = Σ_k d_k (θ_k − Aᵀϕ(s_k))(θ_k − Aᵀϕ(s_k))ᵀ / Z with Z = 1 − Σ_k d_k², and Σ = S.

The dual is solved in :mod:`creps_gym.optimizers.dual`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray
from scipy import linalg

from creps_gym._validation import (
    as_float_array,
    check_count,
    check_generator_state,
    check_positive_int,
    check_real,
    check_real_in_range,
    check_seed,
)
from creps_gym.errors import ConfigError
from creps_gym.optimizers.base import ContextualOptimizer
from creps_gym.optimizers.cma_rules import scaled_mean, stagnation_window
from creps_gym.optimizers.dual import DUAL_KL_TOL, DualSolution, solve_dual
from creps_gym.optimizers.features import FeatureMap, make_features
from creps_gym.optimizers.policies import (
    LinearGaussianPolicy,
    PolicyAccess,
    check_option_names,
    initial_coefficients,
    initial_covariance,
    spd_factor,
    weighted_ml_fit,
)

__all__ = [
    "CREPS",
    "CREPSConfig",
    "DualSolution",
    "solve_dual",
    "spd_factor",
    "weighted_ml_fit",
    "weighted_sample_covariance",
]

Array = NDArray[np.float64]


def weighted_sample_covariance(
    params: Array, means: Array, weights: Array, divide_by_z: bool = True
) -> Array:
    """Weighted sample covariance with the normaliser of Eqs. (12) and (15).

    S = Σ_k d_k (θ_k − m_k)(θ_k − m_k)ᵀ / Z with Z = 1 − Σ_k d_k², for weights summing to one.

    Parameters
    ----------
    params, means : ndarray, shape (N, p)
    weights : ndarray, shape (N,)
    divide_by_z : bool
        False leaves out Z: the right estimate around means that were not fitted to these samples.
    """
    deviations = params - means
    normaliser = 1.0 - float(weights @ weights) if divide_by_z else 1.0
    if normaliser <= 1e-12:
        normaliser = 1.0  # a single effective sample: Z is undefined, fall back to plain ML
    return (deviations.T * weights) @ deviations / normaliser


@dataclass(frozen=True, eq=False)
class CREPSConfig:
    """Configuration of :class:`CREPS`; validates itself on construction.

    Parameters
    ----------
    n_params : int              p, the dimension of θ.
    n_context_dims : int        z, the dimension of s (0 for a non-contextual problem).
    epsilon : float             KL bound ε of the dual, 0 < ε; must be < log N at each ``tell``.
    initial_mean : scalar, (p,) or (k, p)   initial mean (constant over contexts) or full coefficients A.
    initial_cov : scalar, (p,) or (p, p)    initial covariance Σ: variance, variances or SPD matrix.
    mean_features : str, dict or FeatureMap ϕ(s) of the mean; ``"affine"`` = [1, s].
    baseline_features : str, dict or FeatureMap   φ(s) of the dual's baseline; ``"baseline"`` = [s, s²].
    ridge : float               relative ridge of Eq. (7), ≥ 0 (kept tiny; see docs/algorithms.md).
    seed : int or None          seed of the sampling Generator.
    min_std, max_condition, max_std_growth : float   stop criteria: √λ_max(Σ) < min_std, cond(Σ) >
        max_condition, or √λ_max(Σ) > max_std_growth·√λ_max(Σ₀) (divergence, like pycma's tolupsigma).
    tolflatfitness : int        stop after this many consecutive batches whose returns are all equal
        (default 10; like pycma's option of that name: no signal, and Σ would grow without bound).
    tolstagnation : int or None  stop when, over this many iterations, the median batch mean return of the
        last fifth is no better than that of the first fifth (None: pycma's 100 + 100·p^1.5/N). Under returns
        that are pure noise, Σ collapses or grows without end; this criterion ends such runs.
    """

    n_params: int
    n_context_dims: int
    epsilon: float = 0.5
    initial_mean: Any = 0.0
    initial_cov: Any = 1.0
    mean_features: Any = "affine"
    baseline_features: Any = "baseline"
    ridge: float = 1e-8
    seed: int | None = None
    min_std: float = 1e-12
    max_condition: float = 1e14
    max_std_growth: float = 1e8
    tolflatfitness: int = 10
    tolstagnation: int | None = None
    mean_map: FeatureMap = field(init=False, repr=False)
    baseline_map: FeatureMap = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if self.tolstagnation is not None:
            object.__setattr__(self, "tolstagnation", check_positive_int(self.tolstagnation, "tolstagnation"))
        for name, minimum in (("n_params", 1), ("n_context_dims", 0), ("tolflatfitness", 1)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
                raise ValueError(f"{name}: expected an integer >= {minimum}, got {value!r}")
            object.__setattr__(self, name, int(value))  # numpy integers become plain ints (JSON checkpoints)
        for name, low, high, low_inclusive in (
            ("epsilon", 0.0, 50.0, False),
            ("ridge", 0.0, 1.0, True),
            ("min_std", 0.0, 1.0e300, True),
            ("max_condition", 1.0, 1.0e300, False),
            ("max_std_growth", 1.0, 1.0e300, False),
        ):
            value = check_real_in_range(getattr(self, name), name, low, high, low_inclusive=low_inclusive)
            object.__setattr__(self, name, value)
        object.__setattr__(self, "seed", check_seed(self.seed))
        for name in ("mean_features", "baseline_features"):
            feature_map = make_features(getattr(self, name), self.n_context_dims, name)
            object.__setattr__(self, name.replace("features", "map"), feature_map)
        for name, feature_map in (("mean_features", self.mean_map), ("baseline_features", self.baseline_map)):
            width = feature_map(np.zeros((2, self.n_context_dims))).shape
            if width != (2, feature_map.n_features):
                raise ValueError(
                    f"{name}: expected the map to return shape (n, {feature_map.n_features}) as its "
                    f"n_features says, got {width[1:]} columns for n = 2"
                )
        object.__setattr__(
            self, "initial_mean", initial_coefficients(self.initial_mean, self.mean_map, self.n_params)
        )
        object.__setattr__(self, "initial_cov", initial_covariance(self.initial_cov, self.n_params))

    def to_json(self) -> dict[str, Any]:
        """JSON-serialisable scalars and feature specs (the initial arrays are saved separately)."""
        skip = {
            "initial_mean",
            "initial_cov",
            "mean_map",
            "baseline_map",
            "mean_features",
            "baseline_features",
        }
        data = {f.name: getattr(self, f.name) for f in fields(self) if f.init and f.name not in skip}
        data["mean_features"] = self.mean_map.spec()
        data["baseline_features"] = self.baseline_map.spec()
        return data


class CREPS(PolicyAccess, ContextualOptimizer):
    """Contextual REPS with the maximum-likelihood covariance Σ = S (Eq. 12).

    ``CREPS(n_params, n_context_dims, **options)`` or ``CREPS.from_config(config)``; see
    :class:`CREPSConfig` for the options and :mod:`creps_gym.optimizers.base` for the protocol.
    """

    kind: ClassVar[str] = "creps"
    config_class: ClassVar[type[CREPSConfig]] = CREPSConfig

    def __init__(self, n_params: int, n_context_dims: int, **options: Any) -> None:
        check_option_names(self.config_class, options)
        self._init_from_config(self.config_class(n_params=n_params, n_context_dims=n_context_dims, **options))

    @classmethod
    def from_config(cls, config: CREPSConfig) -> CREPS:
        """Build from a config instance."""
        if not isinstance(config, cls.config_class):
            raise TypeError(f"config: expected {cls.config_class.__name__}, got {type(config).__name__}")
        optimizer = cls.__new__(cls)
        optimizer._init_from_config(config)
        return optimizer

    def _init_from_config(self, config: CREPSConfig) -> None:
        super().__init__()
        self.config = config
        self.n_params, self.n_context_dims = config.n_params, config.n_context_dims
        self.rng = np.random.default_rng(config.seed)
        self.policy = LinearGaussianPolicy(config.mean_map, config.initial_mean.copy(), config.initial_cov)
        self._initial_max_std = float(np.sqrt(np.linalg.eigvalsh(config.initial_cov)[-1]))
        self._eta = 1.0  # the dual's warm start, normalised units
        self.flat_iterations = 0
        self.mean_returns: list[float] = []  # the last iterations', for the stagnation criterion
        self.stagnation_window = stagnation_window(config.n_params, 1, config.tolstagnation)

    def mean(self, contexts: Array) -> Array:
        """Policy mean Aᵀϕ(s) for validated contexts (n, z): shape (n, p)."""
        return self.policy.mean(contexts)

    def _covariance_update(
        self, policy: LinearGaussianPolicy, params: Array, old_means: Array, new_means: Array, weights: Array
    ) -> tuple[float, bool]:
        """CREPS: Σ = S around the new mean (Eq. 12), set on ``policy`` (whose coefficients are the new ones).

        Returns (interpolation factor λ, whether Σ needed an SPD repair).
        """
        sample_cov = weighted_sample_covariance(params, new_means, weights)  # Eq. (12)
        return 1.0, policy.set_cov(sample_cov)

    def _update(self, contexts: Array, params: Array, returns: Array) -> None:
        n, k = returns.shape[0], self.config.baseline_map.n_features
        if n <= k + 1:
            raise ValueError(
                f"returns: expected more than k + 1 = {k + 1} samples, since the dual's baseline φ(s) has "
                f"k = {k} features and interpolates any smaller batch, got N = {n}"
            )
        if self.config.epsilon >= np.log(n):
            raise ConfigError(
                "epsilon",
                f"expected < log(N) = {np.log(n):.4f} for a batch of N={n} samples, "
                f"got {self.config.epsilon}",
            )
        dual = solve_dual(
            returns, self.config.baseline_map(contexts), self.config.epsilon, self._eta
        )  # Eqs. (8)-(9)
        phi = self.config.mean_map(contexts)
        old_means = phi @ self.coefficients
        try:
            coefficients = weighted_ml_fit(  # Eq. (7)
                phi, params, dual.weights, self.config.ridge, self.config.mean_map.constant_column
            )
        except linalg.LinAlgError:
            raise RuntimeError(
                f"tell(): the weighted mean regression (Eq. 7) is singular for this batch with ridge="
                f"{self.config.ridge}; use a ridge > 0 or more varied contexts. The optimiser was left "
                "unchanged"
            ) from None
        policy = self.policy.copy()
        policy.coefficients = coefficients
        interpolation, repaired = self._covariance_update(
            policy, params, old_means, phi @ coefficients, dual.weights
        )
        if not policy.is_finite():
            raise RuntimeError(
                "tell(): the update produced non-finite values; the optimiser was left unchanged"
            )
        self.policy = policy
        if abs(dual.kl - self.config.epsilon) <= DUAL_KL_TOL:  # warm-start only from an active constraint
            self._eta = dual.eta
        self._diagnostics = self._describe(dual, returns, interpolation, repaired)
        self._record_returns(returns)

    @property
    def diagnostics(self) -> dict[str, float]:
        """η (return units), KL, ESS, λ, log det Σ, cond Σ, √λ_max(Σ), mean return, ... of the last update.

        The eigenvalue-based entries are computed on first access (an O(p³) step a plain ask/tell loop skips).
        """
        if self._diagnostics and "cond_cov" not in self._diagnostics:
            eigenvalues = np.linalg.eigvalsh(self.cov)
            self._diagnostics["cond_cov"] = float(
                eigenvalues[-1] / max(eigenvalues[0], eigenvalues[-1] * 1e-300)
            )
            self._diagnostics["max_std"] = float(np.sqrt(eigenvalues[-1]))
        return dict(self._diagnostics)

    def _describe(self, dual: DualSolution, returns: Array, interpolation: float, repaired: bool) -> dict:
        return {
            "eta": dual.eta * dual.return_scale,  # in return units (inf for uniform weights)
            "kl": dual.kl,
            "ess": 1.0 / float(dual.weights @ dual.weights),
            "interpolation": float(interpolation),
            "logdet_cov": 2.0 * float(np.log(np.diag(self.policy.chol)).sum())
            + 2.0 * self.n_params * float(np.log(self.policy.step_size)),
            "mean_return": scaled_mean(returns),
            "dual_iterations": float(dual.iterations),
            "cov_repaired": float(repaired),
        }

    def stop(self) -> dict[str, Any]:
        """``min_std``, ``max_condition``, ``max_std_growth``, ``tolflatfitness`` and ``tolstagnation``
        criteria that are met (empty before the first update)."""
        met: dict[str, Any] = {}
        diagnostics = self.diagnostics
        if not diagnostics:
            return met
        if diagnostics["max_std"] < self.config.min_std:
            met["min_std"] = diagnostics["max_std"]
        if diagnostics["cond_cov"] > self.config.max_condition:
            met["max_condition"] = diagnostics["cond_cov"]
        if diagnostics["max_std"] > self.config.max_std_growth * self._initial_max_std:
            met["max_std_growth"] = diagnostics["max_std"] / self._initial_max_std
        met.update(self._no_signal_stops())
        return met

    # -- checkpoints ---------------------------------------------------------------------------------------
    def _state(self) -> dict[str, Any]:
        state = self._policy_state()
        state.update(
            dual_eta=self._eta,
            mean_returns=np.asarray(self.mean_returns, dtype=np.float64),
            stagnation_window=self.stagnation_window,
        )
        return state

    @classmethod
    def _from_state(cls, state: Mapping[str, Any]) -> CREPS:
        options = dict(state["config"])
        config = cls.config_class(
            initial_mean=np.asarray(state["initial_mean"]),
            initial_cov=np.asarray(state["initial_cov"]),
            **options,
        )
        optimizer = cls.from_config(config)
        optimizer.rng.bit_generator.state = check_generator_state(state["rng"], "state['rng']")
        optimizer.policy = LinearGaussianPolicy.from_state(config.mean_map, config.n_params, state)
        optimizer._eta = check_real(state["dual_eta"], "state['dual_eta']", strict=True)
        optimizer.flat_iterations = check_count(state.get("flat_iterations", 0), "state['flat_iterations']")
        if "mean_returns" in state:  # checkpoints written before the stagnation criterion have none
            history = as_float_array(state["mean_returns"], "state['mean_returns']", (None,))
            optimizer.mean_returns = [float(v) for v in history]
            window = check_positive_int(state["stagnation_window"], "state['stagnation_window']")
            optimizer.stagnation_window = window
        return optimizer
