"""The configuration of contextual Bayesian optimisation (:class:`~creps_gym.optimizers.cbo.ContextualBO`):
a frozen dataclass that validates every option on construction."""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np
from numpy.typing import NDArray

from creps_gym._validation import (
    as_float_array,
    check_positive_int,
    check_real_in_range,
    check_seed,
)
from creps_gym.optimizers.acquisitions import ACQUISITIONS, MES_FLOORS
from creps_gym.optimizers.cbo_recommend import RECOMMEND_RULES
from creps_gym.optimizers.features import AffineFeatures, FeatureMap, make_features
from creps_gym.optimizers.gp_model import FIT_SUBSETS
from creps_gym.optimizers.gp_trend import LOG_QUANTILE
from creps_gym.optimizers.policies import initial_covariance

__all__ = ["CBOConfig", "fold_box", "fold_contexts"]

Array = NDArray[np.float64]
#: Largest counts the options may set (each sizes arrays or loops of every ask, refit or distillation; a
#: checkpoint's config is untrusted input).
MAX_COUNTS = {
    "mes_samples": 10_000,
    "candidates": 100_000,
    "starts": 1_000,
    "hyper_restarts": 100,
    "fit_points": 10_000,
    "grid": 10_000,
}
TRANSFORMS = ("none", "log", "rank", "auto")
PRIOR_MEANS = ("min", "mean")
TRENDS = ("constant", "quadratic")
_BOX_ARRAYS = ("param_low", "param_high", "context_low", "context_high")
#: The options that name one of a few choices, and their choices.
_CHOICES = {
    "acquisition": ACQUISITIONS,
    "transform": TRANSFORMS,
    "prior_mean": PRIOR_MEANS,
    "trend": TRENDS,
    "fit_subset": FIT_SUBSETS,
    "recommend_over": RECOMMEND_RULES,
    "mes_floor": MES_FLOORS,
}


def _optional_box(low: Any, high: Any, names: tuple[str, str], size: int) -> tuple[Array, Array] | None:
    """Both bounds as finite arrays (size,) with low < high, or None when both are None."""
    if low is None and high is None:
        return None
    if low is None or high is None:
        raise ValueError(f"{names[0]}, {names[1]}: expected both or neither, got one of them")
    pair = []
    for value, name in zip((low, high), names, strict=True):
        array = as_float_array(value, name)
        pair.append(np.full(size, float(array)) if array.ndim == 0 else as_float_array(array, name, (size,)))
    if not (pair[0] < pair[1]).all():
        raise ValueError(
            f"{names[0]}, {names[1]}: expected low < high in every entry, got {pair[0]}, {pair[1]}"
        )
    return pair[0].copy(), pair[1].copy()


def _bounded_int(value: Any, name: str, minimum: int, maximum: int) -> int:
    """``value`` as an int in [minimum, maximum], else ``TypeError``/``ValueError`` naming ``name``."""
    number = check_positive_int(value, name, minimum)
    if number > maximum:
        raise ValueError(f"{name}: expected an integer of at most {maximum}, got {number}")
    return number


def fold_contexts(contexts: Array, dims: tuple[int, ...]) -> Array:
    """The contexts (n, z) with the dimensions ``dims`` (indices in [0, z), as :class:`CBOConfig` validates
    them) replaced by their absolute values: the GP's contexts under ``symmetric_contexts`` (a copy; the
    contexts themselves when ``dims`` is empty)."""
    if not dims:
        return contexts
    folded = np.array(contexts, dtype=np.float64)
    folded[:, list(dims)] = np.abs(folded[:, list(dims)])
    return folded


def fold_box(low: Array, high: Array, dims: tuple[int, ...]) -> tuple[Array, Array]:
    """The box (low (z,), high (z,)) that :func:`fold_contexts` maps [low, high] onto: in a folded dimension
    [0, max(|low|, |high|)] when the box holds 0, else [min(|low|, |high|), max(|low|, |high|)]."""
    low, high = low.copy(), high.copy()
    for i in dims:
        ends = sorted((abs(low[i]), abs(high[i])))
        low[i], high[i] = (0.0 if low[i] < 0.0 < high[i] else ends[0]), ends[1]
    return low, high


def _context_dims(value: Any, z: int) -> tuple[int, ...]:
    """``symmetric_contexts`` (a list, tuple, range or 1-D integer array) as a sorted tuple of distinct
    integers in [0, z)."""
    if isinstance(value, np.ndarray) and value.ndim == 1 and value.dtype.kind in "iu":
        value = value.tolist()
    if not isinstance(value, (list, tuple, range)):
        raise TypeError(
            f"symmetric_contexts: expected a list, tuple or range of integers, got {type(value).__name__}"
        )
    dims: list[int] = []
    for item in value:
        if isinstance(item, bool) or not isinstance(item, (int, np.integer)):
            raise TypeError(f"symmetric_contexts: expected integers, got {item!r}")
        if not 0 <= int(item) < z:
            raise ValueError(f"symmetric_contexts: expected context dimensions in [0, {z}), got {int(item)}")
        if int(item) in dims:
            raise ValueError(f"symmetric_contexts: expected distinct dimensions, got {int(item)} twice")
        dims.append(int(item))
    return tuple(sorted(dims))


