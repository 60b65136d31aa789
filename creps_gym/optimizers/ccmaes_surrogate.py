"""Surrogate-assisted contextual CMA-ES (``c-cma-es-surrogate``): C-CMA-ES alternating true generations with
generations scored by a model of the return, as ACM-ES alternates them, while the model ranks well.

References: I. Loshchilov, M. Schoenauer, M. Sebag, "Self-adaptive surrogate-assisted covariance matrix
adaptation evolution strategy", GECCO 2012 (ACM-ES: the alternation and the error-driven number of model
generations); N. Hansen, "A global surrogate assisted CMA-ES", GECCO 2019, arXiv:1908.01578 (lq-CMA-ES: the
linear-quadratic model and Kendall τ as its test); A. Fabisch, "Empirical evaluation of contextual policy
search with a comparison-based surrogate model and active covariance matrix adaptation", GECCO 2019,
arXiv:1810.11491 (C-ACM-ES). The equations (S1)–(S6) are in ``docs/algorithms.md``.

Every ``tell`` is a true generation: the plain C-CMA-ES update (C1)–(C9) on the told returns. Then:

1. The model fitted before this batch predicts it; Kendall's τ between its predicted and the true advantages,
   both minus the baseline V(s) that C-CMA-ES fits on the batch (S4), measures how well it ranks θ at s.
2. The batch joins the archive of the most recent true episodes (S1), bounded.
3. τ sets n̂, the number of model generations that follow (S5): 0 when τ is below ``min_tau`` (the step is then
   exactly plain ``c-cma-es``), more as τ nears 1.
4. The model is refitted on the archive (S1)–(S3) and n̂ model generations run (S6): contexts drawn from the
   archive, θ from the policy, scored by the model, and the same C-CMA-ES update. They spend no episode: the
   counters of episodes (``evaluations``, ``true_episodes``) and the stop criteria's histories see only true
   returns.
5. The true batch after model generations checks them (S7): if its median return is below the smallest return
   of the true batch before them, the model led the search where most samples are worse (τ ranks θ within a
   batch, so it cannot see a model that extrapolates); the distribution and paths go back to where the model
   generations started, the batch updates nothing but the archive and the model, n̂ starts again at 0, and
   the most model generations per true one (the cap) halves. A true batch after model generations whose
   median is at least the one before them doubles the cap again (+1, up to ``max_model_generations``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar, cast

import numpy as np
from numpy.typing import NDArray

from creps_gym._validation import as_float_array, check_count, check_positive_int, check_real_in_range
from creps_gym.optimizers.ccmaes import CCMAES
from creps_gym.optimizers.ccmaes_config import CCMAESConfig, options_doc, options_signature
from creps_gym.optimizers.cma_rules import inverse_sqrt, median
from creps_gym.optimizers.policies import LinearGaussianPolicy
from creps_gym.optimizers.surrogate_model import (
    KINDS,
    SurrogateModel,
    choose_kind,
    fit_model,
    kendall_tau,
    model_coefficients,
    richest_kind,
)

__all__ = ["CCMAESSurrogate", "SurrogateConfig", "next_model_generations"]

Array = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class SurrogateConfig(CCMAESConfig):
    """Configuration of :class:`CCMAESSurrogate`: every option of ``c-cma-es`` (:class:`CCMAESConfig`) and
    those of the surrogate below; validates itself on construction.

    Parameters
    ----------
    max_model_generations : int     the most model generations after one true generation (S5); 0 turns the
        surrogate off (plain ``c-cma-es``).
    min_tau : float                 Kendall τ in [−1, 1) below which no model generation runs (S5).
    archive_factor : float          the archive keeps the most recent ⌈factor·m⌉ true episodes, m the
        coefficient count of the richest model (S1), the full quadratic's 1 + d + d(d + 1)/2 with d = p + z
        up to ``MAX_COEFFICIENTS`` = 600 coefficients; at least 1.
    model_margin : float            the model is the richest of linear, diagonal and full quadratic whose
        coefficients times ``model_margin`` are at most the archived episodes (S2); at least 1.
    (and every option of ``c-cma-es``: see :class:`~creps_gym.optimizers.ccmaes_config.CCMAESConfig`)
    """

    max_model_generations: int = 10
    min_tau: float = 0.5
    archive_factor: float = 2.0
    model_margin: float = 1.2

    def __post_init__(self) -> None:
        super().__post_init__()
        generations = check_positive_int(self.max_model_generations, "max_model_generations", minimum=0)
        object.__setattr__(self, "max_model_generations", generations)
        bounds = {"low_inclusive": True, "high_inclusive": False}  # τ = 1 would never run a model generation
        object.__setattr__(self, "min_tau", check_real_in_range(self.min_tau, "min_tau", -1.0, 1.0, **bounds))
        for name in ("archive_factor", "model_margin"):
            value = check_real_in_range(getattr(self, name), name, 1.0, 1e6, low_inclusive=True)
            object.__setattr__(self, name, value)

    @property
    def archive_size(self) -> int:
        """The archive's bound ⌈archive_factor·m⌉, m the richest usable model's coefficient count (S1)."""
        p, z = self.n_params, self.n_context_dims
        return math.ceil(self.archive_factor * model_coefficients(richest_kind(p, z), p, z))


def next_model_generations(tau: float | None, previous: int, most: int, min_tau: float) -> int:
    """n̂ after a true generation whose fresh-batch τ is ``tau`` (None: no model yet), Eq. (S5).

    0 below ``min_tau``; else the target ⌊most·(τ − τ_min)/(1 − τ_min) + ½⌋, reached by at most doubling
    n̂ + 1 per true generation.
    """
    if tau is None or tau < min_tau:
        return 0
    target = math.floor(most * (tau - min_tau) / (1.0 - min_tau) + 0.5)
    return int(min(target, 2 * previous + 1))  # Eq. (S5)


@dataclass(frozen=True)
class _Rollback:
    """The distribution and paths where model generations started, and the true batch before them: its
    smallest return (the floor) and its median (S7)."""

    policy: LinearGaussianPolicy
    path_sigma: Array
    path_cov: Array
    floor: float
    median: float

    @classmethod
    def of(cls, optimizer: CCMAES, returns: Array) -> _Rollback:
        """The optimiser's distribution and paths now, and the smallest and median of ``returns``."""
        paths = (optimizer.path_sigma.copy(), optimizer.path_cov.copy())
        return cls(optimizer.policy.copy(), *paths, float(returns.min()), median(returns))


