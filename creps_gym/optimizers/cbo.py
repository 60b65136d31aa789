"""Contextual Bayesian optimisation (c-bo): a Gaussian process of the return over (s, θ), asked at each s.

References: J. H. Metzen, A. Fabisch, J. Hansen, "Bayesian Optimization for Contextual Policy Search",
IROS 2015 workshop / Metzen 2015 (BO-CPS: a GP over context and parameters, an acquisition maximised over θ
with the observed s fixed); Z. Wang, S. Jegelka, "Max-value Entropy Search for Efficient Bayesian
Optimization", ICML 2017 (A2, A3); N. Srinivas et al., "Gaussian Process Optimization in the Bandit Setting",
ICML 2010 (A1); D. Ginsbourger et al. 2010 (the kriging believer).

One ``ask(contexts)`` for a batch of n contexts (the GP of :mod:`creps_gym.optimizers.gp_model`, the
acquisitions of :mod:`creps_gym.optimizers.acquisitions`):

1. The first ``initial_samples`` episodes are drawn from the initial distribution N(initial_mean,
   initial_cov), clipped to the parameter box.
2. After that, each row's θ maximises the acquisition at its context s (UCB, A1, or MES, A2–A3) over the
   parameter box: random candidates and the observed θ are scored, L-BFGS-B starts from the best few.
3. Within a batch, each chosen (s, θ) is added to the model with its posterior mean as a fantasised return
   (the kriging believer), so a batch of any size spreads out; MES's sampled maxima stay above those
   fantasies (Eq. A4 of :mod:`creps_gym.optimizers.acquisitions`), so it does at one context too.
   ``ask_more(contexts)`` chooses rows after the pending batch's in the same way (a batch asked a row at a
   time, as the real-robot loop does).

``tell`` appends the episodes to the data; the hyperparameters (G3) are refitted by maximum likelihood when
the data have grown by ``refit_growth`` since the last fit, and otherwise kept, so an ask costs one Cholesky
factor and the acquisition's optimisation.

``recommend(contexts)`` follows ``recommend_over``, Eqs. (R1)–(R3) of
:mod:`creps_gym.optimizers.cbo_recommend`: the posterior mean's maximiser at each s within a trust region of
the data (the default), or the told θ with the largest posterior mean at s (of every episode, or of those
with the nearest contexts). :meth:`ContextualBO.mean_policy` distils the recommendation into a
:class:`~creps_gym.optimizers.policy_file.Policy` (least squares of the maximisers on a context grid) and
reports the distillation error in ``diagnostics``.

Checkpoints store the data, the hyperparameters, the context scaling and the Generator; the GP is refitted
from them on restore (never pickled), giving the same bits.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from creps_gym._validation import check_positive_int
from creps_gym.optimizers.acquisitions import AcquisitionMaximiser, acquisition_at, max_value_floor
from creps_gym.optimizers.base import ContextualOptimizer
from creps_gym.optimizers.cbo_config import MAX_COUNTS, CBOConfig, fold_contexts
from creps_gym.optimizers.cbo_recommend import (
    RECOMMEND_SEED,
    distillation_contexts,
    least_squares_distillation,
    told_choice,
    trust_region,
    trust_region_maximiser,
)
from creps_gym.optimizers.cbo_state import GPData, check_kernel_memory, read_gp_data
from creps_gym.optimizers.ccmaes_config import options_doc, options_signature
from creps_gym.optimizers.context_value import context_information, utility_thetas
from creps_gym.optimizers.gp_model import (
    GPModel,
    default_start,
    fit_gp,
    fit_hyperparameters,
    fit_subset,
    transformed_returns,
)
from creps_gym.optimizers.gp_trend import chosen_transform, detrend, residual_share, with_trend_maximiser
from creps_gym.optimizers.policies import check_option_names
from creps_gym.optimizers.policy_file import Policy

__all__ = ["ContextualBO"]

Array = NDArray[np.float64]
#: ``stop()`` looks at the model only from this many told episodes on, and reports ``no_signal`` when the
#: fitted noise holds at least this share of the model's variance.
STOP_EPISODES, NOISE_SHARE = 50, 0.95


class ContextualBO(ContextualOptimizer):
    """Contextual Bayesian optimisation over (s, θ) (see the module docstring).

    Parameters
    ----------
    n_params : int
        p, the dimension of θ.
    n_context_dims : int
        z, the dimension of s.
    **options
        The fields of :class:`~creps_gym.optimizers.cbo_config.CBOConfig` (listed below).
    """

    kind: ClassVar[str] = "c-bo"
    config_class: ClassVar[type] = CBOConfig
    #: ``mean_policy()`` is a least-squares distillation of ``recommend``, not equal to it bit for bit.
    distilled_policy: ClassVar[bool] = True

    @staticmethod
    def recommended_batch_size(n_params: int, n_context_dims: int) -> int:
        """4: small batches keep the model's choices nearly sequential (the kriging believer fills them)."""
        check_positive_int(n_params, "n_params")
        check_positive_int(n_context_dims, "n_context_dims", minimum=0)
        return 4

    @staticmethod
    def minimum_batch_size(n_params: int, n_context_dims: int) -> int:
        """2, the protocol's smallest tell: every episode is data for the GP."""
        check_positive_int(n_params, "n_params")
        check_positive_int(n_context_dims, "n_context_dims", minimum=0)
        return 2

    def __init__(self, n_params: int, n_context_dims: int, **options: Any) -> None:
        check_option_names(self.config_class, options)
        self._init_from_config(self.config_class(n_params, n_context_dims, **options))

    def _init_from_config(self, config: CBOConfig) -> None:
        ContextualOptimizer.__init__(self)
        self.config = config
        self.n_params, self.n_context_dims = config.n_params, config.n_context_dims
        self.rng = np.random.default_rng(config.seed)
        p, z = self.n_params, self.n_context_dims
        self.contexts, self.params, self.returns = np.zeros((0, z)), np.zeros((0, p)), np.zeros(0)
        self.log_hyper = default_start(p + z)
        box = config.scaling_box
        self.context_scale = (np.zeros(z), np.ones(z)) if box is None else (box[0].copy(), box[1].copy())
        self.fitted_at = 0
        self.model: GPModel | None = None
        self._trend = config.trend == "quadratic"
        self._transform = "log" if config.transform == "auto" else config.transform  # chosen at each tell
        self._maximiser = AcquisitionMaximiser(config.starts)
        self._recommend_candidates: Array | None = None
        self._chol_initial = np.linalg.cholesky(config.initial_cov)

    # -- scaling -------------------------------------------------------------------------------------------
    def _scaled_contexts(self, contexts: Array, scale: tuple[Array, Array] | None = None) -> Array:
        """The GP's contexts: folded (``symmetric_contexts``), then scaled by the context scaling."""
        low, high = self.context_scale if scale is None else scale
        return (fold_contexts(contexts, self.config.symmetric_contexts) - low) / (high - low)

    def _scaled_params(self, params: Array) -> Array:
        low, high = self.config.param_box
        return (params - low) / (high - low)

    def _unscaled_params(self, unit: Array) -> Array:
        low, high = self.config.param_box
        return low + unit * (high - low)

    def _fit_scale(self, contexts: Array) -> tuple[Array, Array]:
        """The context box of the GP's scaling: the configured one, else the told (folded) contexts' range
        (a degenerate dimension gets a width of 1 around its value)."""
        if self.config.context_box is not None:
            return self.context_scale
        folded = fold_contexts(contexts, self.config.symmetric_contexts)
        low, high = folded.min(axis=0), folded.max(axis=0)
        flat = high - low <= 1e-12 * np.maximum(np.abs(low), 1.0)
        return np.where(flat, low - 0.5, low), np.where(flat, low + 0.5, high)

    def _targets(self, returns: Array, prior_mean: str | None = None, transform: str | None = None) -> Array:
        """The GP's targets; ``prior_mean`` None: the configured one (the posterior's), "mean" for the
        likelihood of a refit (a constant-mean GP: the pessimistic shift is no signal to explain);
        ``transform`` None: the one in use (``"auto"``'s choice at the last tell)."""
        centre = self.config.prior_mean if prior_mean is None else prior_mean
        return transformed_returns(returns, transform or self._transform, centre, self.config.log_quantile)

    def _chosen_transform(self, inputs: Array, returns: Array) -> str:
        """The configured transform, or ``"auto"``'s choice on these scaled inputs and returns, Eq. (G5)."""
        auto = self.config.transform == "auto"
        quantile = self.config.log_quantile
        return chosen_transform(inputs, returns, self._trend, quantile) if auto else self.config.transform

    def _inputs(self, contexts: Array, params: Array, scale: tuple[Array, Array] | None = None) -> Array:
        return np.hstack([self._scaled_contexts(contexts, scale), self._scaled_params(params)])

    # -- tell ----------------------------------------------------------------------------------------------
    def _update(self, contexts: Array, params: Array, returns: Array) -> None:
        all_contexts = np.vstack([self.contexts, contexts])
        all_params, all_returns = np.vstack([self.params, params]), np.concatenate([self.returns, returns])
        n = all_returns.shape[0]
        check_kernel_memory(n, self.n_params, self.n_context_dims, "returns")
        log_hyper, scale, fitted_at = self.log_hyper, self.context_scale, self.fitted_at
        refit = fitted_at == 0 or n >= fitted_at * self.config.refit_growth
        rng_state = self.rng.bit_generator.state
        try:
            if refit:
                scale = self._fit_scale(all_contexts)
            all_inputs = self._inputs(all_contexts, all_params, scale)
            transform = self._chosen_transform(all_inputs, all_returns)
            if refit:
                seen = fit_subset(n, self.config.fit_points, self.config.fit_subset)  # G3a
                inputs = all_inputs[seen]
                restarts = self.config.hyper_restarts
                targets = self._targets(all_returns, "mean", transform)[seen]
                if self._trend:  # the hyperparameters of the residuals' GP, Eq. (G4)
                    targets = detrend(inputs, targets)[0]
                log_hyper = fit_hyperparameters(inputs, targets, log_hyper, self.rng, restarts)
                fitted_at = n
            model = fit_gp(all_inputs, self._targets(all_returns, None, transform), log_hyper, self._trend)
        except BaseException:
            self.rng.bit_generator.state = rng_state  # a failed tell changes nothing
            raise
        self.contexts, self.params, self.returns = all_contexts, all_params, all_returns
        self.log_hyper, self.context_scale, self.fitted_at, self.model = log_hyper, scale, fitted_at, model
        self._transform = transform
        self._diagnostics = self._model_diagnostics(refit)

    def _model_diagnostics(self, refitted: bool) -> dict[str, float]:
        lengthscales = np.exp(self.log_hyper[:-2])
        return {
            "episodes": float(self.returns.shape[0]),
            "refitted": float(refitted),
            "lengthscale_min": float(lengthscales.min()),
            "lengthscale_max": float(lengthscales.max()),
            "signal_variance": float(np.exp(self.log_hyper[-2])),
            "noise_variance": float(np.exp(self.log_hyper[-1])),
            "best_return": float(self.returns.max()),
        } | ({"transform_log": float(self._transform == "log")} if self.config.transform == "auto" else {})

    def stop(self) -> dict[str, Any]:
        """Met once at least :data:`STOP_EPISODES` episodes are told: ``no_signal`` (the fitted noise is at
        least :data:`NOISE_SHARE` of the model's variance, σ_n²/(σ_f² + σ_n²), and with a quadratic trend
        that is signal, that share times the share of the returns' variance the trend leaves
        (:func:`~creps_gym.optimizers.gp_trend.residual_share`): the returns look like noise in θ and s)
        or ``tolflatfitness`` (every told return is equal)."""
        n = self.returns.shape[0]
        if n < STOP_EPISODES:
            return {}
        if float(self.returns.max() - self.returns.min()) == 0.0:
            return {"tolflatfitness": n}
        noise, signal = math.exp(self.log_hyper[-1]), math.exp(self.log_hyper[-2])
        share = noise / (noise + signal)
        if self.model is not None and self.model.beta is not None:
            share *= residual_share(self.model.scale, self.model.beta, self._targets(self.returns))
        return {"no_signal": share} if share >= NOISE_SHARE else {}

    # -- ask -----------------------------------------------------------------------------------------------
    def _sample(self, contexts: Array) -> Array:
        return self._sample_after(contexts, np.zeros((0, self.n_context_dims)), np.zeros((0, self.n_params)))

    def _sample_after(self, contexts: Array, earlier_contexts: Array, earlier_params: Array) -> Array:
        state = self.rng.bit_generator.state
        try:
            return self._choose(np.vstack([earlier_contexts, contexts]), self._scaled_params(earlier_params))
        except BaseException:
            self.rng.bit_generator.state = state  # a rejected ask changes nothing
            raise

    def _choose(self, contexts: Array, given: Array) -> Array:
        """The rows (n − k, p) for ``contexts`` (n, z) after the first k, whose θ are ``given`` (k, p), in
        θ's unit box: those of the pending batch for ``ask_more`` (k = 0 for ``ask``)."""
        model, known, k, n = self.model, self.returns.shape[0], given.shape[0], contexts.shape[0]
        scaled, rows = self._scaled_contexts(contexts), np.empty((n, self.n_params))
        for i in range(n):
            if model is None or known + i < self.config.n_initial:
                if i >= k:
                    draw = self._chol_initial @ self.rng.standard_normal(self.n_params)
                    rows[i] = np.clip(self.config.initial_mean + draw, *self.config.param_box)
                continue
            unit = given[i] if i < k else self._propose(model, scaled[i])
            rows[i] = self._unscaled_params(unit)
            if i + 1 < n:  # the kriging believer: the chosen point's posterior mean as its return
                x = np.concatenate([scaled[i], unit])
                model = model.condition(x, float(model.predict(x[None, :])[0][0]))
        return rows[k:]

    def _observed_units(self, context: Array) -> tuple[Array, Array]:
        """The observed θ (scaled, clipped to the box) of the ``candidates // 4`` episodes whose scaled
        contexts are nearest to ``context`` (the first on ties), candidates that know where returns were
        good, and those episodes' indices."""
        units = np.clip(self._scaled_params(self.params), 0.0, 1.0)
        keep, nearest = max(1, self.config.candidates // 4), np.arange(units.shape[0])
        if units.shape[0] > keep:
            distance = ((self._scaled_contexts(self.contexts) - context) ** 2).sum(axis=1)
            nearest = np.argsort(distance, kind="stable")[:keep]
        return units[nearest], nearest

    def _propose(self, model: GPModel, context: Array) -> Array:
        """The acquisition's maximiser over θ's unit box at a scaled context (z,), from ``model`` (with the
        batch's earlier rows as the kriging believer's fantasies)."""
        random = self.rng.uniform(size=(self.config.candidates, self.n_params))
        candidates = np.vstack([random, self._observed_units(context)[0]])
        candidates = with_trend_maximiser(candidates, model.beta, context, (0.0, 1.0))
        mean, variance = model.predict(self._maximiser.inputs(context, candidates))
        config, floor = self.config, None  # mes_floor="candidates": the former floor
        if config.acquisition == "mes" and config.mes_floor == "observed":
            held = model.inputs[(model.inputs[:, : context.shape[0]] == context).all(axis=1)]
            floor = max_value_floor(model, held, mean)  # Eq. (A4): the inputs the model holds at s
        options = {"beta": config.beta, "samples": config.mes_samples, "floor": floor}
        acquisition = acquisition_at(config.acquisition, mean, variance, self.rng, **options)
        maximiser = self._maximiser.maximise_scored
        return maximiser(model, context, candidates, mean, variance, acquisition)[0]

    # -- recommend and the policy --------------------------------------------------------------------------
    def recommend(self, contexts: Any) -> Array:
        """At each context, Eq. (R1) (``recommend_over="trust_region"``: the posterior mean's maximiser
        within the trust region of the data), Eq. (R2) (``"observed"``: the told θ with the largest
        posterior mean) or Eq. (R3) (``"neighbours"``: that of the episodes with the nearest contexts) of
        :mod:`~creps_gym.optimizers.cbo_recommend`: shape (n, p).

        Before the GP exists (fewer than two episodes told) it is the initial mean. Deterministic: the
        candidates come from a fixed seed, so a context gives the same θ alone or in any batch.
        """
        contexts = self._check_contexts(contexts, "contexts")
        if self.model is None:
            return np.tile(self.config.initial_mean, (contexts.shape[0], 1))
        scaled, model = self._scaled_contexts(contexts), self.model
        if (rule := self.config.recommend_over) != "trust_region":  # the told θ themselves: R2 or R3
            told = np.clip(self._scaled_params(self.params), 0.0, 1.0)
            every = np.arange(told.shape[0])  # R2: every episode; R3: N(s)
            among = [self._observed_units(row)[1] if rule == "neighbours" else every for row in scaled]
            chosen = [told_choice(model, row, told, rows) for row, rows in zip(scaled, among, strict=True)]
            return np.clip(self.params[chosen], *self.config.param_box)
        if self._recommend_candidates is None:
            fixed = np.random.default_rng(RECOMMEND_SEED).uniform(
                size=(self.config.candidates, self.n_params)
            )
            self._recommend_candidates = fixed
        units = []
        for row in scaled:
            good, bounds = self.trust_region(row)
            units.append(
                trust_region_maximiser(model, row, good, bounds, self._recommend_candidates, self._maximiser)
            )
        return self._unscaled_params(np.array(units))

    def trust_region(self, context: Array) -> tuple[Array, tuple[Array, Array]]:
        """G(s) and B(s) of Eq. (R1) at a scaled context (z,): the good episodes' θ (g, p) and the box's
        (low (p,), high (p,)), in the unit box of θ; the whole unit box for ``trust_share=None``."""
        units, nearest = self._observed_units(context)
        return trust_region(units, self.returns, nearest, self.config.trust_share)

    def context_utility(self, candidates: Any, targets: Any, pending: Any = None) -> Array:
        """What one more episode at each candidate context (m, z) would teach the GP about the optimal θ
        at the ``targets`` (r, z), after the batch's ``pending`` contexts (k, z): Eq. (C1) of
        :mod:`~creps_gym.optimizers.context_value`, shape (m,), in [0, 1]; zeros before the GP exists.
        The protocol's optional model hook (the ``active`` selector's); draws nothing from the Generator."""
        candidates = self._check_contexts(candidates, "candidates")
        targets = self._check_contexts(targets, "targets")
        rows = None if pending is None or not len(pending) else self._check_contexts(pending, "pending")
        if self.model is None:
            return np.zeros(candidates.shape[0])
        thetas = utility_thetas(np.clip(self._scaled_params(self.params), 0.0, 1.0), self.returns)
        scaled = [None if c is None else self._scaled_contexts(c) for c in (candidates, targets, rows)]
        return context_information(self.model, scaled[0], scaled[1], thetas, scaled[2])

    def distillation_contexts(self) -> Array:
        """The grid :meth:`mean_policy` fits on: ``grid_points`` per dimension over the configured context
        box, else over the told contexts' range, shape (g, z) (beyond 10,000 grid points, 1,000 uniform
        contexts from a fixed seed)."""
        config = self.config
        z, box, points = self.n_context_dims, config.context_box, config.grid_points
        return distillation_contexts(z, box, self.contexts, points, MAX_COUNTS["grid"])

    def mean_policy(self) -> Policy:
        """``recommend`` distilled into a :class:`Policy` with the ``mean_features`` map: the least-squares
        fit of the maximisers on :meth:`distillation_contexts`. Its error on the grid goes into
        ``diagnostics``: ``distillation_rmse`` (root mean square over the grid and the parameters) and
        ``distillation_max_error``, in parameter units."""
        grid = self.distillation_contexts()
        coefficients, error = least_squares_distillation(self.config.mean_map(grid), self.recommend(grid))
        self._diagnostics.update(error)
        source = {"optimizer": self.kind, "iteration": self.iteration}
        return Policy(self.config.mean_map, coefficients, source=source)

    # -- checkpoints ---------------------------------------------------------------------------------------
    def _state(self) -> dict[str, Any]:
        state: dict[str, Any] = {"config": self.config.to_json(), **self.config.arrays()}
        data = GPData(
            self.contexts, self.params, self.returns, self.log_hyper, self.context_scale, self.fitted_at
        )
        state.update(rng=self.rng.bit_generator.state, **data.arrays())
        return state

    @classmethod
    def _from_state(cls, state: Mapping[str, Any]) -> ContextualBO:
        document = state["config"]
        if not isinstance(document, Mapping):
            raise TypeError(f"state['config']: expected a JSON object, got {type(document).__name__}")
        own = ("n_params", "n_context_dims", "has_param_box", "has_context_box")
        check_option_names(cls.config_class, {k: v for k, v in document.items() if k not in own})
        config = cls.config_class.from_state(state)
        optimizer = cls.__new__(cls)
        optimizer._init_from_config(config)
        optimizer.rng.bit_generator.state = state["rng"]
        optimizer._restore_data(state)
        return optimizer

    def _restore_data(self, state: Mapping[str, Any]) -> None:
        data = read_gp_data(state, self.n_params, self.n_context_dims, self.config.scaling_box)
        self.contexts, self.params, self.returns = data.contexts, data.params, data.returns
        self.log_hyper, self.context_scale, self.fitted_at = data.log_hyper, data.scale, data.fitted_at
        if self.returns.shape[0] >= 1 and self.fitted_at > 0:
            inputs = self._inputs(self.contexts, self.params)
            self._transform = self._chosen_transform(inputs, self.returns)
            self.model = fit_gp(inputs, self._targets(self.returns), self.log_hyper, self._trend)


ContextualBO.__signature__ = options_signature(CBOConfig)  # type: ignore[attr-defined]
ContextualBO.__doc__ = (ContextualBO.__doc__ or "") + options_doc(CBOConfig)
