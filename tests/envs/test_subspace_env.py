"""AffineSubspaceEnv and the registered low-dimensional ids: θ = θ_ref + B u, the full env's task at u = 0,
the recipes' structure and bad arguments. (Every registered id also goes through the registry-driven env
tests: check_env, overflow, the runner.)"""

from __future__ import annotations

import hashlib

import gymnasium as gym
import numpy as np
import pytest
from helpers import EXTRAS

from creps_gym.envs.kick import REGISTRATIONS as KICK_REGISTRATIONS
from creps_gym.envs.kick.subspace import (
    DIRECTIONS,
    METAPARAMETERS,
    POWER_KICK,
    REACH_KICK,
    kick_metaparameters,
)
from creps_gym.envs.reacher.subspace import via_point_bumps
from creps_gym.envs.subspace import AffineSubspaceEnv

REACHER = "creps_gym/PlanarReacher-v1"


def test_the_low_dimensional_reacher_evaluates_the_full_reacher_at_the_mapped_parameters():
    env = gym.make("creps_gym/PlanarReacherLowDim-v0").unwrapped
    full = gym.make(REACHER).unwrapped
    rng = np.random.default_rng(0)
    contexts, u = env.sample_contexts(rng, 6), rng.uniform(-1, 1, (6, 5))
    returns, info = env.evaluate(contexts, u)
    theta = env.reference + u @ env.basis.T
    np.testing.assert_allclose(info["full_params"], theta, rtol=1e-15, atol=1e-12)
    assert returns.tobytes() == full.evaluate(contexts, info["full_params"])[0].tobytes()
    zero = env.evaluate(contexts, np.zeros((6, 5)))[0]
    assert zero.tobytes() == full.evaluate(contexts, np.zeros((6, 25)))[0].tobytes()  # u = 0: the plain DMP
    mean, std = env.initial_distribution()
    assert mean.tolist() == [0.0] * 5 and std.tolist() == [0.3] * 5
    assert env.param_names == [f"bump/joint{j}" for j in range(5)]


def test_a_batch_gives_the_bits_of_single_rows():
    env = gym.make("creps_gym/PlanarReacherLowDim-v0").unwrapped
    rng = np.random.default_rng(1)
    contexts, u = env.sample_contexts(rng, 5), rng.uniform(-1, 1, (5, 5))
    batch = env.evaluate(contexts, u)[0]
    single = [env.evaluate(contexts[i : i + 1], u[i : i + 1])[0][0] for i in range(5)]
    assert batch.tobytes() == np.array(single).tobytes()


def test_the_reacher_recipe_bumps_each_joint_only_and_spans_the_box():
    _, basis, names = via_point_bumps(gym.make(REACHER).unwrapped)
    assert basis.shape == (25, 5) and len(names) == 5
    for joint in range(5):
        rows = np.flatnonzero(basis[:, joint])
        assert rows.min() >= 5 * joint and rows.max() < 5 * joint + 5
        assert basis[:, joint].max() == 30.0 and (basis[:, joint] >= 0).all()


class _Kick:
    """Stands in for a kick env (its reference kick only), so the recipe is checked without MuJoCo."""

    def reference_params(self) -> np.ndarray:
        return np.linspace(-0.5, 0.5, 25)


def test_the_kick_recipe_has_six_independent_metaparameters_around_the_reference():
    reference, basis, names = kick_metaparameters(_Kick())
    assert names == list(METAPARAMETERS) and basis.shape == (25, 6)
    assert np.linalg.matrix_rank(basis) == 6 and reference.tolist() == _Kick().reference_params().tolist()
    swing = reference[12:18] - reference[0:6]
    np.testing.assert_allclose(basis[12:18, 0], 0.5 * swing)  # the amplitude scales the kicking leg's swing
    assert basis[24].tolist() == [0, 0, 0, 0.5, 0, 0]  # only `duration` moves the swing time


def test_the_v1_recipes_add_the_columns_to_the_power_and_reach_kicks_after_the_six():
    reference = _Kick().reference_params()
    six = kick_metaparameters(_Kick())[1]
    for extra in (("power",), ("power", "reach"), ("reach",)):
        _, basis, names = kick_metaparameters(_Kick(), (*METAPARAMETERS, *extra))
        assert names == [*METAPARAMETERS, *extra] and basis.shape == (25, 6 + len(extra))
        assert basis[:, :6].tobytes() == six.tobytes() and np.linalg.matrix_rank(basis) == basis.shape[1]
        for column, name in enumerate(extra, start=6):
            kick = POWER_KICK if name == "power" else REACH_KICK
            np.testing.assert_allclose(
                reference + basis[:, column], kick, rtol=0, atol=1e-15
            )  # u = 1: the kick
    registered = {r["id"]: r["kwargs"].get("names") for r in KICK_REGISTRATIONS if "LowDim" in r["id"]}
    assert registered == {
        "creps_gym/KickPrecisionLowDim-v0": None,
        "creps_gym/KickFlexibilityLowDim-v0": None,
        "creps_gym/KickPrecisionLowDim-v1": (*METAPARAMETERS, "power"),
        "creps_gym/KickFlexibilityLowDim-v1": (*METAPARAMETERS, "power", "reach"),
        "creps_gym/KickPrecisionLowDim-v2": ("duration", "aim", "power"),
        "creps_gym/KickFlexibilityLowDim-v2": ("aim", "lean", "power", "reach"),
    }


