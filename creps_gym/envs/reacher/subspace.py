"""The low-dimensional reacher's subspace (``creps_gym/PlanarReacherLowDim-v0``): a set-point bump per joint.

θ_ref = 0 (the plain DMP, which swings the arm down to the goal), and column j of B moves joint j's forcing
weights along w = 30 ψ̃(x(0.4 τ)) / max ψ̃, the normalised basis functions at the phase of 0.4 τ, scaled so
the largest weight spans the full env's box (±30 rad). The forcing term x Σψw/Σψ is then a bump of the
joint's set point that peaks shortly before the via-point step (t = 0.5 τ; the spring lags its set point)
and has faded by the end (x(τ) = 0.05), so the plain DMP's reach of the goal is kept. Five metaparameters,
one per joint, fold the arm towards the via-point.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["BUMP_TIME", "make_low_dimensional_reacher", "via_point_bumps"]

Array = NDArray[np.float64]
#: The time (in units of τ) of the phase whose basis values shape each joint's bump.
BUMP_TIME = 0.4


def via_point_bumps(env: Any) -> tuple[Array, Array, list[str]]:
    """(θ_ref (p,), B (p, 5), names) for a :class:`~creps_gym.envs.reacher.planar.PlanarReacherEnv`."""
    dmp = env.dmp
    shape = dmp.basis(np.array([np.exp(-dmp.config.alpha_x * BUMP_TIME)]))[0]
    shape = 30.0 * shape / shape.max()
    n_joints, n_basis = dmp.n_joints, dmp.config.n_basis
    basis = np.zeros((n_joints * n_basis, n_joints))
    for joint in range(n_joints):
        basis[joint * n_basis : (joint + 1) * n_basis, joint] = shape
    return np.zeros(n_joints * n_basis), basis, [f"bump/joint{joint}" for joint in range(n_joints)]


def make_low_dimensional_reacher(full_id: str = "creps_gym/PlanarReacher-v1", **kwargs: Any) -> Any:
    """The entry point of ``creps_gym/PlanarReacherLowDim-v0``: ``full_id`` in :func:`via_point_bumps`'s
    subspace (``kwargs``: :func:`~creps_gym.envs.subspace.make_low_dimensional`'s and the full env's)."""
    from creps_gym.envs.subspace import make_low_dimensional

    return make_low_dimensional(via_point_bumps, full_id, **kwargs)
