"""Contextual CMA-ES (C-CMA-ES): CMA-ES with a context-dependent mean and step-size control.

References: A. Abdolmaleki, B. Price, N. Lau, L. P. Reis, G. Neumann, "Contextual Covariance Matrix Adaptation
Evolutionary Strategies", IJCAI 2017 (the contextual mean and the context baseline), and N. Hansen, "The CMA
Evolution Strategy: A Tutorial", arXiv:1604.00772 (the weights, the evolution paths and every default). The
project's reading, with the equations (C1)–(C9) tagged below and the derivation of the step-size signal, is
in ``docs/algorithms.md``.

One iteration, for a batch of N samples (s_k, θ_k, R_k) drawn from π(θ|s) = N(Aᵀϕ(s), σ²C):

1. Advantages (C1): a_k = R_k − V(s_k), with V a ridge least-squares fit of the returns on a full quadratic in
   s (cross terms included); smaller batches fall back to an affine or a constant baseline. Optionally
   (C1'') V is a local, kernel-weighted median of the recent returns (``baseline_bandwidth``), (C1d) that
   median taken of the residuals of the polynomial fit (``baseline_detrend``), or (C1s) the
   ridge scales with the fraction of the returns that the context leaves unexplained
   (``baseline_ridge_scale``).
2. Weights (C2): CMA-ES rank weights on the advantages, positive for the best ⌊N/2⌋, negative for the rest
   (active CMA, ``active=True``).
3. Mean (C3): A = weighted least squares of θ on ϕ(s) over the positively weighted samples; optionally
   (C3'') minus α times the same fit of the negatively weighted samples' shifts (``mean_repulsion``).
4. Step-size signal (C4): y_w = Σ_{w_k>0} w_k (θ_k − m_old(s_k))/σ, the shift of the mean at the selected
   samples' weighted mean context. Under random selection y_w ~ N(0, C/μ_eff) exactly, as in CMA-ES.
5. Paths, covariance and step size (C5)–(C9): CMA-ES's cumulative step-size adaptation, rank-one and rank-μ
   updates with y_k = (θ_k − m_old(s_k))/σ.
6. Restarts that keep the best (C10, ``keep_best``): a search that ends in a restart leaves its final mean
   policy as the best one if its score (the mean return of its last ``BEST_WINDOW`` batches, from the told
   returns only) beats the best so far; ``recommend`` gives the best policy until the running search's score
   beats it.
7. A restart portfolio (C11, ``restart_baseline_loss``): by default the searches after a restart fit the
   baseline with the other loss (Huber's after the squared fit), so a restart does not repeat a search that
   failed with the first fit.
8. Restarts that can pay off (C12, ``budget``): with a known episode budget a restart is made only while the
   episodes left carry a new search as far as the ended one went; IPOP's growth (C13,
   ``restart_population_factor``): after r restarts the optimiser wants N₀ · F^r samples per batch
   (:mod:`creps_gym.optimizers.ccmaes_restarts`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any, ClassVar, NamedTuple

import numpy as np
from numpy.typing import NDArray
from scipy import linalg

from creps_gym._validation import as_float_array, check_count, check_generator_state, check_positive_int
from creps_gym.optimizers.base import ContextualOptimizer
from creps_gym.optimizers.ccmaes_config import FORMER_ABSENT, CCMAESConfig, options_doc, options_signature
from creps_gym.optimizers.ccmaes_restarts import Restarts
from creps_gym.optimizers.cma_rules import (
    CMAConstants,
    csa_step,
    distribution_stops,
    expected_norm,
    inverse_sqrt,
    stagnation_window,
    update_paths_and_cov,
)
from creps_gym.optimizers.contextual import (
    baseline_features,
    coefficient_shift,
    context_advantages,
    contextual_mean,
    detrended_local_advantages,
    local_advantages,
    recent_samples,
)
from creps_gym.optimizers.policies import LinearGaussianPolicy, PolicyAccess, check_option_names

__all__ = [
    "CCMAES",
    "CCMAESConfig",
    "baseline_features",
    "context_advantages",
    "contextual_mean",
    "recommended_batch_size",
]

Array = NDArray[np.float64]

recommended_batch_size = PolicyAccess.recommended_batch_size


class _Step(NamedTuple):
    policy: LinearGaussianPolicy
    path_sigma: Array
    path_cov: Array
    diagnostics: dict[str, float]


class CCMAES(Restarts, PolicyAccess, ContextualOptimizer):
    """Contextual CMA-ES with cumulative step-size adaptation and active covariance updates.

    ``CCMAES(n_params, n_context_dims, **options)``, the options (listed below, keyword-only) validated by
    :class:`CCMAESConfig`; :mod:`creps_gym.optimizers.base` has the protocol. Any batch size of at least two
    works; the weights and learning rates follow it, and :func:`recommended_batch_size` is the default the
    runner uses.
    """

    kind: ClassVar[str] = "c-cma-es"
    #: The options' dataclass (a subclass of :class:`CCMAESConfig` for a variant with more options).
    config_class: ClassVar[type[CCMAESConfig]] = CCMAESConfig
    #: The option a caller (the runner) sets to the run's episode budget unless given (C12).
    budget_option: ClassVar[str | None] = "budget"
    #: The option that grows the wanted batch after a restart (C13): a fixed-batch caller keeps it at 1.
    batch_growth_option: ClassVar[str | None] = "restart_population_factor"

    def __init__(self, n_params: int, n_context_dims: int, **options: Any) -> None:
        check_option_names(self.config_class, options)
        self._init_from_config(self.config_class(n_params=n_params, n_context_dims=n_context_dims, **options))

    def _init_from_config(self, config: CCMAESConfig) -> None:
        super().__init__()
        self.config = config
        self.n_params, self.n_context_dims = config.n_params, config.n_context_dims
        self.rng = np.random.default_rng(config.seed)
        self.restarts_done = 0
        self.search_start = 0  # the episodes told before the running search began (C12)
        self.best_coefficients: Array | None = None  # the kept mean policy (C10) and its score
        self.best_score = -math.inf
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
        advantages, explained = self._advantages(contexts, returns)
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
        self._restart_if_due()  # Eqs. (C10)-(C13)
        self._diagnostics["restarts"] = float(self.restarts_done)

    def _baseline_loss(self) -> str:
        """The running search's baseline loss: ``baseline_loss`` until the first restart, then the one
        ``restart_baseline_loss`` names (Eq. (C11))."""
        if self.restarts_done == 0:
            return self.config.baseline_loss
        return self.config.restart_loss()  # Eq. (C11): a restart searches with the other baseline fit

    def _advantages(self, contexts: Array, returns: Array) -> tuple[Array, float]:
        """a_k = R_k − V(s_k) of a batch and the fraction of its variance V explains (C1), (C1'')."""
        config = self.config
        past = (self.past_contexts, self.past_returns)
        if config.baseline_bandwidth > 0.0 and config.baseline_detrend:  # Eq. (C1d)
            return detrended_local_advantages(
                contexts,
                returns,
                config.baseline_bandwidth,
                config.baseline_degree,
                config.baseline_ridge,
                *past,
                config.baseline_ridge_scale,
            )
        if config.baseline_bandwidth > 0.0:  # Eq. (C1'')
            return local_advantages(contexts, returns, config.baseline_bandwidth, *past)
        return context_advantages(  # Eq. (C1)
            contexts,
            returns,
            config.baseline_degree,
            config.baseline_ridge,
            *past,
            config.standardise_advantages,
            self._baseline_loss(),
            config.baseline_ridge_scale,  # Eq. (C1s) with "unexplained"
        )

    def _step(self, contexts: Array, params: Array, weights: Array, constants: CMAConstants) -> _Step:
        policy = self.policy.copy()
        sigma = policy.step_size
        deviations = (params - policy.mean(contexts)) / sigma  # y_k ~ N(0, C)
        try:
            fit = (
                self.config.ridge,
                policy.coefficients,
                self.config.mean_repulsion,
                self.config.ridge_centre,
            )
            fitted = contextual_mean(policy.mean_map, contexts, params, weights, *fit)  # (C3), (C3r), (C3'')
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
            self.policy.cov,
            self.path_sigma,
            self.path_cov,
            signal,
            shift,
            deviations,
            weights,
            constants,
            self.iteration,
            inv_sqrt,
        )
        repaired = policy.set_cov(cov)
        policy.step_size = csa_step(sigma, path_sigma, constants)  # Eq. (C9)
        ratio = float(np.linalg.norm(path_sigma)) / expected_norm(path_sigma.size)
        diagnostics = {
            "step_size": policy.step_size,
            "mu_eff": constants.mu_eff,
            "path_sigma_ratio": ratio,
            "hsig": float(hsig),
            "cov_repaired": float(repaired),
        }
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
        """σ (``step_size``), σ·√(mean eigenvalue of C) (``search_scale``, the search's typical spread per
        coordinate), μ_eff, ‖p_σ‖/E‖N(0,I)‖, h_σ, R² of the baseline (negative when the fit predicts the
        batch worse than its mean), mean return, max std and cond of σ²C."""
        if "step_size" in self._diagnostics and "cond_cov" not in self._diagnostics:
            eigenvalues = self._eigen()[0]
            self._diagnostics["cond_cov"] = float(eigenvalues[-1] / max(eigenvalues[0], 1e-300))
            self._diagnostics["max_std"] = self.step_size * float(np.sqrt(eigenvalues[-1]))
            self._diagnostics["search_scale"] = self.step_size * math.sqrt(float(np.mean(eigenvalues)))
        return dict(self._diagnostics)

    def stop(self) -> dict[str, Any]:
        """pycma-like criteria that are met: tolx, tolupsigma, max_condition, tolstagnation and
        tolflatfitness (empty before the first update)."""
        if not self._diagnostics:
            return {}
        config = self.config
        met: dict[str, Any] = distribution_stops(
            self.step_size,
            config.initial_step_size,
            np.diag(self.policy.cov),
            self._eigen()[0],
            self.path_cov,
            config.tolx,
            config.tolupsigma,
            config.max_condition,
        )
        met.update(self._no_signal_stops())
        return met

    # -- checkpoints ---------------------------------------------------------------------------------------
    def _state(self) -> dict[str, Any]:
        state, best = self._policy_state(), self.best_coefficients  # best: None before the first restart
        state.update(
            path_sigma=self.path_sigma.copy(),
            path_cov=self.path_cov.copy(),
            mean_returns=np.asarray(self.mean_returns, dtype=np.float64),
            stagnation_window=self.stagnation_window,
            past_contexts=self.past_contexts.copy(),
            past_returns=self.past_returns.copy(),
            restarts_done=self.restarts_done,
            search_start=self.search_start,
            best_coefficients=np.zeros((0, self.n_params)) if best is None else best.copy(),
            best_score=np.asarray([] if best is None else [self.best_score]),
        )
        return state

    @classmethod
    def _from_state(cls, state: Mapping[str, Any]) -> CCMAES:
        config = cls.config_class(
            initial_mean=np.asarray(state["initial_mean"]),
            initial_cov=np.asarray(state["initial_cov"]),
            **{**FORMER_ABSENT, **dict(state["config"])},
        )
        optimizer = cls.__new__(cls)
        optimizer._init_from_config(config)
        optimizer.rng.bit_generator.state = check_generator_state(state["rng"], "state['rng']")
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
        optimizer.flat_iterations = check_count(state["flat_iterations"], "state['flat_iterations']")
        optimizer.restarts_done = check_count(
            state["restarts_done"], "state['restarts_done']", config.restarts
        )
        if "search_start" in state:  # absent before C12: the budget rule was unknown (budget None)
            optimizer.search_start = check_count(state["search_start"], "state['search_start']")
        if "best_coefficients" in state and np.asarray(state["best_coefficients"]).size:  # absent before C10
            k = config.mean_map.n_features
            optimizer.best_coefficients = read("best_coefficients", (k, p))
            optimizer.best_score = float(read("best_score", (1,))[0])
        return optimizer


# help(CCMAES) and inspect.signature show every option with its default, from the config (one source).
CCMAES.__doc__ = (CCMAES.__doc__ or "") + options_doc(CCMAESConfig)
CCMAES.__init__.__signature__ = options_signature(CCMAESConfig)  # type: ignore[attr-defined]
