"""Registered examples of the episodic conversion on real ecosystem tasks: PointMaze and Reacher.

Ids (collected by :mod:`creps_gym.envs.registration`)
-----------------------------------------------------
``creps_gym/PointMazeGoal-v0``
    :class:`PointMazeGoalEnv` (Gymnasium-Robotics ``PointMaze_OpenDense-v3``), native vector env
    :class:`PointMazeGoalVectorEnv`.
``creps_gym/ReacherTarget-v0``
    :class:`ReacherTargetEnv` (Gymnasium MuJoCo ``Reacher-v5``), native vector env
    :class:`ReacherTargetVectorEnv`.

Each class docstring is the env's manual. Both render ``rgb_array`` frames through the inner MuJoCo env
(headless: EGL or OSMesa, chosen by :func:`creps_gym.envs.opengl.choose_gl_backend` when ``MUJOCO_GL`` is
unset; where none works, every render raises the same ``RuntimeError``). The native vector envs run the
episodes one after another in one process; ``gymnasium.make_vec(id, n, vectorization_mode="async")`` runs
them in parallel processes.

Seeding across vectorisation modes. ``reset(seed=s)`` of the native vector env draws all n contexts from
one generator seeded with ``s``; Gymnasium's sync and async vector envs seed sub-env ``i`` with ``s + i``.
The contexts from the same seed therefore differ between the modes (each mode is reproducible). The runner
is not affected: it gives every episode its own reset seed, so its backends agree bit for bit.

Dependencies. Importing this module imports neither MuJoCo nor Gymnasium-Robotics; making an env does
(``pip install creps-gym[mujoco]`` installs both). Gymnasium-Robotics prints a notice about its Adroit
envs to stderr when imported; the PointMaze env imports it with that notice silenced. Gymnasium-Robotics
1.4.2's Fetch and Shadow-Hand envs fail to reset with mujoco >= 3.12 (their ``set_joint_qpos`` compares
``model.jnt_type`` with the ``mjtJoint`` enum, which no longer compares equal), while PointMaze and
Gymnasium's Reacher-v5 work with mujoco 4.0, which the humanoid kick env needs. So only those two are
registered; a Fetch example would need ``mujoco<3.12``, incompatible with the kick env.
"""

from __future__ import annotations

import contextlib
import copy
import importlib
import io
import sys
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from creps_gym.envs.frames import EpisodeFrames
from creps_gym.envs.opengl import check_rendering, import_mujoco, is_gl_error, record_failure
from creps_gym.wrappers.episodic import EpisodicEnv, EpisodicVectorEnv

__all__ = [
    "REGISTRATIONS",
    "PointMazeGoalEnv",
    "PointMazeGoalVectorEnv",
    "ReacherTargetEnv",
    "ReacherTargetVectorEnv",
]

_POINT_MAZE: dict[str, Any] = {
    "env": "PointMaze_OpenDense-v3",
    "env_kwargs": {"continuing_task": True, "reset_target": False},
    "reset_options": {"reset_cell": [2, 3]},
    "max_inner_steps": 100,
    "controller": {
        "type": "tracking_dmp",
        "position_indices": [4, 5],
        "velocity_indices": [6, 7],
        "goal_low": [-2.25, -1.25],
        "goal_high": [2.25, 1.25],
        "n_basis": 3,
        "weight_bound": 1.0,
        "kp": 5.0,
        "kd": 1.0,
    },
    "context": {"type": "goal", "low": [-2.25, -1.25], "high": [2.25, 1.25]},
}
_REACHER: dict[str, Any] = {
    "env": "Reacher-v5",
    "max_inner_steps": 50,
    "controller": {"type": "dmp", "n_basis": 4, "weight_bound": 1.0},
    "context": {"type": "qpos", "indices": [2, 3], "low": [-0.2, -0.2], "high": [0.2, 0.2]},
}


def _import_robotics_quietly() -> None:
    """Import Gymnasium-Robotics (registers its ids) without the Adroit notice it prints to stderr."""
    if "gymnasium_robotics" not in sys.modules:
        import_mujoco(required=False)  # it imports mujoco, which reads MUJOCO_GL once (a clear error)
        with contextlib.redirect_stderr(io.StringIO()):
            importlib.import_module("gymnasium_robotics")


