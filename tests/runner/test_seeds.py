"""The seed plan (:mod:`creps_gym.runner.seeds`): each stream's child of the master seed, named once."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from creps_gym.runner import split_seed
from creps_gym.runner.build import uniform_mean
from creps_gym.runner.seeds import SeedPlan, seed_child
from creps_gym.runner.selection import selector_stream

PACKAGE = Path(__file__).resolve().parents[2] / "creps_gym"


def test_the_children_keep_the_numbers_every_recorded_result_was_drawn_with() -> None:
    assert [(child.name, int(child)) for child in SeedPlan] == [
        ("ENV", 0),
        ("OPTIMIZER", 1),
        ("EVALUATION", 2),
        ("INITIAL_MEAN", 3),
        ("SELECTOR", 4),
    ]
    for seed in (0, 7, 2**40 + 3):
        legacy = np.random.SeedSequence(seed).spawn(5)
        for child in SeedPlan:
            assert (seed_child(seed, child).generate_state(4) == legacy[child].generate_state(4)).all()


def test_each_stream_draws_from_its_child() -> None:
    seed = 12
    rng, optimizer_seed, eval_seed = split_seed(seed)
    legacy = np.random.SeedSequence(seed).spawn(5)
    assert rng.random(3).tolist() == np.random.default_rng(legacy[0]).random(3).tolist()
    assert (optimizer_seed, eval_seed) == (
        int(legacy[1].generate_state(1)[0]),
        int(legacy[2].generate_state(1)[0]),
    )
    assert selector_stream(seed).random(3).tolist() == np.random.default_rng(legacy[4]).random(3).tolist()
    box = type("Box", (), {"low": np.zeros(2), "high": np.ones(2)})()
    expected = np.random.default_rng(legacy[3]).uniform(box.low, box.high)
    assert uniform_mean(box, seed).tolist() == expected.tolist()


def test_only_the_seed_plan_spawns_children_of_the_master_seed() -> None:
    """The runner's modules name children through :class:`SeedPlan`, never by number."""
    spawning = [
        str(path.relative_to(PACKAGE.parent))
        for path in sorted((PACKAGE / "runner").rglob("*.py"))
        if path.name != "seeds.py" and ".spawn(" in path.read_text(encoding="utf-8")
    ]
    assert not spawning, f"modules that spawn seed children outside creps_gym/runner/seeds.py: {spawning}"
