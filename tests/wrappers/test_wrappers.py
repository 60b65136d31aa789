"""Context wrappers (fixed sets, samplers, hiding, normalisation) on one-step and native vector envs."""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils import seeding
from gymnasium.utils.env_checker import check_env
from gymnasium.vector import AutoresetMode
from helpers import EXTRAS, make_or_skip, python_blocks

import creps_gym
from creps_gym.envs.base import ContextualEpisodicEnv, ContextualEpisodicVectorEnv, initial_distribution
from creps_gym.wrappers import (
    BetaContexts,
    FixedContexts,
    FixedContextsVector,
    GaussianContexts,
    HideContext,
    HideContextVector,
    NormalizeParams,
    NormalizeParamsVector,
    SampleContexts,
    SampleContextsVector,
    UniformContexts,
    context_splits,
)


class Bowl(ContextualEpisodicEnv):
    """Tiny test env: return -|θ[:2] - s|² - θ[2]², contexts in [-1, 1]², parameters in [-2, 3]³."""

    def __init__(self, render_mode: str | None = None) -> None:
        super().__init__(-np.ones(2), np.ones(2), np.full(3, -2.0), np.full(3, 3.0), render_mode)

    def evaluate(self, contexts, params):
        miss = params[:, :2] - contexts
        return -(miss**2).sum(axis=1) - params[:, 2] ** 2, {"miss": miss}


class BowlVector(ContextualEpisodicVectorEnv):
    single_env_class = Bowl


SET = np.array([[0.1, 0.2], [-0.5, 0.5], [0.9, -0.9]])


def _ctx(reset_result):
    return reset_result[1]["context"]


# -- samplers and splits -------------------------------------------------------------------------------
def test_uniform_sampler_stays_in_box_and_follows_the_generator():
    sampler = UniformContexts([0.0, -1.0], [1.0, 3.0])
    draws = sampler(np.random.default_rng(4), 5000)
    assert draws.shape == (5000, 2)
    assert (draws >= [0.0, -1.0]).all() and (draws <= [1.0, 3.0]).all()
    np.testing.assert_allclose(draws.mean(axis=0), [0.5, 1.0], atol=0.05)
    np.testing.assert_array_equal(draws, sampler(np.random.default_rng(4), 5000))


def test_gaussian_sampler_moments_and_clipping():
    cov = np.array([[0.04, 0.03], [0.03, 0.09]])
    draws = GaussianContexts([0.2, -0.1], cov)(np.random.default_rng(0), 40000)
    np.testing.assert_allclose(draws.mean(axis=0), [0.2, -0.1], atol=0.01)
    np.testing.assert_allclose(np.cov(draws.T), cov, atol=0.005)
    clipped = GaussianContexts([0.0, 0.0], 4.0, low=[-1, -1], high=[1, 1])(np.random.default_rng(0), 1000)
    assert clipped.min() == -1.0 and clipped.max() == 1.0
    diag = GaussianContexts([0.0], [0.25])(np.random.default_rng(1), 20000)
    assert diag.std() == pytest.approx(0.5, rel=0.03)


