"""Tests of the MuJoCo humanoid kick tasks (creps_gym/KickPrecision-v0/v1, KickFlexibility-v0/v1/v2)."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("mujoco")

import creps_gym  # noqa: F401  (registers the ids)
from creps_gym.envs.kick.model import (
    JOINT_HIGH,
    JOINT_LOW,
    JOINT_NAMES,
    REFERENCE_KICK,
    load_models,
    mirror_params,
    to_normalised,
    to_physical,
)
from creps_gym.envs.kick.simulation import KickSimulator
from creps_gym.envs.kick.tasks import KickPrecisionEnv

PRECISION, FLEXIBILITY = "creps_gym/KickPrecision-v0", "creps_gym/KickFlexibility-v0"
# The reference kick's distance at the calibrated rolling friction 0.003 (measured; see model.py).
REFERENCE_DISTANCE, REFERENCE_TOLERANCE = 8.49, 0.3


@pytest.fixture(scope="module")
def precision():
    env = gym.make(PRECISION, num_threads=1).unwrapped
    yield env
    env.close()


@pytest.fixture(scope="module")
def flexibility():
    env = gym.make(FLEXIBILITY, num_threads=2).unwrapped
    yield env
    env.close()


@pytest.fixture(scope="module")
def reference_result(precision):
    returns, info = precision.evaluate(np.array([[8.0]]), REFERENCE_KICK[None, :])
    return returns, info


def test_import_does_not_load_mujoco():
    code = "import sys, creps_gym; print('mujoco' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_spaces_and_metadata(precision, flexibility):
    assert precision.action_space.shape == (25,) and flexibility.action_space.shape == (25,)
    assert precision.observation_space.shape == (1,) and flexibility.observation_space.shape == (2,)
    assert "human" not in precision.metadata["render_modes"]
    assert precision.reference_params().shape == (25,)
    assert np.all(np.abs(precision.reference_params()) <= 1.0)
    assert len(precision.param_names) == 25


def test_parameter_mapping_round_trip_and_bounds():
    rng = np.random.default_rng(0)
    u = rng.uniform(-1, 1, (5, 25))
    initial, final, duration = to_physical(u)
    np.testing.assert_allclose(to_normalised(initial, final, duration), u, atol=1e-12)
    lo_init, lo_final, lo_t = to_physical(-np.ones((1, 25)))
    np.testing.assert_allclose(lo_init[0], JOINT_LOW, atol=1e-12)
    np.testing.assert_allclose(lo_final[0], JOINT_LOW, atol=1e-12)
    hi_init = to_physical(np.full((1, 25), 3.0))[0]  # clipped to +1
    np.testing.assert_allclose(hi_init[0], JOINT_HIGH, atol=1e-12)
    assert lo_t[0] == pytest.approx(0.05)


def test_joint_bounds_are_the_model_joint_ranges():
    models = load_models()
    hinge_ranges = np.array([models.full.joint(name).range for name in JOINT_NAMES])
    np.testing.assert_array_equal(hinge_ranges[:, 0], JOINT_LOW)
    np.testing.assert_array_equal(hinge_ranges[:, 1], JOINT_HIGH)
    assert models.full.body_subtreemass[1] == pytest.approx(5.25)
    assert models.ball.nbody == 2 and models.ball.nu == 0  # world and ball only


def test_mirror_swaps_leg_blocks():
    u = np.arange(25.0)[None, :]
    m = mirror_params(u)
    np.testing.assert_array_equal(m[0, :6], u[0, 6:12])
    np.testing.assert_array_equal(m[0, 18:24], u[0, 12:18])
    np.testing.assert_array_equal(m[0, 24], 24.0)
    np.testing.assert_array_equal(mirror_params(m), u)


def test_reference_kick_calibration(reference_result):
    """The calibrated rolling friction pins the distance of the reference kick."""
    _, info = reference_result
    assert not info["fell"][0]
    assert info["ball_displacement"][0, 0] == pytest.approx(REFERENCE_DISTANCE, abs=REFERENCE_TOLERANCE)
    assert abs(info["ball_displacement"][0, 1]) < 1.0
    assert info["min_foot_ball_distance"][0] < 0.005  # the foot touched the ball
    assert 2.0 < info["launch_speed"][0] < 6.0


def test_rolling_friction_sets_the_distance_scale(reference_result):
    env = gym.make(PRECISION, rolling_friction=0.002, num_threads=1).unwrapped
    _, info = env.evaluate(np.array([[8.0]]), REFERENCE_KICK[None, :])
    _, ref = reference_result
    # About the same launch (rolling friction acts on the foot contact too), a longer roll.
    assert info["launch_speed"][0] == pytest.approx(ref["launch_speed"][0], rel=0.02)
    assert info["ball_displacement"][0, 0] > 1.3 * ref["ball_displacement"][0, 0]


def test_precision_return_formula(precision, reference_result):
    returns, info = reference_result
    x, y = info["ball_displacement"][0]
    assert returns[0] == pytest.approx(-((x - 8.0) ** 2) - y**2)
    # The context takes effect: same kick, other target.
    other, other_info = precision.evaluate(np.array([[3.0]]), REFERENCE_KICK[None, :])
    np.testing.assert_array_equal(other_info["ball_displacement"], info["ball_displacement"])
    assert other[0] == pytest.approx(-((x - 3.0) ** 2) - y**2)


def test_determinism_through_gymnasium_api():
    outcomes = []
    for _ in range(2):
        env = gym.make(PRECISION, num_threads=1)
        obs, _ = env.reset(seed=123)
        action = np.clip(REFERENCE_KICK + env.unwrapped.np_random.normal(0, 0.02, 25), -1, 1)
        outcomes.append((obs, env.step(action)[1]))
    np.testing.assert_array_equal(outcomes[0][0], outcomes[1][0])
    assert outcomes[0][1] == outcomes[1][1]


def test_batch_equals_sequential_bit_identically(flexibility):
    rng = np.random.default_rng(1)
    contexts = flexibility.sample_contexts(rng, 4)
    params = np.clip(REFERENCE_KICK + rng.normal(0, 0.03, (4, 25)), -1, 1)
    batch_returns, batch_info = flexibility.evaluate(contexts, params)  # 2 threads, one batch
    single = gym.make(FLEXIBILITY, num_threads=1).unwrapped
    for i in range(4):
        r, info = single.evaluate(contexts[i : i + 1], params[i : i + 1])
        assert r[0] == batch_returns[i]
        np.testing.assert_array_equal(info["ball_displacement"][0], batch_info["ball_displacement"][i])


def test_vector_env_matches_scalar_env(precision):
    envs = gym.make_vec(PRECISION, num_envs=3, vectorization_mode="vector_entry_point", num_threads=2)
    contexts, _ = envs.reset(seed=0, options={"context": np.array([[4.0], [8.0], [11.0]])})
    actions = np.tile(REFERENCE_KICK, (3, 1))
    _, rewards, terminated, truncated, info = envs.step(actions)
    assert terminated.all() and not truncated.any()
    expected, _ = precision.evaluate(contexts, actions)
    np.testing.assert_array_equal(rewards, expected)
    np.testing.assert_array_equal(info["final_info"]["fell"], np.zeros(3, dtype=bool))
    envs.close()


def test_fall_is_penalised(precision, flexibility):
    """The mid-range pose (all zeros) topples the robot: 'ball not moved' minus the penalty."""
    zeros = np.zeros((1, 25))
    returns, info = precision.evaluate(np.array([[5.0]]), zeros)
    assert info["fell"][0]
    assert returns[0] == -(5.0**2) - 1.0
    returns, info = flexibility.evaluate(np.array([[0.2, -0.1]]), zeros)
    assert info["fell"][0] and returns[0] == -1.0
    heavy = gym.make(FLEXIBILITY, fall_penalty=7.5, num_threads=1).unwrapped
    assert heavy.evaluate(np.array([[0.2, -0.1]]), zeros)[0][0] == -7.5


def test_fixed_base_debug_option_never_falls():
    env = gym.make(PRECISION, fixed_base=True, num_threads=1).unwrapped
    _, info = env.evaluate(np.array([[5.0]]), np.zeros((1, 25)))
    assert not info["fell"][0]


def test_mirroring_for_left_balls(flexibility):
    kick = REFERENCE_KICK[None, :]
    contexts = np.array([[0.16, -0.05], [0.16, 0.05]])
    returns, info = flexibility.evaluate(contexts, np.repeat(kick, 2, axis=0))
    np.testing.assert_array_equal(info["mirrored"], [False, True])
    right, left = info["ball_displacement"]
    assert right[0] > 3.0 and not info["fell"].any()
    # Mirror-image kicks: equal forward distance, opposite sideways one (equal to all digits on x86-64 Linux).
    assert left[0] == pytest.approx(right[0], abs=1e-3)
    assert left[1] == pytest.approx(-right[1], abs=1e-3)
    assert returns[0] == pytest.approx(right[0] ** 2 - right[1] ** 2)


@pytest.mark.parametrize(("version", "n_params"), [("v1", 8), ("v2", 4)])
def test_the_flexibility_return_is_even_in_the_balls_sideways_position(version, n_params):
    """What c-bo's ``symmetric_contexts=(1,)`` assumes of the flexibility kick (its docstring): for any θ
    the ball at (x_B, y_B) and at (x_B, -y_B) give the same return (mirror-image kicks; they differed by at
    most 3e-12 here), for kicks that stand, fall or miss alike."""
    env = gym.make(f"creps_gym/KickFlexibilityLowDim-{version}").unwrapped
    rng = np.random.default_rng(4)
    contexts = np.column_stack([rng.uniform(0.15, 0.3, 6), rng.uniform(0.01, 0.15, 6)])
    params = rng.normal(0.0, 0.5, (6, n_params))
    right, info = env.evaluate(contexts * [1.0, -1.0], params)
    left, _ = env.evaluate(contexts, params)
    assert info["fell"].any() and not info["fell"].all()
    np.testing.assert_allclose(left, right, rtol=0.0, atol=1e-6)


def test_ball_only_roll_matches_full_simulation():
    """Phase 2 on the ball-only model agrees with simulating the full model to rest within 2 cm."""
    models = load_models()
    sim = KickSimulator(models, num_threads=1)
    initial, final, duration = to_physical(REFERENCE_KICK[None, :])
    ball = np.array([[0.16, -0.05]])
    two_phase = sim.run(ball, initial, final, duration)
    full = sim.run(ball, initial, final, duration, two_phase=False)
    assert not two_phase.fell[0] and not full.fell[0]
    np.testing.assert_allclose(two_phase.displacement, full.displacement, atol=0.02)
    assert two_phase.launch_speed[0] == full.launch_speed[0]


def test_context_changes_flexibility_outcome(flexibility):
    kick = np.repeat(REFERENCE_KICK[None, :], 2, axis=0)
    _, info = flexibility.evaluate(np.array([[0.16, -0.05], [0.28, -0.14]]), kick)
    assert not np.array_equal(info["ball_displacement"][0], info["ball_displacement"][1])


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        (
            {"rolling_friction": -0.1},
            ValueError,
            r"rolling_friction: expected a finite value in \(0.0, 1.0\], got -0.1",
        ),
        ({"rolling_friction": "0.003"}, TypeError, "rolling_friction: expected a real number, got str"),
        ({"fall_penalty": -1.0}, ValueError, "fall_penalty: expected a finite value >= 0, got -1.0"),
        (
            {"fall_grading": -2.0},
            ValueError,
            r"fall_grading: expected a finite value in \[0.0, 1000000.0\], got -2.0",
        ),
        ({"fall_grading": float("nan")}, ValueError, "fall_grading"),
        ({"num_threads": -1}, ValueError, "num_threads: expected an integer >= 0, got -1"),
        ({"fixed_base": "yes"}, TypeError, "fixed_base: expected a bool, got str"),
        ({"width": 0}, ValueError, "width: expected an integer >= 1, got 0"),
        (
            {"width": 4000, "render_mode": "rgb_array"},
            ValueError,
            "width, height: expected at most 640x480, got 4000x360",
        ),
        (
            {"render_mode": "human"},
            ValueError,
            r"render_mode: expected one of \['rgb_array', 'rgb_array_list'\]",
        ),
    ],
)
def test_bad_constructor_arguments(kwargs, error, match):
    with pytest.raises(error, match=match):
        KickPrecisionEnv(**kwargs)


def test_bad_inputs(precision):
    with pytest.raises(ValueError, match="params"):
        precision.evaluate(np.array([[5.0]]), np.zeros((1, 24)))
    with pytest.raises(ValueError, match="params"):
        precision.evaluate(np.array([[5.0]]), np.full((1, 25), np.nan))
    with pytest.raises(ValueError, match="rows"):
        precision.evaluate(np.array([[5.0], [6.0]]), np.zeros((1, 25)))
    with pytest.raises(ValueError, match="context"):
        precision.evaluate(np.array([[2.0]]), np.zeros((1, 25)))
    env = gym.make(PRECISION, num_threads=1).unwrapped
    with pytest.raises(RuntimeError, match="reset"):
        env.step(np.zeros(25))
    with pytest.raises(ValueError, match="context"):
        env.reset(options={"context": [13.0]})


_GL_EPISODE = textwrap.dedent(
    """
    import sys
    try:
        import mujoco  # the GL backend named by MUJOCO_GL is loaded here
    except Exception as exc:
        print("NOGL", type(exc).__name__, exc)
        sys.exit(0)
    import numpy as np, gymnasium as gym, creps_gym
    from creps_gym.envs.kick.model import REFERENCE_KICK
    try:
        env = gym.make("creps_gym/KickPrecision-v0", render_mode=MODE, width=WIDTH, height=HEIGHT,
                       num_threads=1)
        env.reset(seed=0, options={"context": [8.0]})
        env.step(REFERENCE_KICK)
        frame = env.render()
    except RuntimeError as exc:
        if "OpenGL" in str(exc):
            print("NOGL", exc)
            sys.exit(0)
        raise
    env.close()
    """
)
"""A script that renders one reference kick (8 m target); it prints NOGL and exits 0 without OpenGL."""

_RENDER_SCRIPT = _GL_EPISODE.replace("MODE", "'rgb_array'").replace("WIDTH", "160").replace("HEIGHT", "120")
_RENDER_SCRIPT += (
    'print("SHAPE", frame.shape, frame.dtype, float(frame.std()), int(frame.max()) - int(frame.min()))\n'
)


@pytest.mark.parametrize("backend", ["egl", "osmesa"])
@pytest.mark.slow
def test_rgb_array_frame_is_not_blank(backend):
    env = {**os.environ, "MUJOCO_GL": backend}
    out = subprocess.run([sys.executable, "-c", _RENDER_SCRIPT], capture_output=True, text=True, env=env)
    if out.stdout.startswith("NOGL"):
        pytest.skip(f"no working MUJOCO_GL={backend} OpenGL backend: {out.stdout[-300:]}")
    assert out.returncode == 0, out.stderr[-2000:]
    fields = out.stdout.split("SHAPE", 1)[1].split()
    assert fields[:4] == ["(120,", "160,", "3)", "uint8"]
    assert float(fields[4]) > 5.0 and int(fields[5]) > 50  # a real picture, not a blank frame


@pytest.mark.slow
def test_creps_cma_improves_the_precision_mean_policy():
    """A small learning check: 6 iterations of 20 samples of CREPS-CMA (old mean) from the reference kick.

    Measured at seed 0: the mean return gains 4.96 (15 iterations: 5.31), the far target's kick is 3.08 m
    longer than the near one's, and no kick falls."""
    from creps_gym.optimizers import CREPSCMA

    env = gym.make(PRECISION, num_threads=0).unwrapped
    targets = np.array([[4.0], [6.0], [8.0], [10.0], [11.5]])
    start = {"initial_mean": env.reference_params(), "initial_cov": 0.02**2}
    opt = CREPSCMA(25, 1, variant="old", mean_features="affine", seed=0, **start)
    before = env.evaluate(targets, opt.recommend(targets))[0].mean()
    rng = np.random.default_rng(0)
    for _ in range(6):
        contexts = env.sample_contexts(rng, 20)
        params = opt.ask(contexts)
        opt.tell(contexts, params, env.evaluate(contexts, params)[0])
    after, info = env.evaluate(targets, opt.recommend(targets))
    assert not info["fell"].any()
    # The reference kicks 8.5 m whatever the target (mean return about -7.6); the learned mean policy
    # kicks shorter for near targets and longer for far ones.
    assert after.mean() > before + 2.0
    distances = info["ball_displacement"][:, 0]
    assert distances[0] < distances[-1] - 1.0


