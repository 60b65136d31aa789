"""The seed plan: which child of the master seed's ``SeedSequence`` feeds which stream, named once.

A run's randomness comes from one master seed (``RunConfig.seed``). ``numpy.random.SeedSequence(seed)``
spawns independent children, numbered from 0; each stream of a run takes its own child, so adding a
stream (a new child number) never changes what the others draw. Child ``k`` is the same sequence however
many children are spawned (its spawn key is ``(k,)``), so :func:`seed_child` spawns only as many as it
needs. The numbers are part of every result ever recorded: never renumber a child, only add new ones.

=====================  ======  ============================================================================
Child                  Number  Stream
=====================  ======  ============================================================================
``ENV``                0       episode reset seeds and training contexts (:func:`split_seed`)
``OPTIMIZER``          1       the optimiser's seed (:func:`split_seed`)
``EVALUATION``         2       the test contexts' seed (:func:`split_seed`, ``creps-gym evaluate``)
``INITIAL_MEAN``       3       ``initial_mean="uniform"`` (:func:`~creps_gym.runner.build.uniform_mean`)
``SELECTOR``           4       a context selector's draws (:func:`.selection.selector_stream`)
=====================  ======  ============================================================================
"""

from __future__ import annotations

import enum

import numpy as np

__all__ = ["SeedPlan", "seed_child", "split_seed"]


class SeedPlan(enum.IntEnum):
    """The children of the master seed's ``SeedSequence``, by stream (see the module docstring)."""

    ENV = 0
    OPTIMIZER = 1
    EVALUATION = 2
    INITIAL_MEAN = 3
    SELECTOR = 4


def seed_child(seed: int, child: SeedPlan) -> np.random.SeedSequence:
    """The master ``seed``'s ``SeedSequence`` child ``child`` (the same whatever else is spawned)."""
    return np.random.SeedSequence(seed).spawn(int(child) + 1)[int(child)]


def split_seed(seed: int) -> tuple[np.random.Generator, int, int]:
    """The env stream (a Generator), the optimiser's seed and the test contexts' seed from a master seed.

    Children :attr:`SeedPlan.ENV`, :attr:`SeedPlan.OPTIMIZER` and :attr:`SeedPlan.EVALUATION`; the two
    seeds are each child's first 32-bit word of state.
    """
    env_seq, optimizer_seq, eval_seq = (
        seed_child(seed, child) for child in (SeedPlan.ENV, SeedPlan.OPTIMIZER, SeedPlan.EVALUATION)
    )
    return (
        np.random.default_rng(env_seq),
        int(optimizer_seq.generate_state(1)[0]),
        int(eval_seq.generate_state(1)[0]),
    )