def test_beta_sampler_weights_the_ends_of_the_box_as_the_arcsine_law_says():
    arcsine = BetaContexts([3.0, -1.0], [12.0, 1.0], 0.5)
    draws = arcsine(np.random.default_rng(0), 200_000)
    assert draws.shape == (200_000, 2)
    assert (draws >= [3.0, -1.0]).all() and (draws <= [12.0, 1.0]).all()
    u = (draws - [3.0, -1.0]) / [9.0, 2.0]
    # Arcsine CDF (2/π)·asin(√u): a third of the draws in each outer quarter, 15.1 % in each outer 1/18.
    for side in (u, 1.0 - u):
        np.testing.assert_allclose((side < 0.25).mean(axis=0), 1 / 3, atol=0.005)
        np.testing.assert_allclose(
            (side < 1 / 18).mean(axis=0), 2 / np.pi * np.arcsin(np.sqrt(1 / 18)), atol=0.004
        )
    skewed = BetaContexts([0.0], [1.0], 2.0, 6.0)(np.random.default_rng(1), 100_000)
    assert skewed.mean() == pytest.approx(0.25, abs=0.003)  # a / (a + b)
    assert skewed.var() == pytest.approx(2 * 6 / (8**2 * 9), rel=0.03)  # ab / ((a + b)²(a + b + 1))
    np.testing.assert_array_equal(draws, arcsine(np.random.default_rng(0), 200_000))
    assert "a=0.5, b=0.5" in repr(arcsine)
    with pytest.raises(TypeError, match="a: expected a real number"):
        BetaContexts([0.0], [1.0], "0.5")


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda: GaussianContexts([0.0, 0.0], [[1.0, 2.0], [2.0, 1.0]]), "positive semi-definite"),
        (lambda: GaussianContexts([0.0, 0.0], [[1.0, 0.5], [0.0, 1.0]]), "symmetric"),
        (lambda: GaussianContexts([0.0, 0.0], [1.0, -1.0]), "non-negative"),
        (lambda: GaussianContexts([0.0], 1.0, low=[0.0]), "both or neither"),
        (lambda: UniformContexts([1.0], [0.0]), "low <= high"),
        (lambda: UniformContexts([0.0, np.nan], [1.0, 1.0]), "finite"),
        (lambda: BetaContexts([1.0], [0.0], 0.5), "low <= high"),
        (lambda: BetaContexts([0.0], [1.0], 0.0), "a: expected a finite value > 0"),
        (lambda: BetaContexts([-1e308], [1e308], 0.5), "width high - low is finite"),
        (lambda: BetaContexts([0.0], [1.0], 0.5, np.inf), "b: expected a finite value > 0"),
    ],
)
def test_sampler_bad_inputs(make, message):
    with pytest.raises(ValueError, match=message):
        make()


def test_context_splits_are_seeded_named_and_distinct():
    splits = context_splits(Bowl(), {"train": 20, "test": 7}, seed=3)
    assert set(splits) == {"train", "test"}
    assert splits["train"].shape == (20, 2) and splits["test"].shape == (7, 2)
    assert not np.isin(splits["test"], splits["train"]).any()
    again = context_splits(Bowl(), {"train": 20, "test": 7}, seed=3)
    np.testing.assert_array_equal(splits["test"], again["test"])
    other = context_splits(UniformContexts([-1, -1], [1, 1]), {"train": 20}, seed=4)
    assert not np.array_equal(other["train"], splits["train"])
    with pytest.raises(ValueError, match="non-empty mapping"):
        context_splits(Bowl(), {}, seed=0)
    with pytest.raises(ValueError, match=r"sizes\['test'\]"):
        context_splits(Bowl(), {"test": 0}, seed=0)
    with pytest.raises(TypeError, match="source"):
        context_splits(3, {"test": 1}, seed=0)


# -- scalar wrappers -----------------------------------------------------------------------------------
def test_fixed_contexts_cycle_restarts_on_seed_and_sets_the_task():
    env = FixedContexts(Bowl(), SET, order="cycle", name="test")
    seen = [_ctx(env.reset(seed=0))] + [_ctx(env.reset()) for _ in range(3)]
    np.testing.assert_array_equal(seen, np.vstack([SET, SET[:1]]))
    _, info = env.reset(seed=5)
    np.testing.assert_array_equal(info["context"], SET[0])
    assert info["context_index"] == 0 and env.name == "test"
    _, reward, terminated, _, step_info = env.step(np.array([0.1, 0.2, 0.0]))
    assert reward == 0.0 and terminated
    np.testing.assert_array_equal(step_info["context"], SET[0])
    _, info = env.reset(options={"context": [0.0, 0.0]})
    np.testing.assert_array_equal(info["context"], [0.0, 0.0])
    assert "context_index" not in info