def test_empty_batch(flexibility):
    returns, info = flexibility.evaluate(np.zeros((0, 2)) + 0.2, np.zeros((0, 25)))
    assert returns.shape == (0,) and info["ball_displacement"].shape == (0, 2)


def test_recorded_frames_cover_the_episode(precision):
    """The frames rgb_array_list renders: one per 0.04 s of both phases, ending where the ball stopped."""
    contexts, params = np.array([[8.0]]), REFERENCE_KICK[None, :]
    plain = precision.simulate(contexts, params)
    recorded = precision.simulate(contexts, params, frame_steps=20)
    np.testing.assert_array_equal(recorded.displacement, plain.displacement)  # recording changes nothing
    frames = recorded.frames[0]
    assert frames.shape == (round(recorded.sim_time[0] / 0.04), precision.models.full.nq)
    adr = precision.models.ball_qpos_address
    np.testing.assert_allclose(
        frames[-1, adr : adr + 2] - frames[0, adr : adr + 2], plain.displacement[0], atol=0.02
    )


@pytest.mark.parametrize(("suffix", "backend"), [(".gif", "imageio"), (".mp4", "imageio_ffmpeg")])
def test_save_video_writes_a_file_that_reads_back(tmp_path, suffix, backend):
    pytest.importorskip(backend)
    import imageio.v3 as iio

    from creps_gym.envs.kick.rendering import save_video

    frames = [np.full((32, 48, 3), 40 * k, dtype=np.uint8) for k in range(6)]
    path = save_video(frames, tmp_path / f"kick{suffix}", fps=25)
    back = iio.imread(path, index=None)
    assert back.shape[0] == 6 and back.shape[1:3] == (32, 48)
    assert back[5].mean() > back[0].mean() + 100  # MP4 is lossy, but the brightness ramp survives


