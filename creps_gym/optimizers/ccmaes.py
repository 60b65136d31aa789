"""Contextual CMA-ES (C-CMA-ES): CMA-ES with a context-dependent mean and step-size control.

References: A. Abdolmaleki, B. Price, N. Lau, L. P. Reis, G. Neumann, "Contextual Covariance Matrix Adaptation
Evolutionary Strategies", IJCAI 2017 (the contextual mean and the context baseline), and N. Hansen, "The CMA
Evolution Strategy: A Tutorial", arXiv:1604.00772 (the weights, the evolution paths and every default). The
project's reading, with the equations (C1)–(C9) tagged below and the derivation of the step-size signal, is
in ``docs/algorithms.md``.

One iteration, for a batch of N samples (s_k, θ_k, R_k) drawn from π(θ|s) = N(Aᵀϕ(s), σ²C):

1. Advantages (C1): a_k = R_k − V(s_k), with V a ridge least-squares fit of the returns on a full quadratic in
   s (cross terms included); smaller batches fall back to an affine or a constant baseline. Optionally
   (C1'') V is a local, kernel-weighted median of the recent returns (``baseline_bandwidth``).
2. Weights (C2): CMA-ES rank weights on the advantages, positive for the best ⌊N/2⌋, negative for the rest
   (active CMA, ``active=True``).
3. Mean (C3): A = weighted least squares of θ on ϕ(s) over the positively weighted samples; optionally
   (C3'') minus α times the same fit of the negatively weighted samples' shifts (``mean_repulsion``).
4. Step-size signal (C4): y_w = Σ_{w_k>0} w_k (θ_k − m_old(s_k))/σ, the shift of the mean at the selected
   samples' weighted mean context. Under random selection y_w ~ N(0, C/μ_eff) exactly, as in CMA-ES.
5. Paths, covariance and step size (C5)–(C9): CMA-ES's cumulative step-size adaptation, rank-one and rank-μ
   updates with y_k = (θ_k − m_old(s_k))/σ.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from typing import Any, ClassVar, NamedTuple

import numpy as np
from numpy.typing import NDArray
from scipy import linalg

from creps_gym._validation import (
    as_float_array,
    check_bool,
    check_positive_int,
    check_real_in_range,
    check_seed,
)
from creps_gym.optimizers.base import ContextualOptimizer
from creps_gym.optimizers.cma_rules import (
    CMAConstants,
    cma_constants,
    csa_step,
    distribution_stops,
    expected_norm,
    inverse_sqrt,
    rank_weights,
    stagnation_window,
    update_paths_and_cov,
)
from creps_gym.optimizers.contextual import (
    LOSSES,
    baseline_features,
    check_local_baseline,
    coefficient_shift,
    context_advantages,
    contextual_mean,
    local_advantages,
    recent_samples,
)
from creps_gym.optimizers.features import FeatureMap, make_features
from creps_gym.optimizers.policies import (
    LinearGaussianPolicy,
    PolicyAccess,
    check_option_names,
    initial_coefficients,
    initial_covariance,
    split_step_size,
)

__all__ = [
    "CCMAES",
    "CCMAESConfig",
    "baseline_features",
    "context_advantages",
    "contextual_mean",
    "recommended_batch_size",
]

Array = NDArray[np.float64]
#: The options of C1's polynomial fit, which the local baseline (C1'') ignores: they must keep their defaults.
UNUSED_BY_LOCAL_BASELINE = ("standardise_advantages", "baseline_loss", "baseline_degree", "baseline_ridge")
SIGNALS = ("coefficients", "mean")

recommended_batch_size = PolicyAccess.recommended_batch_size


class _Step(NamedTuple):
    policy: LinearGaussianPolicy
    path_sigma: Array
    path_cov: Array
    diagnostics: dict[str, float]


@dataclass(frozen=True, eq=False)
class CCMAESConfig:
    """Configuration of :class:`CCMAES`; validates itself on construction.

    Parameters
    ----------
    n_params : int                  p, the dimension of θ.
    n_context_dims : int            z, the dimension of s (0 for a plain CMA-ES).
    initial_mean : scalar, (p,) or (k, p)   initial mean (constant over contexts) or coefficients A.
    initial_cov : scalar, (p,) or (p, p)    initial Σ0 = σ0²C0, split with det C0 = 1.
    mean_features : str, dict or FeatureMap ϕ(s) of the mean; ``"affine"`` = [1, s].
    active : bool                   negative weights for the worst half (active CMA).
    baseline_degree : int           degree of the context baseline's polynomial (2: a full quadratic).
    baseline_batches : int          batches the baseline is fitted on: the current one and the last
        (``baseline_batches`` − 1)·N samples before it (sample reuse; 1: the current batch only).
    standardise_advantages : bool   divide a_k by a context-dependent scale fitted like V (C1).
    baseline_loss : str             ``"squared"`` (least squares) or ``"huber"`` (Huber's M-estimate, robust
        to a few outlying returns such as falls) for the fit of V (C1).
    baseline_bandwidth : float      0: the polynomial V above; h > 0: a local V, the kernel-weighted median of
        the recent returns with a Gaussian bandwidth of h context standard deviations (C1'').
    ridge, baseline_ridge : float   relative ridges of the mean fit (C3) and of the baseline (C1).
    c_sigma, d_sigma, c_c, c_1, c_mu : float or None   learning rates; None = the tutorial's defaults.
    c_m : float                     the mean's learning rate in (0, 1] (C3'): A ← A + c_m (A_fit − A);
        below 1 it averages the regression's noise over about (2 − c_m)/c_m batches.
    mean_repulsion : float          α in [0, 1] (C3''): A_fit also moves away from the negatively weighted
        samples by α times their fitted shift (needs ``active``; 0: CMA-ES's positive-weight mean).
    seed : int or None              seed of the sampling Generator.
    restarts : int                  restarts from the initial distribution when a stop criterion is met
        (``stop()`` reports criteria only once they are used up).
    tolx, tolupsigma, max_condition, tolstagnation, tolflatfitness : stop criteria like pycma's
        (``tolstagnation=None`` means 100 + 100·p^1.5/N iterations).
    """

    n_params: int
    n_context_dims: int
    initial_mean: Any = 0.0
    initial_cov: Any = 1.0
    mean_features: Any = "affine"
    active: bool = True
    baseline_degree: int = 2
    baseline_batches: int = 3
    standardise_advantages: bool = False
    baseline_loss: str = "squared"
    baseline_bandwidth: float = 0.0
    restarts: int = 3
    step_size_signal: str = "mean"
    ridge: float = 1e-8
    baseline_ridge: float = 1e-10
    c_sigma: float | None = None
    d_sigma: float | None = None
    c_c: float | None = None
    c_1: float | None = None
    c_mu: float | None = None
    c_m: float = 1.0
    mean_repulsion: float = 0.0
    seed: int | None = None
    tolx: float = 1e-11
    tolupsigma: float = 1e20
    max_condition: float = 1e14
    tolstagnation: int | None = None
    tolflatfitness: int = 10
    mean_map: FeatureMap = field(init=False, repr=False)
    initial_step_size: float = field(init=False, repr=False)
    initial_shape: Array = field(init=False, repr=False)

    def __post_init__(self) -> None:
        for name, minimum in (
            ("n_params", 1),
            ("n_context_dims", 0),
            ("tolflatfitness", 1),
            ("baseline_degree", 0),
            ("baseline_batches", 1),
            ("restarts", 0),
        ):
            object.__setattr__(self, name, check_positive_int(getattr(self, name), name, minimum))
        if self.tolstagnation is not None:
            object.__setattr__(self, "tolstagnation", check_positive_int(self.tolstagnation, "tolstagnation"))
        object.__setattr__(self, "active", check_bool(self.active, "active"))
        standardise = check_bool(self.standardise_advantages, "standardise_advantages")
        object.__setattr__(self, "standardise_advantages", standardise)
        if self.baseline_loss not in LOSSES:
            raise ValueError(f"baseline_loss: expected one of {LOSSES}, got {self.baseline_loss!r}")
        if self.step_size_signal not in SIGNALS:
            raise ValueError(f"step_size_signal: expected one of {SIGNALS}, got {self.step_size_signal!r}")
        for name, low, high in (
            ("ridge", 0.0, 1.0),
            ("baseline_ridge", 0.0, 1.0),
            ("tolx", 0.0, 1e300),
            ("tolupsigma", 1.0, 1e300),
            ("max_condition", 1.0, 1e300),
            ("mean_repulsion", 0.0, 1.0),
            ("baseline_bandwidth", 0.0, 1e3),
        ):
            value = check_real_in_range(getattr(self, name), name, low, high, low_inclusive=low == 0.0)
            object.__setattr__(self, name, value)
        for name, high in (("c_sigma", 1.0), ("d_sigma", 1e6), ("c_c", 1.0), ("c_1", 1.0), ("c_mu", 1.0)):
            if getattr(self, name) is not None:  # None: the tutorial's default; else in (0, high]
                object.__setattr__(self, name, check_real_in_range(getattr(self, name), name, 0.0, high))
        object.__setattr__(self, "c_m", check_real_in_range(self.c_m, "c_m", 0.0, 1.0))
        if self.mean_repulsion > 0.0 and not self.active:  # it repels the negatively weighted samples
            raise ValueError(f"mean_repulsion: expected 0 with active=False, got {self.mean_repulsion}")
        defaults = {option.name: option.default for option in fields(self)}
        unused = {name: (getattr(self, name), defaults[name]) for name in UNUSED_BY_LOCAL_BASELINE}
        check_local_baseline(self.baseline_bandwidth, unused)
        if self.c_1 is not None and self.c_mu is not None and self.c_1 + self.c_mu > 1.0:
            raise ValueError(f"c_1, c_mu: expected c_1 + c_mu <= 1, got {self.c_1} + {self.c_mu}")
        object.__setattr__(self, "seed", check_seed(self.seed))
        mean_map = make_features(self.mean_features, self.n_context_dims, "mean_features")
        object.__setattr__(self, "mean_map", mean_map)
        object.__setattr__(
            self, "initial_mean", initial_coefficients(self.initial_mean, mean_map, self.n_params)
        )
        object.__setattr__(self, "initial_cov", initial_covariance(self.initial_cov, self.n_params))
        sigma, shape = split_step_size(self.initial_cov)
        object.__setattr__(self, "initial_step_size", sigma)
        object.__setattr__(self, "initial_shape", shape)

    def constants(self, n_samples: int) -> CMAConstants:
        """The strategy constants for a batch of ``n_samples``, with this config's overrides."""
        return cma_constants(
            self.n_params,
            rank_weights(n_samples),
            active=self.active,
            overrides={n: getattr(self, n) for n in ("c_sigma", "d_sigma", "c_c", "c_1", "c_mu")},
        )

    def to_json(self) -> dict[str, Any]:
        """JSON-serialisable scalars and the feature spec (the initial arrays are saved separately)."""
        skip = {"initial_mean", "initial_cov", "mean_features"}
        data = {f.name: getattr(self, f.name) for f in fields(self) if f.init and f.name not in skip}
        data["mean_features"] = self.mean_map.spec()
        return data


class CCMAES(PolicyAccess, ContextualOptimizer):
    """Contextual CMA-ES with cumulative step-size adaptation and active covariance updates.

    ``CCMAES(n_params, n_context_dims, **options)``; see :class:`CCMAESConfig` for the options and
    :mod:`creps_gym.optimizers.base` for the protocol. Any batch size of at least two works; the weights and
    learning rates follow it, and :func:`recommended_batch_size` is the default the runner uses.
    """

    kind: ClassVar[str] = "c-cma-es"

    def __init__(self, n_params: int, n_context_dims: int, **options: Any) -> None:
        check_option_names(CCMAESConfig, options)
        self._init_from_config(CCMAESConfig(n_params=n_params, n_context_dims=n_context_dims, **options))

    def _init_from_config(self, config: CCMAESConfig) -> None:
        super().__init__()
        self.config = config
        self.n_params, self.n_context_dims = config.n_params, config.n_context_dims
        self.rng = np.random.default_rng(config.seed)
        self.restarts_done = 0
        self._eigen_of: Array | None = None
        self._eigen_cache: tuple[Array, Array] = (np.ones(0), np.ones((0, 0)))
        self._reset_search()

    def _reset_search(self) -> None:
        """The initial distribution and empty paths and histories (at the start and at each restart)."""
        config = self.config
        self.policy = LinearGaussianPolicy(
            config.mean_map, config.initial_mean.copy(), config.initial_shape, config.initial_step_size
        )
        columns = config.mean_map.n_features if config.step_size_signal == "coefficients" else 1
        self.path_sigma = np.zeros((config.n_params, columns))
        self.path_cov = np.zeros(config.n_params)
        self.mean_returns: list[float] = []  # the last iterations', for the stagnation criterion
        self.stagnation_window = stagnation_window(config.n_params, 1, config.tolstagnation)
        self.past_contexts = np.empty((0, config.n_context_dims))  # for the baseline (baseline_batches > 1)
        self.past_returns = np.empty(0)
        self.flat_iterations = 0

    def _update(self, contexts: Array, params: Array, returns: Array) -> None:
        config = self.config
        past = (self.past_contexts, self.past_returns)
        if config.baseline_bandwidth > 0.0:  # Eq. (C1'')
            advantages, explained = local_advantages(contexts, returns, config.baseline_bandwidth, *past)
        else:
            advantages, explained = context_advantages(  # Eq. (C1)
                contexts, returns, config.baseline_degree, config.baseline_ridge, *past,
                config.standardise_advantages, config.baseline_loss,
            )  # fmt: skip
        constants = self.config.constants(returns.shape[0])
        order = np.argsort(-advantages, kind="stable")
        weights = np.empty_like(constants.weights)
        weights[order] = constants.weights  # Eq. (C2): the k-th best advantage gets the k-th weight
        step = self._step(contexts, params, weights, constants)
        if not (step.policy.is_finite() and np.isfinite(step.path_sigma).all()):
            raise RuntimeError(
                "tell(): the update produced non-finite values; the optimiser was left unchanged"
            )
        self.policy, self.path_sigma, self.path_cov = step.policy, step.path_sigma, step.path_cov
        self._record_returns(returns)
        if config.baseline_batches > 1:
            self.past_contexts, self.past_returns = recent_samples(
                self.past_contexts, self.past_returns, contexts, returns, config.baseline_batches - 1
            )
        self._diagnostics = dict(step.diagnostics, baseline_r2=explained, mean_return=self.mean_returns[-1])
        if self.restarts_done < config.restarts and self.stop():
            self._reset_search()
            self.restarts_done += 1
            for stale in ("cond_cov", "max_std"):  # they described the abandoned distribution
                self._diagnostics.pop(stale, None)
        self._diagnostics["restarts"] = float(self.restarts_done)

    def _step(self, contexts: Array, params: Array, weights: Array, constants: CMAConstants) -> _Step:
        policy = self.policy.copy()
        sigma = policy.step_size
        deviations = (params - policy.mean(contexts)) / sigma  # y_k ~ N(0, C)
        try:
            fit = (self.config.ridge, policy.coefficients, self.config.mean_repulsion)
            fitted = contextual_mean(policy.mean_map, contexts, params, weights, *fit)  # Eqs. (C3), (C3'')
        except linalg.LinAlgError:
            raise RuntimeError(
                "tell(): the weighted mean regression (C3) is singular for this batch; use a ridge > 0 or "
                "more varied contexts. The optimiser was left unchanged"
            ) from None
        old, c_m = policy.coefficients, self.config.c_m  # the signals below are the fit's shift: step / c_m
        policy.coefficients = fitted if c_m == 1.0 else old + c_m * (fitted - old)  # Eq. (C3')
        selected = weights > 0
        shift = weights[selected] @ deviations[selected]  # Eq. (C4): N(0, C/μ_eff) if selection is blind
        inv_sqrt = inverse_sqrt(self.policy.cov, self._eigen())
        if self.config.step_size_signal == "mean":
            signal = math.sqrt(constants.mu_eff) * (inv_sqrt @ shift)[:, None]  # Eq. (C4)
        else:
            signal = inv_sqrt @ coefficient_shift(  # Eq. (C4'): every coefficient's shift, whitened
                policy.mean_map, contexts[selected], deviations[selected], weights[selected]
            )
        path_sigma, path_cov, cov, hsig = update_paths_and_cov(  # Eqs. (C5)-(C8)
            self.policy.cov, self.path_sigma, self.path_cov, signal, shift, deviations, weights, constants,
            self.iteration, inv_sqrt,
        )  # fmt: skip
        repaired = policy.set_cov(cov)
        policy.step_size = csa_step(sigma, path_sigma, constants)  # Eq. (C9)
        ratio = float(np.linalg.norm(path_sigma)) / expected_norm(path_sigma.size)
        diagnostics = {"step_size": policy.step_size, "mu_eff": constants.mu_eff, "path_sigma_ratio": ratio,
                       "hsig": float(hsig), "cov_repaired": float(repaired)}  # fmt: skip
        return _Step(policy, path_sigma, path_cov, diagnostics)

    def _eigen(self) -> tuple[Array, Array]:
        """``eigh`` of C, computed once per update: the diagnostics, the stop criteria and the next update's
        C^(−1/2) share it."""
        cov = self.policy.cov
        if self._eigen_of is not cov:
            self._eigen_cache, self._eigen_of = np.linalg.eigh(cov), cov
        return self._eigen_cache

    @property
    def diagnostics(self) -> dict[str, float]:
        """σ, μ_eff, ‖p_σ‖/E‖N(0,I)‖, h_σ, R² of the baseline, mean return, max std and cond of σ²C."""
        if "step_size" in self._diagnostics and "cond_cov" not in self._diagnostics:
            eigenvalues = self._eigen()[0]
            self._diagnostics["cond_cov"] = float(eigenvalues[-1] / max(eigenvalues[0], 1e-300))
            self._diagnostics["max_std"] = self.step_size * float(np.sqrt(eigenvalues[-1]))
        return dict(self._diagnostics)

    def stop(self) -> dict[str, Any]:
        """pycma-like criteria that are met: tolx, tolupsigma, max_condition, tolstagnation and
        tolflatfitness (empty before the first update)."""
        if not self._diagnostics:
            return {}
        config = self.config
        met: dict[str, Any] = distribution_stops(
            self.step_size, config.initial_step_size, np.diag(self.policy.cov), self._eigen()[0],
            self.path_cov, config.tolx, config.tolupsigma, config.max_condition,
        )  # fmt: skip
        met.update(self._no_signal_stops())
        return met

    # -- checkpoints ---------------------------------------------------------------------------------------
    def _state(self) -> dict[str, Any]:
        state = self._policy_state()
        state.update(
            path_sigma=self.path_sigma.copy(),
            path_cov=self.path_cov.copy(),
            mean_returns=np.asarray(self.mean_returns, dtype=np.float64),
            stagnation_window=self.stagnation_window,
            past_contexts=self.past_contexts.copy(),
            past_returns=self.past_returns.copy(),
            restarts_done=self.restarts_done,
        )
        return state

    @classmethod
    def _from_state(cls, state: Mapping[str, Any]) -> CCMAES:
        config = CCMAESConfig(
            initial_mean=np.asarray(state["initial_mean"]),
            initial_cov=np.asarray(state["initial_cov"]),
            **dict(state["config"]),
        )
        optimizer = cls.__new__(cls)
        optimizer._init_from_config(config)
        optimizer.rng.bit_generator.state = state["rng"]
        optimizer.policy = LinearGaussianPolicy.from_state(config.mean_map, config.n_params, state)
        p, z = config.n_params, config.n_context_dims

        def read(key: str, shape: tuple[int | None, ...]) -> Array:
            return as_float_array(state[key], f"state['{key}']", shape).copy()

        optimizer.path_sigma = read("path_sigma", optimizer.path_sigma.shape)
        optimizer.path_cov = read("path_cov", (p,))
        optimizer.mean_returns = [float(v) for v in read("mean_returns", (None,))]
        window = check_positive_int(state["stagnation_window"], "state['stagnation_window']")
        optimizer.stagnation_window = window
        optimizer.past_contexts = read("past_contexts", (None, z))
        optimizer.past_returns = read("past_returns", (optimizer.past_contexts.shape[0],))
        optimizer.flat_iterations = int(state["flat_iterations"])
        optimizer.restarts_done = int(state["restarts_done"])
        return optimizer