@pytest.mark.parametrize("order", ["cycle", "random"])
@pytest.mark.parametrize(
    ("seed", "options", "match"),
    [
        (None, {"bogus": 1}, "unknown keys"),
        (5, {"bogus": 1}, "unknown keys"),
        (5, {"context": [9.0, 9.0]}, "context box"),
    ],
)
def test_a_rejected_reset_leaves_the_context_wrapper_unchanged(order, seed, options, match):
    """Neither the cycle position nor the generator moves when the wrapped env rejects the reset."""
    env, twin = (FixedContexts(Bowl(), SET, order=order) for _ in range(2))
    for wrapper in (env, twin):
        wrapper.reset(seed=0)
        wrapper.reset()
    with pytest.raises(ValueError, match=match):
        env.reset(seed=seed, options=options)
    after, expected = ([_ctx(wrapper.reset()) for _ in range(4)] for wrapper in (env, twin))
    np.testing.assert_array_equal(after, expected)


@pytest.mark.parametrize("options", [{"bogus": 1}, {"context": np.full((2, 2), 9.0)}])
def test_a_rejected_reset_leaves_the_vector_context_wrapper_unchanged(options):
    env, twin = (FixedContextsVector(BowlVector(2), SET) for _ in range(2))
    for wrapper in (env, twin):
        wrapper.reset(seed=0)
    with pytest.raises(ValueError):
        env.reset(seed=3, options=options)
    np.testing.assert_array_equal(env.reset()[1]["context"], twin.reset()[1]["context"])


def test_fixed_contexts_random_is_seeded_and_covers_the_set():
    def run(seed):
        env = FixedContexts(Bowl(), SET, order="random")
        infos = [env.reset(seed=seed)[1]] + [env.reset()[1] for _ in range(59)]
        return np.array([i["context_index"] for i in infos]), np.array([i["context"] for i in infos])

    index, contexts = run(1)
    np.testing.assert_array_equal(contexts, SET[index])
    assert set(index.tolist()) == {0, 1, 2}
    np.testing.assert_array_equal(run(1)[0], index)
    assert not np.array_equal(run(2)[0], index)


def test_fixed_contexts_bad_inputs():
    with pytest.raises(ValueError, match="contexts: expected values in the context box"):
        FixedContexts(Bowl(), [[2.0, 0.0]])
    with pytest.raises(ValueError, match=r"contexts: expected shape \(n, 2\)"):
        FixedContexts(Bowl(), [[0.0, 0.0, 0.0]])
    with pytest.raises(ValueError, match="order"):
        FixedContexts(Bowl(), SET, order="shuffle")
    with pytest.raises(ValueError, match="at least one context"):
        FixedContexts(Bowl(), np.zeros((0, 2)))
    with pytest.raises(TypeError, match="ContextualEpisodicEnv"):
        FixedContexts(gym.make("CartPole-v1"), SET)


@pytest.mark.parametrize("contexts", [[0.5, 1.0], 0.5, [[[0.5]]]], ids=["1-D", "scalar", "3-D"])
def test_fixed_contexts_of_the_wrong_rank_name_the_expected_shape_n_by_z(contexts):
    """Before: the message said ``expected shape (n, n)`` for a one-dimensional context box."""
    env = gym.make("creps_gym/Sphere-v0")  # z = 1
    with pytest.raises(ValueError, match=r"contexts: expected shape \(n, 1\), got "):
        FixedContexts(env, contexts)
    vector = gym.make_vec("creps_gym/Sphere-v0", 2)
    with pytest.raises(ValueError, match=r"contexts: expected shape \(n, 1\), got "):
        FixedContextsVector(vector, contexts)


def test_sample_contexts_draws_from_the_env_np_random():
    sampler = GaussianContexts([0.2, -0.3], 0.1, low=[-1, -1], high=[1, 1])
    env = SampleContexts(Bowl(), sampler)
    seen = [_ctx(env.reset(seed=11))] + [_ctx(env.reset()) for _ in range(4)]
    rng = seeding.np_random(11)[0]
    np.testing.assert_array_equal(seen, [sampler(rng, 1)[0] for _ in range(5)])
    assert env.np_random_seed == -1  # the wrapper seeded the env's generator itself


