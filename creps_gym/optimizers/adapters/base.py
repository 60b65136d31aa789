"""Common base of the adapters that plug a non-contextual *minimiser* into the ask/tell protocol.

This module is the one place that handles the two conventions the libraries differ on:

* **Sign.** pycma, nevergrad and optuna minimise; creps_gym maximises returns.
  :meth:`MinimizerAdapter._update` hands the library ``loss = -return``; nothing else negates anything.
* **Contexts.** The adapters are not contextual: ``ask(contexts (n, z))`` uses only ``n`` and ignores the
  values, and ``recommend`` gives the same parameters for every context.

The library searches normalised coordinates ``y`` and the adapter returns ``theta = initial_mean +
initial_std * y``, so every library starts from the same initial distribution N(mean, diag(std²)).

Checkpoints use **deterministic replay**: the library objects cannot be saved without pickle, so
:meth:`state_dict` stores the configuration (including the seed) and the full record of asks and tells, and
:meth:`from_state_dict` rebuilds the library optimiser and replays them, checking that every replayed ask
equals the recorded one bit for bit (``RuntimeError`` otherwise, e.g. after a library upgrade). Replay costs
as much optimiser time (not evaluation time) as the run so far.
"""

from __future__ import annotations

import importlib
import math
from abc import abstractmethod
from collections.abc import Mapping
from typing import Any, ClassVar, cast

import numpy as np
from numpy.typing import NDArray

from creps_gym._validation import as_float_array, check_positive_int
from creps_gym.optimizers.base import ContextualOptimizer
from creps_gym.optimizers.policy_file import Policy

__all__ = ["MinimizerAdapter", "import_optional", "initial_variances"]

Array = NDArray[np.float64]


def import_optional(module: str, extra: str = "adapters") -> Any:
    """Import an optional library, or raise ``ImportError`` saying which extra installs it."""
    try:
        return importlib.import_module(module)
    except ImportError as exc:
        raise ImportError(
            f"{module} is not installed: install it with `pip install creps-gym[{extra}]` ({exc})"
        ) from None


def initial_variances(initial_cov: Any, n_params: int) -> Array:
    """Per-coordinate variances (p,) from a scalar, (p,) or diagonal (p, p) covariance."""
    cov = as_float_array(initial_cov, "initial_cov")
    if cov.ndim == 0:
        variances = np.full(n_params, float(cov))
    elif cov.shape == (n_params,):
        variances = cov.copy()
    elif cov.shape == (n_params, n_params):
        if np.any(cov != np.diag(np.diag(cov))):
            raise ValueError(
                "initial_cov: expected a scalar, a (p,) vector of variances or a diagonal (p, p) matrix "
                "(non-contextual adapters support only axis-aligned initial distributions), got a matrix "
                "with off-diagonal entries"
            )
        variances = np.diag(cov).copy()
    else:
        raise ValueError(
            f"initial_cov: expected a scalar, shape ({n_params},) or ({n_params}, {n_params}), "
            f"got {cov.shape}"
        )
    if np.any(variances <= 0):
        raise ValueError(f"initial_cov: expected positive variances, got {variances.min()}")
    return variances


def _initial_mean(initial_mean: Any, n_params: int) -> Array:
    mean = as_float_array(initial_mean, "initial_mean")
    if mean.ndim == 0:
        return np.full(n_params, float(mean))
    if mean.shape != (n_params,):
        raise ValueError(
            f"initial_mean: expected a scalar or shape ({n_params},) (non-contextual adapters have no "
            f"context-dependent mean), got {mean.shape}"
        )
    return mean.copy()


def _resolve_seed(seed: Any) -> int:
    if seed is None:
        return int(np.random.SeedSequence().generate_state(1)[0])
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, (int, np.integer)):
        raise TypeError(f"seed: expected an int in [0, 2**32) or None, got {type(seed).__name__} {seed!r}")
    if not 0 <= seed < 2**32:  # the libraries seed numpy's legacy RandomState, which takes 32 bits
        raise ValueError(f"seed: expected an int in [0, 2**32) or None, got {seed}")
    return int(seed)


