"""The configuration of contextual CMA-ES (:class:`~creps_gym.optimizers.ccmaes.CCMAES`): a frozen dataclass
that validates every option on construction. The algorithm and its references are in
:mod:`creps_gym.optimizers.ccmaes`."""

from __future__ import annotations

import inspect
from collections.abc import Mapping
from dataclasses import MISSING, dataclass, field, fields
from types import MappingProxyType
from typing import Any

import numpy as np
from numpy.typing import NDArray

from creps_gym._validation import check_bool, check_positive_int, check_real_in_range, check_seed
from creps_gym.optimizers.cma_rules import CMAConstants, cma_constants, rank_weights
from creps_gym.optimizers.contextual import BASELINE_RIDGE_SCALES, LOSSES, check_local_baseline
from creps_gym.optimizers.features import FeatureMap, make_features
from creps_gym.optimizers.policies import initial_coefficients, initial_covariance, split_step_size

__all__ = [
    "FORMER_ABSENT",
    "OTHER_LOSS",
    "RESTART_LOSSES",
    "RIDGE_CENTRES",
    "SIGNALS",
    "UNUSED_BY_DETRENDED_BASELINE",
    "UNUSED_BY_LOCAL_BASELINE",
    "CCMAESConfig",
    "options_doc",
    "options_signature",
]