def test_sample_contexts_user_callable_and_bad_samplers():
    env = SampleContexts(Bowl(), lambda rng, n: np.tile([0.5, rng.uniform(-1, 1)], (n, 1)))
    contexts = np.array([_ctx(env.reset(seed=s)) for s in range(3)])
    assert (contexts[:, 0] == 0.5).all() and len(set(contexts[:, 1])) == 3
    with pytest.raises(ValueError, match=r"sampler .* output: expected values in the context box"):
        SampleContexts(Bowl(), UniformContexts([1.5, 0.0], [2.0, 0.0])).reset(seed=0)
    with pytest.raises(ValueError, match=r"sampler .* output: expected shape \(1, 2\)"):
        SampleContexts(Bowl(), lambda rng, n: np.zeros((n, 3))).reset(seed=0)
    with pytest.raises(TypeError, match="sampler: expected a callable"):
        SampleContexts(Bowl(), [0.0, 0.0])


def test_hide_context_keeps_the_context_in_info_only():
    base = Bowl()
    env = HideContext(FixedContexts(Bowl(), SET))
    obs, info = env.reset(seed=0)
    assert obs.shape == (0,) and env.observation_space.shape == (0,)
    assert env.observation_space.contains(obs)
    theta = np.array([0.3, -0.2, 1.0])
    obs, reward, *_, step_info = env.step(theta)
    base.reset(options={"context": info["context"]})
    assert obs.shape == (0,) and reward == base.step(theta)[1]
    np.testing.assert_array_equal(step_info["context"], SET[0])


def test_normalize_params_maps_the_unit_box_onto_the_bounds():
    env = NormalizeParams(Bowl())
    assert env.action_space == gym.spaces.Box(-1.0, 1.0, (3,), np.float64)
    np.testing.assert_array_equal(env.action(-np.ones(3)), np.full(3, -2.0))
    np.testing.assert_array_equal(env.action(np.ones(3)), np.full(3, 3.0))
    np.testing.assert_array_equal(env.action(np.zeros(3)), np.full(3, 0.5))
    u = np.array([0.2, -0.7, 0.4])
    np.testing.assert_allclose(env.normalize(env.action(u)), u)
    env.reset(options={"context": [0.5, 0.5]})
    _, reward, *_ = env.step(u)
    theta = env.action(u)
    assert reward == pytest.approx(-((theta[:2] - 0.5) ** 2).sum() - theta[2] ** 2)
    with pytest.raises(ValueError, match=r"action: expected shape \(3,\)"):
        env.step(np.zeros(2))
    with pytest.raises(TypeError, match="1-D Box"):
        NormalizeParams(gym.make("CartPole-v1"))


def test_normalize_params_maps_the_declared_initial_distribution():
    """N(mean, std²) of the env becomes N(normalize(mean), (2 std / (high − low))²) in [-1, 1]^p."""

    class Declaring(gym.Wrapper):
        def initial_distribution(self):
            return np.array([-2.0, 0.5, 2.0]), np.array([0.5, 1.0, 0.25])

    env = NormalizeParams(Declaring(Bowl()))
    mean, std = initial_distribution(env)
    np.testing.assert_allclose(mean, [-1.0, 0.0, 0.6])
    np.testing.assert_allclose(std, [0.2, 0.4, 0.1])
    box_mean, box_std = initial_distribution(NormalizeParams(Bowl()))  # the box rule maps onto itself
    np.testing.assert_array_equal(box_mean, np.zeros(3))
    np.testing.assert_array_equal(box_std, np.full(3, 0.5))


def test_normalize_params_rejects_infinite_bounds():
    env = Bowl()
    env.action_space = gym.spaces.Box(-np.inf, np.inf, (3,), np.float64)
    with pytest.raises(ValueError, match="finite bounds"):
        NormalizeParams(env)