def test_a_recipe_of_a_few_directions_takes_their_columns_in_its_order():
    """The v2 ids search a few of the eight directions: the same columns as in the v1 recipe, which are the
    columns the recipe gave before it took any subset (their SHA-256, computed by the recipe of 5ad396f)."""
    _, eight, names = kick_metaparameters(_Kick(), DIRECTIONS)
    assert names == [*METAPARAMETERS, "power", "reach"] and eight.shape == (25, 8)
    digest = hashlib.sha256(np.ascontiguousarray(eight).tobytes()).hexdigest()
    assert digest == "e14a731f83a4f9268f5d4ff548c6cc292f4121fdb5eaa8dc36b34fcd56a77698"
    for few in (("duration", "aim", "power"), ("power", "amplitude"), ("reach",)):
        _, basis, chosen = kick_metaparameters(_Kick(), few)
        assert chosen == list(few)
        assert basis.tobytes() == eight[:, [DIRECTIONS.index(n) for n in few]].tobytes()


@pytest.mark.parametrize(
    "names",
    [
        (),
        (*METAPARAMETERS, "power", "power"),
        (*METAPARAMETERS, "speed"),
        ("aim", "aim"),
    ],
)
def test_a_recipe_of_unknown_or_repeated_names_is_refused_naming_them(names):
    with pytest.raises(
        ValueError, match=r"^names: expected distinct names of \['amplitude', .*'reach'\], got"
    ):
        kick_metaparameters(_Kick(), names)


@EXTRAS
@pytest.mark.parametrize(
    ("env_id", "context", "column", "forward"),
    [
        ("creps_gym/KickPrecisionLowDim-v1", [12.0], 6, (11.95, 12.05)),
        ("creps_gym/KickFlexibilityLowDim-v1", [0.30, 0.0], 7, (12.0, 12.5)),
        ("creps_gym/KickPrecisionLowDim-v2", [12.0], 2, (11.95, 12.05)),  # v2's `power` and `reach`: the
        ("creps_gym/KickFlexibilityLowDim-v2", [0.30, 0.0], 3, (12.0, 12.5)),  # same kicks
    ],
)
def test_the_strong_kicks_at_their_unit_vectors_stand_and_go_as_far_as_documented(
    env_id, context, column, forward
):
    env = gym.make(env_id).unwrapped
    u = np.zeros((1, env.action_space.shape[0]))
    u[0, column] = 1.0
    info = env.evaluate(np.array([context]), u)[1]
    assert not info["fell"][0] and forward[0] < info["ball_displacement"][0, 0] < forward[1]


@EXTRAS
@pytest.mark.parametrize(
    ("low", "full"), [("Precision", "KickPrecision-v1"), ("Flexibility", "KickFlexibility-v2")]
)
def test_a_low_dimensional_kick_at_zero_is_the_reference_kick(low, full):
    env = gym.make(f"creps_gym/Kick{low}LowDim-v0").unwrapped
    full_env = gym.make(f"creps_gym/{full}").unwrapped
    contexts = env.sample_contexts(np.random.default_rng(0), 2)
    reference = np.tile(full_env.reference_params(), (2, 1))
    assert (
        env.evaluate(contexts, np.zeros((2, 6)))[0].tobytes()
        == full_env.evaluate(contexts, reference)[0].tobytes()
    )


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        ({"reference": np.zeros(3)}, ValueError, r"reference: expected shape \(25,\)"),
        ({"basis": np.zeros((25, 2))}, ValueError, "basis: expected 1 to 25 linearly independent columns"),
        ({"basis": np.ones((25, 2))}, ValueError, "basis: expected 1 to 25 linearly independent columns"),
        ({"basis": np.eye(25, 2) * np.nan}, ValueError, "basis: expected finite values"),
        ({"names": ["a"]}, ValueError, "names: expected 2 names"),
        ({"initial_std": 0.0}, ValueError, "initial_std: expected a finite value > 0"),
        ({"env": "creps_gym/PlanarReacher-v1"}, TypeError, "env: expected a ContextualEpisodicEnv"),
    ],
)
def test_bad_arguments_are_refused_naming_them(kwargs, error, match):
    arguments = {"env": gym.make(REACHER).unwrapped, "reference": np.zeros(25), "basis": np.eye(25, 2)}
    arguments.update(kwargs)
    with pytest.raises(error, match=match):
        AffineSubspaceEnv(**arguments)


def test_the_vector_env_and_the_step_api_work_through_gymnasium():
    vector = gym.make_vec("creps_gym/PlanarReacherLowDim-v0", num_envs=3)
    vector.reset(seed=0)
    _, rewards, terminated, _, _ = vector.step(np.zeros((3, 5)))
    assert rewards.shape == (3,) and terminated.all()