Array = NDArray[np.float64]
#: The options of C1's polynomial fit, which the local baseline (C1'') ignores: they must keep their defaults.
UNUSED_BY_LOCAL_BASELINE = (
    "standardise_advantages",
    "baseline_loss",
    "baseline_degree",
    "baseline_ridge",
    "baseline_ridge_scale",
)
#: Those of them that the detrended local baseline (C1d) ignores too (it uses the degree and the ridges).
UNUSED_BY_DETRENDED_BASELINE = ("standardise_advantages", "baseline_loss")
SIGNALS = ("coefficients", "mean")
#: What the mean fit's ridge shrinks towards: 0 (C3, the classic ridge) or the old coefficients (C3r).
RIDGE_CENTRES = ("zero", "old")
#: The values of options whose default changed after they were added, for a stored config written before
#: they existed (it has no such field, and ran with the value here): ``ridge_centre`` was C3 until issue 45.
FORMER_ABSENT: Mapping[str, Any] = MappingProxyType({"ridge_centre": "zero"})
#: ``restart_baseline_loss``'s default: after a restart, the loss of ``LOSSES`` the first search did not use.
OTHER_LOSS = "other"
RESTART_LOSSES = (None, *LOSSES, OTHER_LOSS)


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
    baseline_detrend : bool         with ``baseline_bandwidth`` > 0: V is the polynomial fit of C1
        (``baseline_degree``, ``baseline_ridge``, ``baseline_ridge_scale``) plus the local median of its
        residuals (C1d), which has no slope bias at the ends of the context range.
    ridge, baseline_ridge : float   relative ridges of the mean fit (C3) and of the baseline (C1).
    baseline_ridge_scale : str      ``"fixed"`` (C1) or ``"unexplained"`` (C1s: the baseline's ridge times the
        fraction of the returns' variance a first fit leaves unexplained, so its bias, ``baseline_ridge``
        times the context's effect on the returns, shrinks with the part θ decides).
    ridge_centre : str              what the mean fit's ridge shrinks towards: ``"old"`` (C3r, the default
        since issue 45: the step towards 0, i.e. the slopes towards the old ones, a bias of ``ridge`` times
        the step, which shrinks with σ) or ``"zero"`` (C3, the default before: the slopes towards 0, a bias
        of ``ridge`` times the slopes that does not shrink with σ and floors the regret on ill-conditioned
        functions). A stored config without the field (written before it existed) loads as ``"zero"``.
    c_sigma, d_sigma, c_c, c_1, c_mu : float or None   learning rates; None = the tutorial's defaults.
    c_m : float                     the mean's learning rate in (0, 1] (C3'): A ← A + c_m (A_fit − A);
        below 1 it averages the regression's noise over about (2 − c_m)/c_m batches.
    mean_repulsion : float          α in [0, 1] (C3''): A_fit also moves away from the negatively weighted
        samples by α times their fitted shift (needs ``active``; 0: CMA-ES's positive-weight mean).
    seed : int or None              seed of the sampling Generator.
    restarts : int                  restarts from the initial distribution when a stop criterion is met
        (``stop()`` reports criteria only once they are used up).
    keep_best : bool                at each restart, keep the ending search's mean policy if it scored best so
        far (score: the mean return of its last ``BEST_WINDOW`` batches); ``recommend`` gives it until the
        new search scores better, so a restart cannot make the recommendation worse (C10).
    restart_baseline_loss : str or None   the baseline's loss in every search after a restart (C11: a
        restart portfolio): ``"other"`` (the default) the loss of ``LOSSES`` that the first search did not use
        (Huber's after the squared fit, and the reverse), ``"squared"`` or ``"huber"`` that one, None
        ``baseline_loss``. The first search uses ``baseline_loss``, so a run that never restarts does not
        depend on it. The local baseline (C1'') has no loss: with ``baseline_bandwidth > 0`` only None and
        ``"other"`` are accepted, and both keep it.
    budget : int or None            the run's episode budget (true episodes told), or None (unknown: every
        stop criterion restarts while restarts are left). Given, a stop criterion restarts only while the
        episodes left can carry the new search as far as the ended one went (C12): B − E ≥ F · E_search,
        with F = ``restart_population_factor``; otherwise the converged search goes on sampling and
        ``stop()`` keeps reporting its criterion. The runner and the protocol set it to their budget.
    restart_population_factor : float   F ≥ 1 (C13, IPOP): after the r-th restart the optimiser wants
        batches of N₀ · F^r samples (``wanted_batch_size(N₀)``; the caller chooses the batch it asks for).
        1: the batch stays the caller's; IPOP-CMA-ES uses 2.
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
    baseline_detrend: bool = False
    restarts: int = 3
    keep_best: bool = True
    restart_baseline_loss: str | None = OTHER_LOSS
    budget: int | None = None
    restart_population_factor: float = 1.0
    step_size_signal: str = "mean"
    ridge: float = 1e-8
    baseline_ridge: float = 1e-10
    baseline_ridge_scale: str = "fixed"
    ridge_centre: str = "old"
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
        self._check_counts_and_flags()
        self._check_choices()
        self._check_reals()
        self._check_combinations()
        self._resolve_start()

    def _check_counts_and_flags(self) -> None:
        for name, minimum in (
            ("n_params", 1),
            ("n_context_dims", 0),
            ("tolflatfitness", 1),
            ("baseline_degree", 0),
            ("baseline_batches", 1),
            ("restarts", 0),
        ):
            object.__setattr__(self, name, check_positive_int(getattr(self, name), name, minimum))
        for name in ("tolstagnation", "budget"):  # None: the default rule / no known budget
            if getattr(self, name) is not None:
                object.__setattr__(self, name, check_positive_int(getattr(self, name), name))
        object.__setattr__(self, "active", check_bool(self.active, "active"))
        object.__setattr__(self, "keep_best", check_bool(self.keep_best, "keep_best"))
        standardise = check_bool(self.standardise_advantages, "standardise_advantages")
        object.__setattr__(self, "standardise_advantages", standardise)
        object.__setattr__(self, "baseline_detrend", check_bool(self.baseline_detrend, "baseline_detrend"))

    def _check_choices(self) -> None:
        if self.baseline_loss not in LOSSES:
            raise ValueError(f"baseline_loss: expected one of {LOSSES}, got {self.baseline_loss!r}")
        loss = self.restart_baseline_loss
        if not (loss is None or (isinstance(loss, str) and loss in RESTART_LOSSES)):
            raise ValueError(
                f"restart_baseline_loss: expected one of {RESTART_LOSSES}, got {self.restart_baseline_loss!r}"
            )
        for name, choices in (
            ("ridge_centre", RIDGE_CENTRES),
            ("baseline_ridge_scale", BASELINE_RIDGE_SCALES),
        ):
            value = getattr(self, name)
            if not isinstance(value, str):
                raise TypeError(f"{name}: expected one of {choices}, got {type(value).__name__}")
            if value not in choices:
                raise ValueError(f"{name}: expected one of {choices}, got {value!r}")
        if self.step_size_signal not in SIGNALS:
            raise ValueError(f"step_size_signal: expected one of {SIGNALS}, got {self.step_size_signal!r}")

    def _check_reals(self) -> None:
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
        factor = check_real_in_range(
            self.restart_population_factor, "restart_population_factor", 1.0, 100.0, low_inclusive=True
        )
        object.__setattr__(self, "restart_population_factor", factor)

    def _check_combinations(self) -> None:
        """The options that constrain each other (checked after each is valid on its own)."""
        if self.mean_repulsion > 0.0 and not self.active:  # it repels the negatively weighted samples
            raise ValueError(f"mean_repulsion: expected 0 with active=False, got {self.mean_repulsion}")
        defaults = {option.name: option.default for option in fields(self)}
        if self.baseline_detrend and self.baseline_bandwidth == 0.0:  # C1d detrends the local baseline
            raise ValueError("baseline_detrend: expected False with baseline_bandwidth = 0, got True")
        names = UNUSED_BY_DETRENDED_BASELINE if self.baseline_detrend else UNUSED_BY_LOCAL_BASELINE
        unused = {name: (getattr(self, name), defaults[name]) for name in names}
        check_local_baseline(self.baseline_bandwidth, unused)
        if self.baseline_bandwidth > 0.0 and self.restart_baseline_loss in LOSSES:  # C1'' has no loss
            got = self.restart_baseline_loss
            raise ValueError(
                f"restart_baseline_loss: expected None or {OTHER_LOSS!r} with baseline_bandwidth > 0, "
                f"got {got!r}"
            )
        if self.c_1 is not None and self.c_mu is not None and self.c_1 + self.c_mu > 1.0:
            raise ValueError(f"c_1, c_mu: expected c_1 + c_mu <= 1, got {self.c_1} + {self.c_mu}")

    def _resolve_start(self) -> None:
        """The seed, the mean features and the initial distribution (coefficients, σ and C)."""
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

    def restart_loss(self) -> str:
        """The baseline's loss in the searches after a restart (Eq. (C11))."""
        if self.restart_baseline_loss is None:
            return self.baseline_loss
        if self.restart_baseline_loss == OTHER_LOSS:
            return next(loss for loss in LOSSES if loss != self.baseline_loss)
        return str(self.restart_baseline_loss)

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


