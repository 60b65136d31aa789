"""The DMP-driven 5-link planar reacher of Abdolmaleki et al. (2019), section 5.2, batched.

Abdolmaleki, Simões, Lau, Reis and Neumann, "Contextual Direct Policy Search With Regularized Covariance
Matrix Estimation", J. Intell. Robot. Syst. (2019), doi:10.1007/s10846-018-0968-4, section 5.2 and
Fig. 4. The joint trajectories come from :class:`creps_gym.movement.DiscreteDMP`; a batch of ``n``
rollouts is a hundred element-wise numpy steps on ``(n, 5)`` arrays, whatever ``n``.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from creps_gym._validation import as_float_array, check_fits_in_memory, check_positive_int, check_real
from creps_gym.envs.base import ContextualEpisodicEnv, ContextualEpisodicVectorEnv
from creps_gym.envs.frames import EpisodeFrames
from creps_gym.movement import DiscreteDMP, DMPConfig, DMPTrajectory

__all__ = ["PlanarReacherEnv", "PlanarReacherVectorEnv", "end_effector", "forward_kinematics"]

Array = NDArray[np.float64]

N_LINKS = 5
LINK_LENGTH = 1.0
N_STEPS = 100
DT = 0.01
VIA_STEP = 50
VIDEO_STRIDE = 2  # steps per rgb_array_list frame: 25 frames/s show the 100 steps/s motion at half speed
GOAL = np.array([5.0, 0.0])
START_ANGLES = np.array([np.pi / 2, 0.0, 0.0, 0.0, 0.0])
GOAL_ANGLES = np.zeros(N_LINKS)
ALPHA_Z, BETA_Z = 25.0, 6.25


def forward_kinematics(angles: Any, link_length: float = LINK_LENGTH) -> Array:
    """Joint positions of the planar arm with its base at the origin.

    Parameters
    ----------
    angles : array_like, shape (..., links)
        Relative joint angles (rad); joint ``j`` turns link ``j`` relative to link ``j - 1`` (the first
        relative to the x axis).
    link_length : float
        Length of every link (m).

    Returns
    -------
    ndarray, shape (..., links + 1, 2)
        The base (index 0), the joints and the end effector (index ``links``), in metres.
    """
    angles = as_float_array(angles, "angles")
    if angles.ndim == 0:
        raise ValueError(f"angles: expected shape (..., links), got {angles.shape}")
    absolute = np.cumsum(angles, axis=-1)
    links = link_length * np.stack([np.cos(absolute), np.sin(absolute)], axis=-1)
    base = np.zeros((*angles.shape[:-1], 1, 2))
    return np.concatenate([base, np.cumsum(links, axis=-2)], axis=-2)


def end_effector(angles: Any, link_length: float = LINK_LENGTH) -> Array:
    """End-effector position for relative joint angles (..., links): shape (..., 2)."""
    return forward_kinematics(angles, link_length)[..., -1, :]


class PlanarReacherEnv(ContextualEpisodicEnv):
    """A 5-link planar arm, driven by joint-space DMPs, passes a via-point and reaches a fixed goal.

    ## Description
    The paper's section 5.2 task (Abdolmaleki et al., 2019, Fig. 4). Five links of 1 m are joined by
    revolute joints; the base is at the origin. The motion lasts ``N_STEPS = 100`` steps of ``Δt = 0.01`` s
    (``τ = 1`` s). Each joint angle follows a discrete DMP (:mod:`creps_gym.movement.dmp`) from the start
    posture ``q_0 = (π/2, 0, 0, 0, 0)`` (the arm points straight up, hand at ``(0, 5)``) to the known, fixed
    goal attractor ``q = 0`` (the stretched arm along the x axis, hand at ``v100 = (5, 0)``). The hand must
    pass the via-point ``v50`` (the context) at step 50 and be at ``v100`` at step 100. With zero weights the
    arm swings down along the circle of radius 5 and misses every via-point in the context box by more than
    2 m, so the forcing terms must fold the arm.

    ## Context Space
    ``Box([0, 0], [2, 2], (2,), float64)``: the via-point ``v50 = (x, y)`` in metres, drawn uniformly as in
    the paper. It is the observation and ``info["context"]``; ``reset(options={"context": v50})`` sets it.

    ## Parameter Space
    ``Box(-30, 30, (25,), float64)``: ``n_basis = 5`` forcing weights per joint, joint-major (entries
    ``5 j .. 5 j + 4`` drive joint ``j``). The DMPs use ``α_z = 25``, ``β_z = α_z / 4``, ``α_x = 3`` and
    ``weight_scale = α_z β_z``, so a weight is in radians: at phase ``x`` the spring's set point is shifted
    by ``x Σψw/Σψ``. The phase falls from 1 to 0.05 over the motion, so the late weights need larger values
    for the same effect (learned policies use ``|w|`` up to about 16, on the last basis functions, which
    pull the lagging spring onto the goal); the box ``[-30, 30]`` holds every useful motion with a margin.
    Parameters outside the box are evaluated as given. ``θ = 0`` (the plain DMP) is the natural start:
    ``initial_distribution()`` declares N(0, σ²) per weight, σ = ``initial_std``: 1 in v1, the paper's
    start (initial covariance I), and 15 in v0 (the box rule: mean ± 2σ spans the box). Measured with the
    runner, 200 iterations, median final mean return over seeds 0-2: CREPS-CMA-old at N = 100 ends at
    −0.024 from σ = 1, −0.032 from 0.3, −2.4 from 3 and −7.4 from 15; C-CMA-ES at its recommended N = 39
    at −0.075, −0.061, −0.23 and −11. A wide start throws the arm into postures that the search then has
    to unlearn.

    ## Return
    ``R = −w_p (d50² + d100²) − w_a A``, with ``d50 = ‖p_50 − v50‖`` and ``d100 = ‖p_100 − v100‖`` the hand's
    distances (m) to the via-point at step 50 and to the goal at step 100, and
    ``A = Σ_k Σ_j q̈_j(t_k)² Δt`` (rad² s⁻³) the integrated squared joint accelerations over the 101 samples
    (``q̈`` from the DMP's transformation system). The paper gives no weights. Defaults: ``w_p = 1`` m⁻², so
    the distance part reads directly in m², and ``w_a = 1e-5``. The plain DMP (``θ = 0``) has
    ``A ≈ 1.4e3``, so ``w_a A ≈ 0.014`` beside a distance cost of about 18 m² on average: the start is all
    about distances. Measured at the policy CREPS-CMA-old learns in 300 iterations of 100 samples
    (mean over 200 test via-points), the choice gives a via-point miss of 4 cm, a goal miss of 2 cm
    (0.002 m² together) and an acceleration cost of 0.012 (``A ≈ 1.2e3``; any motion from ``q_0`` to the
    goal needs some acceleration, so this term has a floor near 0.01). Returns thus read as "−(squared
    misses in m²) − about 0.01 for a smooth motion". With ``w_a = 1e-4`` the optimum gave up 12 cm of
    via-point accuracy for smoothness; with ``1e-6`` peak joint accelerations grew by 60 % to gain 1.5 cm.

    ``info`` holds ``via_distance`` (d50), ``goal_distance`` (d100), ``acceleration_cost`` (``w_a A``),
    ``via_position`` (``p_50``, shape (2,)) and ``final_position`` (``p_100``).

    ## Episode End
    One step: ``step(θ)`` runs the whole motion and returns ``terminated=True``, ``truncated=False``.

    ## Arguments
    ``gymnasium.make("creps_gym/PlanarReacher-v1", position_weight=1.0, acceleration_weight=1e-5,
    n_basis=5, render_mode=None, initial_std=1.0)``. ``initial_std`` (> 0) is the declared start's σ
    (v0 registers 15). ``n_basis`` changes the number of basis functions per joint (the
    parameter count is ``5 n_basis``); the paper and the documented numbers use 5.
    ``render_mode="rgb_array"`` draws the last motion as overlaid postures, darker nearer step 50, with the
    via-point (red cross), the goal (blue star), the hand's path and a legend, like the paper's Fig. 4b
    (needs matplotlib, the ``plot`` extra). ``"rgb_array_list"`` draws the motion as it runs, for a video:
    the arm at every second step (51 frames, the hand's path so far, the time), at
    ``metadata["render_fps"]`` = 25, half the motion's speed (its 1 s lasts 2 s);
    ``env.unwrapped.episode_frames()`` gives the same frames, each drawn when read. Before the first step
    both draw the start posture. There is no ``"human"`` mode.

    ## Version History
    * v1: the declared start is the paper's, σ = 1 (``initial_std=1.0``); the dynamics and the return are
      v0's.
    * v0: initial version (declared start σ = 15).
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["rgb_array", "rgb_array_list"], "render_fps": 25}

    def __init__(
        self,
        position_weight: float = 1.0,
        acceleration_weight: float = 1e-5,
        n_basis: int = 5,
        render_mode: str | None = None,
        initial_std: float = 15.0,
    ) -> None:
        self.position_weight = check_real(position_weight, "position_weight")
        self.acceleration_weight = check_real(acceleration_weight, "acceleration_weight")
        self.initial_std = check_real(initial_std, "initial_std", strict=True)
        n_basis = check_positive_int(n_basis, "n_basis")
        # one episode's basis activations (steps x basis), forcing and weights, per link, and the boxes
        check_fits_in_memory(8.0 * N_LINKS * n_basis * (N_STEPS + 12), "n_basis", n_basis, "the DMP's arrays")
        config = DMPConfig(
            n_basis=n_basis, alpha_z=ALPHA_Z, beta_z=BETA_Z, alpha_x=3.0, weight_scale=ALPHA_Z * BETA_Z
        )
        self.dmp = DiscreteDMP(N_LINKS, config)
        bound = np.full(self.dmp.n_params, 30.0)
        super().__init__(np.zeros(2), np.full(2, 2.0), -bound, bound, render_mode=render_mode)

    def initial_distribution(self) -> tuple[Array, Array]:
        """The env-declared search start: the plain DMP (θ = 0) and ``initial_std`` per weight (15 in v0,
        1 in v1; see the manual)."""
        return np.zeros(self.param_dim), np.full(self.param_dim, self.initial_std)

    def joint_trajectories(self, params: Any) -> DMPTrajectory:
        """DMP joint trajectories for params (n, 5 n_basis): each array of shape (n, 101, 5)."""
        params = self.check_params(params, "params")
        return self.dmp.rollout(params, START_ANGLES, GOAL_ANGLES, N_STEPS, DT)

    def evaluate(self, contexts: Array, params: Array) -> tuple[Array, dict[str, Array]]:
        """Returns (n,) and info for via-points (n, 2) and weights (n, 5 n_basis); see the class docstring."""
        contexts = as_float_array(contexts, "contexts", (None, 2))
        params = self.check_params(params, "params")
        if contexts.shape[0] != params.shape[0]:
            raise ValueError(
                f"contexts: expected as many rows as params ({params.shape[0]}), got {contexts.shape[0]}"
            )
        traj = self.joint_trajectories(params)
        via_position = end_effector(traj.positions[:, VIA_STEP])
        final_position = end_effector(traj.positions[:, N_STEPS])
        via_distance = np.sqrt(((via_position - contexts) ** 2).sum(axis=1))
        goal_distance = np.sqrt(((final_position - GOAL) ** 2).sum(axis=1))
        squared = (traj.accelerations**2).sum(axis=2)
        acceleration_cost = self.acceleration_weight * squared.sum(axis=1) * DT
        returns = -self.position_weight * (via_distance**2 + goal_distance**2) - acceleration_cost
        info = {
            "via_distance": via_distance,
            "goal_distance": goal_distance,
            "acceleration_cost": acceleration_cost,
            "via_position": via_position,
            "final_position": final_position,
        }
        return returns, info

    def render(self) -> NDArray[np.uint8] | list[NDArray[np.uint8]] | None:
        """``rgb_array``: an RGB image (uint8, shape (480, 480, 3)) of the last motion; ``rgb_array_list``:
        its frames (:meth:`episode_frames`); None without a render mode."""
        if self.render_mode is None:
            return None
        if self.render_mode == "rgb_array_list":
            return list(self.episode_frames())
        from creps_gym.envs.reacher.rendering import draw_motion

        return draw_motion(self._postures(), self._context, GOAL, VIA_STEP)

    def episode_frames(self) -> EpisodeFrames:
        """The last motion as it runs, one frame every second step (each drawn when read; the start
        posture alone before the first step)."""
        from creps_gym.envs.reacher.rendering import motion_frames

        return motion_frames(self._postures(), self._context, GOAL, VIA_STEP, DT, stride=VIDEO_STRIDE)

    def _postures(self) -> Array:
        """Joint positions (T, 6, 2) of the last motion, or (1, 6, 2) of the start before the first step."""
        if self._context is None:
            raise RuntimeError("render() called before reset(): there is no via-point to draw")
        if self._last_params is None:
            return forward_kinematics(START_ANGLES)[None]
        return forward_kinematics(self.joint_trajectories(self._last_params[None]).positions[0])


class PlanarReacherVectorEnv(ContextualEpisodicVectorEnv):
    """Native vector version of :class:`PlanarReacherEnv`: one batched DMP rollout per step."""

    single_env_class = PlanarReacherEnv
