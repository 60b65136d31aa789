"""The DMP-driven 5-link planar reacher (Abdolmaleki et al., 2019, section 5.2).

``gymnasium.make("creps_gym/PlanarReacher-v1")`` gives :class:`PlanarReacherEnv`;
``gymnasium.make_vec("creps_gym/PlanarReacher-v1", num_envs=n)`` the native
:class:`PlanarReacherVectorEnv`, which rolls out the whole batch at once. v1 declares the paper's start
(σ = 1); v0, kept as it was, declares σ = 15. ``creps_gym/PlanarReacherLowDim-v0`` is v1 searched over five
metaparameters, one set-point bump per joint (:mod:`creps_gym.envs.reacher.subspace`, through
:class:`creps_gym.envs.subspace.AffineSubspaceEnv`).
"""

from typing import Any

from creps_gym.envs.reacher.planar import (
    PlanarReacherEnv,
    PlanarReacherVectorEnv,
    end_effector,
    forward_kinematics,
)

__all__ = [
    "REGISTRATIONS",
    "PlanarReacherEnv",
    "PlanarReacherVectorEnv",
    "end_effector",
    "forward_kinematics",
]

REGISTRATIONS: list[dict[str, Any]] = [
    {
        "id": "creps_gym/PlanarReacher-v0",
        "entry_point": "creps_gym.envs.reacher.planar:PlanarReacherEnv",
        "vector_entry_point": "creps_gym.envs.reacher.planar:PlanarReacherVectorEnv",
        "kwargs": {"position_weight": 1.0, "acceleration_weight": 1e-5, "initial_std": 15.0},
    },
    {
        "id": "creps_gym/PlanarReacher-v1",
        "entry_point": "creps_gym.envs.reacher.planar:PlanarReacherEnv",
        "vector_entry_point": "creps_gym.envs.reacher.planar:PlanarReacherVectorEnv",
        "kwargs": {"position_weight": 1.0, "acceleration_weight": 1e-5, "initial_std": 1.0},
    },
    {  # 5 metaparameters: creps_gym/envs/reacher/subspace.py
        "id": "creps_gym/PlanarReacherLowDim-v0",
        "entry_point": "creps_gym.envs.reacher.subspace:make_low_dimensional_reacher",
        "kwargs": {"full_id": "creps_gym/PlanarReacher-v1", "initial_std": 0.3},
    },
]
