"""The ask/tell protocol shared by every creps_gym optimiser and adapter.

``ask(contexts (n, z)) -> params (n, p)``, ``tell(contexts, params, returns (n,))`` and
``recommend(contexts) -> params``. Returns are **maximised**. Optimisers never see an environment.

Protocol rules (enforced by :class:`ContextualOptimizer`, documented for users):

* ``tell`` consumes the batch of the last ``ask``. Telling with no pending ask, or telling the same batch
  twice, raises ``RuntimeError``.
* By default every told row ``(context, params)`` must be a row that ``ask`` returned, bit for bit, in any
  order, each at most once; at least two rows must be told (a subset is fine: a failed episode may be left
  out). Rows the optimiser did not ask for are *external* samples: they are accepted only with
  ``tell(..., allow_external=True)``, after the same shape and finiteness checks, much as pycma's ``tell``
  accepts injected solutions. External rows are counted in the diagnostics.
* A rejected call raises before anything changes, so the optimiser is left exactly as it was.
* A second ``ask`` before ``tell`` replaces the pending batch: only the latest asked rows can be told.
  ``ask_more`` adds rows to it instead, so a batch may be asked a row at a time and told at once.

Checkpoints are ``.npz`` files holding the arrays plus one JSON document (``__state__.json``), never
pickle (:mod:`creps_gym.optimizers.state_files`). A restored optimiser continues with bit-identical asks.

Optional model hook: an optimiser with a model of the return may define
``context_utility(candidates (m, z), targets (r, z), pending (k, z) or None) -> (m,)``, the value of one
more episode at each candidate context for learning the optimal parameters at the target contexts, after
episodes at the ``pending`` contexts (larger is better; finite; deterministic given the optimiser's state,
drawing nothing from its Generator). The runner hands it, as a plain callable, to context selectors that
ask for it (:mod:`creps_gym.selectors.active`); ``c-bo`` implements it
(:meth:`creps_gym.optimizers.cbo.ContextualBO.context_utility`).
"""

from __future__ import annotations

import os
from abc import ABC, abstractmethod
from collections.abc import Mapping
from pathlib import Path
from typing import Any, ClassVar, Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from creps_gym._validation import as_float_array, check_bool, check_positive_int
from creps_gym.optimizers.state_files import load_state, save_state

__all__ = [
    "AskTellOptimizer",
    "ContextualOptimizer",
    "load_state",
    "overflowing_contexts",
    "save_state",
]

Array = NDArray[np.float64]
#: Largest context magnitude accepted: s² and products of two contexts stay far below the float64 range.
MAX_CONTEXT = 1e100


@runtime_checkable
class AskTellOptimizer(Protocol):
    """What the runner needs from an optimiser. Returns are maximised."""

    n_params: int
    n_context_dims: int

    def ask(self, contexts: Array) -> Array:
        """Parameters (n, p) to evaluate under contexts (n, z)."""

    def tell(self, contexts: Array, params: Array, returns: Array) -> None:
        """Update from the evaluated batch."""

    def recommend(self, contexts: Array) -> Array:
        """The current best guess (the mean policy), shape (n, p)."""

    @property
    def diagnostics(self) -> Mapping[str, float]:
        """Scalars describing the last update."""

    def stop(self) -> dict[str, Any]:
        """The optimiser's own stop criteria that are met (empty if it should go on)."""

    def state_dict(self) -> dict[str, Any]:
        """Arrays and JSON-serialisable values that restore the optimiser exactly."""


def overflowing_contexts(contexts: NDArray[np.float64], what: str) -> ValueError:
    """The error for contexts that pass the magnitude check but make ``what`` non-finite."""
    return ValueError(
        "contexts: expected contexts whose mean features are finite (smaller magnitudes), got values up to "
        f"{float(np.abs(contexts).max()):.3g} that make {what} non-finite"
    )