def options_signature(config_class: type = CCMAESConfig) -> inspect.Signature:
    """``(self, n_params, n_context_dims, *, option=default, ...)`` for every init field of ``config_class``:
    the signature ``help()`` and ``inspect.signature`` show for an optimiser that takes ``**options``."""
    self_ = inspect.Parameter("self", inspect.Parameter.POSITIONAL_OR_KEYWORD)
    parameters = [self_]
    for option in fields(config_class):
        if not option.init:
            continue
        positional = option.name in ("n_params", "n_context_dims")
        kind = inspect.Parameter.POSITIONAL_OR_KEYWORD if positional else inspect.Parameter.KEYWORD_ONLY
        default = inspect.Parameter.empty if option.default is MISSING else option.default
        parameters.append(inspect.Parameter(option.name, kind, default=default))
    return inspect.Signature(parameters, return_annotation=None)


def options_doc(config_class: type = CCMAESConfig) -> str:
    """The "Parameters" section of ``config_class``'s docstring, headed "Options", for the optimiser's own
    docstring (one source for the options' documentation)."""
    doc = inspect.cleandoc(config_class.__doc__ or "")
    _, _, parameters = doc.partition("Parameters\n----------\n")
    body = "\n".join(f"    {line}" if line else "" for line in parameters.splitlines())
    return f"\n    Options\n    -------\n{body}\n"
