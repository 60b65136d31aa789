"""MES's floor of the sampled maxima, Eq. (A4) of :mod:`creps_gym.optimizers.acquisitions` (``mes_floor``):
the former floor bit for bit where the model holds no input at the asked context, five noise deviations
above those it holds there (told episodes, the believer's fantasies), and the option's validation and
checkpoints. The spread of a batch at one context is in ``test_cbo``."""

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


def test_without_inputs_held_at_the_context_the_floor_is_the_former_one_bit_for_bit():
    optimizer = _taught()
    _, mean, variance = _candidates(optimizer, 0.4)
    floor = max_value_floor(optimizer.model, np.zeros((0, 3)), mean)
    best = float(mean.max())
    assert floor == best + 1e-6 * (1.0 + abs(best))
    former = gumbel_max_values(mean, variance, 50, np.random.default_rng(1))
    floored = gumbel_max_values(mean, variance, 50, np.random.default_rng(1), floor)
    assert floored.tobytes() == former.tobytes()


def test_the_floor_is_five_noise_deviations_above_the_inputs_held_at_the_context():
    optimizer = _taught()
    model = optimizer.model
    inputs, mean, variance = _candidates(optimizer, 0.4)
    held = inputs[np.argsort(mean)[-2:]]  # the two best candidates, as if told or believed at s = 0.4
    floor = max_value_floor(model, held, mean)
    assert floor == float(model.predict(held)[0].max()) + 5.0 * math.sqrt(model.observation_noise)
    assert floor > mean.max() + 1e-6 * (1.0 + abs(mean.max()))
    assert (gumbel_max_values(mean, variance, 200, np.random.default_rng(2), floor) >= floor).all()
    worst = inputs[np.argsort(mean)[:2]]  # inputs the model rates far below the best: the first term stays
    assert float(model.predict(worst)[0].max()) + 5.0 * math.sqrt(model.observation_noise) < mean.max()
    assert max_value_floor(model, worst, mean) == max_value_floor(model, worst[:0], mean)


@pytest.mark.parametrize("acquisition", ["mes", "ucb"])
def test_where_no_context_repeats_both_floors_ask_the_same_bits(acquisition):
    """The floor's second term needs an input held at exactly the asked context: runs whose contexts are
    drawn from a continuous distribution (the studies') ask the same θ under both floors."""
    new = _taught(acquisition=acquisition)
    former = _taught(acquisition=acquisition, mes_floor="candidates")
    assert new.state_dict()["data_params"].tobytes() == former.state_dict()["data_params"].tobytes()
    contexts = np.array([[0.2], [0.6], [0.7]])
    assert new.ask(contexts).tobytes() == former.ask(contexts).tobytes()


def test_the_observation_noise_is_in_the_posteriors_units_with_a_trend_too():
    """σ_n² scales as ``predict``'s variance does against the GP's own (σ_r² with a trend, 1 without)."""
    for trend in ("constant", "quadratic"):
        model = _taught(trend=trend).model
        assert (model.beta is not None) == (trend == "quadratic")
        x = model.inputs[:3]
        units = model.predict(x)[1] / model.latent_variance(x)
        np.testing.assert_allclose(units, model.observation_noise / model.noise, rtol=1e-12)


@pytest.mark.parametrize("acquisition", ["mes", "ucb"])
def test_at_a_repeated_context_only_mes_rows_after_the_first_change(acquisition):
    """A batch's first row at a fresh context holds nothing there, and UCB samples no maxima: both floors
    ask the same θ; MES's later rows at the repeated context differ."""
    contexts = np.array([[0.2], [0.2], [0.7]])
    new = _taught(acquisition=acquisition)
    state = copy.deepcopy(new.state_dict())
    state["config"]["mes_floor"] = "candidates"
    former = ContextualBO.from_state_dict(state)
    assert new.ask(contexts[:1]).tobytes() == former.ask(contexts[:1]).tobytes()
    rows, former_rows = new.ask(contexts), former.ask(contexts)
    assert rows[0].tobytes() == former_rows[0].tobytes()
    assert (rows.tobytes() == former_rows.tobytes()) == (acquisition == "ucb")


@pytest.mark.parametrize(
    ("value", "error"), [("fantasies", ValueError), (None, ValueError), (True, ValueError)]
)
def test_an_unknown_floor_is_refused_naming_it_in_options_and_in_a_checkpoint(value, error):
    with pytest.raises(error, match=r"mes_floor: expected one of \('observed', 'candidates'\)"):
        make_optimizer("c-bo", 2, 1, 0, mes_floor=value)
    state = make_optimizer("c-bo", 2, 1, 0).state_dict()
    state["config"] = {**state["config"], "mes_floor": value}
    with pytest.raises(error, match="mes_floor: expected"):
        ContextualBO.from_state_dict(state)


@pytest.mark.parametrize("written", [{}, {"mes_floor": "observed"}, {"mes_floor": "candidates"}])
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