def _number(value: Any, key: Any) -> float:
    """A diagnostic of a state dict as a float (inf allowed: e.g. η of uniform weights), or a TypeError."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise TypeError(f"state['diagnostics'][{key!r}]: expected a number, got {type(value).__name__}")
    return float(value)


class ContextualOptimizer(ABC):
    """Base class with the protocol bookkeeping; subclasses implement the maths.

    Subclasses implement :meth:`_sample`, :meth:`_update`, :meth:`recommend`, :meth:`_state` and
    :meth:`_from_state`, and set ``n_params`` and ``n_context_dims`` in ``__init__``.
    """

    kind: ClassVar[str] = "base"
    n_params: int
    n_context_dims: int

    def __init__(self) -> None:
        self._pending: tuple[Array, Array] | None = None
        self._pending_index: dict[bytes, list[int]] = {}
        self._told_rows: NDArray[np.int64] = np.empty(0, dtype=np.int64)  # asked index per told row
        self._diagnostics: dict[str, float] = {}
        self.iteration = 0
        self.evaluations = 0

    # -- protocol --------------------------------------------------------------------------------------
    def ask(self, contexts: Any) -> Array:
        """Sample parameters for each context.

        Parameters
        ----------
        contexts : array_like, shape (n, z)

        Returns
        -------
        ndarray, shape (n, p)
        """
        contexts = self._check_contexts(contexts, "contexts")
        params = self._checked_sample(contexts, None)
        self._set_pending(contexts.copy(), params.copy())
        return params

    def ask_more(self, contexts: Any) -> Array:
        """Sample parameters for more contexts of the pending batch (``ask`` when none is pending).

        The rows join the pending batch, which one ``tell`` then takes: a batch may be asked a few rows at
        a time (a real robot's episodes, :mod:`creps_gym.runner.manual`). An optimiser whose rows depend
        on the batch's others (c-bo's kriging believer) chooses them after the pending rows; the others
        sample them as ``ask`` does. Contexts (n, z) in, parameters (n, p) out, as for :meth:`ask`.
        """
        if self._pending is None:
            return self.ask(contexts)
        contexts = self._check_contexts(contexts, "contexts")
        earlier_contexts, earlier_params = self._pending
        params = self._checked_sample(contexts, self._pending)
        self._set_pending(np.vstack([earlier_contexts, contexts]), np.vstack([earlier_params, params]))
        return params

    def _checked_sample(self, contexts: Array, earlier: tuple[Array, Array] | None) -> Array:
        """:meth:`_sample` (``earlier`` None) or :meth:`_sample_after`, refused when not finite."""
        generator = getattr(self, "rng", None)
        state = None if generator is None else generator.bit_generator.state
        with np.errstate(over="ignore", invalid="ignore"):
            params = self._sample(contexts) if earlier is None else self._sample_after(contexts, *earlier)
        if not np.isfinite(params).all():  # e.g. a high-degree polynomial of contexts near 1e100
            if state is not None:
                generator.bit_generator.state = state  # a rejected ask changes nothing
            raise overflowing_contexts(contexts, "the sampled parameters")
        return params

    def _sample_after(self, contexts: Array, earlier_contexts: Array, earlier_params: Array) -> Array:
        """:meth:`_sample` for rows that join a pending batch of ``earlier_contexts`` (k, z) and
        ``earlier_params`` (k, p); by default a row does not depend on the batch's others."""
        return self._sample(contexts)

    def _set_pending(self, contexts: Array, params: Array) -> None:
        """Remember an asked batch; a second ``ask`` before ``tell`` replaces the first."""
        self._pending = (contexts, params)
        self._pending_index = {}
        for i, row in enumerate(np.concatenate([contexts, params], axis=1)):
            self._pending_index.setdefault(row.tobytes(), []).append(i)

    def tell(self, contexts: Any, params: Any, returns: Any, *, allow_external: bool = False) -> None:
        """Update the search distribution from an evaluated batch (returns are maximised).

        Parameters
        ----------
        contexts : array_like, shape (n, z)
        params : array_like, shape (n, p)
        returns : array_like, shape (n,)
        allow_external : bool
            Accept rows that the last ``ask`` did not return (see the module docstring).

        Raises
        ------
        RuntimeError
            No pending ``ask`` (and ``allow_external`` is False), the batch was told already, or a row was
            not asked.
        ValueError, TypeError
            Shapes, non-finite values, returns whose spread max − min overflows, or fewer than two samples.
        """
        allow_external = check_bool(allow_external, "allow_external")
        contexts = self._check_contexts(contexts, "contexts")
        n = contexts.shape[0]
        params = as_float_array(params, "params", (n, self.n_params))
        returns = as_float_array(returns, "returns", (n,))
        if n < 2:
            raise ValueError(f"returns: expected at least 2 samples per tell, got {n}")
        with np.errstate(over="ignore"):
            spread = returns.max() - returns.min()
        if not np.isfinite(spread):  # every update compares returns; their differences must be numbers
            raise ValueError(
                f"returns: expected a finite spread max - min (at most {np.finfo(np.float64).max:.4g}), "
                f"got returns from {returns.min():.4g} to {returns.max():.4g}"
            )
        self._told_rows = self._match_told_rows(contexts, params, allow_external)  # for _update
        external = int((self._told_rows < 0).sum())
        self._update(contexts, params, returns)
        self._pending, self._pending_index = None, {}
        self._diagnostics["external_samples"] = float(external)
        self.iteration += 1
        self.evaluations += n

    @property
    def diagnostics(self) -> dict[str, float]:
        """Scalars describing the last update (empty before the first ``tell``)."""
        return dict(self._diagnostics)

    def stop(self) -> dict[str, Any]:
        """Stop criteria that are met; empty while the optimiser should continue."""
        return {}

    def restart(self) -> bool:
        """Abandon the running search and start a new one now, if the optimiser has restarts (the runner
        calls it when its divergence rule fires, between a ``tell`` and the next ``ask``); returns whether it
        did. The base class has none: it returns False and changes nothing."""
        return False

    @abstractmethod
    def recommend(self, contexts: Any) -> Array:
        """The mean policy's parameters for contexts (n, z): shape (n, p)."""

    # -- checkpoints -------------------------------------------------------------------------------------
    def state_dict(self) -> dict[str, Any]:
        """Everything needed to continue bit-identically: arrays plus JSON-serialisable values."""
        state = self._state()
        state.update(
            kind=self.kind,
            iteration=self.iteration,
            evaluations=self.evaluations,
            diagnostics=dict(self._diagnostics),
        )
        if self._pending is not None:
            state["pending_contexts"], state["pending_params"] = (a.copy() for a in self._pending)
        return state

    @classmethod
    def from_state_dict(cls, state: Mapping[str, Any]) -> ContextualOptimizer:
        """Rebuild an optimiser from :meth:`state_dict` output.

        A state that is not one (a missing key, a counter that is not an int >= 0, a pending batch of the
        wrong shape or with non-finite values, ...) raises ``ValueError`` or ``TypeError`` naming the key.
        """
        if state.get("kind") != cls.kind:
            hint = "" if "kind" in state else " (a run's learned policy: creps_gym.load_policy(run_folder))"
            raise ValueError(f"state: expected a {cls.kind!r} checkpoint, got {state.get('kind')!r}{hint}")
        try:
            optimizer = cls._from_state(state)
            for counter in ("iteration", "evaluations"):
                value = check_positive_int(state[counter], f"state[{counter!r}]", minimum=0)
                setattr(optimizer, counter, value)
            optimizer._diagnostics = {str(k): _number(v, k) for k, v in dict(state["diagnostics"]).items()}
            if "pending_contexts" in state:
                contexts = optimizer._check_contexts(state["pending_contexts"], "state['pending_contexts']")
                shape = (contexts.shape[0], optimizer.n_params)
                params = as_float_array(state["pending_params"], "state['pending_params']", shape)
                optimizer._set_pending(contexts, params)
        except KeyError as exc:
            missing = exc.args[0]
            raise ValueError(f"state: expected the key {missing!r} of a {cls.kind!r} checkpoint") from None
        return optimizer

    def save(self, path: str | os.PathLike[str]) -> Path:
        """Write a checkpoint (``.npz`` with an embedded JSON document) atomically."""
        return save_state(self.state_dict(), path)

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> ContextualOptimizer:
        """Restore an optimiser written by :meth:`save`, or the optimiser of a run folder's
        ``checkpoint.npz`` (its state at the last checkpoint; for the learned policy use
        ``creps_gym.load_policy(run_folder)``)."""
        state = load_state(path)
        if str(state.get("format", "")).startswith("creps_gym.run/"):  # a runner checkpoint
            prefix = "optimizer."
            state = {k[len(prefix) :]: v for k, v in state.items() if k.startswith(prefix)}
        return cls.from_state_dict(state)

    # -- subclass hooks ----------------------------------------------------------------------------------
    @abstractmethod
    def _sample(self, contexts: Array) -> Array: ...

    @abstractmethod
    def _update(self, contexts: Array, params: Array, returns: Array) -> None:
        """Update the distribution; must validate everything before mutating state."""

    @abstractmethod
    def _state(self) -> dict[str, Any]: ...

    @classmethod
    @abstractmethod
    def _from_state(cls, state: Mapping[str, Any]) -> ContextualOptimizer: ...

    # -- helpers -----------------------------------------------------------------------------------------
    def _check_contexts(self, contexts: Any, name: str) -> Array:
        contexts = as_float_array(contexts, name, (None, self.n_context_dims))
        if contexts.shape[0] < 1:
            raise ValueError(f"{name}: expected at least one row, got shape {contexts.shape}")
        largest = float(np.abs(contexts).max()) if contexts.size else 0.0
        if largest > MAX_CONTEXT:  # quadratic features and baselines would overflow to inf
            raise ValueError(
                f"{name}: expected |s| <= {MAX_CONTEXT:g}, so that quadratic context features stay finite, "
                f"got max |s| = {largest:g}; rescale the contexts"
            )
        return contexts

    def _match_told_rows(self, contexts: Array, params: Array, allow_external: bool) -> NDArray[np.int64]:
        """Index in the pending ask of each told row, −1 for external rows; raises on protocol misuse.

        Identical asked rows are matched in order, each at most once.
        """
        if self._pending is None and not allow_external:
            raise RuntimeError(
                "tell() without a pending ask(): the last batch was told already or nothing was asked; "
                "pass allow_external=True to tell samples generated elsewhere"
            )
        used: dict[bytes, int] = {}  # how often each distinct asked row was told so far
        indices = np.full(contexts.shape[0], -1, dtype=np.int64)
        for k, row in enumerate(np.concatenate([contexts, params], axis=1)):
            key = row.tobytes()
            asked = self._pending_index.get(key)
            if asked is None:
                if not allow_external:
                    raise RuntimeError(
                        f"tell(): row {k} (contexts[{k}], params[{k}]) was not returned by the last ask(); "
                        "pass allow_external=True to tell external samples"
                    )
                continue
            used[key] = used.get(key, 0) + 1
            if used[key] > len(asked):
                raise RuntimeError(
                    f"tell(): row {k} repeats asked sample {asked[0]}; each sample is told once"
                )
            indices[k] = asked[used[key] - 1]
        return indices