def test_save_video_rejects_bad_input(tmp_path):
    from creps_gym.envs.kick.rendering import save_video

    frames = [np.zeros((12, 16, 3), dtype=np.uint8)]
    with pytest.raises(ValueError, match="path"):
        save_video(frames, tmp_path / "kick.avi")
    with pytest.raises(ValueError, match="frames"):
        save_video([], tmp_path / "kick.gif")
    for fps in (0, -1, float("nan")):
        with pytest.raises(ValueError, match=f"fps: expected a finite value > 0, got {fps}"):
            save_video(frames, tmp_path / "kick.gif", fps=fps)
    with pytest.raises(ValueError, match=r"frames\[0\]: expected shape \(height, width, 3\)"):
        save_video([np.zeros((2, 2), np.uint8)], tmp_path / "kick.gif")
    with pytest.raises(ValueError, match=r"frames\[1\]: expected .* \(12, 16, 3\), got \(13, 16, 3\)"):
        save_video([frames[0], np.zeros((13, 16, 3), np.uint8)], tmp_path / "kick.gif")
    with pytest.raises(TypeError, match=r"frames\[0\]: expected a uint8 RGB image .*, got float64"):
        save_video([np.full((12, 16, 3), 0.5)], tmp_path / "kick.gif")
    assert not list(tmp_path.iterdir())  # nothing written


