"""``ask_more``: rows that join the pending batch instead of replacing it, for every registered optimiser.

creps_gym's own optimisers sample them after the pending rows (c-bo's kriging believer) or as ``ask`` does,
and one ``tell`` takes the whole batch; an adapter's library asks whole populations, so it refuses them
while a batch is pending. The real-robot loop that asks a row at a time is in ``tests/cli``."""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest
from helpers import driven_cbo, marked

from creps_gym.optimizers import make_optimizer, optimizer_names
from creps_gym.optimizers.cbo import ContextualBO
from creps_gym.optimizers.registry import optimizer_class

NATIVE = [name for name in optimizer_names() if ".adapters." not in optimizer_class(name).__module__]
ADAPTERS = [name for name in optimizer_names() if name not in NATIVE]
CONTEXTS = np.array([[0.1], [0.9], [0.5], [0.3]])


@pytest.mark.parametrize("name", NATIVE)
def test_without_a_pending_batch_ask_more_is_ask(name):
    first, second = make_optimizer(name, 2, 1, 3), make_optimizer(name, 2, 1, 3)
    assert first.ask_more(CONTEXTS).tobytes() == second.ask(CONTEXTS).tobytes()
    assert str(first.state_dict()) == str(second.state_dict())


@pytest.mark.parametrize("name", NATIVE)
def test_the_rows_join_the_pending_batch_and_one_tell_takes_them_all(name):
    optimizer = make_optimizer(name, 2, 1, 3)
    size = max(4, optimizer.minimum_batch_size(2, 1))
    contexts = np.linspace(0.0, 1.0, size)[:, None]
    params = np.vstack(
        [optimizer.ask(contexts[:2]), *(optimizer.ask_more(row[None]) for row in contexts[2:])]
    )
    state = optimizer.state_dict()
    np.testing.assert_array_equal(state["pending_contexts"], contexts)
    np.testing.assert_array_equal(state["pending_params"], params)
    optimizer.tell(contexts[::-1], params[::-1], -(params**2).sum(axis=1)[::-1])  # asked rows: no external
    assert optimizer.iteration == 1 and optimizer.diagnostics["external_samples"] == 0.0


@pytest.mark.parametrize("name", NATIVE)
def test_a_refused_ask_more_leaves_the_pending_batch_and_the_generator_as_they_were(name):
    optimizer = make_optimizer(name, 2, 1, 3)
    optimizer.ask(CONTEXTS)
    before = copy.deepcopy(optimizer.state_dict())
    for contexts, error in (([[math.nan]], ValueError), (np.zeros((1, 2)), ValueError), ("s", TypeError)):
        with pytest.raises(error, match="contexts"):
            optimizer.ask_more(contexts)
    assert str(optimizer.state_dict()) == str(before)


@pytest.mark.parametrize("name", marked(ADAPTERS))
def test_an_adapter_refuses_ask_more_while_a_batch_is_pending_and_changes_nothing(name):
    optimizer = make_optimizer(name, 2, 1, 3)
    contexts = np.zeros((6, 1))
    params = optimizer.ask_more(contexts)  # nothing pending: an ask
    before = copy.deepcopy(optimizer.state_dict())
    with pytest.raises(RuntimeError, match=r"ask_more: expected no pending batch .* got 6 pending rows"):
        optimizer.ask_more(contexts[:1])
    assert str(optimizer.state_dict()) == str(before)
    optimizer.tell(contexts, params, -(params**2).sum(axis=1))


@pytest.mark.parametrize("options", [{}, {"acquisition": "ucb"}])
def test_a_c_bo_batch_asked_a_row_at_a_time_is_the_batch_asked_at_once(options):
    """The believer conditions on the pending rows as on a batch's earlier rows: MES's rows are the same
    bits; UCB's within rounding (a pending θ comes back through the parameter box's scaling)."""
    optimizer = driven_cbo(3, 6, **options)
    state = copy.deepcopy(optimizer.state_dict())
    contexts = np.array([[0.5], [0.5], [0.2], [0.5]])
    whole = optimizer.ask(contexts)
    restored = ContextualBO.from_state_dict(state)
    parts = np.vstack([restored.ask_more(row[None]) for row in contexts])
    np.testing.assert_allclose(parts, whole, rtol=0.0, atol=1e-12)
    assert (parts.tobytes() == whole.tobytes()) or options
    assert np.linalg.norm(parts[1] - parts[0]) > 1e-3  # the second row at 0.5 left the first