class _RenderedEpisodicEnv(EpisodicEnv):
    """An :class:`EpisodicEnv` with fixed defaults that renders the inner env: ``rgb_array`` (one frame) and
    ``rgb_array_list`` (the inner episode, a frame per inner step, at the inner env's ``render_fps``)."""

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["rgb_array", "rgb_array_list"], "render_fps": 4}
    _defaults: ClassVar[dict[str, Any]]

    def __init__(self, render_mode: str | None = None, **overrides: Any) -> None:
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(
                f"render_mode: expected one of {self.metadata['render_modes']} or None, got {render_mode!r}"
            )
        import_mujoco(required=False)  # before the inner env imports mujoco, which reads MUJOCO_GL once
        kwargs = {**copy.deepcopy(self._defaults), **overrides}
        if render_mode is not None:  # the inner env renders the frames
            kwargs["env_kwargs"] = {**kwargs.get("env_kwargs", {}), "render_mode": "rgb_array"}
        super().__init__(**kwargs, render_mode=render_mode)
        if render_mode is not None:  # keeps the inner states, whose frames are drawn when read
            self.inner = _StateRecorder(self.inner)
            fps = self.inner.metadata.get("render_fps", self.metadata["render_fps"])
            self.metadata = {**self.metadata, "render_fps": fps}  # the inner steps' own rate

    def render(self) -> NDArray[np.uint8] | list[NDArray[np.uint8]] | None:
        """``rgb_array``: the inner env's frame (uint8, (height, width, 3)): the start with the context set
        after ``reset``, the last inner state after ``step``; ``rgb_array_list``: the frames of
        :meth:`episode_frames`; None without a render mode."""
        if self.render_mode is None:
            return None
        if self.render_mode == "rgb_array_list":
            return list(self.episode_frames())
        if self._last_params is None:
            return self._start_frame()
        return self._inner_frame()

    def episode_frames(self) -> EpisodeFrames:
        """The last inner episode, a frame at its start and after every inner step, each drawn when read
        (the start with the context set alone before the first step)."""
        if self.render_mode is None:
            raise RuntimeError("episode_frames(): expected an env made with a render_mode, got None")
        if self._last_params is None:
            return EpisodeFrames(1, lambda _: self._start_frame())
        states = list(self.inner.states)
        return EpisodeFrames(len(states), lambda i: self._state_frame(states[i]))

    def _start_frame(self) -> NDArray[np.uint8]:
        """The episode's start with its context (the goal marker moved to it)."""
        if self._context is None:
            raise RuntimeError("render() called before reset(): there is no context to show")
        check_rendering()  # one clear error, every time, where a GL context would fail or abort
        observation, _ = self.inner.reset(seed=self.start_seed, options=self.reset_options)
        self.access.write(self.inner, self._context, observation)
        _update_positions(self.inner)  # the goal marker moved to the context: place it before drawing
        return self._inner_frame()

    def _state_frame(self, qpos: NDArray[np.float64]) -> NDArray[np.uint8]:
        _simulation(self.inner)[1].qpos[:] = qpos
        _update_positions(self.inner)
        return np.array(self._inner_frame(), dtype=np.uint8)  # a copy: a renderer may reuse its buffer

    def _inner_frame(self) -> NDArray[np.uint8]:
        check_rendering()
        try:
            return self.inner.render()
        except Exception as exc:  # the GL backends raise assorted error types
            if is_gl_error(exc):
                raise record_failure(exc) from exc
            raise