def test_flexibility_v1_pays_forward_distance_only(flexibility):
    forward_only = gym.make("creps_gym/KickFlexibility-v1", num_threads=1).unwrapped
    contexts = np.array([[0.2, -0.05], [0.2, -0.05]])
    kicks = np.array([[5.0, 1.0], [-5.0, 1.0]])  # a forward kick and its backward mirror image
    v0, v1 = flexibility.task_returns(contexts, kicks), forward_only.task_returns(contexts, kicks)
    assert v0[0] == v0[1] == 24.0  # the paper's x² - y² pays both the same
    assert v1[0] == 24.0 and v1[1] == -26.0  # sign(x) x² - y²
    assert "v1: the return is" in type(forward_only).__doc__
    forward_only.close()


def test_flexibility_v2_scores_a_miss_by_how_close_the_foot_came():
    v1 = gym.make("creps_gym/KickFlexibility-v1", num_threads=1).unwrapped
    v2 = gym.make("creps_gym/KickFlexibility-v2", num_threads=1).unwrapped
    contexts = np.array([[0.30, -0.05], [0.20, -0.05], [0.20, -0.05]])  # far ball (missed), near ball
    params = np.tile(v1.reference_params(), (3, 1))
    params[2] = np.random.default_rng(0).uniform(-1, 1, 25)  # a random pose: it falls
    r1, info = v1.evaluate(contexts, params)
    r2, _ = v2.evaluate(contexts, params)
    np.testing.assert_array_equal(info["fell"], [False, False, True])
    assert info["min_foot_ball_distance"][0] > 0.0 and info["ball_displacement"][0, 0] == 0.0  # a miss
    miss = np.where(info["fell"], 1.0, np.clip(info["min_foot_ball_distance"], 0.0, 1.0))
    np.testing.assert_allclose(r2, r1 - miss)
    assert r2[0] < 0.0 < r2[1] and r2[2] < -1.0 - 0.999  # a fall is below every standing kick
    assert "v2: a kick that misses" in type(v2).__doc__
    with pytest.raises(ValueError, match="miss_weight"):
        gym.make("creps_gym/KickFlexibility-v2", miss_weight=-1.0)
    v1.close()
    v2.close()


