"""What the low-dimensional kicks can reach (benchmarks/low_budget/reach.py): the committed table is the
rendering of the committed JSON, which covers every test context of both ids with provenance, and the
search itself finds what it reports."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from helpers import EXTRAS

from benchmarks.low_budget import reach
from benchmarks.low_budget.study import evaluation_contexts, task_by_name

RESULTS = Path(__file__).resolve().parents[2] / "benchmarks" / "low_budget" / "results"


#: The committed results: the v0 ids', the v1 ids', the v2 ids'.
FILES = {"reach": reach.TASKS[:2], "reach_v1": reach.TASKS[2:4], "reach_v2": reach.TASKS[4:]}


@pytest.mark.parametrize("name", sorted(FILES))
def test_the_committed_table_is_the_rendering_of_the_committed_results(tmp_path, name):
    copy = tmp_path / f"{name}.json"
    shutil.copy(RESULTS / f"{name}.json", copy)
    assert reach.render(copy) == (RESULTS / f"{name}.md").read_text(encoding="utf-8")


@EXTRAS  # the kick (MuJoCo)
@pytest.mark.parametrize("name", sorted(FILES))
def test_the_committed_results_cover_every_test_context_of_both_ids_with_provenance(name):
    document = json.loads((RESULTS / f"{name}.json").read_text(encoding="utf-8"))
    assert document["provenance"]["recorded"] is True
    assert [result["task"] for result in document["results"]] == list(FILES[name])
    for result in document["results"]:
        env = gym.make(task_by_name(result["task"]).env_id).unwrapped
        contexts = evaluation_contexts(task_by_name(result["task"]), env)
        assert [row["context"] for row in result["contexts"]] == contexts.tolist()
        assert result["evaluations"] == 300
        for row in result["contexts"]:
            assert np.isfinite(row["best"]) and len(row["u"]) == env.action_space.shape[0]
            assert max(map(abs, row["u"])) <= 1.0
        env.close()


@EXTRAS  # the kick (MuJoCo) and pycma
@pytest.mark.slow
def test_the_best_u_found_gives_the_recorded_error_and_the_farthest_kick_does_not_fall():
    pytest.importorskip("cma")
    document = reach.reach("KickPrecisionLowDim", 12, [[3.0], [12.0]])
    env = gym.make("creps_gym/KickPrecisionLowDim-v0").unwrapped
    for row in document["contexts"]:
        contexts = np.array([row["context"]])
        info = env.evaluate(contexts, np.array([row["u"]]))[1]
        x, y = info["ball_displacement"][0]
        assert np.hypot(x - row["context"][0], y) == pytest.approx(row["best"], abs=1e-9)  # the study's error
    farthest = document["farthest"]
    info = env.evaluate(np.array([[12.0]]), np.array([farthest["u"]]))[1]
    assert not info["fell"][0] and info["ball_displacement"][0, 0] == pytest.approx(farthest["distance"])
    env.close()


def test_the_v1_kicks_in_the_package_are_the_committed_strong_kicks_to_6_decimals():
    """``creps_gym/envs/kick/subspace.py`` keeps the θ that ``strong_kicks.py`` found (its committed JSON)."""
    from benchmarks.low_budget import strong_kicks
    from creps_gym.envs.kick.subspace import POWER_KICK, REACH_KICK

    document = json.loads((RESULTS / "strong_kicks.json").read_text(encoding="utf-8"))
    assert document["provenance"]["recorded"] is True and set(document["kicks"]) == set(strong_kicks.KICKS)
    for name, kept in (("power", POWER_KICK), ("reach", REACH_KICK)):
        kick = document["kicks"][name]
        experiment, context = strong_kicks.KICKS[name]
        assert (kick["experiment"], kick["context"], kick["fell"]) == (experiment, list(context), False)
        assert tuple(round(value, 6) for value in kick["theta"]) == kept
    assert document["kicks"]["power"]["metric"] < 0.05 and document["kicks"]["reach"]["metric"] > 12.0
