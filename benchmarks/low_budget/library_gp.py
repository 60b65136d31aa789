"""c-bo on another library's GP: what the study's BoTorch and scikit-learn columns share (issue 44, item 1).

Issue 44 asks for a GP "from a well-kept library: scikit-learn's GaussianProcessRegressor or BoTorch. Measure
both on this issue's study and choose". ``creps_gym``'s ``c-bo`` keeps its own GP (the optimisers import only
numpy and scipy), so the study measures the other side of that choice with two columns, ``c-bo-botorch``
(:mod:`benchmarks.low_budget.botorch_cbo`) and ``c-bo-sklearn`` (:mod:`benchmarks.low_budget.sklearn_cbo`):
the same contextual BO with the library's model in place of c-bo's own. ``gp_backends.py`` times the pieces
(a fit, a prediction, a value and gradient) of all three.

:class:`LibraryGPCBO` keeps everything of :class:`~creps_gym.optimizers.cbo.ContextualBO` that is not the
model: the data, the scaling of s and θ to the unit box, the initial design, the returns' transform, the
refit schedule (``refit_growth``, ``fit_points``, ``fit_subset``), the kriging believer within a batch, the
recommendation rules, the distilled policy and the checkpoints' data. A subclass says how the library fits
the hyperparameters (:meth:`LibraryGPCBO._fit`, on the episodes of
:func:`~creps_gym.optimizers.gp_model.fit_subset`, at c-bo's refits), how it builds the model on every
episode with them (:meth:`LibraryGPCBO._model`, at every tell: a tell between refits costs no fit) and how
its hyperparameters read in c-bo's layout
(:meth:`LibraryGPCBO._log_hyper`). A checkpoint stores the library's raw hyperparameters by name
(``hyper_names``, ``hyper``); the model is rebuilt from them on restore.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from creps_gym.optimizers.cbo import ContextualBO
from creps_gym.optimizers.cbo_config import CBOConfig
from creps_gym.optimizers.cbo_state import check_kernel_memory, read_gp_data
from creps_gym.optimizers.gp_model import fit_subset, hyper_bounds

__all__ = ["FIXED_OPTIONS", "SEEDS", "LibraryGPCBO", "LibraryGPConfig"]

Array = NDArray[np.float64]
SEEDS = 2**31 - 1  #: the seeds a library's call draws from the optimiser's Generator are below this
#: The options of c-bo's own GP that a library's model has no use for, with the values they must keep.
FIXED_OPTIONS: Mapping[str, Any] = MappingProxyType(
    {"prior_mean": "min", "trend": "constant", "hyper_restarts": 1}
)


@dataclass(frozen=True, eq=False)
class LibraryGPConfig(CBOConfig):
    """:class:`~creps_gym.optimizers.cbo_config.CBOConfig` for c-bo on a library's GP: ``prior_mean``,
    ``trend`` and ``hyper_restarts`` must keep their defaults (:data:`FIXED_OPTIONS`)."""

    #: The column and the library, for the error messages.
    column: ClassVar[str] = "c-bo on a library's GP"
    library: ClassVar[str] = "the library"

    def __post_init__(self) -> None:
        super().__post_init__()
        for name, default in FIXED_OPTIONS.items():
            if getattr(self, name) != default:
                raise ValueError(
                    f"{name}: expected {default!r} (an option of c-bo's own GP; {self.column} uses "
                    f"{self.library}'s model), got {getattr(self, name)!r}"
                )


class LibraryGPCBO(ContextualBO):
    """c-bo with a library's model (see the module docstring); subclasses give ``_fit``, ``_model`` and
    ``_log_hyper``."""

    #: The active selector's hook needs c-bo's own GP (its posterior covariances); none is offered.
    context_utility = None  # type: ignore[assignment]

    def _init_from_config(self, config: CBOConfig) -> None:
        super()._init_from_config(config)
        self.hyper_names: list[str] = []
        self.hyper = np.zeros(0)

    # -- what a library gives ------------------------------------------------------------------------------
    def _fit(self, inputs: Array, targets: Array, seed: int) -> tuple[list[str], Array]:
        """The library's fit on (inputs (n, d), targets (n,)): its raw hyperparameters' names and values."""
        raise NotImplementedError

    def _model(self, inputs: Array, targets: Array, names: list[str], hyper: Array) -> Any:
        """The library's model on every episode with the kept hyperparameters (no fit); ``ValueError``
        naming ``hyper_names`` when they are not the model's. It has c-bo's model calls: ``predict``,
        ``predict_with_gradient`` where c-bo's own optimiser maximises on it, ``condition`` and ``beta``."""
        raise NotImplementedError

    def _log_hyper(self, model: Any) -> Array:
        """c-bo's layout of the model's hyperparameters, for its diagnostics and ``stop``: log
        lengthscales (d,), log signal variance and log noise variance."""
        raise NotImplementedError

    # -- tell ----------------------------------------------------------------------------------------------
    def _update(self, contexts: Array, params: Array, returns: Array) -> None:
        all_contexts = np.vstack([self.contexts, contexts])
        all_params, all_returns = np.vstack([self.params, params]), np.concatenate([self.returns, returns])
        n = all_returns.shape[0]
        check_kernel_memory(n, self.n_params, self.n_context_dims, "returns")
        refit = self.fitted_at == 0 or n >= self.fitted_at * self.config.refit_growth
        names, hyper, scale, fitted_at = self.hyper_names, self.hyper, self.context_scale, self.fitted_at
        rng_state = self.rng.bit_generator.state
        try:
            if refit:
                scale = self._fit_scale(all_contexts)
            inputs = self._inputs(all_contexts, all_params, scale)
            transform = self._chosen_transform(inputs, all_returns)
            targets = self._targets(all_returns, None, transform)
            if refit:
                seen = fit_subset(n, self.config.fit_points, self.config.fit_subset)
                seed = int(self.rng.integers(SEEDS))
                names, hyper = self._fit(inputs[seen], targets[seen], seed)
                fitted_at = n
            model = self._model(inputs, targets, names, hyper)
        except BaseException:
            self.rng.bit_generator.state = rng_state  # a failed tell changes nothing
            raise
        self.contexts, self.params, self.returns = all_contexts, all_params, all_returns
        self.hyper_names, self.hyper, self.context_scale, self.fitted_at = names, hyper, scale, fitted_at
        self.model, self._transform = model, transform
        self.log_hyper = self._log_hyper(model)
        self._diagnostics = self._model_diagnostics(refit)

    # -- checkpoints ---------------------------------------------------------------------------------------
    def _state(self) -> dict[str, Any]:
        """c-bo's state, and the library's raw hyperparameters by name. ``log_hyper`` is derived from those
        (:meth:`_log_hyper`, recomputed on restore); it is stored within the box of c-bo's own GP
        (``hyper_bounds``), which c-bo's checkpoint reader checks and a library's fit may leave."""
        low, high = np.array(hyper_bounds(self.n_params + self.n_context_dims)).T
        state = {**super()._state(), "hyper_names": list(self.hyper_names), "hyper": self.hyper.copy()}
        return {**state, "log_hyper": np.clip(self.log_hyper, low, high)}

    def _restore_data(self, state: Mapping[str, Any]) -> None:
        data = read_gp_data(state, self.n_params, self.n_context_dims, self.config.scaling_box)
        names, hyper = state["hyper_names"], np.asarray(state["hyper"])
        if not isinstance(names, list) or not all(isinstance(name, str) for name in names):
            raise TypeError(f"state['hyper_names']: expected a list of strings, got {names!r}")
        if hyper.dtype != np.float64 or hyper.ndim != 1 or not np.isfinite(hyper).all():
            raise ValueError(
                f"state['hyper']: expected a finite float64 vector, got {hyper.dtype} of shape {hyper.shape}"
            )
        self.contexts, self.params, self.returns = data.contexts, data.params, data.returns
        self.log_hyper, self.context_scale, self.fitted_at = data.log_hyper, data.scale, data.fitted_at
        self.hyper_names, self.hyper = names, hyper
        if self.returns.shape[0] >= 1 and self.fitted_at > 0:
            inputs = self._inputs(self.contexts, self.params)
            self._transform = self._chosen_transform(inputs, self.returns)
            self.model = self._model(inputs, self._targets(self.returns), names, hyper)
            self.log_hyper = self._log_hyper(self.model)
