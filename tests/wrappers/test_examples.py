"""The registered ecosystem examples (PointMaze, Reacher): manual, rendering, native vector env, seeding."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import textwrap

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils import seeding
from helpers import EXTRAS, SPHERE, make_or_skip

import creps_gym  # noqa: F401  (registers the ids)
from creps_gym.wrappers.examples import ReacherTargetEnv

pytestmark = EXTRAS
IDS = ["creps_gym/PointMazeGoal-v0", "creps_gym/ReacherTarget-v0"]
SECTIONS = [
    "Description",
    "Context Space",
    "Parameter Space",
    "Return",
    "Episode End",
    "Arguments",
    "Version History",
]


@pytest.mark.parametrize("env_id", IDS)
def test_the_manual_has_gymnasiums_sections_in_order(env_id):
    env = make_or_skip(env_id).unwrapped
    doc = type(env).__doc__
    assert env.inner.spec.id in doc  # this env's own manual, not the generic EpisodicEnv one
    positions = [m.start() for s in SECTIONS for m in [re.search(rf"^    {s}$", doc, re.MULTILINE)] if m]
    assert len(positions) == len(SECTIONS) and positions == sorted(positions), doc


@pytest.mark.parametrize("env_id", IDS)
def test_a_registered_native_vector_env_matches_the_single_env(env_id):
    vector = make_or_skip(env_id, vector=True, num_envs=3)
    assert gym.spec(env_id).vector_entry_point is not None
    assert type(vector).__name__ == type(vector.model).__name__.replace("Env", "VectorEnv")
    contexts, _ = vector.reset(seed=0)
    params = np.random.default_rng(0).uniform(-0.5, 0.5, (3, vector.single_action_space.shape[0]))
    _, returns, terminated, _, _ = vector.step(params)
    assert terminated.all()
    np.testing.assert_array_equal(returns, vector.model.evaluate(contexts, params)[0])


@pytest.mark.parametrize("env_id", [*IDS, SPHERE])
@pytest.mark.slow
def test_seeding_of_native_and_sync_vector_envs_is_as_documented(env_id):
    """Native: n contexts from one generator seeded s; sync/async: sub-env i seeded s + i."""
    native = make_or_skip(env_id, vector=True, num_envs=3)
    sync = make_or_skip(env_id, vector=True, num_envs=3, vectorization_mode="sync")
    native_contexts, _ = native.reset(seed=5)
    sync_contexts, _ = sync.reset(seed=5)
    model = native.model
    np.testing.assert_array_equal(native_contexts, model.sample_contexts(seeding.np_random(5)[0], 3))
    singles = [make_or_skip(env_id).reset(seed=5 + i)[0] for i in range(3)]
    np.testing.assert_array_equal(sync_contexts, singles)
    np.testing.assert_array_equal(native_contexts[0], sync_contexts[0])
    assert not np.array_equal(native_contexts[1:], sync_contexts[1:])  # as the docs warn


@pytest.mark.slow
def test_making_point_maze_prints_no_gymnasium_robotics_notice():
    script = "import gymnasium as gym, creps_gym; gym.make('creps_gym/PointMazeGoal-v0').reset(seed=0)"
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    if "No module named" in out.stderr:
        pytest.skip("the mujoco extra is not installed")
    assert out.returncode == 0 and out.stdout == "" and out.stderr == "", out.stderr[-2000:]


_RENDER_SCRIPT = textwrap.dedent(
    """
    import sys, warnings
    warnings.filterwarnings("ignore", ".*symmetric and normalized")
    try:
        import mujoco  # the GL backend named by MUJOCO_GL is loaded here
    except Exception as exc:
        print("NOGL", type(exc).__name__, exc)
        sys.exit(0)
    import numpy as np, gymnasium as gym, creps_gym
    from gymnasium.utils.env_checker import check_env
    env = gym.make(sys.argv[1], render_mode="rgb_array")
    env.reset(seed=0)
    try:
        start = env.render()
    except Exception as exc:
        print("NOGL", type(exc).__name__, exc)
        sys.exit(0)
    env.step(np.full(env.action_space.shape, 0.5))
    end = env.render()
    check_env(env.unwrapped)  # includes the render check
    print("FRAMES", start.shape, start.dtype, float((start != end).mean()), float(start.std()))
    """
)


@pytest.mark.parametrize("env_id", IDS)
@pytest.mark.slow
def test_rgb_array_frames_show_the_start_and_the_end_of_the_episode(env_id):
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    out = subprocess.run(
        [sys.executable, "-c", _RENDER_SCRIPT, env_id], capture_output=True, text=True, env=env, timeout=300
    )
    if out.stdout.startswith("NOGL"):
        pytest.skip(f"no working OpenGL backend: {out.stdout[-300:]}")
    assert out.returncode == 0, out.stderr[-2000:]
    assert "Adroit" not in out.stderr
    fields = out.stdout.split("FRAMES", 1)[1].split()
    assert fields[:4] == ["(480,", "480,", "3)", "uint8"]
    assert float(fields[4]) > 0.001 and float(fields[5]) > 5.0  # the motion changed the picture


def test_render_mode_is_checked_before_anything_is_built():
    with pytest.raises(
        ValueError,
        match=r"render_mode: expected one of \['rgb_array', 'rgb_array_list'\] or None, got 'human'",
    ):
        ReacherTargetEnv(render_mode="human")  # gym.make would wrap it in HumanRendering