class CCMAESSurrogate(CCMAES):
    """Contextual CMA-ES with a linear-quadratic surrogate of the return over (s, θ) (S1)–(S6).

    ``CCMAESSurrogate(n_params, n_context_dims, **options)``; the update of every generation is
    :class:`~creps_gym.optimizers.ccmaes.CCMAES`'s. Diagnostics add ``true_episodes`` (episodes told so far,
    model generations never count), ``model_generations`` (run after this tell), ``model_generations_total``,
    ``kendall_tau`` (of the model on this fresh batch; absent until a model has predicted one), and
    ``model_kind`` (0 none, 1 linear, 2 diagonal, 3 full quadratic: the model fitted after this tell).
    """

    kind: ClassVar[str] = "c-cma-es-surrogate"
    config_class: ClassVar[type[CCMAESConfig]] = SurrogateConfig
    config: SurrogateConfig

    def __init__(self, n_params: int, n_context_dims: int, **options: Any) -> None:
        super().__init__(n_params, n_context_dims, **options)

    def _init_from_config(self, config: CCMAESConfig) -> None:
        super()._init_from_config(config)
        z, p = config.n_context_dims, config.n_params
        self.archive: tuple[Array, Array, Array] = (np.empty((0, z)), np.empty((0, p)), np.empty(0))
        self.model: SurrogateModel | None = None
        self.planned_generations = 0  # n̂
        self.model_generations_total = 0
        self.model_rejections = 0  # S7: model generations undone

    def _reset_search(self) -> None:
        super()._reset_search()
        self.rollback: _Rollback | None = None  # S7: the distribution before the last model generations
        self.model_cap = self.config.max_model_generations  # S7: halved by a rejection, reset at a restart

    def _update(self, contexts: Array, params: Array, returns: Array) -> None:
        if self._model_made_worse(returns):  # Eq. (S7): undo the model generations, keep the batch's data
            self._reject_model_generations(contexts, params, returns)
            return
        if self.rollback is not None and median(returns) >= self.rollback.median:  # Eq. (S7)
            self.model_cap = min(self.config.max_model_generations, 2 * self.model_cap + 1)  # they helped
        tau = self._fresh_tau(contexts, params, returns)  # before the update: its V is the one C1 fits
        super()._update(contexts, params, returns)  # the true generation; raises with the state unchanged
        true_diagnostics = dict(self._diagnostics)
        self._archive(contexts, params, returns)
        config = self.config
        self.planned_generations = next_model_generations(
            tau, self.planned_generations, self.model_cap, config.min_tau
        )  # Eq. (S5), at most the cap of Eq. (S7)
        self.model = self._fit()
        before, restarts = _Rollback.of(self, returns), self.restarts_done
        ran = self._model_generations(self.planned_generations, contexts.shape[0])
        self.rollback = before if ran and self.restarts_done == restarts else None  # for Eq. (S7)
        self.model_generations_total += ran
        diagnostics = dict(self._diagnostics) if ran else true_diagnostics
        for key in ("mean_return", "baseline_r2"):  # the true batch's, not a model generation's
            diagnostics[key] = true_diagnostics[key]
        diagnostics.update(
            true_episodes=float(self.evaluations + contexts.shape[0]),
            model_generations=float(ran),
            model_generations_total=float(self.model_generations_total),
            model_kind=float(KINDS.index(self.model.kind) if self.model is not None else 0),
            planned_generations=float(self.planned_generations),
        )
        if tau is not None:
            diagnostics["kendall_tau"] = tau
        diagnostics["model_rejections"] = float(self.model_rejections)
        self._diagnostics = diagnostics

    def _archive(self, contexts: Array, params: Array, returns: Array) -> None:
        """Append a true batch to the archive, keeping its most recent ``archive_size`` episodes (S1)."""
        keep = self.config.archive_size
        self.archive = tuple(  # type: ignore[assignment]
            np.concatenate([old, new])[-keep:]
            for old, new in zip(self.archive, (contexts, params, returns), strict=True)
        )  # Eq. (S1)

    def _model_made_worse(self, returns: Array) -> bool:
        """Eq. (S7): model generations ran before this true batch, and its median return is below the
        smallest return of the true batch before them."""
        return self.rollback is not None and median(returns) < self.rollback.floor

    def _reject_model_generations(self, contexts: Array, params: Array, returns: Array) -> None:
        """Eq. (S7): the distribution and paths of before the model generations, the batch in the archive and
        the model refitted on it; n̂ = 0, so the next true generation is plain C-CMA-ES."""
        rollback = cast(_Rollback, self.rollback)
        self.policy = rollback.policy.copy()
        self.path_sigma, self.path_cov = rollback.path_sigma.copy(), rollback.path_cov.copy()
        self.rollback, self.planned_generations = None, 0
        self.model_rejections += 1
        self.model_cap //= 2
        self._archive(contexts, params, returns)
        self.model = self._fit()
        for stale in ("cond_cov", "max_std", "search_scale"):  # they described the abandoned distribution
            self._diagnostics.pop(stale, None)
        self._diagnostics.update(
            step_size=self.step_size,
            true_episodes=float(self.evaluations + contexts.shape[0]),
            model_generations=0.0,
            planned_generations=0.0,
            model_rejections=float(self.model_rejections),
        )

    def _fresh_tau(self, contexts: Array, params: Array, returns: Array) -> float | None:
        """Kendall τ of the current model's advantages against the true ones on this batch (S4); None
        without a model or when its predictions are not finite. Changes nothing."""
        if self.model is None:
            return None
        with np.errstate(over="ignore", invalid="ignore"):
            predicted = self.model.predict(self.policy.mean_map, contexts, params)
        if not np.isfinite(predicted).all():
            return None
        advantages, _ = self._advantages(contexts, returns)
        baseline = returns - advantages  # V(s_k), Eq. (C1)
        return kendall_tau(predicted - baseline, advantages)  # Eq. (S4)

    def _fit(self) -> SurrogateModel | None:
        """The model of the archive in the current distribution's coordinates (S1)–(S3), or None."""
        config = self.config
        kind = choose_kind(self.archive[2].size, config.n_params, config.n_context_dims, config.model_margin)
        if kind == "none" or config.max_model_generations == 0:
            return None
        policy = self.policy
        whitening = inverse_sqrt(policy.cov, self._eigen())
        with np.errstate(over="ignore", invalid="ignore"):
            fitted = fit_model(
                kind, policy.mean_map, policy.coefficients, policy.step_size, whitening, self.archive
            )
        return fitted

    def _model_generations(self, count: int, batch: int) -> int:
        """Run up to ``count`` model generations of ``batch`` samples (S6); returns how many ran.

        They stop early at a restart or when the model's scores or the update are not finite. The histories
        of the stop criteria are restored afterwards (only true returns enter them); the baseline (C1) reuses
        the model batches only, and after them the next true update fits V on its own batch.
        """
        if self.model is None or count == 0:
            return 0
        kept = (list(self.mean_returns), self.flat_iterations, self.past_contexts, self.past_returns)
        restarts, ran = self.restarts_done, 0
        empty = (np.empty((0, self.n_context_dims)), np.empty(0))
        self.past_contexts, self.past_returns = empty  # Eq. (S6): the baseline reuses model batches only
        archived = self.archive[0]
        for _ in range(count):
            contexts = archived[self.rng.integers(0, archived.shape[0], batch)]  # Eq. (S6)
            params = self.policy.sample(contexts, self.rng)
            with np.errstate(over="ignore", invalid="ignore"):
                scores = self.model.predict(self.policy.mean_map, contexts, params)  # Eq. (S6)
                spread = scores.max() - scores.min()
            if not (np.isfinite(scores).all() and np.isfinite(spread)):
                break
            try:
                CCMAES._update(self, contexts, params, scores)  # Eq. (S6): the same update (C1)-(C9)
            except RuntimeError:  # non-finite or singular: the update left everything unchanged
                break
            ran += 1
            if self.restarts_done != restarts:
                return ran  # the restart reset the histories
        self.mean_returns, self.flat_iterations = kept[:2]
        # Eq. (S6): after model generations the next true update's V fits its own batch (the reused true
        # batches are from a distribution the model generations have left); without any, nothing changed.
        self.past_contexts, self.past_returns = empty if ran else kept[2:]
        return ran

    # -- checkpoints ---------------------------------------------------------------------------------------
    def _state(self) -> dict[str, Any]:
        state = super()._state()
        contexts, params, returns = self.archive
        state.update(
            archive_contexts=contexts.copy(),
            archive_params=params.copy(),
            archive_returns=returns.copy(),
            planned_generations=self.planned_generations,
            model_generations_total=self.model_generations_total,
            model_rejections=self.model_rejections,
            model_cap=self.model_cap,
        )
        if self.model is not None:
            state.update(self.model.state("model_"))
        if self.rollback is not None:  # Eq. (S7)
            rollback = self.rollback
            state.update({f"rollback_{key}": value for key, value in rollback.policy.state().items()})
            state.update(
                rollback_path_sigma=rollback.path_sigma.copy(),
                rollback_path_cov=rollback.path_cov.copy(),
                rollback_floor=np.asarray([rollback.floor]),
                rollback_median=np.asarray([rollback.median]),
            )
        return state

    @classmethod
    def _from_state(cls, state: Mapping[str, Any]) -> CCMAESSurrogate:
        optimizer = cast(CCMAESSurrogate, super()._from_state(state))
        config = optimizer.config
        p, z = config.n_params, config.n_context_dims
        contexts = as_float_array(state["archive_contexts"], "state['archive_contexts']", (None, z)).copy()
        n = contexts.shape[0]
        if n > config.archive_size:
            bound = config.archive_size
            raise ValueError(f"state['archive_contexts']: expected at most {bound} rows, got {n}")
        params = as_float_array(state["archive_params"], "state['archive_params']", (n, p)).copy()
        returns = as_float_array(state["archive_returns"], "state['archive_returns']", (n,)).copy()
        optimizer.archive = (contexts, params, returns)
        for name in ("planned_generations", "model_generations_total"):
            setattr(optimizer, name, check_count(state[name], f"state[{name!r}]"))
        rejections = state.get("model_rejections", 0)  # absent before S7
        optimizer.model_rejections = check_count(rejections, "state['model_rejections']")
        cap = check_positive_int(
            state.get("model_cap", config.max_model_generations), "state['model_cap']", 0
        )
        if cap > config.max_model_generations:
            most = config.max_model_generations
            raise ValueError(f"state['model_cap']: expected an integer <= {most}, got {cap}")
        optimizer.model_cap = cap
        if "rollback_coefficients" in state:  # Eq. (S7); absent before it, and when no model generation ran
            optimizer.rollback = _read_rollback(optimizer, state)
        if "model_kind" in state:
            n_features = config.mean_map.n_features
            optimizer.model = SurrogateModel.from_state(state, "model_", p, z, n_features)
        return optimizer


