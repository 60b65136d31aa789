"""Failures during a run: one retry policy on every backend, retried resets, checked rewards, set-up errors,
foreign optimisers and an evaluation that sees the user's wrappers (issue 15, items 8-10, 16-18)."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest
from flaky_envs import OddReward, flaky, register
from gymnasium.wrappers import TransformReward
from helpers import SPHERE

from creps_gym.errors import EpisodeError
from creps_gym.optimizers import CREPSCMA
from creps_gym.runner import RunConfig, Runner, run
from creps_gym.runner.backends import episode_return

BACKENDS = {
    "serial": {},
    "sync": {"backend": "vector", "vector_mode": "sync", "workers": 10},
    "async": {"backend": "vector", "vector_mode": "async", "workers": 5},
    "native": {"backend": "vector", "vector_mode": "native"},
}
SEEDS = (0, 1, 2)


@pytest.fixture(scope="module")
def references():
    """Runs of the env that never fails (serial; every backend gives the same bits)."""
    return {seed: run(CREPSCMA(2, 1, seed=seed), flaky(), 3, 20, seed) for seed in SEEDS}


@pytest.mark.parametrize("backend", BACKENDS.values(), ids=BACKENDS)
@pytest.mark.parametrize("flakes", [{"step_rate": 0.1}, {"reset_rate": 0.1}], ids=["steps", "resets"])
@pytest.mark.slow
def test_flaky_steps_and_resets_are_retried_alike_on_every_backend_and_lose_no_sample(
    flakes, backend, references
):
    """Each step (or reset) fails with probability 0.1; 3 retries absorb that alike on every backend."""
    for seed in SEEDS:
        env = flaky(flake_seed=seed, **flakes)
        history = run(CREPSCMA(2, 1, seed=seed), env, 3, 20, seed, retries=3, **backend)
        assert history.equals(references[seed]), seed


@pytest.mark.parametrize(
    ("draws", "where"),
    [
        ("reset", r"\(reset seed \d+\): reset"),  # the context is read from the reset
        ("batch", r"\(reset seed \d+, context \[[-0-9.e, ]+\]\)"),
    ],  # drawn first: the episode's reset fails
)
def test_a_reset_that_keeps_failing_stops_the_run_with_an_episode_error(draws, where):
    pattern = rf"iteration 1, episode 0 {where} failed 2 time\(s\); last error: RuntimeError: simulated reset"
    with pytest.raises(EpisodeError, match=pattern):
        run(CREPSCMA(2, 1, seed=0), flaky(reset_rate=1.0), 2, 10, 0, retries=1, context_draws=draws)


@pytest.mark.parametrize("backend", BACKENDS.values(), ids=BACKENDS)
@pytest.mark.slow
def test_an_episode_that_keeps_failing_gives_the_same_error_on_every_backend(backend):
    def message(**options):
        env = flaky(fail_above=0.5)
        with pytest.raises(EpisodeError) as caught:
            run(CREPSCMA(2, 1, seed=0), env, 2, 10, 0, retries=2, **options)
        return str(caught.value)

    serial = message()
    assert "failed 3 time(s); last error: RuntimeError: simulated crash" in serial
    assert message(**backend) == serial


@pytest.mark.parametrize("reward", ["1.5", True, np.bool_(False), None, 1 + 0j, [1.0, 2.0]], ids=repr)
@pytest.mark.parametrize("backend", ["serial", "sync"])
def test_a_reward_that_is_not_a_real_number_is_refused_not_converted(reward, backend):
    register()
    env = gym.make("test/OddReward-v0", reward=reward, disable_env_checker=True)
    options = {"backend": "vector", "vector_mode": "sync", "workers": 2} if backend == "sync" else {}
    pattern = r"episode 0 .* failed 2 time\(s\); last error: TypeError: reward: expected a real number"
    with pytest.raises(EpisodeError, match=pattern):
        run(CREPSCMA(1, 1, seed=0), env, 2, 10, 0, retries=1, **options)


def test_real_rewards_of_any_numeric_type_are_accepted():
    for reward in (2, np.float32(0.25), np.int64(-3), np.array(1.5), np.array([0.5])):
        assert episode_return(reward) == float(np.asarray(reward).reshape(()))
    for reward, error in (("2", TypeError), (False, TypeError), (math.inf, ValueError)):
        with pytest.raises(error):
            episode_return(reward)
    history = run(CREPSCMA(1, 1, seed=0), OddReward(np.float32(0.25)), 2, 10, 0)
    assert history.records[-1].mean_return == 0.25


def test_evaluation_goes_through_the_users_reward_wrapper():
    """Regression: eval_return of TransformReward(1000 r - 5) around Sphere was the raw Sphere's (-1.7)."""
    env = TransformReward(gym.make(SPHERE, dim=3), lambda r: 1000.0 * r - 5.0)
    history = run(CREPSCMA(3, 1, seed=0, initial_cov=4.0), env, 3, 10, 0)
    assert history.meta["metric"] == "return" and np.isnan(history.column("eval_regret")).all()
    train, evaluated = history.column("mean_return"), history.column("eval_return")
    assert np.all(evaluated < -100.0) and np.all(train < -100.0)  # both on the wrapper's scale
    runner = Runner(RunConfig(None, None, 1, 10, 0), env=env, optimizer=CREPSCMA(3, 1, seed=0))
    params = runner.optimizer.recommend(runner.test_contexts)
    by_hand = []
    for seed, context, theta in zip(runner.eval_seeds, runner.test_contexts, params, strict=True):
        assert np.array_equal(env.reset(seed=int(seed))[0], context)
        by_hand.append(env.step(theta)[1])
    assert runner.evaluate() == (np.mean(by_hand), pytest.approx(math.nan, nan_ok=True))


