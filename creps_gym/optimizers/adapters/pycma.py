"""Adapter for pycma's CMA-ES (``pip install creps-gym[adapters]``).

Hansen, N., "The CMA Evolution Strategy: A Tutorial", arXiv:1604.00772. pycma is imported only when the
first batch is asked.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from creps_gym.optimizers.adapters.base import MinimizerAdapter, import_optional

__all__ = ["STRING_OPTIONS", "CMAAdapter", "check_option_value"]

Array = NDArray[np.float64]
_MANAGED = ("seed", "randn", "CMA_stds", "verbose", "verb_log", "verb_disp")
#: The only strings an option may hold, by option (pycma evaluates a string option as Python code, so any
#: other string is refused: an option is data, never an expression).
STRING_OPTIONS = {"BoundaryHandler": ("BoundTransform",)}  # the one class name pycma reads as a safe word
_DEPTH = 3  # lists of lists of lists at most (``bounds=[[-1, -2], [1, 2]]``)


def _plain(value: Any) -> Any:
    """A numpy scalar as the Python number it holds (JSON-serialisable); anything else as is."""
    return value.item() if isinstance(value, np.generic) else value


def _is_data(value: Any, depth: int = 0) -> bool:
    """Whether ``value`` is None, a bool, an int, a float or a (nested) list of them (never evaluated)."""
    if value is None or isinstance(value, (bool, int, float)):
        return True
    if isinstance(value, (list, tuple)) and depth < _DEPTH:
        return all(_is_data(_plain(item), depth + 1) for item in value)
    return False


def check_option_value(name: str, value: Any) -> Any:
    """``value`` if it is data (see :data:`STRING_OPTIONS`), else ``ValueError`` naming the option."""
    allowed = STRING_OPTIONS.get(name, ())
    if (isinstance(value, str) and value in allowed) or (not isinstance(value, str) and _is_data(value)):
        return value
    strings = f", or one of the strings {list(allowed)}" if allowed else ""
    raise ValueError(
        f"{name}: expected a number, a boolean, None or a list of them (pycma would evaluate a string as "
        f"code){strings}, got {type(value).__name__} {str(value)[:80]!r}"
    )


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
    **cma_options
        pycma options by their pycma names, flat as in ``cma.CMAEvolutionStrategy(x0, sigma0, options)``
        (for example ``tolfun=1e-12``, or ``--opt tolfun=1e-12`` on the command line); the names are checked
        against ``cma.CMAOptions()``. ``popsize``, if given, must equal the batch size (the runner's samples
        per iteration). ``seed``, ``randn``, ``CMA_stds`` and the verbosity options are set by the adapter.
        The nested form ``cma_options={...}`` of earlier versions is still accepted. Values are data: numbers,
        booleans, None and lists of them (pycma evaluates strings as Python code, so a string is refused,
        except the names in :data:`STRING_OPTIONS`). pycma sees normalised
        coordinates u = (θ − initial_mean) / initial_std, so options on positions, such as ``bounds``, are
        in u: ``bounds=[-2, 2]`` keeps θ within initial_mean ± 2 initial_std. Numpy scalars are stored as
        the Python numbers they hold (the options are saved as JSON).
    """

    kind: ClassVar[str] = "cma"
    fixed_batch: ClassVar[bool] = True

    def _check_options(self, options: dict[str, Any]) -> dict[str, Any]:
        nested = options.pop("cma_options", {})
        if not isinstance(nested, dict):
            raise TypeError(f"cma_options: expected a dict, got {type(nested).__name__}")
        twice = sorted(set(nested) & set(options))
        if twice:
            raise ValueError(f"options: expected each pycma option once, got {twice} flat and in cma_options")
        merged = {key: _plain(value) for key, value in {**nested, **options}.items()}
        managed = sorted(set(merged) & set(_MANAGED))
        if managed:
            raise ValueError(
                f"options: expected none of {list(_MANAGED)} (set by the adapter), got {managed}"
            )
        unknown = sorted(set(merged) - set(import_optional("cma").CMAOptions()))
        if unknown:
            raise TypeError(
                f"options: expected pycma option names (see cma.CMAOptions()), got unknown {unknown}"
            )
        merged = {key: check_option_value(key, value) for key, value in merged.items()}
        popsize = merged.get("popsize")
        if popsize is not None and (isinstance(popsize, bool) or not isinstance(popsize, int) or popsize < 2):
            raise ValueError(f"popsize: expected an int >= 2 (the batch size), got {popsize!r}")
        return merged

    def _create(self, batch_size: int) -> Any:
        cma = import_optional("cma")
        popsize = self.options.get("popsize", batch_size)
        if popsize != batch_size:
            raise ValueError(
                f"popsize: expected the batch size {batch_size} (the runner's samples per iteration), "
                f"got {popsize}"
            )
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
            **self.options,
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