class MinimizerAdapter(ContextualOptimizer):
    """Base class of the adapters (see the module docstring for the conventions).

    Parameters
    ----------
    n_params : int
        Number of parameters p.
    n_context_dims : int
        Number of context dimensions z (accepted and ignored).
    initial_mean : float or array_like, shape (p,)
        Centre of the initial search distribution.
    initial_cov : float, array_like of shape (p,) or diagonal (p, p)
        Initial variances.
    seed : int or None
        Seed of the library's random stream; ``None`` draws one (recorded in the state).
    **options
        JSON-serialisable library options, documented by each subclass.

    Subclasses implement :meth:`_create` (build the library optimiser for a batch size), :meth:`_lib_ask`
    (``n`` normalised points, shape (n, p)), :meth:`_lib_tell` (losses of some of the last asked points) and
    :meth:`_lib_recommend` (normalised point, shape (p,)), and may override :meth:`stop` and
    :meth:`_lib_diagnostics`. ``fixed_batch = True`` means every ask must have the first ask's size and
    every tell must hold the whole batch (pycma's population). ``budget_option`` names an option that the
    runner fills with the run's episode budget (iterations × samples, at most ``max_episodes``) unless the
    user gave it; :meth:`close` releases what the library opened.
    """

    kind: ClassVar[str] = "adapter"
    fixed_batch: ClassVar[bool] = False
    budget_option: ClassVar[str | None] = None

    @staticmethod
    def recommended_batch_size(n_params: int, n_context_dims: int) -> int:
        """CMA-ES's default population 4 + ⌊3 ln p⌋ (the libraries ignore the context)."""
        return 4 + int(3 * math.log(n_params))

    def __init__(
        self,
        n_params: int,
        n_context_dims: int,
        *,
        initial_mean: Any = 0.0,
        initial_cov: Any = 1.0,
        seed: int | None = None,
        **options: Any,
    ) -> None:
        super().__init__()
        self.n_params = check_positive_int(n_params, "n_params")
        self.n_context_dims = check_positive_int(n_context_dims, "n_context_dims", minimum=0)
        self.initial_mean = _initial_mean(initial_mean, self.n_params)
        self._initial_var = initial_variances(initial_cov, self.n_params)
        self.initial_std = np.sqrt(self._initial_var)
        self.seed = _resolve_seed(seed)
        self.options = self._check_options(dict(options))
        self.batch_size: int | None = None
        self._lib: Any = None
        self._events: list[int] = []  # +n: ask of n rows; -m: tell of m rows
        self._asked: list[Array] = []
        self._told_index: list[NDArray[np.int64]] = []
        self._told_losses: list[Array] = []

    # -- library hooks -------------------------------------------------------------------------------------
    def _check_options(self, options: dict[str, Any]) -> dict[str, Any]:
        """Validate the library options (override to check names and values); returns them."""
        return options

    @abstractmethod
    def _create(self, batch_size: int) -> Any:
        """Build the library optimiser for batches of ``batch_size`` points."""

    @abstractmethod
    def _lib_ask(self, n: int) -> Array:
        """Ask the library for ``n`` normalised points, shape (n, p)."""

    @abstractmethod
    def _lib_tell(self, indices: NDArray[np.int64], losses: Array) -> None:
        """Tell the losses (m,) of the rows ``indices`` (m,) of the last ``_lib_ask``."""

    @abstractmethod
    def _lib_recommend(self) -> Array:
        """The library's recommendation in normalised coordinates, shape (p,)."""

    def _lib_diagnostics(self) -> dict[str, float]:
        return {}

    def close(self) -> None:
        """Release what the library opened (threads, files); the default has nothing to release.

        The runner calls it at the end of a run with an optimiser it built by name. Adapters are also
        context managers: ``with NevergradAdapter(...) as adapter: ...`` closes on exit.
        """

    def __enter__(self) -> MinimizerAdapter:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    # -- protocol ------------------------------------------------------------------------------------------
    def _sample(self, contexts: Array) -> Array:
        n = contexts.shape[0]
        if self.fixed_batch and self.batch_size is not None and n != self.batch_size:
            raise ValueError(
                f"contexts: expected {self.batch_size} rows ({self.kind} keeps the population size of the "
                f"first ask), got {n}"
            )
        y = self._raw_ask(n)
        return self.initial_mean + self.initial_std * y

    def _sample_after(self, contexts: Array, earlier_contexts: Array, earlier_params: Array) -> Array:
        """Refused: the wrapped library asks and tells whole populations (``ask_more`` is ``ask`` only
        while no batch is pending)."""
        raise RuntimeError(
            f"ask_more: expected no pending batch ({self.kind} asks and tells whole populations), got "
            f"{earlier_contexts.shape[0]} pending rows: tell them first, or ask the whole batch at once"
        )

    def _raw_ask(self, n: int) -> Array:
        if self._lib is None:
            self._lib = self._create(n)
            self.batch_size = n
        y = np.asarray(self._lib_ask(n), dtype=np.float64).reshape(n, self.n_params)
        self._events.append(n)
        self._asked.append(y.copy())
        return y

    def _update(self, contexts: Array, params: Array, returns: Array) -> None:
        indices = self._told_rows  # asked index per told row, matched by ContextualOptimizer.tell
        if (indices < 0).any():
            raise RuntimeError(
                f"tell(): the {self.kind} adapter cannot use external samples "
                "(rows not returned by the last ask)"
            )
        if self.fixed_batch and len(indices) != self.batch_size:
            raise ValueError(
                f"returns: expected all {self.batch_size} asked samples "
                f"({self.kind} needs whole populations), got {len(indices)}"
            )
        losses = -np.asarray(returns, dtype=np.float64)  # the sign convention: libraries minimise
        self._raw_tell(indices, losses)

    def _raw_tell(self, indices: NDArray[np.int64], losses: Array) -> None:
        self._lib_tell(indices, losses)
        self._events.append(-len(indices))
        self._told_index.append(indices.copy())
        self._told_losses.append(losses.copy())
        self._diagnostics.update(self._lib_diagnostics())
        best = max(self._diagnostics.get("best_return", -np.inf), float(-losses.min()))
        self._diagnostics["best_return"] = best

    def recommend(self, contexts: Any) -> Array:
        """The library's recommendation, repeated for each context: shape (n, p)."""
        contexts = self._check_contexts(contexts, "contexts")
        y = np.zeros(self.n_params) if self._lib is None else np.asarray(self._lib_recommend(), np.float64)
        return np.tile(self.initial_mean + self.initial_std * y, (contexts.shape[0], 1))

    def mean_policy(self) -> Policy:
        """The recommendation as a constant :class:`~creps_gym.optimizers.policy_file.Policy` (ϕ(s) = [1]):
        the same parameters for every context, equal to ``recommend``'s bit for bit."""
        params = self.recommend(np.zeros((1, self.n_context_dims)))[0]
        source = {"optimizer": self.kind, "iteration": self.iteration}
        return Policy.constant(params, self.n_context_dims, source=source)

    # -- checkpoints by replay -------------------------------------------------------------------------------
    def _state(self) -> dict[str, Any]:
        empty = np.zeros((0, self.n_params))
        return {
            "adapter": {
                "n_params": self.n_params,
                "n_context_dims": self.n_context_dims,
                "initial_mean": self.initial_mean.tolist(),
                "initial_var": self._initial_var.tolist(),
                "seed": self.seed,
                "options": self.options,
                "events": list(self._events),
            },
            "asked": np.concatenate(self._asked) if self._asked else empty,
            "told_index": np.concatenate(self._told_index) if self._told_index else np.zeros(0, np.int64),
            "told_losses": np.concatenate(self._told_losses) if self._told_losses else np.zeros(0),
        }

    @classmethod
    def from_state_dict(cls, state: Mapping[str, Any]) -> MinimizerAdapter:
        """Rebuild the adapter by replay; a pending batch must be the last ask that the replay repeats.

        ``ValueError`` naming ``state['pending_params']`` otherwise (rows the library did not ask could be
        told), on top of the checks of :meth:`ContextualOptimizer.from_state_dict`.
        """
        adapter = cast(MinimizerAdapter, super().from_state_dict(state))
        if adapter._pending is not None:
            events, params = adapter._events, adapter._pending[1]
            asked = events[-1] if events and events[-1] > 0 else 0
            expected = adapter.initial_mean + adapter.initial_std * adapter._asked[-1] if asked else None
            if expected is None or not np.array_equal(params, expected):
                raise ValueError(
                    f"state['pending_params']: expected the batch of the last ask that replaying {cls.kind} "
                    f"gives ({asked} rows), got {params.shape[0]} rows that differ from it"
                )
        return adapter

    @classmethod
    def _from_state(cls, state: Mapping[str, Any]) -> MinimizerAdapter:
        config = dict(state["adapter"])
        adapter = cls(
            config["n_params"],
            config["n_context_dims"],
            initial_mean=np.asarray(config["initial_mean"]),
            initial_cov=np.asarray(config["initial_var"]),
            seed=config["seed"],
            **config["options"],
        )
        events = _checked_events(config["events"], state)
        adapter._replay(events, state["asked"], state["told_index"], state["told_losses"])
        return adapter

    def _replay(self, events: list[int], asked: Array, told_index: Array, told_losses: Array) -> None:
        """Re-run the recorded asks and tells; every ask must reproduce the recorded rows bit for bit."""
        a = t = 0
        last_ask = 0
        for k, event in enumerate(events):
            if event < 0:
                indices = np.asarray(told_index[t : t - event])
                if indices.size and not (indices.min() >= 0 and indices.max() < last_ask):
                    raise ValueError(
                        f"state['told_index']: expected rows of the last ask (0 to {last_ask - 1}) at event "
                        f"{k}, got {indices.tolist()}"
                    )
            last_ask = event if event > 0 else last_ask
            if event > 0:
                y = self._raw_ask(event)
                if not np.array_equal(y, asked[a : a + event]):
                    raise RuntimeError(
                        f"state: replaying {self.kind} diverged at event {k} (ask of {event} rows): the "
                        "library does not reproduce the recorded asks (was it upgraded since the checkpoint?)"
                    )
                a += event
            else:
                m = -event
                indices = np.asarray(told_index[t : t + m], dtype=np.int64)
                self._raw_tell(indices, np.asarray(told_losses[t : t + m], dtype=np.float64))
                t += m


