"""Adapter for optuna's samplers (``pip install creps-gym[adapters]``); imported on the first ask."""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from creps_gym.optimizers.adapters.base import MinimizerAdapter, import_optional

__all__ = ["OptunaAdapter"]

Array = NDArray[np.float64]
_SAMPLERS = ("tpe", "random")


class OptunaAdapter(MinimizerAdapter):
    """An optuna study (ask-and-tell interface) behind the ask/tell protocol (contexts are ignored).

    Optuna needs bounds: each normalised coordinate is searched in ``[-bound_stds, bound_stds]``, i.e.
    ``initial_mean ± bound_stds * initial_std``. The runner's default initial distribution is the one the
    env declares: for an env with the box rule (centre of the action box, standard deviation a quarter of
    its width) and ``bound_stds=2`` the bounds are the action box; for an env that declares its own start
    (the kick: its reference kick with a small σ) they are that start ± 2σ.
    The recommendation is the best trial so far. Creating the study sets optuna's logging verbosity to
    WARNING (optuna otherwise logs every trial).

    Parameters
    ----------
    n_params, n_context_dims, initial_mean, initial_cov, seed
        See :class:`~creps_gym.optimizers.adapters.base.MinimizerAdapter`.
    sampler : {"tpe", "random"}
        ``optuna.samplers.TPESampler`` (default) or ``RandomSampler``, seeded with ``seed``.
    bound_stds : float
        Half-width of the search box in initial standard deviations (default 2).
    """

    kind: ClassVar[str] = "optuna"

    def _check_options(self, options: dict[str, Any]) -> dict[str, Any]:
        unknown = set(options) - {"sampler", "bound_stds"}
        if unknown:
            raise TypeError(f"options: expected only 'sampler' and 'bound_stds', got {sorted(unknown)}")
        sampler = options.get("sampler", "tpe")
        if sampler not in _SAMPLERS:
            raise ValueError(f"sampler: expected one of {list(_SAMPLERS)}, got {sampler!r}")
        bound = options.get("bound_stds", 2.0)
        if isinstance(bound, bool) or not isinstance(bound, (int, float)) or not 0 < bound < np.inf:
            raise ValueError(f"bound_stds: expected a positive finite number, got {bound!r}")
        return {"sampler": sampler, "bound_stds": float(bound)}

    def _create(self, batch_size: int) -> Any:
        optuna = import_optional("optuna")
        optuna.logging.set_verbosity(optuna.logging.WARNING)
        samplers = {"tpe": optuna.samplers.TPESampler, "random": optuna.samplers.RandomSampler}
        sampler = samplers[self.options["sampler"]](seed=self.seed)
        self._trials: list[Any] = []
        return optuna.create_study(direction="minimize", sampler=sampler)

    def _lib_ask(self, n: int) -> Array:
        bound = self.options["bound_stds"]
        self._trials = [self._lib.ask() for _ in range(n)]
        rows = [[t.suggest_float(f"y{j}", -bound, bound) for j in range(self.n_params)] for t in self._trials]
        return np.array(rows, dtype=np.float64)

    def _lib_tell(self, indices: NDArray[np.int64], losses: Array) -> None:
        for index, loss in zip(indices, losses, strict=True):
            self._lib.tell(self._trials[index], float(loss))

    def _lib_recommend(self) -> Array:
        completed = [t for t in self._lib.trials if t.value is not None]
        if not completed:
            return np.zeros(self.n_params)
        best = self._lib.best_trial.params
        return np.array([best[f"y{j}"] for j in range(self.n_params)], dtype=np.float64)