@pytest.mark.slow
def test_precision_v1_grades_a_fall_by_how_far_the_robot_went_down(precision):
    """v1 = v0 for standing kicks; a fall scores v0's fall return minus 30 × (1 − uprightness), with the
    uprightness the lowest min(height ratio, cos tilt) while watched: 1 for a kick that stands, and
    samples that all fall get different returns, ordered by how far each went down."""
    v1 = gym.make("creps_gym/KickPrecision-v1", num_threads=1).unwrapped
    rng = np.random.default_rng(0)
    contexts = np.full((24, 1), 12.0)
    params = np.clip(REFERENCE_KICK + 0.05 * rng.standard_normal((24, 25)), -1, 1)
    r0, info = precision.evaluate(contexts, params)
    r1, info1 = v1.evaluate(contexts, params)
    fell, upright = info["fell"], info["uprightness"]
    np.testing.assert_array_equal(info1["uprightness"], upright)
    assert 4 <= fell.sum() <= 20  # both kinds in the batch
    np.testing.assert_array_equal(r1[~fell], r0[~fell])
    np.testing.assert_allclose(r1[fell], r0[fell] - 30.0 * (1.0 - np.clip(upright[fell], -1, 1)))
    assert np.unique(r0[fell]).size == 1 and np.unique(r1[fell]).size == fell.sum()
    assert (upright[~fell] >= 0.5).all() and (upright[~fell] <= 1.0).all()  # never below the fall lines
    assert "v1: a fall's return is graded" in type(v1).__doc__
    v1.close()