class _StateRecorder(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Keeps the inner MuJoCo positions (qpos) at the start of each inner episode (the context written)
    and after every step, so that a rendering env draws its frames afterwards, each when read."""

    def __init__(self, env: gym.Env) -> None:
        gym.utils.RecordConstructorArgs.__init__(self)
        gym.Wrapper.__init__(self, env)
        self.states: list[NDArray[np.float64]] = []

    def reset(self, **kwargs: Any) -> Any:
        self.states = []
        return self.env.reset(**kwargs)

    def step(self, action: Any) -> Any:
        data = _simulation(self.env)[1]
        if not self.states:  # the start, after the context was written
            self.states.append(data.qpos.copy())
        result = self.env.step(action)
        self.states.append(data.qpos.copy())
        return result


def _simulation(env: Any) -> tuple[Any, Any]:
    """The MuJoCo model and data behind ``env`` (a maze's ``point_env``, or the env itself)."""
    inner = env.unwrapped
    simulation = getattr(inner, "point_env", inner)
    return simulation.model, simulation.data


def _update_positions(env: Any) -> None:
    """``mj_forward`` on the MuJoCo model behind ``env``, so that sites moved by writing the context (the
    maze's goal marker) or bodies placed by setting ``qpos`` are drawn where they now are."""
    import mujoco

    mujoco.mj_forward(*_simulation(env))


class PointMazeGoalEnv(_RenderedEpisodicEnv):
    """A point mass steered to a goal in an open PointMaze arena by a tracked DMP reference.

    Description
        Gymnasium-Robotics ``PointMaze_OpenDense-v3``: an open 3 x 5 arena, dense reward
        ``exp(-|x - g|)`` per step, a continuing task without goal resets. Every episode starts the ball in
        the arena's centre cell (reset cell (2, 3), inner reset seed ``start_seed``) and runs 100 inner
        steps. A DMP reference from the ball's start to a learned goal is tracked by the PD force
        ``5 (y_ref - x) - v`` (:class:`~creps_gym.wrappers.TrackingDMPController`).
    Context Space
        ``Box([-2.25, -1.25], [2.25, 1.25], (2,), float64)``: the desired goal g. Contexts drawn on reset
        come from PointMaze's own goal distribution (the centres of the arena's cells, with noise).
    Parameter Space
        ``Box(8,)``: the DMP's goal (2, in the context box) and 3 weights per axis (6, in [-1, 1]).
    Return
        The sum of the 100 inner rewards, in [0, 100]; higher when the ball gets to g early and stays.
    Episode End
        After the single step (``terminated=True``); the inner episode always runs 100 steps (``info``
        has ``inner_length``, ``inner_terminated``, ``inner_truncated`` and the last ``inner_info``).
    Arguments
        render_mode : {"rgb_array", "rgb_array_list", None}
            ``rgb_array``: ``render()`` gives the inner MuJoCo frame (480 x 480); ``rgb_array_list``: the
            inner episode, a frame at its start and after each inner step, at the inner env's
            ``render_fps`` (50: real time). ``episode_frames()`` draws the same frames, each when read.
        **overrides
            Any :class:`~creps_gym.wrappers.EpisodicEnv` argument (``max_inner_steps``, ``start_seed``,
            ``controller``, ...) replacing the defaults above.
    Version History
        v0: initial version.
    """

    _defaults: ClassVar[dict[str, Any]] = _POINT_MAZE

    def __init__(self, render_mode: str | None = None, **overrides: Any) -> None:
        _import_robotics_quietly()
        super().__init__(render_mode, **overrides)


class ReacherTargetEnv(_RenderedEpisodicEnv):
    """Gymnasium's two-joint Reacher reaching a target with an open-loop DMP torque profile.

    Description
        Gymnasium MuJoCo ``Reacher-v5``, 50 inner steps from the inner reset ``start_seed``; the
        target is the context. The torques follow an open-loop DMP profile
        (:class:`~creps_gym.wrappers.DMPController`).
    Context Space
        ``Box(-0.2, 0.2, (2,), float64)``: the target position ``qpos[2:4]``. Contexts drawn on reset
        come from Reacher's own target distribution (uniform in the disc of radius 0.2).
    Parameter Space
        ``Box(-1, 1, (8,), float64)``: 4 DMP weights per joint.
    Return
        The sum of Reacher-v5's 50 rewards: minus the fingertip-target distance minus the control cost,
        per step (at most 0).
    Episode End
        After the single step (``terminated=True``); the inner episode runs 50 steps (``info`` has
        ``inner_length``, ``inner_terminated``, ``inner_truncated`` and the last ``inner_info``).
    Arguments
        render_mode : {"rgb_array", "rgb_array_list", None}
            ``rgb_array``: ``render()`` gives the inner MuJoCo frame (480 x 480); ``rgb_array_list``: the
            inner episode, a frame at its start and after each inner step, at the inner env's
            ``render_fps`` (50: real time). ``episode_frames()`` draws the same frames, each when read.
        **overrides
            Any :class:`~creps_gym.wrappers.EpisodicEnv` argument replacing the defaults above.
    Version History
        v0: initial version.
    """

    _defaults: ClassVar[dict[str, Any]] = _REACHER


class PointMazeGoalVectorEnv(EpisodicVectorEnv):
    """Native vector version of :class:`PointMazeGoalEnv` (episodes run one after another)."""

    single_env_class = PointMazeGoalEnv


class ReacherTargetVectorEnv(EpisodicVectorEnv):
    """Native vector version of :class:`ReacherTargetEnv` (episodes run one after another)."""

    single_env_class = ReacherTargetEnv


_MODULE = "creps_gym.wrappers.examples"
REGISTRATIONS: list[dict[str, Any]] = [
    {
        "id": "creps_gym/PointMazeGoal-v0",
        "entry_point": f"{_MODULE}:PointMazeGoalEnv",
        "vector_entry_point": f"{_MODULE}:PointMazeGoalVectorEnv",
    },
    {
        "id": "creps_gym/ReacherTarget-v0",
        "entry_point": f"{_MODULE}:ReacherTargetEnv",
        "vector_entry_point": f"{_MODULE}:ReacherTargetVectorEnv",
    },
]
