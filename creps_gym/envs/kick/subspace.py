"""The low-dimensional kicks' subspace (``creps_gym/KickPrecisionLowDim-v0``, ``KickFlexibilityLowDim-v0``):
six movement metaparameters around the reference kick; the v1 and v2 ids' directions.

θ_ref is the reference right-leg kick (``model.REFERENCE_KICK``, normalised units). With Δ = θ_final,r −
θ_initial,r the kicking leg's swing (its six joints), the columns of B are, in normalised units:

1. ``amplitude``: 0.5 Δ on the kicking leg's final pose (u = ±1: a swing 1.5 or 0.5 times as long);
2. ``hip``: 0.6 on the kicking leg's final hip pitch (the foot further forward: the reference reaches balls
   up to x_B = 0.20 m, u = 1 one at 0.25 m);
3. ``ankle``: 0.6 on its final ankle pitch (the toe's angle at contact, which also moves the contact
   forward);
4. ``duration``: 0.5 on the swing time t. The reference swings at the fastest time (t = −1, 0.05 s), which
   the env clips at: u < 0 is as fast as u = 0, u = 1 is t = −0.5 (0.19 s);
5. ``aim``: 0.6 on the kicking leg's final hip roll (the swing's sideways direction);
6. ``lean``: 0.1 on both hips' roll in both poses (the body's sideways shift over the support foot).

The scales were chosen by hand, as a robot's engineer picks metaparameters, from one-at-a-time scans at
u_i = ±0.5 and ±1 (eight contexts): none of them makes the robot fall alone, while moving the initial
(wind-up) pose of the kicking leg by half its swing, or the hips' roll by twice the ``lean`` scale, does,
which is why neither is a larger direction. They are not fitted, and a combination of several large u_i
can still fall.

The v1 ids add ``power`` and ``reach``: the columns to a standing 12 m kick and to a standing kick of a ball
at x_B = 0.30 m (u = 1 is that kick), found by pycma in the full ids
(``benchmarks/low_budget/strong_kicks.py``). ``creps_gym/KickPrecisionLowDim-v2`` searches three of the
eight directions only, ``duration``, ``aim`` and ``power`` (:data:`DIRECTIONS`; the same columns): the
kick's timing, direction and strength, which together set where the ball stops, as the real-robot BO-CPS
work searches the two parameters of a throw. The other four shape the swing; within a real robot's budget
the seven of the v1 id are learnt far less well (``benchmarks/low_budget/README.md``).
``creps_gym/KickFlexibilityLowDim-v2`` searches four: ``aim`` and ``lean`` (the kick's sideways direction
and the body's shift, for a ball off the centre line) and ``power`` and ``reach`` (its strength for a near
and a far ball). They were picked by hand among seven subsets of the eight, each tried with `c-bo` (three
of them with `c-bo-ucb` too) on seeds 0–2 of the low-budget study, and the chosen one with `c-bo-ucb` on
seeds 3–7, so the study's figures on those seeds favour c-bo. The precision's three were the first subset
tried.

What the six reach (``benchmarks/low_budget/reach.py``, pycma per context, 300 episodes each):
the farthest precision kick that stands is 9.68 m, short of the paper's 10–12 m targets (best mean
error over its 10 targets 0.427 m, above the paper's 0.34 m), and no flexibility kick moves a ball at
x_B = 0.30 m (best mean distance over the 28 positions 4.1 m, below the paper's 6.5 m). The v2 id's three
reach a best mean error of 0.00616 m (``benchmarks/low_budget/results/reach_v2.md``;
the v1 id's seven 0.032 m).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "DIRECTIONS",
    "METAPARAMETERS",
    "POWER_KICK",
    "REACH_KICK",
    "kick_metaparameters",
    "make_low_dimensional_kick",
]

Array = NDArray[np.float64]
METAPARAMETERS = ("amplitude", "hip", "ankle", "duration", "aim", "lean")
_R, _L = 0, 6  # first joint of the right (kicking) and left leg in a pose; poses: initial 0-11, final 12-23
_HIP_ROLL, _HIP_PITCH, _ANKLE_PITCH, _FINAL, _DURATION = 1, 2, 4, 12, 24


#: A standing kick of the full precision id to 12 m (error 0.029 m), θ in normalised units (6 decimals):
#: ``benchmarks/low_budget/strong_kicks.py`` (pycma from the env-declared start, 3,000 episodes, seed 0).
POWER_KICK = (
    0.358012,
    0.602348,
    0.160674,
    0.468374,
    0.018147,
    0.689751,
    0.635785,
    0.02288,
    0.062512,
    -0.498243,
    -0.114838,
    0.214973,
    -0.368463,
    -0.005823,
    -0.548318,
    -0.46106,
    0.216199,
    0.352452,
    0.75456,
    -0.045526,
    0.6615,
    -0.20359,
    -0.419503,
    0.064912,
    -1.222019,
)
#: A standing kick of the full flexibility id of a ball at x_B = 0.30 m, y_B = 0 (12.2 m), likewise.
REACH_KICK = (
    -0.060169,
    1.027817,
    0.161719,
    0.46461,
    0.24971,
    0.513099,
    0.91865,
    -0.518931,
    0.338794,
    -0.511231,
    -0.332763,
    -0.31315,
    -0.594316,
    0.322967,
    -0.541994,
    -0.461725,
    0.423271,
    -0.077981,
    1.190881,
    0.55547,
    0.843744,
    -0.064585,
    -0.411894,
    -0.104718,
    -1.426926,
)
#: The v1 ids' extra metaparameters: u = 1 is the kick itself (θ = θ_kick, the column θ_kick − θ_ref).
_KICKS = {"power": POWER_KICK, "reach": REACH_KICK}
#: Every direction a low-dimensional kick id may search: the six and the two kicks'.
DIRECTIONS = (*METAPARAMETERS, *_KICKS)


def kick_metaparameters(env: Any, names: tuple[str, ...] = METAPARAMETERS) -> tuple[Array, Array, list[str]]:
    """(θ_ref (25,), B (25, k), names) for a kick env (its ``reference_params()``).

    ``names``: distinct names of :data:`DIRECTIONS`, B's columns in their order: the v0 ids' six
    (:data:`METAPARAMETERS`, the default), the v1 ids' six followed by ``"power"`` and ``"reach"`` (the
    columns :data:`POWER_KICK` − θ_ref and :data:`REACH_KICK` − θ_ref), or the v2 ids' few.
    """
    names = tuple(names)
    if not names or any(n not in DIRECTIONS for n in names) or len(set(names)) != len(names):
        raise ValueError(f"names: expected distinct names of {list(DIRECTIONS)}, got {list(names)}")
    reference = np.asarray(env.reference_params(), dtype=np.float64)
    swing = reference[_FINAL + _R : _FINAL + _R + 6] - reference[_R : _R + 6]
    columns = {name: np.zeros(reference.shape[0]) for name in DIRECTIONS}
    columns["amplitude"][_FINAL + _R : _FINAL + _R + 6] = 0.5 * swing
    columns["hip"][_FINAL + _R + _HIP_PITCH] = 0.6
    columns["ankle"][_FINAL + _R + _ANKLE_PITCH] = 0.6
    columns["duration"][_DURATION] = 0.5
    columns["aim"][_FINAL + _R + _HIP_ROLL] = 0.6
    for pose in (0, _FINAL):
        for leg in (_R, _L):
            columns["lean"][pose + leg + _HIP_ROLL] += 0.1
    for name, kick in _KICKS.items():
        columns[name] = np.asarray(kick) - reference
    return reference, np.stack([columns[name] for name in names], axis=1), list(names)


def make_low_dimensional_kick(full_id: str, names: tuple[str, ...] = METAPARAMETERS, **kwargs: Any) -> Any:
    """The entry point of the low-dimensional kick ids: ``full_id`` in :func:`kick_metaparameters`'s
    subspace of ``names`` (``kwargs``: :func:`~creps_gym.envs.subspace.make_low_dimensional`'s and the full
    env's)."""
    from creps_gym.envs.subspace import make_low_dimensional

    return make_low_dimensional(lambda env: kick_metaparameters(env, names), full_id, **kwargs)