@dataclass(frozen=True, eq=False)
class CBOConfig:
    """Configuration of :class:`ContextualBO`; validates itself on construction.

    Parameters
    ----------
    n_params : int                  p, the dimension of θ.
    n_context_dims : int            z, the dimension of s (0: plain Bayesian optimisation).
    initial_mean : scalar or (p,)   centre of the initial design and of the default parameter box.
    initial_cov : scalar, (p,) or (p, p)   covariance of the initial design (draws clipped to the box); its
        standard deviations set the default parameter box.
    param_low, param_high : scalar, (p,) or None   the box θ is searched in; None: initial_mean ± 3
        standard deviations of ``initial_cov``.
    context_low, context_high : scalar, (z,) or None   the context box: the GP's context scaling and the grid
        of :meth:`ContextualBO.mean_policy`; None: the range of the told contexts at the last refit.
    acquisition : str               ``"mes"`` (max-value entropy search, A2) or ``"ucb"`` (A1).
    beta : float                    UCB's β: α = μ + √β σ.
    transform : str                 the returns' transform before the GP, order-preserving: ``"log"``
        (−log(1 + (R_max − R)/c), c a low quantile of the gaps to the best return, ``log_quantile``; it
        compresses long tails of bad returns), ``"none"`` or ``"rank"`` (the Gaussian copula of the
        ranks); see :func:`~creps_gym.optimizers.gp_model.transformed_returns`; ``"auto"``: ``"none"`` or
        ``"log"`` at every tell, whichever the prior mean (see ``trend``) fits with the larger profile
        likelihood, Eq. (G5) of :mod:`~creps_gym.optimizers.gp_trend`.
    log_quantile : float            q in (0, 1] of the log transform's scale c, the q-quantile of the gaps
        R_max − R over the told returns (Eq. G6 of :mod:`~creps_gym.optimizers.gp_trend`): the GP resolves
        the returns within about c of the best and compresses the rest. Before 2026-11-30 the median (0.5),
        which on a run whose early asks are far worse than its best sets c by the bad ones: a checkpoint
        that does not name it resumes with 0.5. Default 0.25.
    prior_mean : str                the GP's constant prior mean: the smallest transformed return seen
        (``"min"``, pessimistic: unexplored θ are not recommended for their prior) or their mean (``"mean"``).
    trend : str                     ``"constant"`` (that prior mean alone) or ``"quadratic"``: a quadratic in
        (s, θ) fitted by least squares is the prior mean and the GP models its residuals, Eq. (G4) of
        :mod:`~creps_gym.optimizers.gp_trend` (from 2q episodes on, q its coefficients; ``prior_mean`` then
        only matters before).
    mes_samples : int               K, the sampled maximum values of MES (A3).
    initial_samples : int or None   episodes drawn from the initial distribution before the GP is used;
        None: max(4, 2(p + z)).
    candidates : int                random θ scored at each asked context (the observed θ are scored too).
    starts : int                    L-BFGS-B runs from the best candidates.
    mes_floor : str                 the floor of MES's sampled maxima (Eq. A4 of
        :mod:`~creps_gym.optimizers.acquisitions`): ``"observed"``, the candidates' largest posterior mean
        and five noise standard deviations above the posterior mean at every input the model holds at the
        asked context (told episodes there, and a batch's earlier rows: episodes asked at one context then
        spread out), or ``"candidates"``, the first alone, under which a batch at one context collapses
        onto its first row. The two differ only at a context the model already holds an input at.
        ``"candidates"`` before 2026-11-30, as a checkpoint that does not name it resumes. Default
        ``"observed"``.
    trust_share : float or None     q of ``recommend``'s trust region (Eq. R1 of
        :mod:`~creps_gym.optimizers.cbo`): the posterior mean is maximised over the box spanned by the θ of
        the best share q of the ``candidates // 4`` episodes with the nearest contexts; None: over the
        whole parameter box (the posterior mean may then extrapolate to a face of it, far from the data).
        Smaller: closer to the best episodes; larger: reaches optima that move with s past the neighbours.
    recommend_over : str            ``"trust_region"``: ``recommend`` maximises the posterior mean over that
        trust region (Eq. R1 of :mod:`~creps_gym.optimizers.cbo_recommend`); ``"observed"``: it returns the
        told θ with the largest posterior mean at s (Eq. R2), never a θ no episode tried (safer where some
        parameters fail badly, as a kick that falls; it cannot interpolate between the told θ);
        ``"neighbours"``: the same over the ``candidates // 4`` episodes with the nearest contexts (Eq. R3:
        a θ tried near s, not one the GP rates at s by extrapolating from a distant context).
    symmetric_contexts : sequence of int   the context dimensions i in which the return is even about 0,
        R(…, s_i, …; θ) = R(…, −s_i, …; θ) for every θ: the GP models the return over |s_i| (its scaling,
        neighbours and selector utilities too), so the episodes on both sides inform each other. Task
        knowledge the user gives, e.g. ``(1,)`` on a kick that the env mirrors for a ball on the other side
        (``creps_gym/KickFlexibility*``: y_B); on a task where it is false the model is wrong. The
        recommendations are then even in s_i, so ``mean_features`` must hold even functions: the affine
        map is refused with it (``"quadratic"`` does). Default (): none.
    refit_growth : float            the hyperparameters are refitted (maximum likelihood, G3) when the data
        have grown by this factor since the last fit (a geometric schedule); in between only the Cholesky
        factor is updated, so asks stay fast.
    hyper_restarts : int            random L-BFGS-B starts of a refit, besides the previous hyperparameters.
    fit_points : int                a refit maximises the likelihood of at most ``fit_points`` episodes: every
        episode up to that many; the GP itself conditions on every episode. A refit's cost grows as the cube
        of the episodes it sees: lower it where a long run's refits would keep a robot waiting.
    fit_subset : str                which ``fit_points`` episodes a refit sees beyond that
        (:func:`~creps_gym.optimizers.gp_model.fit_subset`): ``"spread"`` evenly over the whole history
        (Eq. G3a) or ``"recent"``, the most recent ones (for a task that drifts, a robot whose wear
        changes its returns; on a stationary task it fits the hyperparameters to where the search has
        converged). Before 2026-11-30 the defaults were 256 and ``"recent"``: a checkpoint that does not
        name ``fit_subset`` resumes with ``"recent"``.
    mean_features : str, dict or FeatureMap   ϕ(s) of :meth:`ContextualBO.mean_policy`'s distilled policy.
    distillation_points : int or None   contexts per dimension of the distillation grid; None:
        max(2, round(25^(1/z))).
    seed : int or None              seed of the Generator (initial design, candidates, MES samples, refits).
    """

    n_params: int
    n_context_dims: int
    initial_mean: Any = 0.0
    initial_cov: Any = 1.0
    param_low: Any = None
    param_high: Any = None
    context_low: Any = None
    context_high: Any = None
    acquisition: str = "mes"
    beta: float = 4.0
    transform: str = "log"
    log_quantile: float = LOG_QUANTILE
    prior_mean: str = "min"
    trend: str = "constant"
    mes_samples: int = 10
    mes_floor: str = "observed"
    initial_samples: int | None = None
    candidates: int = 256
    starts: int = 3
    trust_share: float | None = 1.0 / 3.0
    recommend_over: str = "trust_region"
    symmetric_contexts: Any = ()
    refit_growth: float = 1.2
    hyper_restarts: int = 1
    fit_points: int = 1024
    fit_subset: str = "spread"
    mean_features: Any = "affine"
    distillation_points: int | None = None
    seed: int | None = None
    mean_map: FeatureMap = field(init=False, repr=False)
    param_box: tuple[Array, Array] = field(init=False, repr=False)
    context_box: tuple[Array, Array] | None = field(init=False, repr=False)

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        set_(self, "n_params", check_positive_int(self.n_params, "n_params"))
        set_(self, "n_context_dims", check_positive_int(self.n_context_dims, "n_context_dims", minimum=0))
        p, z = self.n_params, self.n_context_dims
        for name, minimum in (
            ("mes_samples", 1),
            ("candidates", 1),
            ("starts", 1),
            ("hyper_restarts", 0),
            ("fit_points", 2),
        ):
            set_(self, name, _bounded_int(getattr(self, name), name, minimum, MAX_COUNTS[name]))
        if self.initial_samples is not None:
            set_(self, "initial_samples", check_positive_int(self.initial_samples, "initial_samples", 2))
        if self.distillation_points is not None:
            points = _bounded_int(self.distillation_points, "distillation_points", 2, MAX_COUNTS["grid"])
            if points ** max(z, 1) > MAX_COUNTS["grid"]:
                raise ValueError(
                    f"distillation_points: expected a grid of at most {MAX_COUNTS['grid']} contexts "
                    f"(points ** z), got {points} ** {z}"
                )
            set_(self, "distillation_points", points)
        for name, choices in _CHOICES.items():
            value = getattr(self, name)
            if not isinstance(value, str) or value not in choices:
                raise ValueError(f"{name}: expected one of {choices}, got {value!r}")
        set_(self, "beta", check_real_in_range(self.beta, "beta", 0.0, 1e6))
        set_(self, "log_quantile", check_real_in_range(self.log_quantile, "log_quantile", 0.0, 1.0))
        set_(self, "refit_growth", check_real_in_range(self.refit_growth, "refit_growth", 1.0, 1e6))
        if self.trust_share is not None:
            set_(self, "trust_share", check_real_in_range(self.trust_share, "trust_share", 0.0, 1.0))
        set_(self, "seed", check_seed(self.seed))
        set_(self, "symmetric_contexts", _context_dims(self.symmetric_contexts, z))
        mean = as_float_array(self.initial_mean, "initial_mean")
        if mean.ndim == 0:
            mean = np.full(p, float(mean))
        set_(self, "initial_mean", as_float_array(mean, "initial_mean", (p,)).copy())
        set_(self, "initial_cov", initial_covariance(self.initial_cov, p))
        box = _optional_box(self.param_low, self.param_high, ("param_low", "param_high"), p)
        if box is None:
            spread = 3.0 * np.sqrt(np.diag(self.initial_cov))
            box = (self.initial_mean - spread, self.initial_mean + spread)
            if not (np.isfinite(box[0]).all() and np.isfinite(box[1]).all() and (box[0] < box[1]).all()):
                raise ValueError(
                    "initial_cov: expected a box initial_mean ± 3 std that is finite and not empty"
                )
        set_(self, "param_box", box)
        set_(
            self,
            "context_box",
            _optional_box(self.context_low, self.context_high, ("context_low", "context_high"), z),
        )
        set_(self, "mean_map", make_features(self.mean_features, z, "mean_features"))
        if self.symmetric_contexts and isinstance(self.mean_map, AffineFeatures):
            raise ValueError(
                "mean_features: with symmetric_contexts the recommendations are even in those contexts, "
                "which an affine map cannot fit (the distilled policy would ignore them); expected a map "
                "that holds even functions, e.g. 'quadratic', got 'affine'"
            )

    @property
    def scaling_box(self) -> tuple[Array, Array] | None:
        """The configured context box as the GP sees it (:func:`fold_box` of ``symmetric_contexts``)."""
        box = self.context_box
        return None if box is None else fold_box(box[0], box[1], self.symmetric_contexts)

    @property
    def n_initial(self) -> int:
        """Episodes of the initial design (``initial_samples`` or its default)."""
        default = max(4, 2 * (self.n_params + self.n_context_dims))
        return self.initial_samples if self.initial_samples is not None else default

    @property
    def grid_points(self) -> int:
        """Contexts per dimension of the distillation grid."""
        if self.distillation_points is not None:
            return self.distillation_points
        return max(2, round(25 ** (1.0 / max(self.n_context_dims, 1))))

    def to_json(self) -> dict[str, Any]:
        """JSON-serialisable scalars and the feature spec (the arrays are saved separately, see
        :meth:`arrays`)."""
        skip = {"initial_mean", "initial_cov", "mean_features", *_BOX_ARRAYS}
        data = {f.name: getattr(self, f.name) for f in fields(self) if f.init and f.name not in skip}
        data["mean_features"] = self.mean_map.spec()
        data["has_param_box"] = self.param_low is not None
        data["has_context_box"] = self.context_box is not None
        return data

    def arrays(self) -> dict[str, Array]:
        """The array options: initial mean and covariance, and the boxes that were given."""
        arrays = {"initial_mean": self.initial_mean.copy(), "initial_cov": self.initial_cov.copy()}
        if self.param_low is not None:
            arrays["param_low"], arrays["param_high"] = (a.copy() for a in self.param_box)
        if self.context_box is not None:
            arrays["context_low"], arrays["context_high"] = (a.copy() for a in self.context_box)
        return arrays

    @classmethod
    def from_state(cls, state: Any) -> CBOConfig:
        """Rebuild the configuration from a checkpoint's ``config`` document and arrays."""
        document = dict(state["config"])
        document.setdefault("fit_subset", "recent")  # written before the options existed: their rules
        document.setdefault("log_quantile", 0.5)
        document.setdefault("mes_floor", "candidates")
        has_param, has_context = document.pop("has_param_box", False), document.pop("has_context_box", False)
        arrays = {
            "initial_mean": np.asarray(state["initial_mean"]),
            "initial_cov": np.asarray(state["initial_cov"]),
        }
        for flag, names in ((has_param, _BOX_ARRAYS[:2]), (has_context, _BOX_ARRAYS[2:])):
            if flag is True:
                arrays.update({name: np.asarray(state[name]) for name in names})
        return cls(**arrays, **document)
