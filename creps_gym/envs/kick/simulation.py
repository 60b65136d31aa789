"""Batched two-phase simulation of kick episodes on ``mujoco.batch`` (threads, bit-identical at any count).

Motion (the paper's linear interpolator), with ``T0 = 0.4 s`` and ``T_HOLD = 0.1 s``: the servo targets
move linearly from ``STAND_POSE`` to the initial pose over ``[0, T0]``, hold it until ``T0 + T_HOLD``, move
linearly to the final pose over the duration ``t``, then hold it. Controls are open-loop, so every episode is
a ``Batch.rollout`` with precomputed controls, run in chunks of ``CHUNK`` steps.

Phase 1 (robot, ball and floor) lasts at least until ``SETTLE`` seconds after the swing ends (the watch);
it ends at the first chunk boundary after that at which the ball is more than ``FAR`` metres from the torso
(horizontally) or slower than ``REST_SPEED``, at the latest ``PHASE1_EXTRA`` seconds later. The robot has
*fallen* if, at any step of the watch, its torso is lower than ``FALL_HEIGHT`` times the standing height or
tilted by more than ``FALL_TILT`` (rad), or if at the first chunk boundary after the watch the torso still
moves faster than ``FALL_SPEED`` (m/s): a fall in progress. A fallen episode stops there.
Phase 2 finishes the ball's roll on the ball-only model until it is slower than ``REST_SPEED`` or the
episode reaches ``MAX_TIME``. The ball-only roll (4 ms steps) matches a full simulation to within 2 cm over
an 8 m kick (tested in ``tests/envs/test_kick.py``; measured difference 2 mm).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field

from creps_gym.envs.opengl import import_mujoco

import_mujoco()  # chooses the GL backend first (MuJoCo reads MUJOCO_GL once); a clear error
import mujoco  # noqa: E402
import mujoco.batch  # noqa: E402
import numpy as np  # noqa: E402
from numpy.typing import NDArray  # noqa: E402

from creps_gym.envs.kick.model import STAND_POSE, KickModels  # noqa: E402

__all__ = [
    "CHUNK",
    "FALL_HEIGHT",
    "FALL_SPEED",
    "FALL_TILT",
    "FAR",
    "MAX_TIME",
    "PHASE1_EXTRA",
    "REST_SPEED",
    "SETTLE",
    "T0",
    "T_HOLD",
    "KickSimulator",
    "SimulationResult",
    "controls",
]

Array = NDArray[np.float64]

T0 = 0.4
T_HOLD = 0.1
SETTLE = 1.5
FALL_SPEED = 0.25
FAR = 0.8
REST_SPEED = 0.02
PHASE1_EXTRA = 3.0
MAX_TIME = 16.0
FALL_HEIGHT = 0.6
FALL_TILT = np.pi / 3.0
CHUNK = 60
BALL_CHUNK = 120


def controls(initial: Array, final: Array, duration: Array, times: Array) -> Array:
    """Servo targets of the linear interpolator.

    Parameters
    ----------
    initial, final : ndarray, shape (n, 12)
        Initial and final poses (rad).
    duration : ndarray, shape (n,)
        Swing durations (s).
    times : ndarray, shape (k,)
        Times (s) at which the targets are wanted.

    Returns
    -------
    ndarray, shape (n, k, 12)
    """
    t = times[None, :, None]
    to_initial = np.clip(t / T0, 0.0, 1.0)
    swing = np.clip((t - T0 - T_HOLD) / duration[:, None, None], 0.0, 1.0)
    start = STAND_POSE + (initial[:, None, :] - STAND_POSE) * to_initial
    return start + (final[:, None, :] - initial[:, None, :]) * swing


@dataclass
class SimulationResult:
    """Per-episode outcomes, each with leading dimension n.

    Attributes
    ----------
    displacement : ndarray, shape (n, 2)
        The ball's final displacement (m) in x and y; for a fallen episode, its displacement at the fall.
    fell : ndarray of bool, shape (n,)
    min_foot_ball_distance : ndarray, shape (n,)
        Smallest signed surface distance (m) between either foot and the ball during phase 1 (capped at
        1 m; negative while a foot penetrates the ball, as MuJoCo's contact distance is).
    launch_speed : ndarray, shape (n,)
        Highest ball speed (m/s) during phase 1.
    uprightness : ndarray, shape (n,)
        Lowest value during the watch of min(torso height / standing height, cosine of the torso's tilt),
        at least 0.5 for a kick that stands (a kicking robot leans and crouches: 0.58-0.87 measured). A fallen
        episode stops at the end of the ``CHUNK`` of steps in which the fall was detected, so for a fall it is
        the pose up to 0.12 s after the torso crossed a fall line: it depends on where in the chunk that was.
    sim_time : ndarray, shape (n,)
        Simulated episode time (s), both phases.
    phase1_time : ndarray, shape (n,)
        Time (s) simulated with the full model; the rest ran on the ball-only model.
    frames : list of ndarray
        Only when recording: per episode, (m, nq) full-model qpos at ``frame_dt`` intervals.
    """

    displacement: Array
    fell: NDArray[np.bool_]
    min_foot_ball_distance: Array
    launch_speed: Array
    uprightness: Array
    sim_time: Array
    phase1_time: Array
    frames: list[Array] = field(default_factory=list)


class KickSimulator:
    """Runs batches of kick episodes with a reusable ``mujoco.batch.Batch`` per model.

    Parameters
    ----------
    models : KickModels
    num_threads : int
        Threads of the batch; 0 means all CPUs. Results do not depend on it.
    """

    def __init__(self, models: KickModels, num_threads: int = 0) -> None:
        self.models = models
        self.num_threads = int(num_threads) if num_threads > 0 else (os.cpu_count() or 1)
        self._full: mujoco.batch.Batch | None = None
        self._ball: mujoco.batch.Batch | None = None
        self._s = models.sensor_slices

    def _batches(self, n: int) -> tuple[mujoco.batch.Batch, mujoco.batch.Batch]:
        n = max(n, 1)  # an empty batch still needs a (1-simulation) Batch to bind fields of
        if self._full is None or self._full.nsim < n:
            threads = min(self.num_threads, n)
            self._full = mujoco.batch.Batch(self.models.full, nsim=n, nthread=threads)
            self._ball = mujoco.batch.Batch(self.models.ball, nsim=n, nthread=threads)
        return self._full, self._ball

    def run(
        self,
        ball_xy: Array,
        initial: Array,
        final: Array,
        duration: Array,
        frame_steps: int = 0,
        two_phase: bool = True,
    ) -> SimulationResult:
        """Simulate n episodes.

        Parameters
        ----------
        ball_xy : ndarray, shape (n, 2)
            Ball start positions (m) relative to the settled torso.
        initial, final : ndarray, shape (n, 12)
            Poses (rad).
        duration : ndarray, shape (n,)
            Swing durations (s).
        frame_steps : int
            If > 0, also record the full qpos every ``frame_steps`` full-model steps (for rendering); it
            must divide ``CHUNK``, and the same interval in ball-model steps must divide ``BALL_CHUNK``.
        two_phase : bool
            Finish the ball's roll on the ball-only model (default). False keeps the full model until the
            ball rests or ``MAX_TIME`` (the reference the two-phase scheme is tested against).

        Returns
        -------
        SimulationResult
        """
        n = ball_xy.shape[0]
        full, ball = self._batches(n)
        start = self._start_ball(full, ball_xy, n)
        res = SimulationResult(
            displacement=np.zeros((n, 2)),
            fell=np.zeros(n, dtype=bool),
            min_foot_ball_distance=np.full(n, np.inf),
            launch_speed=np.zeros(n),
            uprightness=np.ones(n),
            sim_time=np.zeros(n),
            phase1_time=np.zeros(n),
            frames=[[] for _ in range(n)] if frame_steps else [],
        )
        handoff = self._phase1(full, start, (initial, final, duration), res, frame_steps, two_phase)
        self._phase2(ball, start, handoff, res, frame_steps)
        if frame_steps:
            res.frames = [np.concatenate(f) if f else np.zeros((0, self.models.full.nq)) for f in res.frames]
        return res

    def _start_ball(self, full: mujoco.batch.Batch, ball_xy: Array, n: int) -> Array:
        """Load the settled state into the first n simulations and place the balls; returns ball xy (n, 2)."""
        m = self.models
        full.state[:n] = m.initial_state
        qpos = full.bind("qpos")
        adr = m.ball_qpos_address
        qpos[:n, adr : adr + 2] = ball_xy
        qpos[:n, adr + 2] = m.full.geom("ball").size[0]
        qpos[:n, adr + 3 : adr + 7] = (1.0, 0.0, 0.0, 0.0)
        return qpos[:n, adr : adr + 2].copy()

    def _phase1(
        self,
        full: mujoco.batch.Batch,
        start: Array,
        motion: tuple[Array, Array, Array],
        res: SimulationResult,
        frame_steps: int,
        two_phase: bool,
    ) -> NDArray[np.bool_]:
        """Full-model phase; fills ``res``; returns a mask of the episodes whose ball rolls on in phase 2."""
        initial, final, duration = motion
        s, dt = self._s, self.models.full.opt.timestep
        n = start.shape[0]
        active = np.arange(n)
        done_motion = T0 + T_HOLD + duration + SETTLE
        extra = PHASE1_EXTRA if two_phase else MAX_TIME
        step, handoff, checked = 0, np.zeros(n, dtype=bool), np.zeros(n, dtype=bool)
        height_min = FALL_HEIGHT * self.models.stand_height
        while active.size:
            times = (step + np.arange(CHUNK)) * dt
            ctrl = controls(initial[active], final[active], duration[active], times)
            record = ["sensordata", "qpos"] if frame_steps else ["sensordata"]
            out = full.rollout(CHUNK, ctrl, record=record, ids=active)
            sens = out["sensordata"]
            if frame_steps:
                for row, i in enumerate(active):
                    res.frames[i].append(out["qpos"][row, frame_steps - 1 :: frame_steps].copy())
            step += CHUNK
            now = step * dt
            torso, up, ball_pos, ball_vel = (
                sens[:, :, s[k]] for k in ("torso_pos", "torso_up", "ball_pos", "ball_vel")
            )
            watched = times[None, :] <= done_motion[active, None]
            down = (torso[:, :, 2] < height_min) | (up[:, :, 2] < np.cos(FALL_TILT))
            upright = np.minimum(torso[:, :, 2] / self.models.stand_height, up[:, :, 2])
            upright = np.where(watched, upright, np.inf).min(axis=1)
            res.uprightness[active] = np.minimum(res.uprightness[active], upright)
            fell = res.fell[active] | (down & watched).any(axis=1)
            settled = now >= done_motion[active] - 1e-9
            first = settled & ~checked[active]  # end of the watch: a fall still in progress counts
            moving = np.linalg.norm(sens[:, -1, s["torso_vel"]], axis=1) > FALL_SPEED
            fell |= first & moving
            checked[active] |= settled
            feet = np.minimum(sens[:, :, s["r_foot_ball"]], sens[:, :, s["l_foot_ball"]])[:, :, 0]
            res.min_foot_ball_distance[active] = np.minimum(
                res.min_foot_ball_distance[active], feet.min(axis=1)
            )
            speed = np.linalg.norm(ball_vel, axis=2)
            res.launch_speed[active] = np.maximum(res.launch_speed[active], speed.max(axis=1))
            res.displacement[active] = ball_pos[:, -1, :2] - start[active]
            res.sim_time[active] = now
            res.phase1_time[active] = now
            far = two_phase & (np.linalg.norm(ball_pos[:, -1, :2] - torso[:, -1, :2], axis=1) > FAR)
            slow = speed[:, -1] < REST_SPEED
            timeout = (now >= done_motion[active] + extra - 1e-9) | (now >= MAX_TIME - 1e-9)
            finished = fell | (settled & (far | slow)) | timeout
            res.fell[active] = fell
            handoff[active] = finished & ~fell & ~slow & two_phase
            active = active[~finished]
        return handoff

    def _phase2(
        self,
        ball: mujoco.batch.Batch,
        start: Array,
        handoff: NDArray[np.bool_],
        res: SimulationResult,
        frame_steps: int,
    ) -> None:
        """Finish the roll of the handed-off balls on the ball-only model (updates ``res`` in place)."""
        active = np.flatnonzero(handoff)
        if not active.size:
            return
        m = self.models
        full_qpos, full_qvel = self._full.bind("qpos"), self._full.bind("qvel")
        ball.state[active] = 0.0
        qpos, qvel, time = ball.bind("qpos"), ball.bind("qvel"), ball.bind("time")
        qa, va = m.ball_qpos_address, m.ball_qvel_address
        qpos[active] = full_qpos[active, qa : qa + 7]
        qvel[active] = full_qvel[active, va : va + 6]
        time[active] = res.sim_time[active, None] if time.ndim == 2 else res.sim_time[active]
        dt = m.ball.opt.timestep
        while active.size:
            out = ball.rollout(BALL_CHUNK, None, record=["qpos", "qvel"], ids=active)
            if frame_steps:
                stride = round(frame_steps * m.full.opt.timestep / dt)
                self._ball_frames(active, out["qpos"], res, stride)
            res.sim_time[active] += BALL_CHUNK * dt
            res.displacement[active] = out["qpos"][:, -1, :2] - start[active]
            slow = np.linalg.norm(out["qvel"][:, -1, :3], axis=1) < REST_SPEED
            finished = slow | (res.sim_time[active] >= MAX_TIME - 1e-9)
            active = active[~finished]

    def _ball_frames(self, active: Array, ball_qpos: Array, res: SimulationResult, stride: int) -> None:
        """Append full-model frames: the robot frozen in its last recorded pose, the ball from phase 2."""
        adr = self.models.ball_qpos_address
        for row, i in enumerate(active):
            last = res.frames[i][-1][-1]
            picked = ball_qpos[row, stride - 1 :: stride]
            frames = np.repeat(last[None, :], picked.shape[0], axis=0)
            frames[:, adr : adr + 7] = picked
            res.frames[i].append(frames)
