"""Adapter for pycma's CMA-ES (``pip install creps-gym[adapters]``).

Hansen, N., "The CMA Evolution Strategy: A Tutorial", arXiv:1604.00772. pycma is imported only when the
first batch is asked.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from creps_gym.optimizers.adapters.base import MinimizerAdapter, import_optional

__all__ = ["CMAAdapter"]

Array = NDArray[np.float64]
_MANAGED = ("seed", "randn", "popsize", "CMA_stds", "verbose", "verb_log", "verb_disp")


class CMAAdapter(MinimizerAdapter):
    """pycma's ``CMAEvolutionStrategy`` behind the ask/tell protocol (contexts are ignored).

    The population size is the number of rows of the first ``ask``; later asks must have the same size and
    each ``tell`` must hold the whole population. Samples come from a ``numpy.random.Generator`` seeded with
    ``seed`` (passed to pycma as its ``randn`` option), so pycma never touches the global numpy state.

    Parameters
    ----------
    n_params, n_context_dims, initial_mean, initial_cov, seed
        See :class:`~creps_gym.optimizers.adapters.base.MinimizerAdapter`. pycma starts at
        ``initial_mean`` with step size 1 in coordinates scaled by the initial standard deviations.
    cma_options : dict, optional
        Further JSON-serialisable pycma options (for example ``{"tolfun": 1e-12}``). The options
        ``seed``, ``randn``, ``popsize``, ``CMA_stds`` and the verbosity options are set by the adapter.
    """

    kind: ClassVar[str] = "cma"
    fixed_batch: ClassVar[bool] = True

    def _check_options(self, options: dict[str, Any]) -> dict[str, Any]:
        unknown = set(options) - {"cma_options"}
        if unknown:
            raise TypeError(f"options: expected only 'cma_options', got unknown keys {sorted(unknown)}")
        cma_options = options.get("cma_options", {})
        if not isinstance(cma_options, dict):
            raise TypeError(f"cma_options: expected a dict, got {type(cma_options).__name__}")
        managed = sorted(set(cma_options) & set(_MANAGED))
        if managed:
            raise ValueError(f"cma_options: expected none of {list(_MANAGED)}, got {managed}")
        return {"cma_options": dict(cma_options)} if cma_options else {}

    def _create(self, batch_size: int) -> Any:
        cma = import_optional("cma")
        rng = np.random.default_rng(self.seed)

        def randn(*shape: int) -> Array:
            return rng.standard_normal(shape)

        opts = {
            "popsize": batch_size,
            "randn": randn,
            "seed": np.nan,  # "do nothing": randomness comes from ``randn``
            "verbose": -9,
            "verb_log": 0,
            "verb_disp": 0,
            **self.options.get("cma_options", {}),
        }
        self._solutions: list[Array] = []
        return cma.CMAEvolutionStrategy(np.zeros(self.n_params), 1.0, opts)

    def _lib_ask(self, n: int) -> Array:
        self._solutions = self._lib.ask(n)
        return np.array(self._solutions, dtype=np.float64)

    def _lib_tell(self, indices: NDArray[np.int64], losses: Array) -> None:
        self._lib.tell([self._solutions[i] for i in indices], [float(v) for v in losses])

    def _lib_recommend(self) -> Array:
        return np.asarray(self._lib.mean, dtype=np.float64)

    def _lib_diagnostics(self) -> dict[str, float]:
        eigenvalues = np.asarray(self._lib.D, dtype=np.float64) if self._lib.D is not None else np.ones(1)
        return {"sigma": float(self._lib.sigma), "axis_ratio": float(eigenvalues.max() / eigenvalues.min())}

    def stop(self) -> dict[str, Any]:
        """pycma's termination criteria that are met (empty while CMA-ES should go on)."""
        if self._lib is None or self._lib.countiter == 0:
            return {}
        return {str(k): v for k, v in dict(self._lib.stop()).items()}
