"""Videos of evaluated episodes: frames through the whole motion, drawn when read, with progress, of only the
contexts asked for (``creps-gym evaluate RUN --video FILE``, :mod:`creps_gym.runner.results.video`)."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import textwrap

import gymnasium as gym
import numpy as np
import pytest
from helpers import EXTRAS

from creps_gym.cli import main
from creps_gym.envs.frames import EpisodeFrames
from creps_gym.runner import run

REACHER = "creps_gym/PlanarReacher-v1"


def test_episode_frames_are_drawn_only_when_read():
    drawn = []

    def draw(i):
        drawn.append(i)
        return np.full((2, 2, 3), i, dtype=np.uint8)

    frames = EpisodeFrames(3, draw)
    assert len(frames) == 3 and drawn == []
    assert frames[-1][0, 0, 0] == 2 and drawn == [2]
    assert [int(f[0, 0, 0]) for f in frames] == [0, 1, 2] and drawn == [2, 0, 1, 2]
    assert [int(f[0, 0, 0]) for f in frames[1:]] == [1, 2]
    with pytest.raises(IndexError, match="index: expected one in"):
        frames[3]
    with pytest.raises(ValueError, match="count: expected an int >= 1, got 0"):
        EpisodeFrames(0, draw)


@EXTRAS
@pytest.mark.slow
def test_the_reacher_draws_its_motion_as_it_runs():
    pytest.importorskip("matplotlib")
    env = gym.make(REACHER, render_mode="rgb_array_list")
    env.reset(seed=0, options={"context": [1.0, 1.0]})
    assert len(env.render()) == 1  # before the first step: the start posture
    env.step(np.full(25, 0.5))
    frames = env.unwrapped.episode_frames()
    assert len(frames) == 51 and env.metadata["render_fps"] == 25  # every second of 101 steps, half speed
    first, middle, last = frames[0], frames[25], frames[50]
    assert first.shape == (480, 480, 3) and first.dtype == np.uint8
    assert (first != middle).mean() > 0.01 and (middle != last).mean() > 0.01  # the arm moves
    listed = env.render()
    assert len(listed) == 51 and np.array_equal(listed[50], last)


@EXTRAS
def test_the_reachers_frames_are_the_whole_figure_drawn_again_in_any_order():
    """Twin check of the blitted frames (the moving parts drawn over a copy of the rest): each is, pixel for
    pixel, the figure drawn whole with the same arm, path and title, whichever frame was read before."""
    pytest.importorskip("matplotlib")
    from creps_gym.envs.reacher import rendering
    from creps_gym.envs.reacher.planar import DT, GOAL, VIA_STEP

    env = gym.make(REACHER, render_mode="rgb_array_list")
    env.reset(seed=0, options={"context": [1.0, 1.5]})
    env.step(np.linspace(-1, 1, 25))
    postures = env.unwrapped._postures()
    frames = env.unwrapped.episode_frames()
    canvas, ax = rendering._axes(postures)
    (path,) = ax.plot([], [], "-", color="tab:green", lw=1.0, label="hand path")
    (arm,) = ax.plot([], [], "-o", color="black", lw=2.0, ms=3.5, label="arm")
    rendering._markers(ax, env.unwrapped._context, GOAL)
    for index, k in [(50, 100), (0, 0), (25, VIA_STEP), (24, 48)]:  # read out of order
        arm.set_data(postures[k, :, 0], postures[k, :, 1])
        path.set_data(postures[: k + 1, -1, 0], postures[: k + 1, -1, 1])
        note = " (via-point time)" if k == VIA_STEP else ""
        ax.set_title(f"t = {k * DT:.2f} s, step {k} of 100{note}", fontsize=10)
        assert np.array_equal(frames[index], rendering._image(canvas)), index


def _reacher_run(tmp_path):
    run_dir = tmp_path / "reacher"
    run("creps-cma-old", REACHER, 2, 20, 0, eval_every=1, eval_contexts=4, run_dir=run_dir)
    return run_dir


@EXTRAS
@pytest.mark.slow
def test_evaluate_video_records_only_the_contexts_asked_for_with_progress(tmp_path, capsys):
    pytest.importorskip("matplotlib")
    pytest.importorskip("imageio_ffmpeg")
    from PIL import Image

    run_dir = _reacher_run(tmp_path)
    capsys.readouterr()
    path = tmp_path / "one.gif"
    assert main(["evaluate", str(run_dir), "--video", str(path)]) == 0
    out, err = capsys.readouterr()
    result = json.loads(out)
    assert result["contexts"] == 1 and result["video"] == str(path)  # no 100-context evaluation first
    assert "video: episode 1/1" in err and "rendering 51 frames (2.04 s at 25 fps)" in err
    assert Image.open(path).n_frames == 51  # the motion, not one frame
    recorded = [float(v) for v in re.findall(r"return (\S+): rendering", err)]
    assert recorded == pytest.approx([result["mean_return"]], rel=1e-5)  # the evaluated episode

    two = tmp_path / "two.mp4"
    assert main(["evaluate", str(run_dir), "--video", str(two), "--contexts", "2", "--seed", "3"]) == 0
    out, err = capsys.readouterr()
    result = json.loads(out)
    recorded = [float(v) for v in re.findall(r"return (\S+): rendering", err)]
    assert result["contexts"] == 2 and len(recorded) == 2 and "episode 2/2" in err
    assert np.mean(recorded) == pytest.approx(result["mean_return"], rel=1e-5)
    import imageio.v2 as imageio

    reader = imageio.get_reader(two)
    assert reader.count_frames() == 102 and reader.get_meta_data()["fps"] == 25
    reader.close()


@EXTRAS
def test_evaluate_without_video_still_uses_100_contexts(tmp_path, capsys):
    run_dir = _reacher_run(tmp_path)
    capsys.readouterr()
    assert main(["evaluate", str(run_dir)]) == 0
    assert json.loads(capsys.readouterr().out)["contexts"] == 100


_GL_FRAMES = textwrap.dedent(
    """
    import sys
    try:
        import mujoco  # the GL backend named by MUJOCO_GL is loaded here
    except Exception as exc:
        print("NOGL", type(exc).__name__, exc)
        sys.exit(0)
    import numpy as np, gymnasium as gym, creps_gym
    import json
    env_id, kwargs = sys.argv[1], json.loads(sys.argv[2])
    env = gym.make(env_id, render_mode="rgb_array_list", **kwargs)
    env.reset(seed=0)
    params = (env.unwrapped.reference_params() if "Kick" in env_id
              else np.full(env.action_space.shape, 0.5))
    _, _, _, _, info = env.step(params)
    try:
        frames = env.unwrapped.episode_frames()
        first, last = frames[0], frames[len(frames) - 1]
    except RuntimeError as exc:
        if "OpenGL" in str(exc):
            print("NOGL", exc)
            sys.exit(0)
        raise
    steps = int(info.get("inner_length", -1))
    print("FRAMES", len(frames), steps, env.metadata["render_fps"], first.shape[0], first.shape[1],
          float((first != last).mean()))
    """
)


@EXTRAS
@pytest.mark.parametrize(
    ("env_id", "kwargs"),
    [
        ("creps_gym/PointMazeGoal-v0", {}),
        ("creps_gym/ReacherTarget-v0", {}),
        ("creps_gym/KickPrecision-v1", {"width": 96, "height": 64, "num_threads": 1}),
    ],
)
@pytest.mark.slow
def test_mujoco_envs_give_a_frame_per_step_through_the_episode(env_id, kwargs):
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    command = [sys.executable, "-c", _GL_FRAMES, env_id, json.dumps(kwargs)]
    out = subprocess.run(command, capture_output=True, text=True, env=env, timeout=600)
    if out.stdout.startswith("NOGL") or "No module named" in out.stderr:
        pytest.skip(f"no working OpenGL backend or MuJoCo: {(out.stdout + out.stderr)[-300:]}")
    assert out.returncode == 0, out.stderr[-2000:]
    count, steps, fps, height, width, changed = out.stdout.split("FRAMES", 1)[1].split()
    if "Kick" in env_id:  # one frame per 0.04 s of the swing and the roll
        assert int(count) > 100 and fps == "25" and (height, width) == ("64", "96")
    else:  # the start and one frame per inner step, at the inner env's rate
        assert int(count) == int(steps) + 1 and fps == "50"
    assert float(changed) > 0.001  # the motion changed the picture


@pytest.mark.slow
@EXTRAS
@pytest.mark.parametrize("mode", ["rgb_array", "rgb_array_list"])
def test_the_reacher_drawings_have_a_legend(mode, monkeypatch):
    """Fig. 4b's marks are explained in the picture: the via-point (the context), the goal, the hand path."""
    pytest.importorskip("matplotlib")
    from creps_gym.envs.reacher import rendering

    figures = []

    def image(canvas, redraw=True):
        figures.append(canvas.figure)
        return np.zeros((1, 1, 3), dtype=np.uint8)

    monkeypatch.setattr(rendering, "_image", image)
    env = gym.make(REACHER, render_mode=mode)
    env.reset(seed=0, options={"context": [1.0, 1.0]})
    env.step(np.zeros(25))
    env.render()
    legend = figures[-1].axes[0].get_legend()
    texts = {text.get_text() for text in legend.get_texts()}
    assert {"via-point (context)", "goal", "hand path"} <= texts
