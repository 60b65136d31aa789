"""Rendering never aborts the interpreter: MuJoCo's GL backend is chosen before mujoco is imported (EGL,
then OSMesa, on a headless machine), a render that cannot work raises the same clear error every time, and
PointMaze's first frame shows the goal marker at the context."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest
from helpers import EXTRAS

RENDER_TWICE = textwrap.dedent(
    """
    import sys, warnings
    warnings.filterwarnings("ignore")
    import gymnasium as gym, creps_gym
    env = gym.make(sys.argv[1], render_mode="rgb_array")
    env.reset(seed=0)
    messages = []
    for attempt in range(2):
        try:
            frame = env.render()
            print("FRAME", frame.shape)
        except RuntimeError as exc:
            messages.append(str(exc))
            print("ERROR", str(exc)[:60])
    print("SAME" if len(set(messages)) <= 1 else "DIFFERENT")
    """
)


def _headless_env(**extra: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY", "MUJOCO_GL")}
    env.pop("PYOPENGL_PLATFORM", None)
    return {**env, **extra}


@EXTRAS
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="headless GLFW is a Linux case")
@pytest.mark.parametrize("env_id", ["creps_gym/KickPrecision-v1", "creps_gym/PointMazeGoal-v0"])
@pytest.mark.parametrize("backend", ["glfw", None])
@pytest.mark.slow
def test_rendering_twice_headless_never_aborts(env_id: str, backend: str | None) -> None:
    """Headless with GLFW (MUJOCO_GL=glfw, which needs a display), or with MUJOCO_GL unset: two renders
    give two frames (a backend was chosen) or the same RuntimeError twice; never the abort (exit 134) a
    second GLFW attempt used to cause."""
    pytest.importorskip("mujoco")
    env = _headless_env(**({"MUJOCO_GL": backend} if backend else {}))
    out = subprocess.run(
        [sys.executable, "-c", RENDER_TWICE, env_id], capture_output=True, text=True, env=env, timeout=300
    )
    if "No module named" in out.stderr:
        pytest.skip(f"an extra is missing: {out.stderr[-300:]}")
    assert out.returncode == 0, (out.returncode, out.stderr[-2000:])
    lines = out.stdout.splitlines()
    if backend == "glfw":
        assert [line.split()[0] for line in lines] == ["ERROR", "ERROR", "SAME"], out.stdout
        assert "no OpenGL context can be created" in lines[0]
    else:
        assert lines[-1] == "SAME" and len(lines) == 3, out.stdout  # two frames, or two equal errors


def _choose(probe_result: str, display: str | None = None) -> str:
    """Run choose_gl_backend in a fresh interpreter (mujoco not imported) with a fake probe that accepts
    the backends in ``probe_result``; prints the choice, MUJOCO_GL and check_rendering's outcome."""
    script = textwrap.dedent(
        f"""
        from creps_gym.envs import opengl
        opengl.probe_backend = lambda backend, timeout=60.0: backend in {probe_result!r}.split(",")
        import os
        choice = opengl.choose_gl_backend()
        try:
            opengl.check_rendering()
            verdict = "OK"
        except RuntimeError as exc:
            verdict = "REFUSED " + str(exc)
        print(choice, os.environ.get("MUJOCO_GL"), verdict)
        """
    )
    env = _headless_env(**({"DISPLAY": display} if display else {}))
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=env, timeout=60)
    assert out.returncode == 0, out.stderr[-2000:]
    return out.stdout.strip()


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the headless choice is made on Linux")
@pytest.mark.slow
def test_headless_choice_prefers_egl_then_osmesa_and_refuses_when_none_works() -> None:
    assert _choose("egl,osmesa") == "egl egl OK"
    assert _choose("osmesa") == "osmesa osmesa OK"
    none = _choose("")
    assert none.startswith("None None REFUSED no OpenGL context can be created")
    assert "EGL and OSMesa did not work here" in none
    assert _choose("egl", display=":0") == "None None OK"  # a display: mujoco's default (GLFW) is left


def test_an_explicit_backend_is_never_changed(monkeypatch: pytest.MonkeyPatch) -> None:
    from creps_gym.envs import opengl

    monkeypatch.setenv("MUJOCO_GL", "osmesa")
    monkeypatch.setattr(opengl, "probe_backend", lambda *a, **k: pytest.fail("probed"))
    assert opengl.choose_gl_backend() == "osmesa"
    assert os.environ["MUJOCO_GL"] == "osmesa"


POINT_MAZE_FIRST_FRAME = textwrap.dedent(
    """
    import sys, warnings
    warnings.filterwarnings("ignore")
    import numpy as np, gymnasium as gym, creps_gym
    env = gym.make("creps_gym/PointMazeGoal-v0", render_mode="rgb_array")
    inner = env.unwrapped.inner.unwrapped
    site = inner.target_site_id
    for context in ([1.5, -0.8], [-2.0, 1.0]):
        env.reset(seed=0, options={"context": np.array(context)})
        try:
            frame = env.render()
        except RuntimeError as exc:
            print("NOGL", exc)
            sys.exit(0)
        marker = inner.point_env.data.site_xpos[site][:2]
        red = (frame[..., 0] > 150) & (frame[..., 1] < 80) & (frame[..., 2] < 80)
        rows, cols = np.nonzero(red)
        print("MARKER", *marker, cols.mean() if red.any() else -1, rows.mean() if red.any() else -1)
    """
)


@EXTRAS
@pytest.mark.slow
def test_point_maze_first_frame_draws_the_goal_marker_at_the_context() -> None:
    out = subprocess.run(
        [sys.executable, "-c", POINT_MAZE_FIRST_FRAME], capture_output=True, text=True, timeout=300
    )
    if "No module named" in out.stderr:
        pytest.skip(f"an extra is missing: {out.stderr[-300:]}")
    assert out.returncode == 0, out.stderr[-2000:]
    if out.stdout.startswith("NOGL"):
        pytest.skip(f"no working OpenGL backend: {out.stdout[-300:]}")
    rows = [[float(v) for v in line.split()[1:]] for line in out.stdout.splitlines()]
    np.testing.assert_allclose(rows[0][:2], [1.5, -0.8], atol=1e-12)  # the site, where MuJoCo draws it
    np.testing.assert_allclose(rows[1][:2], [-2.0, 1.0], atol=1e-12)
    # the red marker's pixels moved with the context: right and down for (1.5, -0.8), left and up for (-2, 1)
    assert rows[0][2] > rows[1][2] and rows[0][3] > rows[1][3], rows
