"""Adapter for nevergrad's optimisers (``pip install creps-gym[adapters]``); imported on the first ask."""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from creps_gym.optimizers.adapters.base import MinimizerAdapter, import_optional

__all__ = ["NevergradAdapter"]

Array = NDArray[np.float64]


class NevergradAdapter(MinimizerAdapter):
    """A nevergrad optimiser behind the ask/tell protocol (contexts are ignored).

    The parametrisation is an unbounded ``ng.p.Array`` in normalised coordinates (initial value 0, mutation
    scale 1), seeded through its ``random_state`` (nevergrad requires a ``numpy.random.RandomState``; it
    is seeded with ``seed`` and private to this adapter). ``num_workers`` is the first ask's batch size.

    Parameters
    ----------
    n_params, n_context_dims, initial_mean, initial_cov, seed
        See :class:`~creps_gym.optimizers.adapters.base.MinimizerAdapter`.
    optimizer : str
        A name in ``nevergrad.optimizers.registry`` (default ``"TwoPointsDE"``). Portfolio optimisers such
        as ``"NGOpt"`` need ``budget``.
    budget : int or None
        Total number of evaluations announced to nevergrad (optional for most optimisers).
    """

    kind: ClassVar[str] = "nevergrad"

    def _check_options(self, options: dict[str, Any]) -> dict[str, Any]:
        unknown = set(options) - {"optimizer", "budget"}
        if unknown:
            raise TypeError(f"options: expected only 'optimizer' and 'budget', got {sorted(unknown)}")
        name = options.get("optimizer", "TwoPointsDE")
        registry = import_optional("nevergrad").optimizers.registry
        if name not in registry:
            raise ValueError(f"optimizer: expected a name in nevergrad.optimizers.registry, got {name!r}")
        budget = options.get("budget")
        if budget is not None and (isinstance(budget, bool) or not isinstance(budget, int) or budget < 1):
            raise ValueError(f"budget: expected a positive int or None, got {budget!r}")
        return {"optimizer": name, "budget": budget}

    def _create(self, batch_size: int) -> Any:
        ng = import_optional("nevergrad")
        parametrization = ng.p.Array(init=np.zeros(self.n_params)).set_mutation(sigma=1.0)
        parametrization.random_state = np.random.RandomState(self.seed)
        self._candidates: list[Any] = []
        factory = ng.optimizers.registry[self.options["optimizer"]]
        return factory(parametrization=parametrization, budget=self.options["budget"], num_workers=batch_size)

    def _lib_ask(self, n: int) -> Array:
        self._candidates = [self._lib.ask() for _ in range(n)]
        return np.array([c.value for c in self._candidates], dtype=np.float64)

    def _lib_tell(self, indices: NDArray[np.int64], losses: Array) -> None:
        for index, loss in zip(indices, losses, strict=True):
            self._lib.tell(self._candidates[index], float(loss))

    def _lib_recommend(self) -> Array:
        return np.asarray(self._lib.provide_recommendation().value, dtype=np.float64)
