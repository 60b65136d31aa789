"""Shared machinery of the kick tasks: the base env (simulation, info, rendering hooks) and its vector env."""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from creps_gym._validation import check_bool, check_positive_int, check_real, check_real_in_range
from creps_gym.envs.base import ContextualEpisodicEnv, ContextualEpisodicVectorEnv
from creps_gym.envs.frames import EpisodeFrames
from creps_gym.envs.kick.model import (
    DURATION_RANGE,
    JOINT_HIGH,
    JOINT_LOW,
    JOINT_NAMES,
    REFERENCE_KICK,
    load_models,
    mirror_params,
    rest_qpos,
    to_physical,
)
from creps_gym.envs.kick.simulation import T0, T_HOLD, KickSimulator, SimulationResult

__all__ = ["KickEnv", "KickVectorEnv"]

Array = NDArray[np.float64]
FRAME_STEPS = 20  # one rendered frame every 20 steps of 2 ms: 25 frames per second


INITIAL_STD = 0.02  # normalised units; see KickEnv.initial_distribution


class KickEnv(ContextualEpisodicEnv):
    """Base of the kick tasks; see :class:`~creps_gym.envs.kick.tasks.KickPrecisionEnv` for the manual.

    Subclasses implement :meth:`ball_positions` (context to ball start, and which episodes mirror the
    kick) and :meth:`task_returns` (outcome to return).
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["rgb_array", "rgb_array_list"], "render_fps": 25}

    def __init__(
        self,
        context_low: Array,
        context_high: Array,
        *,
        rolling_friction: float = 0.003,
        fall_penalty: float = 1.0,
        fall_grading: float = 0.0,
        num_threads: int = 0,
        fixed_base: bool = False,
        render_mode: str | None = None,
        width: int = 480,
        height: int = 360,
    ) -> None:
        rolling = check_real_in_range(rolling_friction, "rolling_friction", 0.0, 1.0)
        self.fall_penalty = check_real(fall_penalty, "fall_penalty")
        self.fall_grading = check_real_in_range(fall_grading, "fall_grading", 0.0, 1e6, low_inclusive=True)
        threads = check_positive_int(num_threads, "num_threads", minimum=0)
        fixed = check_bool(fixed_base, "fixed_base")
        self.width = check_positive_int(width, "width")
        self.height = check_positive_int(height, "height")
        buffer = (640, 480)  # the MJCF's offscreen buffer
        if self.width > buffer[0] or self.height > buffer[1]:
            raise ValueError(f"width, height: expected at most {buffer[0]}x{buffer[1]}, got {width}x{height}")
        super().__init__(context_low, context_high, -np.ones(25), np.ones(25), render_mode=render_mode)
        self.models = load_models(rolling, fixed)
        self.simulator = KickSimulator(self.models, threads)
        self._renderer: Any = None

    # -- documented units --------------------------------------------------------------------------------
    def reference_params(self) -> Array:
        """The shipped reference kick (normalised units, shape (25,)): the recommended initial mean.

        A right-leg kick of the precision task's ball to about 8.5 m (``model.REFERENCE_KICK``).
        """
        return np.array(REFERENCE_KICK)

    def initial_distribution(self) -> tuple[Array, Array]:
        """The env-declared search start: the reference kick and σ = ``INITIAL_STD`` per parameter.

        At σ = 0.02 few sampled kicks fall; the measured fall rates are in the manual's Parameter Space.
        """
        return self.reference_params(), np.full(self.param_dim, INITIAL_STD)

    @property
    def param_names(self) -> tuple[str, ...]:
        """Names of the 25 parameters: ``initial/<joint>``, ``final/<joint>``, ``duration``."""
        return (*(f"initial/{j}" for j in JOINT_NAMES), *(f"final/{j}" for j in JOINT_NAMES), "duration")

    @property
    def physical_low(self) -> Array:
        """Physical value (rad, and s for the duration) of normalised -1, shape (25,)."""
        return np.concatenate([JOINT_LOW, JOINT_LOW, [DURATION_RANGE[0]]])

    @property
    def physical_high(self) -> Array:
        """Physical value (rad, and s for the duration) of normalised +1, shape (25,)."""
        return np.concatenate([JOINT_HIGH, JOINT_HIGH, [DURATION_RANGE[1]]])

    def to_physical(self, params: Any) -> Array:
        """Physical parameters (rad, s) of normalised ones (clipped to [-1, 1]): shape (n, 25)."""
        params = self.check_params(params, "params")
        initial, final, duration = to_physical(params)
        return np.concatenate([initial, final, duration[:, None]], axis=1)

    # -- the task: subclasses implement these ------------------------------------------------------------
    def ball_positions(self, contexts: Array) -> tuple[Array, NDArray[np.bool_]]:
        """Ball start (n, 2) relative to the torso and the mask (n,) of episodes that mirror the kick."""
        raise NotImplementedError

    def task_returns(self, contexts: Array, displacement: Array) -> Array:
        """Return (n,) of ball displacements (n, 2) (x forward, y left) under contexts (n, z)."""
        raise NotImplementedError

    def target_offset(self, context: Array) -> Array | None:
        """Where the ball should come to rest relative to its start, (x, y) m, drawn on the pitch when
        rendering; None (the default) for tasks without a target."""
        return None

    def fallen_returns(self, contexts: Array) -> Array:
        """Return of a fall: the 'ball not moved' return minus ``fall_penalty``, shape (n,)."""
        return self.task_returns(contexts, np.zeros((contexts.shape[0], 2))) - self.fall_penalty

    def fall_severity(self, result: SimulationResult) -> Array:
        """``1 - uprightness`` clipped to [0, 2], shape (n,): how far each robot had gone down when its
        episode stopped (for a fall, up to 0.12 s after it crossed a fall line; see ``SimulationResult``).
        Above 0.4 once the torso is below 0.6 of its height, above 0.5 once it tilts past 60°."""
        return 1.0 - np.clip(result.uprightness, -1.0, 1.0)

    def episode_returns(self, contexts: Array, result: SimulationResult) -> Array:
        """Returns (n,) of simulated episodes: the task's, or the fall return for a fall, lowered by
        ``fall_grading`` times its :meth:`fall_severity`."""
        fallen = self.fallen_returns(contexts)
        if self.fall_grading > 0.0:
            fallen = fallen - self.fall_grading * self.fall_severity(result)
        return np.where(result.fell, fallen, self.task_returns(contexts, result.displacement))

    # -- evaluation ----------------------------------------------------------------------------------------
    def simulate(self, contexts: Array, params: Array, frame_steps: int = 0) -> SimulationResult:
        """Run the episodes of contexts (n, z) and normalised params (n, 25) without scoring them."""
        balls, mirrored = self.ball_positions(contexts)
        params = np.where(mirrored[:, None], mirror_params(params), params)
        initial, final, duration = to_physical(params)
        return self.simulator.run(balls, initial, final, duration, frame_steps=frame_steps)

    def evaluate(self, contexts: Array, params: Array) -> tuple[Array, dict[str, np.ndarray]]:
        """Evaluate a batch of kicks.

        Parameters
        ----------
        contexts : ndarray, shape (n, z)
        params : ndarray, shape (n, 25)
            Normalised parameters (clipped to [-1, 1]).

        Returns
        -------
        returns : ndarray, shape (n,)
        info : dict
            ``fell`` (n,) bool, ``ball_displacement`` (n, 2) m, ``kick_distance`` (n,) m,
            ``min_foot_ball_distance`` (n,) m, ``launch_speed`` (n,) m/s, ``uprightness`` (n,) (the lowest
            min(torso height / standing height, cos tilt) while watched), ``mirrored`` (n,) bool.
        """
        contexts = self.check_contexts(contexts, "contexts")
        params = self.check_params(params, "params")
        if contexts.shape[0] != params.shape[0]:
            raise ValueError(
                f"params: expected {contexts.shape[0]} rows (one per context), got {params.shape[0]}"
            )
        result = self.simulate(contexts, params)
        returns = self.episode_returns(contexts, result)
        info = {
            "fell": result.fell.copy(),
            "ball_displacement": result.displacement.copy(),
            "kick_distance": np.linalg.norm(result.displacement, axis=1),
            "min_foot_ball_distance": result.min_foot_ball_distance.copy(),
            "launch_speed": result.launch_speed.copy(),
            "uprightness": result.uprightness.copy(),
            "mirrored": self.ball_positions(contexts)[1],
        }
        return returns, info

    # -- rendering -----------------------------------------------------------------------------------------
    def _episode_frames(self) -> tuple[Array, int]:
        """qpos frames (m, nq) of the current episode and the index of the frame at the end of the swing."""
        box = self.observation_space
        context = self._context if self._context is not None else (box.low + box.high) / 2.0  # RNG untouched
        if self._last_params is None:  # nothing kicked yet: the settled robot and the placed ball
            balls, _ = self.ball_positions(context[None, :])
            qpos = rest_qpos(self.models, balls[0])
            return qpos[None, :], 0
        result = self.simulate(context[None, :], self._last_params[None, :], frame_steps=FRAME_STEPS)
        duration = to_physical(self._last_params[None, :])[2][0]
        frames = result.frames[0]
        dt = self.models.full.opt.timestep * FRAME_STEPS
        swing_end = round((T0 + T_HOLD + duration) / dt)
        return frames, int(min(swing_end, frames.shape[0] - 1))

    def render(self) -> np.ndarray | list[np.ndarray] | None:
        """``rgb_array``: one (height, width, 3) uint8 frame at the end of the last kick's swing;
        ``rgb_array_list``: the frames of the whole last episode at ``metadata["render_fps"]`` (a list of
        :meth:`episode_frames`)."""
        if self.render_mode is None:
            from gymnasium import logger

            logger.warn("render() called without a render_mode: pass render_mode='rgb_array' to make().")
            return None
        if self.render_mode == "rgb_array":
            frames, index = self._episode_frames()
            return self._frame_renderer()(frames[index], self._render_target(frames[0]))
        return list(self.episode_frames())

    def episode_frames(self) -> EpisodeFrames:
        """The frames of the whole last episode (the settled robot before the first kick), one every
        ``FRAME_STEPS`` simulation steps (``metadata["render_fps"]`` = 25 per simulated second), each rendered
        when it is read: the simulation runs here, the rendering (about 0.1 s a frame in software) later.
        In the ``rgb_array_list`` mode the frames have no shadows or reflections, which halves that."""
        frames, _ = self._episode_frames()
        target = self._render_target(frames[0])
        draw = self._frame_renderer()
        return EpisodeFrames(frames.shape[0], lambda i: draw(frames[i], target))

    def _frame_renderer(self) -> Any:
        from creps_gym.envs.kick.rendering import KickRenderer

        if self._renderer is None:
            video = self.render_mode == "rgb_array_list"  # hundreds of frames: no shadows or reflections
            self._renderer = KickRenderer(self.models.full, self.width, self.height, shadows=not video)
        return self._renderer.frame

    def _render_target(self, first_frame: Array) -> Array | None:
        """World (x, y) of the task's target for the current context (the ball's start plus
        :meth:`target_offset`), or None."""
        box = self.observation_space
        context = self._context if self._context is not None else (box.low + box.high) / 2.0
        offset = self.target_offset(context)
        adr = self.models.ball_qpos_address
        return None if offset is None else first_frame[adr : adr + 2] + offset

    def close(self) -> None:
        """Release the renderer's GL context."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
        super().close()


class KickVectorEnv(ContextualEpisodicVectorEnv):
    """Native vector env of a kick task: one batched, multi-threaded simulation per ``step``.

    ``make_vec(id, num_envs=n)`` evaluates the n episodes on ``num_threads`` threads (0: all CPUs); results
    are bit-identical to the scalar env's.
    """

    single_env_class: ClassVar[type[ContextualEpisodicEnv]] = KickEnv

    def render(self) -> Any:
        """Rendering is done by the scalar env: use ``gymnasium.make`` with a ``render_mode``."""
        raise NotImplementedError(
            "render(): the kick vector env does not render; use gymnasium.make(id, ...)"
        )