@pytest.mark.filterwarnings("ignore:.*is different from the unwrapped version")
def test_stacked_scalar_wrappers_pass_check_env():
    env = NormalizeParams(HideContext(SampleContexts(Bowl(), UniformContexts([-1, -1], [1, 1]))))
    check_env(env, skip_render_check=True)
    obs, info = env.reset(seed=2)
    assert obs.shape == (0,) and info["context"].shape == (2,)


# -- vector wrappers on the native vector env ----------------------------------------------------------
def test_fixed_contexts_vector_per_env_contexts_and_same_step_autoreset():
    env = FixedContextsVector(BowlVector(num_envs=2), SET, order="cycle")
    obs, info = env.reset(seed=0)
    np.testing.assert_array_equal(obs, SET[:2])
    np.testing.assert_array_equal(info["context_index"], [0, 1])
    theta = np.array([[0.1, 0.2, 0.0], [0.0, 0.0, 0.0]])
    obs, rewards, terminated, _, info = env.step(theta)
    np.testing.assert_array_equal(rewards, Bowl().evaluate(SET[:2], theta)[0])
    np.testing.assert_array_equal(info["final_obs"], SET[:2])
    np.testing.assert_array_equal(obs, SET[[2, 0]])  # the wrapper's next contexts, not the env's
    np.testing.assert_array_equal(info["context"], SET[[2, 0]])
    assert terminated.all()
    obs, info = env.reset(options={"reset_mask": np.array([False, True])})
    np.testing.assert_array_equal(obs, SET[[2, 1]])
    np.testing.assert_array_equal(info["_context_index"], [False, True])
    with pytest.raises(ValueError, match=r"options\['reset_mask'\]: expected a bool array of shape \(2,\)"):
        env.reset(seed=3, options={"reset_mask": np.array([1, 0])})
    np.testing.assert_array_equal(env.reset()[0], SET[[2, 0]])  # the rejected call left the cycle alone


def test_sample_contexts_vector_seeded_per_env_draws_in_disabled_mode():
    sampler = UniformContexts([-1, -1], [1, 1])
    base = BowlVector(num_envs=3, autoreset_mode=AutoresetMode.DISABLED)
    env = SampleContextsVector(base, sampler)
    obs, _ = env.reset(seed=7)
    np.testing.assert_array_equal(obs, sampler(seeding.np_random(7)[0], 3))
    assert len({tuple(row) for row in obs}) == 3
    final, rewards, *_ = env.step(np.zeros((3, 3)))
    np.testing.assert_array_equal(final, obs)
    np.testing.assert_array_equal(rewards, -(obs**2).sum(axis=1))
    with pytest.raises(RuntimeError, match="not reset"):
        env.step(np.zeros((3, 3)))
    again, _ = SampleContextsVector(BowlVector(num_envs=3), sampler).reset(seed=7)
    np.testing.assert_array_equal(again, obs)


def test_hide_and_normalize_vector():
    env = NormalizeParamsVector(HideContextVector(FixedContextsVector(BowlVector(num_envs=2), SET)))
    obs, info = env.reset(seed=0)
    assert obs.shape == (2, 0) and env.single_observation_space.shape == (0,)
    u = np.array([[1.0, -1.0, 0.0], [0.0, 0.0, -1.0]])
    obs, rewards, _, _, info = env.step(u)
    theta = -2.0 + 0.5 * (u + 1.0) * 5.0
    np.testing.assert_allclose(rewards, Bowl().evaluate(SET[:2], theta)[0])
    assert obs.shape == (2, 0) and info["final_obs"].shape == (2, 0)
    np.testing.assert_array_equal(info["context"], SET[[2, 0]])
    with pytest.raises(ValueError, match=r"actions: expected shape \(2, 3\)"):
        env.step(np.zeros((3, 3)))


def test_vector_wrappers_reject_non_native_vector_envs():
    sync = gym.make_vec("creps_gym/Sphere-v0", num_envs=2, vectorization_mode="sync")
    for wrapper in (
        lambda e: FixedContextsVector(e, [[1.0]]),
        lambda e: SampleContextsVector(e, UniformContexts([0.0], [1.0])),
        HideContextVector,
    ):
        with pytest.raises(TypeError, match="ContextualEpisodicVectorEnv"):
            wrapper(sync)
    sync.close()


