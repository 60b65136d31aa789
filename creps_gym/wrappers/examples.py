"""Registered examples of the episodic conversion on real ecosystem tasks.

Ids (collected by :mod:`creps_gym.envs.registration`)
-----------------------------------------------------
``creps_gym/PointMazeGoal-v0``
    Gymnasium-Robotics ``PointMaze_OpenDense-v3`` (open 3 x 5 arena, dense reward ``exp(-|x - g|)``,
    continuing task without goal resets) for 100 steps from the arena's centre cell. Context: the desired
    goal ``g`` (2,), in ``[-2.25, 2.25] x [-1.25, 1.25]``. Parameters (8): a DMP reference from the ball's
    start to a learned goal (2, in the context box) shaped by 3 weights per axis (6, in ``[-1, 1]``),
    tracked by the PD force ``5 (y_ref - x) - v`` (:class:`~creps_gym.wrappers.TrackingDMPController`).
    The flat observation is ``[achieved_goal, desired_goal, observation]``, so x is at 4:6 and v at 6:8.
``creps_gym/ReacherTarget-v0``
    Gymnasium MuJoCo ``Reacher-v5`` (50 steps). Context: the target position ``qpos[2:4]`` (2,), in
    ``[-0.2, 0.2]^2``. Parameters: an open-loop DMP torque profile
    (:class:`~creps_gym.wrappers.DMPController`), 4 weights per joint (8), in ``[-1, 1]``.

Contexts drawn on reset come from the inner env's own goal distribution. Neither id has a native vector
entry point: ``gymnasium.make_vec(id, n, vectorization_mode="async")`` runs episodes in parallel processes.

Dependencies. Importing this module imports neither MuJoCo nor Gymnasium-Robotics: the entry points are
strings resolved at ``gymnasium.make`` time (``"gymnasium_robotics:Id"`` imports the package then), and
``pip install creps-gym[mujoco]`` installs both. Gymnasium-Robotics 1.4.2's Fetch and Shadow-Hand envs fail
to reset with mujoco >= 3.12 (their ``set_joint_qpos`` compares ``model.jnt_type`` with the ``mjtJoint``
enum, which no longer compares equal), while PointMaze and Gymnasium's Reacher-v5 work with mujoco 4.0,
which the humanoid kick env needs. So only those two are registered; a Fetch example would need
``mujoco<3.12``, incompatible with the kick env.
"""

from __future__ import annotations

from typing import Any

__all__ = ["REGISTRATIONS"]

_ENTRY_POINT = "creps_gym.wrappers.episodic:EpisodicEnv"

REGISTRATIONS: list[dict[str, Any]] = [
    {
        "id": "creps_gym/PointMazeGoal-v0",
        "entry_point": _ENTRY_POINT,
        "kwargs": {
            "env": "gymnasium_robotics:PointMaze_OpenDense-v3",
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
        },
    },
    {
        "id": "creps_gym/ReacherTarget-v0",
        "entry_point": _ENTRY_POINT,
        "kwargs": {
            "env": "Reacher-v5",
            "max_inner_steps": 50,
            "controller": {"type": "dmp", "n_basis": 4, "weight_bound": 1.0},
            "context": {"type": "qpos", "indices": [2, 3], "low": [-0.2, -0.2], "high": [0.2, 0.2]},
        },
    },
]