@pytest.mark.slow
def test_the_generic_path_learns_from_the_declared_start():
    """Issue 13: with no initial distribution given, C-CMA-ES through the runner improves on the start.

    The declared start is the reference kick (σ = 0.02); before, the runner started at the box centre, where
    the robot falls on every sample and the evaluation return never moves.
    """
    from creps_gym.envs.evaluation import evaluate_policy, test_contexts
    from creps_gym.runner import run, split_seed

    env = gym.make(PRECISION, num_threads=0).unwrapped
    gains = []
    # Five iterations from σ = 0.02: seeds 0 to 3 gained 3.40, 2.77, 3.05 and 4.00. Ten did not always
    # improve (-0.25, +2.83, +3.77, -16.0: a longer run can lose the gain again), so the run is five long.
    for seed in (1, 2):
        history = run("c-cma-es", PRECISION, 5, 20, seed, eval_every=5)
        contexts = test_contexts(env, 16, split_seed(seed)[2])  # the runner's test contexts
        start = evaluate_policy(env, env.reference_params(), contexts).mean_return
        gains.append(history.column("eval_return")[-1] - start)
    assert all(gain > 1.0 for gain in gains), gains
    env.close()


@pytest.mark.slow
def test_no_constant_kick_beats_the_reference_by_more_than_the_context_variance_at_seed_0():
    """Issue 13's ``--optimizer cma`` line, bounded: a non-contextual optimiser's mean policy is one kick for
    every target, and a kick whose ball stops at (x, y) scores mean(−(x − s)² − y²) ≤ −var(s) over the test
    contexts (equality at x = mean(s), y = 0). At ``--seed 0`` the reference kick, where the runner starts
    pycma, is within 0.13 of that bound, so no constant kick can improve the CLI's evaluation by more."""
    from creps_gym.envs.evaluation import evaluate_policy, test_contexts
    from creps_gym.runner import split_seed

    env = gym.make(PRECISION, num_threads=1).unwrapped
    contexts = test_contexts(env, 16, split_seed(0)[2])  # the CLI's 16 evaluation contexts at --seed 0
    params = np.repeat(env.reference_params()[None], len(contexts), axis=0)
    returns, info = env.evaluate(contexts, params)
    x, y = info["ball_displacement"].T
    np.testing.assert_allclose(returns, -((x - contexts[:, 0]) ** 2) - y**2)  # the return the bound is of
    reference = evaluate_policy(env, env.reference_params(), contexts).mean_return
    assert reference == pytest.approx(returns.mean())
    headroom = -contexts[:, 0].var() - reference
    assert 0.0 < headroom < 0.13, headroom  # measured: 0.124 (−5.515 against −5.639)
    env.close()