NATIVE_IDS = [i for i in creps_gym.registered_ids() if gym.spec(i).vector_entry_point is not None]


@pytest.mark.parametrize("env_id", NATIVE_IDS)
def test_every_vector_wrapper_on_every_registered_native_vector_env(env_id):
    vec = make_or_skip(env_id, vector=True, num_envs=2)
    model = vec.unwrapped.model
    low, high = model.observation_space.low, model.observation_space.high
    contexts = np.vstack([low, high, 0.5 * (low + high)])
    env = NormalizeParamsVector(HideContextVector(FixedContextsVector(vec, contexts, order="random")))
    _, info = env.reset(seed=1)
    np.testing.assert_array_equal(info["context"], contexts[info["context_index"]])
    u = np.random.default_rng(0).uniform(-1, 1, size=(2, model.param_dim))
    obs, rewards, *_ = env.step(u)
    theta = env.actions(u)
    np.testing.assert_allclose(rewards, model.evaluate(info["context"], theta)[0], rtol=1e-12)
    assert obs.shape == (2, 0)
    sampled = SampleContextsVector(gym.make_vec(env_id, num_envs=2), UniformContexts(low, high))
    obs, _ = sampled.reset(seed=3)
    np.testing.assert_array_equal(obs, UniformContexts(low, high)(seeding.np_random(3)[0], 2))


DOC = Path(__file__).resolve().parents[2] / "docs" / "wrappers.md"


@pytest.mark.parametrize("index", [0, 1, pytest.param(2, marks=EXTRAS)])  # block 2 makes a MuJoCo env
def test_doc_examples_run(index, capsys):
    blocks = python_blocks(DOC)
    assert len(blocks) == 5
    exec(compile(blocks[index], f"{DOC}:block{index}", "exec"), {"__name__": "docs"})
    assert "return" in capsys.readouterr().out


@pytest.mark.filterwarnings("ignore:.*(is different from the unwrapped version|symmetric and normalized)")
@pytest.mark.parametrize("env_id", creps_gym.registered_ids())
@pytest.mark.slow
def test_check_env_on_every_wrapped_registered_id(env_id):
    env = make_or_skip(env_id)
    low, high = env.observation_space.low, env.observation_space.high
    stacked = NormalizeParams(HideContext(SampleContexts(env, UniformContexts(low, high))))
    check_env(stacked, skip_render_check=True)
    _, info = stacked.reset(seed=0)
    np.testing.assert_array_equal(info["context"], UniformContexts(low, high)(seeding.np_random(0)[0], 1)[0])
    fixed = FixedContexts(make_or_skip(env_id), np.vstack([low, high]), order="random")
    check_env(fixed, skip_render_check=True)
    assert fixed.reset(seed=1)[1]["context_index"] in (0, 1)


def test_one_model_lookup_with_one_message_for_every_kind():
    from creps_gym.envs.evaluation import contextual_model

    env = gym.make("creps_gym/Sphere-v0", dim=3)
    vec = gym.make_vec("creps_gym/Sphere-v0", 2, vectorization_mode="vector_entry_point", dim=3)
    assert contextual_model(env) is env.unwrapped and contextual_model(vec) is vec.unwrapped.model
    assert contextual_model(env, ("env",)) is env.unwrapped
    scalar = r"env: HideContext expected a creps_gym ContextualEpisodicEnv \(possibly wrapped\)"
    with pytest.raises(TypeError, match=scalar + ", got SphereVectorEnv$"):
        contextual_model(vec, ("env",), user="HideContext")
    native = r"env: expected a native creps_gym ContextualEpisodicVectorEnv \(possibly wrapped\)"
    with pytest.raises(TypeError, match=native + ", got SphereEnv$"):
        contextual_model(env, ("vector",))
    with pytest.raises(ValueError, match=r"accept: expected a non-empty tuple of \('env', 'vector'\)"):
        contextual_model(env, ("gpu",))