def test_model_preserving_wrappers_keep_the_regret_evaluation():
    from creps_gym.wrappers import FixedContexts

    env = FixedContexts(gym.make(SPHERE, dim=3), [[0.5], [1.0]])
    history = run(CREPSCMA(3, 1, seed=0), env, 2, 10, 0)
    assert history.meta["metric"] == "regret" and np.isfinite(history.column("eval_regret")).all()


def test_an_env_the_vector_backend_cannot_copy_is_a_set_up_error():
    class Doubled(gym.Wrapper):  # no RecordConstructorArgs: gymnasium cannot re-create it from the spec
        def step(self, action):
            obs, reward, terminated, truncated, info = self.env.step(action)
            return obs, 2.0 * reward, terminated, truncated, info

    started = []
    env = Doubled(gym.make(SPHERE, dim=3))
    options = {"backend": "vector", "vector_mode": "sync", "callbacks": [lambda r, h: started.append(r)]}
    with pytest.raises(TypeError, match=r"env: the vector backend \(sync\) could not build copies .*Doubled"):
        run(CREPSCMA(3, 1, seed=0), env, 2, 10, 0, **options)
    assert started == []  # refused before the first iteration, not as an episode failure
    reward_wrapped = TransformReward(gym.make(SPHERE, dim=3), lambda r: 2.0 * r)
    with pytest.raises(ValueError, match=r"vector_mode: expected 'auto', 'sync' or 'async' .*adds wrappers"):
        run(CREPSCMA(3, 1, seed=0), reward_wrapped, 2, 10, 0, backend="vector", vector_mode="native")
    serial = run(CREPSCMA(3, 1, seed=0), reward_wrapped, 2, 10, 0)
    vector = run(CREPSCMA(3, 1, seed=0), reward_wrapped, 2, 10, 0, backend="vector", vector_mode="sync")
    assert vector.equals(serial)


def test_foreign_optimisers_are_refused_with_the_adapter_to_use():
    cma = pytest.importorskip("cma")
    strategy = cma.CMAEvolutionStrategy(np.zeros(3), 1.0, {"verbose": -9, "seed": 1})
    adapter = r"raw cma\..*CMAEvolutionStrategy; use the adapter .*pycma\.CMAAdapter \(registry name 'cma'\)"
    with pytest.raises(TypeError, match=adapter):
        run(strategy, SPHERE, 2, 10, 0, env_kwargs=None)
    with pytest.raises(TypeError, match=r"optimizer: expected an ask/tell optimiser .* without ask, tell"):
        run(object(), SPHERE, 2, 10, 0)
    with pytest.raises(TypeError, match=r"got the class creps_gym\.optimizers\.creps_cma\.CREPSCMA"):
        run(CREPSCMA, SPHERE, 2, 10, 0)


@pytest.mark.parametrize("library", ["nevergrad", "optuna"])
def test_raw_nevergrad_and_optuna_objects_name_their_adapter(library):
    module = pytest.importorskip(library)
    if library == "nevergrad":
        raw = module.optimizers.TwoPointsDE(parametrization=3, budget=10)
    else:
        raw = module.create_study()
    adapter = {"nevergrad": "NevergradAdapter", "optuna": "OptunaAdapter"}[library]
    with pytest.raises(TypeError, match=rf"raw {library}\..*use the adapter .*{adapter}"):
        run(raw, SPHERE, 2, 10, 0)
