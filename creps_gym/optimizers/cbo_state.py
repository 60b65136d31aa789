"""The data part of a c-bo checkpoint (:class:`~creps_gym.optimizers.cbo.ContextualBO`): the told episodes,
the GP's hyperparameters, its context scaling and the episode count of the last refit, written as arrays and
read back as untrusted input (shapes, bounds and the memory the GP would need are checked before anything is
built from them)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from creps_gym._validation import as_float_array, check_fits_in_memory, check_positive_int
from creps_gym.optimizers.gp_model import hyper_bounds

__all__ = ["GPData", "check_kernel_memory", "read_gp_data"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class GPData:
    """What c-bo has learned: n told episodes and the GP's fitted state.

    contexts (n, z), params (n, p), returns (n,); log_hyper (p + z + 2,): the log lengthscales, signal and
    noise variance; scale: the context box of the GP's scaling, two (z,) arrays; fitted_at: the episode
    count at the last hyperparameter refit (0: never).
    """

    contexts: Array
    params: Array
    returns: Array
    log_hyper: Array
    scale: tuple[Array, Array]
    fitted_at: int

    def arrays(self) -> dict[str, Any]:
        """The checkpoint entries (copies)."""
        return {
            "data_contexts": self.contexts.copy(),
            "data_params": self.params.copy(),
            "data_returns": self.returns.copy(),
            "log_hyper": self.log_hyper.copy(),
            "scale_low": self.scale[0].copy(),
            "scale_high": self.scale[1].copy(),
            "fitted_at": self.fitted_at,
        }


def check_kernel_memory(n: int, p: int, z: int, name: str) -> None:
    """``MemoryError``-free refusal (``ValueError`` naming ``name``) of n episodes whose GP kernel matrices
    (n × n × (p + z + 6) floats) would not fit in memory."""
    check_fits_in_memory(
        8.0 * n * n * (p + z + 6), name, n, "the GP's kernel matrices (n x n x (p + z + 6) floats)"
    )


def read_gp_data(state: Mapping[str, Any], p: int, z: int, box: tuple[Array, Array] | None = None) -> GPData:
    """The :class:`GPData` of a checkpoint ``state`` of an optimiser with p parameters and z context
    dimensions; ``TypeError``/``ValueError`` naming the entry when one is malformed or out of bounds, or
    when a configured context ``box`` (the GP's, low (z,), high (z,)) is not the stored scaling."""
    contexts = as_float_array(state["data_contexts"], "state['data_contexts']", (None, z)).copy()
    n = contexts.shape[0]
    params = as_float_array(state["data_params"], "state['data_params']", (n, p)).copy()
    returns = as_float_array(state["data_returns"], "state['data_returns']", (n,)).copy()
    log_hyper = as_float_array(state["log_hyper"], "state['log_hyper']", (p + z + 2,)).copy()
    low, high = np.array(hyper_bounds(p + z)).T
    if ((log_hyper < low) | (log_hyper > high)).any():
        raise ValueError(
            f"state['log_hyper']: expected values within {low.tolist()} and {high.tolist()}, "
            f"got {log_hyper.tolist()}"
        )
    scale = tuple(as_float_array(state[k], f"state['{k}']", (z,)).copy() for k in ("scale_low", "scale_high"))
    if not (scale[0] < scale[1]).all():
        raise ValueError(f"state['scale_low'], state['scale_high']: expected low < high, got {scale}")
    if box is not None and not all(np.array_equal(a, b) for a, b in zip(scale, box, strict=True)):
        raise ValueError(
            f"state['scale_low'], state['scale_high']: expected the configured context box "
            f"{[b.tolist() for b in box]}, got {[a.tolist() for a in scale]}"
        )
    fitted_at = check_positive_int(state["fitted_at"], "state['fitted_at']", minimum=0)
    if fitted_at > n:
        raise ValueError(f"state['fitted_at']: expected at most the {n} stored episodes, got {fitted_at}")
    check_kernel_memory(n, p, z, "state['data_returns']")
    return GPData(contexts, params, returns, log_hyper, (scale[0], scale[1]), fitted_at)