_VIDEO_SCRIPT = _GL_EPISODE.replace("MODE", "'rgb_array_list'").replace("WIDTH", "96").replace("HEIGHT", "64")
_VIDEO_SCRIPT += textwrap.dedent(
    """
    from creps_gym.envs.kick.rendering import save_video
    path = save_video(frame, sys.argv[1])
    last = frame[-1].astype(int)
    red = int(((last[..., 0] > 150) & (last[..., 1] < 90) & (last[..., 2] < 90)).sum())
    print("VIDEO", len(frame), path.stat().st_size, red)
    """
)


@pytest.mark.slow
def test_a_whole_episode_records_to_video_with_the_target_drawn(tmp_path):
    pytest.importorskip("imageio")
    env = {**os.environ, "MUJOCO_GL": "egl"}
    path = tmp_path / "kick.gif"
    out = subprocess.run(
        [sys.executable, "-c", _VIDEO_SCRIPT, str(path)], capture_output=True, text=True, env=env
    )
    if out.stdout.startswith("NOGL"):
        pytest.skip(f"no working MUJOCO_GL=egl OpenGL backend: {out.stdout[-300:]}")
    assert out.returncode == 0, out.stderr[-2000:]
    count, size, red = (int(v) for v in out.stdout.split("VIDEO", 1)[1].split())
    assert count > 100 and size > 1000 and path.exists()  # the whole episode: swing and roll
    assert red > 0  # the target disc, 8 m ahead, is in view when the ball comes to rest near it
