"""c-bo's refit data (Eq. G3a): which episodes a hyperparameter fit sees, the option that chooses them, and
checkpoints written before the option existed."""

from __future__ import annotations

import copy
from fractions import Fraction

import numpy as np
import pytest

import creps_gym.optimizers.cbo as cbo_module
from creps_gym.optimizers import make_optimizer
from creps_gym.optimizers.cbo import ContextualBO
from creps_gym.optimizers.gp_model import FIT_SUBSETS, fit_subset


@pytest.mark.parametrize("rule", FIT_SUBSETS)
@pytest.mark.parametrize("n", [1, 2, 7, 8])
def test_a_fit_sees_every_episode_while_there_are_at_most_fit_points(rule, n):
    assert fit_subset(n, 8, rule).tolist() == list(range(n))


@pytest.mark.parametrize(
    ("n", "points"), [(9, 8), (20, 8), (30, 15), (116, 15), (500, 256), (1000, 3), (10_001, 1024)]
)
def test_spread_takes_distinct_episodes_evenly_over_the_history_from_the_first_to_the_latest(n, points):
    """Eq. G3a in exact arithmetic, ties (30 and 116 episodes of 15: j (n − 1)/(m − 1) = 14.5, 57.5)
    rounded up."""
    chosen = fit_subset(n, points, "spread")
    assert chosen.dtype == np.int64 and chosen.shape == (points,) and chosen[0] == 0 and chosen[-1] == n - 1
    gaps = np.diff(chosen)
    assert (gaps >= 1).all()  # distinct and in order
    assert gaps.max() - gaps.min() <= 1  # even: every gap is ⌊(n−1)/(m−1)⌋ or one more
    exact = [int(Fraction(j * (n - 1), points - 1) + Fraction(1, 2)) for j in range(points)]
    assert chosen.tolist() == exact


@pytest.mark.parametrize("n", range(0, 40))
def test_recent_takes_the_episodes_of_the_former_slice(n):
    """The former refit's rows, ``slice(max(0, n − m), n)``, which the study's pinned runs used."""
    assert fit_subset(n, 8, "recent").tolist() == list(range(n))[max(0, n - 8) : n]


@pytest.mark.parametrize(
    ("args", "match"),
    [
        ((10, 4, "latest"), r"rule: expected one of \('spread', 'recent'\), got 'latest'"),
        ((10, 1, "spread"), "points: expected an integer >= 2, got 1"),
        ((10, 4.0, "spread"), "points: expected an integer >= 2, got 4.0"),
        ((-1, 4, "spread"), "n: expected an integer >= 0, got -1"),
    ],
)
def test_bad_arguments_are_refused_naming_them(args, match):
    with pytest.raises(ValueError, match=match):
        fit_subset(*args)


def _taught(batches: int = 6, **options) -> ContextualBO:
    optimizer = make_optimizer("c-bo", 2, 1, 3, initial_samples=6, **options)
    rng = np.random.default_rng(5)
    for _ in range(batches):
        contexts = rng.uniform(0, 1, (4, 1))
        params = optimizer.ask(contexts)
        optimizer.tell(contexts, params, -((params - contexts) ** 2).sum(axis=1))
    return optimizer


@pytest.mark.slow
@pytest.mark.parametrize("rule", FIT_SUBSETS)
def test_each_refit_maximises_the_likelihood_of_the_chosen_episodes(monkeypatch, rule):
    """A spy on the fit: at every refit it is given exactly the rows of :func:`fit_subset` of the data."""
    seen = []
    real = cbo_module.fit_hyperparameters

    def spy(inputs, targets, *args, **kwargs):
        seen.append(inputs.copy())
        return real(inputs, targets, *args, **kwargs)

    monkeypatch.setattr(cbo_module, "fit_hyperparameters", spy)
    optimizer = _taught(fit_points=8, fit_subset=rule)
    assert len(seen) >= 3 and max(len(inputs) for inputs in seen) == 8  # the cap was reached
    data = optimizer._inputs(optimizer.contexts, optimizer.params, optimizer.context_scale)
    last = seen[-1]
    n = optimizer.fitted_at
    assert last.tobytes() == data[:n][fit_subset(n, 8, rule)].tobytes()


@pytest.mark.slow
def test_the_two_rules_agree_until_the_cap_and_part_after_it():
    """Below ``fit_points`` both rules fit every episode: the same run bit for bit."""
    spread, recent = _taught(batches=2, fit_points=8), _taught(batches=2, fit_points=8, fit_subset="recent")
    assert spread.state_dict()["log_hyper"].tobytes() == recent.state_dict()["log_hyper"].tobytes()
    spread, recent = _taught(fit_points=8), _taught(fit_points=8, fit_subset="recent")
    assert spread.state_dict()["log_hyper"].tobytes() != recent.state_dict()["log_hyper"].tobytes()


@pytest.mark.slow
def test_a_run_past_the_cap_resumes_bit_for_bit():
    optimizer = _taught(fit_points=8)
    restored = ContextualBO.from_state_dict(optimizer.state_dict())
    assert restored.config.fit_subset == "spread" and restored.config.fit_points == 8
    contexts = np.array([[0.2], [0.7], [0.4], [0.9]])
    for one in (optimizer, restored):
        params = one.ask(contexts)
        one.tell(contexts, params, -((params - contexts) ** 2).sum(axis=1))
    assert restored.state_dict()["log_hyper"].tobytes() == optimizer.state_dict()["log_hyper"].tobytes()
    assert restored.ask(contexts).tobytes() == optimizer.ask(contexts).tobytes()


@pytest.mark.slow
def test_a_checkpoint_written_before_the_option_resumes_with_the_most_recent_episodes():
    """Before 2026-11-30 a checkpoint named no ``fit_subset``; its refits took the most recent episodes.
    Past the cap, such a checkpoint resumes bit for bit as the run that wrote it."""
    optimizer = _taught(fit_points=8, fit_subset="recent")
    state = copy.deepcopy(optimizer.state_dict())
    del state["config"]["fit_subset"]
    restored = ContextualBO.from_state_dict(state)
    assert restored.config.fit_subset == "recent"
    contexts = np.array([[0.1], [0.5], [0.8], [0.3]])
    for one in (optimizer, restored):
        for _ in range(2):  # past the next refit
            params = one.ask(contexts)
            one.tell(contexts, params, -((params - contexts) ** 2).sum(axis=1))
    assert restored.state_dict()["log_hyper"].tobytes() == optimizer.state_dict()["log_hyper"].tobytes()
    assert restored.ask(contexts).tobytes() == optimizer.ask(contexts).tobytes()


@pytest.mark.parametrize("value", ["latest", None, ["spread"]])
def test_an_unknown_rule_is_refused_naming_it_in_options_and_in_a_checkpoint(value):
    match = r"fit_subset: expected one of \('spread', 'recent'\), got "
    with pytest.raises(ValueError, match=match):
        make_optimizer("c-bo", 2, 1, 0, fit_subset=value)
    state = make_optimizer("c-bo", 2, 1, 0).state_dict()
    state["config"] = {**state["config"], "fit_subset": value}
    with pytest.raises(ValueError, match=match):
        ContextualBO.from_state_dict(state)
