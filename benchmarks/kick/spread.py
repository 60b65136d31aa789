"""Why a kick run does or does not settle (issue 32): the fall rate of its last training batches and the
spread of its final search distribution, per run, for the study's tables (:mod:`.report`).

* ``late_fall_rate``: the mean fall rate of the last :data:`LATE_BATCHES` training batches (of all of them
  if the run has fewer), from the run file's history (``batch`` rows are ``[mean return, fall rate]``).
* ``final_ess``: the effective sample size 1/Σd² of the last update's weights, from the diagnostics saved
  in the run's final checkpoint (CREPS methods; None for an optimiser that records none).
* ``final_spread``: the RMS per coordinate of the policy's standard deviation at the run's final
  checkpoint, σ·√(mean of diag(C)), in the offset parameters' σ units (every method starts at 1.0). σ is the
  optimiser's step size (``step_size`` in the checkpoint; 1.0 for an optimiser without step-size control,
  whose policy keeps σ = 1, as CREPS-CMA-old does).

The checkpoint is read from the study's own runs folder as a run directory's file: never through a link,
at most :data:`MAX_CHECKPOINT_BYTES`, and parsed by the project's state loader (never pickle).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from creps_gym.optimizers.state_files import load_state
from creps_gym.runner.rundir import files

__all__ = [
    "COLUMNS",
    "KEYS",
    "LATE_BATCHES",
    "MAX_CHECKPOINT_BYTES",
    "final_ess",
    "final_spread",
    "late_fall_rate",
    "mean_and_std",
]

#: How many of the last training batches the late fall rate averages.
LATE_BATCHES = 200
#: The two quantities' keys in ``results.json`` (per trial) and their table columns (mean ± std).
KEYS = ("late_fall_rate", "final_spread")
COLUMNS = f"falls, last {LATE_BATCHES} it. | final spread (σ units)"
#: Largest checkpoint read (bytes): a kick run's is about 30 KB.
MAX_CHECKPOINT_BYTES = 16 * files.MiB


def late_fall_rate(batch: Sequence[Sequence[float]], last: int = LATE_BATCHES) -> float | None:
    """The mean fall rate (second entry of each ``[mean return, fall rate]`` row) of the last ``last``
    rows of ``batch``, or of all of them if there are fewer; None for no row.

    A row that is not a pair of finite numbers, or a rate outside [0, 1], raises ``ValueError``.
    """
    if isinstance(last, bool) or not isinstance(last, int) or last < 1:
        raise ValueError(f"last: expected a positive int, got {last!r}")
    rows = list(batch)[-last:]
    if not rows:
        return None
    rates = np.asarray(rows, dtype=float)
    if rates.ndim != 2 or rates.shape[1] != 2 or not np.all(np.isfinite(rates)):
        raise ValueError(f"batch: expected rows [mean return, fall rate] of finite numbers, got {rows[:3]!r}")
    if np.any((rates[:, 1] < 0.0) | (rates[:, 1] > 1.0)):
        low, high = rates[:, 1].min(), rates[:, 1].max()
        raise ValueError(f"batch: expected fall rates in [0, 1], got rates from {low} to {high}")
    return float(np.mean(rates[:, 1]))


def final_spread(checkpoint: Path, iterations: int) -> float | None:
    """σ·√(mean of diag(C)) of the optimiser checkpoint ``checkpoint`` (``<name>-trial<k>.npz``), or None
    if there is no such file or it was written at another iteration than the run's ``iterations`` (not
    the run's final search distribution).

    A link or a special file in its place, a file over :data:`MAX_CHECKPOINT_BYTES`, or one that is not a
    checkpoint with a square finite ``cov`` and a positive finite ``step_size`` raises ``ValueError`` naming
    the file.
    """
    state = _final_state(checkpoint, iterations)
    return None if state is None else _spread(state, checkpoint)


def final_ess(checkpoint: Path, iterations: int) -> float | None:
    """The effective sample size ``ess`` (1/Σd²) of the last update, from the diagnostics of the final
    checkpoint ``checkpoint``, or None if there is no such file, it is of another iteration than
    ``iterations``, or its optimiser records no ``ess``; read as :func:`final_spread` reads it. An ``ess``
    that is not a finite positive number raises ``ValueError`` naming the file."""
    state = _final_state(checkpoint, iterations)
    diagnostics = {} if state is None else state.get("diagnostics", {})
    if not isinstance(diagnostics, dict) or "ess" not in diagnostics:
        return None
    ess = diagnostics["ess"]
    if isinstance(ess, bool) or not isinstance(ess, (int, float)) or not (math.isfinite(ess) and ess > 0.0):
        raise ValueError(f"checkpoint {checkpoint}: expected a finite positive 'ess', got {ess!r:.200}")
    return float(ess)


def _final_state(checkpoint: Path, iterations: int) -> dict[str, Any] | None:
    """The state of ``checkpoint`` if it exists and was written at ``iterations``, else None."""
    try:
        stream = files.open_binary(checkpoint, limit=MAX_CHECKPOINT_BYTES)
    except FileNotFoundError:
        return None
    except files.RunDirError as exc:
        raise ValueError(f"checkpoint: expected a regular file, got {exc}") from None
    try:
        with stream:
            state = load_state(stream)
    except ValueError as exc:
        raise ValueError(f"checkpoint {checkpoint}: {exc}") from None
    return state if state.get("iteration") == iterations else None


def _spread(state: dict[str, Any], checkpoint: Path) -> float:
    cov, step_size = np.asarray(state.get("cov")), state.get("step_size", 1.0)
    if cov.ndim != 2 or cov.shape[0] != cov.shape[1] or cov.size == 0 or cov.dtype.kind not in "iuf":
        raise ValueError(f"checkpoint {checkpoint}: expected a square 'cov' array, got {cov!r:.200}")
    diagonal = np.diag(cov).astype(float)
    if not (np.all(np.isfinite(diagonal)) and np.all(diagonal >= 0.0)):
        raise ValueError(f"checkpoint {checkpoint}: expected a finite non-negative diag(cov), got {diagonal}")
    if isinstance(step_size, bool) or not isinstance(step_size, (int, float)) or not step_size > 0.0:
        raise ValueError(f"checkpoint {checkpoint}: expected a positive 'step_size', got {step_size!r}")
    if not math.isfinite(step_size):
        raise ValueError(f"checkpoint {checkpoint}: expected a finite 'step_size', got {step_size!r}")
    return float(step_size) * math.sqrt(float(np.mean(diagonal)))


def mean_and_std(values: Sequence[float | None], digits: int = 2) -> str:
    """``"0.15 ± 0.01"``: mean ± std (ddof 0) over the trials that have a value, with ``" (2 of 3)"`` when
    some have none; ``"—"`` when none has."""
    known = np.asarray([v for v in values if v is not None], dtype=float)
    if not len(known):
        return "—"
    text = f"{known.mean():.{digits}f} ± {known.std():.{digits}f}"
    return text if len(known) == len(values) else f"{text} ({len(known)} of {len(values)})"
