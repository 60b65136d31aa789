"""Adapter for nevergrad's optimisers (``pip install creps-gym[adapters]``); imported on the first ask.

Two workarounds for nevergrad 1.0.12 (the latest release) live here:

* **numpy >= 2.4.** nevergrad's meta-model (used by ``NGOpt`` in most settings) calls ``float()`` on a
  one-element array, which numpy 2.4 turned from a deprecation warning into a ``TypeError``
  (facebookresearch/nevergrad#1612). :func:`_allow_one_element_float` gives that module a ``float`` that
  accepts one-element arrays, which restores the behaviour of earlier numpy versions there only.
* **Threads.** "Recast" optimisers (Powell, Cobyla, SQP, ..., and the Powell inside the meta-model) run
  scipy in a non-daemon thread that waits for the next ``tell``; a thread left waiting keeps the process
  alive after the script ends. The adapter records the threads the library starts and :meth:`close`
  stops them; a library call that raises stops them at once.
"""

from __future__ import annotations

import builtins
import difflib
import threading
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from creps_gym.optimizers.adapters.base import MinimizerAdapter, import_optional

__all__ = ["NevergradAdapter"]

Array = NDArray[np.float64]


def _one_element_float(value: Any) -> float:
    """``float`` that also accepts one-element arrays, as numpy < 2.4 did."""
    if isinstance(value, np.ndarray) and value.size == 1:
        return builtins.float(value.reshape(()))
    return builtins.float(value)


def _allow_one_element_float(ng: Any) -> None:
    """Give nevergrad's meta-model module the ``float`` above when this numpy rejects one-element arrays."""
    try:
        builtins.float(np.ones(1))
    except TypeError:
        metamodel = getattr(getattr(ng, "optimization", None), "metamodel", None)
        if metamodel is not None:
            metamodel.float = _one_element_float  # module globals shadow the builtin in that module only


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
        Total number of evaluations announced to nevergrad. The runner passes the run's episode budget
        (iterations × samples, at most ``max_episodes``) unless it is given; ``NGOpt`` and other portfolio
        optimisers need it when the adapter is used directly.

    Optimisers that nevergrad runs one candidate at a time (``no_parallelization``, e.g. the recast
    ``"Powell"`` and ``"Cobyla"``) are refused: every tell holds a batch of at least 2. Call :meth:`close`
    (or use the adapter as a context manager) when done, to stop the threads an optimiser may start; the
    runner does it for the optimisers it builds.
    """

    kind: ClassVar[str] = "nevergrad"
    budget_option: ClassVar[str | None] = "budget"

    def _check_options(self, options: dict[str, Any]) -> dict[str, Any]:
        unknown = set(options) - {"optimizer", "budget"}
        if unknown:
            raise TypeError(f"options: expected only 'optimizer' and 'budget', got {sorted(unknown)}")
        name = options.get("optimizer", "TwoPointsDE")
        registry = import_optional("nevergrad").optimizers.registry
        if name not in registry:
            close = difflib.get_close_matches(str(name), list(registry), n=3, cutoff=0.6)
            hint = f" (did you mean {' or '.join(map(repr, close))}?)" if close else ""
            raise ValueError(
                f"optimizer: expected a name in nevergrad.optimizers.registry, got {name!r}{hint}"
            )
        if getattr(registry[name], "no_parallelization", False):  # e.g. the recast "Powell", "Cobyla"
            raise ValueError(
                f"optimizer: expected a nevergrad optimiser that evaluates batches (a tell needs at least 2 "
                f"samples), got {name!r}, which nevergrad runs one candidate at a time"
            )
        budget = options.get("budget")
        if budget is not None and (isinstance(budget, bool) or not isinstance(budget, int) or budget < 1):
            raise ValueError(f"budget: expected a positive int or None, got {budget!r}")
        return {"optimizer": name, "budget": budget}

    def _create(self, batch_size: int) -> Any:
        ng = import_optional("nevergrad")
        _allow_one_element_float(ng)
        self._threads: list[Any] = []
        parametrization = ng.p.Array(init=np.zeros(self.n_params)).set_mutation(sigma=1.0)
        parametrization.random_state = np.random.RandomState(self.seed)
        self._candidates: list[Any] = []
        factory = ng.optimizers.registry[self.options["optimizer"]]
        return factory(parametrization=parametrization, budget=self.options["budget"], num_workers=batch_size)

    def _call(self, method: Any, *args: Any) -> Any:
        """Call the library, recording the scipy threads it starts; on an error, stop them and re-raise."""
        before = set(threading.enumerate())
        try:
            result = method(*args)
        except BaseException:
            self._record_threads(before)
            self.close()
            raise
        self._record_threads(before)
        return result

    def _record_threads(self, before: set[threading.Thread]) -> None:
        started = [t for t in threading.enumerate() if t not in before and hasattr(t, "messages_tell")]
        self._threads = [t for t in self._threads if t.is_alive()] + started  # nevergrad's recast threads

    def close(self) -> None:
        """Stop the threads the library started (recast optimisers); the adapter is unusable afterwards."""
        for thread in getattr(self, "_threads", []):
            if thread.is_alive():
                thread.stop()  # nevergrad's own stop signal: the thread's scipy loop ends
                thread.join(timeout=5)
        self._threads = []

    def _lib_ask(self, n: int) -> Array:
        self._candidates = [self._call(self._lib.ask) for _ in range(n)]
        return np.array([c.value for c in self._candidates], dtype=np.float64)

    def _lib_tell(self, indices: NDArray[np.int64], losses: Array) -> None:
        for index, loss in zip(indices, losses, strict=True):
            self._call(self._lib.tell, self._candidates[index], float(loss))

    def _lib_recommend(self) -> Array:
        return np.asarray(self._call(self._lib.provide_recommendation).value, dtype=np.float64)