def _read_rollback(optimizer: CCMAESSurrogate, state: Mapping[str, Any]) -> _Rollback:
    """The rollback of Eq. (S7) from a checkpoint, checked like the running distribution (errors name the
    ``rollback_`` keys)."""
    config = optimizer.config
    entries = {key[len("rollback_") :]: state[key] for key in state if key.startswith("rollback_")}
    try:
        policy = LinearGaussianPolicy.from_state(config.mean_map, config.n_params, entries)
        path_sigma = as_float_array(entries["path_sigma"], "state['path_sigma']", optimizer.path_sigma.shape)
        path_cov = as_float_array(entries["path_cov"], "state['path_cov']", (config.n_params,))
        floor = as_float_array(entries["floor"], "state['floor']", (1,))
        median = as_float_array(entries["median"], "state['median']", (1,))
    except KeyError as exc:
        raise ValueError(f"state: expected the key 'rollback_{exc.args[0]}' of the rollback (S7)") from None
    except (TypeError, ValueError) as exc:
        raise type(exc)(str(exc).replace("state['", "state['rollback_")) from None
    return _Rollback(policy, path_sigma.copy(), path_cov.copy(), float(floor[0]), float(median[0]))


# help(CCMAESSurrogate) and inspect.signature show every option with its default, from the config.
CCMAESSurrogate.__doc__ = (CCMAESSurrogate.__doc__ or "") + options_doc(SurrogateConfig)
CCMAESSurrogate.__init__.__signature__ = options_signature(SurrogateConfig)  # type: ignore[attr-defined]
