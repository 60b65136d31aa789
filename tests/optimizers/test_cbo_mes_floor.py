"""MES's floor of the sampled maxima, Eq. (A4) of :mod:`creps_gym.optimizers.acquisitions` (``mes_floor``):
the former floor bit for bit where no batch row came before, five noise deviations above the believer's
fantasies after one, and the option's validation and checkpoints. The batch's spread is in ``test_cbo``."""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest
from helpers import driven_cbo

from creps_gym.optimizers import make_optimizer
from creps_gym.optimizers.acquisitions import gumbel_max_values, max_value_floor
from creps_gym.optimizers.cbo import ContextualBO


def _taught(**options) -> ContextualBO:
    """24 episodes of a contextual sphere, in batches of 4 at fresh contexts."""
    return driven_cbo(3, 6, **options)


def _candidates(optimizer: ContextualBO, context: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    thetas = np.random.default_rng(0).uniform(size=(64, 2))
    inputs = np.hstack([np.full((64, 1), context), thetas])
    return (inputs, *optimizer.model.predict(inputs))


def test_without_earlier_rows_the_floor_is_the_former_one_bit_for_bit():
    optimizer = _taught()
    _, mean, variance = _candidates(optimizer, 0.4)
    floor = max_value_floor(optimizer.model, np.zeros((0, 3)), mean)
    best = float(mean.max())
    assert floor == best + 1e-6 * (1.0 + abs(best))
    former = gumbel_max_values(mean, variance, 50, np.random.default_rng(1))
    floored = gumbel_max_values(mean, variance, 50, np.random.default_rng(1), floor)
    assert floored.tobytes() == former.tobytes()


def test_after_earlier_rows_the_floor_is_five_noise_deviations_above_their_fantasies():
    optimizer = _taught()
    model = optimizer.model
    inputs, mean, variance = _candidates(optimizer, 0.4)
    believed = inputs[np.argsort(mean)[-2:]]  # the two best candidates, as if chosen before
    floor = max_value_floor(model, believed, mean)
    assert floor == float(model.predict(believed)[0].max()) + 5.0 * math.sqrt(model.observation_noise)
    assert floor > mean.max() + 1e-6 * (1.0 + abs(mean.max()))
    assert (gumbel_max_values(mean, variance, 200, np.random.default_rng(2), floor) >= floor).all()
    worst = inputs[np.argsort(mean)[:2]]  # rows the model rates far below the best: the first term stays
    assert float(model.predict(worst)[0].max()) + 5.0 * math.sqrt(model.observation_noise) < mean.max()
    assert max_value_floor(model, worst, mean) == max_value_floor(model, worst[:0], mean)


def test_the_observation_noise_is_in_the_posteriors_units_with_a_trend_too():
    for trend in ("constant", "quadratic"):
        model = _taught(trend=trend).model
        assert model.observation_noise == pytest.approx(model.scale**2 * model.noise, rel=1e-15)


@pytest.mark.parametrize("acquisition", ["mes", "ucb"])
def test_a_first_row_and_every_ucb_row_are_the_former_rules_bit_for_bit(acquisition):
    """A batch's first row has no fantasies to floor on, and UCB samples no maxima: both floors ask the
    same θ from the same state."""
    contexts = np.array([[0.2], [0.2], [0.7]])
    new = _taught(acquisition=acquisition)
    state = copy.deepcopy(new.state_dict())
    state["config"]["mes_floor"] = "candidates"
    former = ContextualBO.from_state_dict(state)
    assert new.ask(contexts[:1]).tobytes() == former.ask(contexts[:1]).tobytes()
    rows, former_rows = new.ask(contexts), former.ask(contexts)
    assert (rows.tobytes() == former_rows.tobytes()) == (acquisition == "ucb")


@pytest.mark.parametrize(
    ("value", "error"), [("fantasies", ValueError), (None, ValueError), (True, ValueError)]
)
def test_an_unknown_floor_is_refused_naming_it_in_options_and_in_a_checkpoint(value, error):
    with pytest.raises(error, match=r"mes_floor: expected one of \('believed', 'candidates'\)"):
        make_optimizer("c-bo", 2, 1, 0, mes_floor=value)
    state = make_optimizer("c-bo", 2, 1, 0).state_dict()
    state["config"] = {**state["config"], "mes_floor": value}
    with pytest.raises(error, match="mes_floor: expected"):
        ContextualBO.from_state_dict(state)


@pytest.mark.parametrize("written", [{}, {"mes_floor": "believed"}, {"mes_floor": "candidates"}])
def test_a_checkpoint_resumes_bit_for_bit_and_one_written_before_the_option_with_the_former_floor(written):
    """A checkpoint keeps the option; one that names none (written before 2026-11-30) resumes with
    ``"candidates"``, the floor its run used, bit for bit through batches at repeated contexts."""
    optimizer = _taught(mes_floor=written.get("mes_floor", "candidates"))
    state = copy.deepcopy(optimizer.state_dict())
    if not written:
        del state["config"]["mes_floor"]
    restored = ContextualBO.from_state_dict(state)
    assert restored.config.mes_floor == written.get("mes_floor", "candidates")
    contexts = np.array([[0.1], [0.1], [0.8], [0.8]])
    for one in (optimizer, restored):
        for _ in range(2):
            params = one.ask(contexts)
            one.tell(contexts, params, -((params - contexts) ** 2).sum(axis=1))
    assert restored.ask(contexts).tobytes() == optimizer.ask(contexts).tobytes()