def _checked_events(events: Any, state: Mapping[str, Any]) -> list[int]:
    """The recorded events (asks > 0, tells < 0) checked against the recorded arrays and counters."""
    valid = isinstance(events, list) and all(isinstance(e, int) and not isinstance(e, bool) for e in events)
    if not valid or 0 in events:
        raise ValueError(f"state['adapter']['events']: expected a list of non-zero ints, got {events!r}")
    asked = as_float_array(state["asked"], "state['asked']", (None, None))
    told = np.asarray(state["told_index"])
    losses = as_float_array(state["told_losses"], "state['told_losses']", (told.shape[0],))
    if told.dtype.kind not in "iu":
        raise TypeError(f"state['told_index']: expected integers, got dtype {told.dtype}")
    counts = (sum(e for e in events if e > 0), -sum(e for e in events if e < 0))
    if counts != (asked.shape[0], losses.shape[0]):
        raise ValueError(
            f"state['adapter']['events']: expected asks and tells of {asked.shape[0]} and {losses.shape[0]} "
            f"rows (the recorded arrays), got {counts[0]} and {counts[1]}"
        )
    tells = sum(e < 0 for e in events)
    if "iteration" in state and tells != state["iteration"]:
        got = state["iteration"]
        raise ValueError(f"state['iteration']: expected {tells} (the recorded tells), got {got!r}")
    return events
