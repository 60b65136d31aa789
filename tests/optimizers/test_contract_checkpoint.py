"""Contract of every registered optimiser (issue 43, item 3): a checkpoint restores bit-identically.

Parametrised over the optimiser registry (the adapters too, marked ``extras``) and the moment of the
checkpoint (after a ``tell``, or between an ``ask`` and its ``tell``: the pending batch is told to all). One
trained optimiser is restored through each route a state takes: its own file (``save``/``load``), the state
functions a runner checkpoint goes through (``save_state``/``load_state``/``restore_optimizer``) and the
state in memory (``state_dict``/``restore_optimizer``). Each restored optimiser has the same shape,
diagnostics and iteration, and then asks, tells and recommends in lockstep with the original, bit for bit
(and holds the same search covariance where it has one).

Option-specific state (a ridge centre, a surrogate's archive, a restart portfolio, kept policies) has its
own checkpoint tests beside the option's other tests.
"""

from __future__ import annotations

import numpy as np
import pytest
from helpers import marked

from creps_gym.optimizers import registry
from creps_gym.optimizers.state_files import load_state, save_state

NAMES = registry.optimizer_names()
ADAPTERS = [name for name in NAMES if ".adapters." in registry.optimizer_class(name).__module__]
#: (iterations, samples) before the checkpoint: fewer for c-bo, whose every ask optimises an acquisition per
#: row (its GP is in use from the third batch on: 2 (5 + 2) = 14 initial episodes), and for the adapters,
#: which replay every told ask when restored. The contract does not depend on the budget.
BUDGETS = {"c-bo": (4, 8), **dict.fromkeys(ADAPTERS, (3, 8))}
N_PARAMS, N_CONTEXT_DIMS = 5, 2


def _regret(contexts: np.ndarray, params: np.ndarray) -> np.ndarray:
    """The paper's contextual sphere x = θ + A·s (A fixed), regret |x|²."""
    matrix = np.random.default_rng(0).uniform(-1, 1, (N_PARAMS, N_CONTEXT_DIMS))
    return ((params + contexts @ matrix.T) ** 2).sum(axis=1)


def _restored(name: str, optimizer, folder) -> dict:
    """``optimizer`` restored through each route, by route."""
    state = save_state(optimizer.state_dict(), folder / "state.npz")
    return {
        "file": type(optimizer).load(optimizer.save(folder / "opt.npz")),
        "state": registry.restore_optimizer(name, load_state(state)),
        "memory": registry.restore_optimizer(name, optimizer.state_dict()),
    }


@pytest.mark.parametrize("pending", [False, True])
@pytest.mark.parametrize("name", marked(NAMES))
@pytest.mark.slow
def test_a_checkpoint_restores_bit_identically(name, pending, tmp_path):
    iterations, samples = BUDGETS.get(name, (12, 20))
    rng = np.random.default_rng(0)
    original = registry.make_optimizer(name, N_PARAMS, N_CONTEXT_DIMS, 9, initial_mean=1.0, initial_cov=2.0)
    assert (original.n_params, original.n_context_dims) == (N_PARAMS, N_CONTEXT_DIMS)
    for _ in range(iterations):
        contexts = rng.uniform(0, 3, (samples, N_CONTEXT_DIMS))
        params = original.ask(contexts)
        original.tell(contexts, params, -_regret(contexts, params))
    contexts = rng.uniform(0, 3, (samples, N_CONTEXT_DIMS))
    asked = original.ask(contexts) if pending else None
    routes = _restored(name, original, tmp_path)
    for route, restored in routes.items():
        assert type(restored) is type(original), route
        assert (restored.n_params, restored.n_context_dims) == (N_PARAMS, N_CONTEXT_DIMS), route
        assert restored.diagnostics == original.diagnostics, route
        assert restored.iteration == original.iteration == iterations, route
    everyone = [original, *routes.values()]
    if pending:  # the pending batch can be told to a restored optimiser
        for optimizer in everyone:
            optimizer.tell(contexts, asked, -_regret(contexts, asked))
    for _ in range(3):
        contexts = rng.uniform(0, 3, (samples, N_CONTEXT_DIMS))
        a = original.ask(contexts)
        for route, restored in routes.items():
            np.testing.assert_array_equal(restored.ask(contexts), a, err_msg=route)
        for optimizer in everyone:
            optimizer.tell(contexts, a, -_regret(contexts, a))
    for route, restored in routes.items():
        assert restored.diagnostics == original.diagnostics, route
        if hasattr(original, "cov"):  # the search distribution of the linear-Gaussian optimisers
            np.testing.assert_array_equal(restored.cov, original.cov, err_msg=route)
        np.testing.assert_array_equal(
            restored.recommend(contexts), original.recommend(contexts), err_msg=route
        )
