"""The paper's 15 contextual benchmark functions (Table 1) as registered Gymnasium environments.

``gymnasium.make("creps_gym/Rosenbrock-v0", dim=15, context_dim=1, instance=0)`` gives one function; every id
also has a native vector env (``gymnasium.make_vec(id, num_envs=n)``). The ids, in the paper's order:
Rosenbrock, Sphere, ShiftedSphere, ShiftedSchwefel, CigTab, Tablet, ShiftedRotatedElliptic,
ShiftedRotatedElliptic1e4, DifferentPowers, Plane, TwoAxes, Cigar, Rastrigin, ParabolicRidge, SharpRidge
(each ``creps_gym/<Name>-v0``).

Modules: :mod:`.definitions` (the pure batched kernels), :mod:`.specs` (formula, reference, optimum, target),
:mod:`.instance` (the seeded A, shift and rotation), :mod:`.env` (the env classes and their manual) and
:mod:`.suite` (one class per function).
"""

from __future__ import annotations

from typing import Any

from creps_gym.envs.functions.env import (
    BoundedFunctionEnv,
    ContextualFunctionEnv,
    ContextualFunctionVectorEnv,
    UnboundedFunctionEnv,
)
from creps_gym.envs.functions.specs import SPECS, FunctionSpec
from creps_gym.envs.functions.suite import ENV_CLASSES

__all__ = [
    "ENV_CLASSES",
    "REGISTRATIONS",
    "SPECS",
    "BoundedFunctionEnv",
    "ContextualFunctionEnv",
    "ContextualFunctionVectorEnv",
    "FunctionSpec",
    "UnboundedFunctionEnv",
]

_SUITE = "creps_gym.envs.functions.suite"

#: ``gymnasium.register`` kwargs of every function id (collected by :mod:`creps_gym.envs.registration`).
#: No ``max_episode_steps``: a TimeLimit of 1 would mark the single step truncated.
REGISTRATIONS: list[dict[str, Any]] = [
    {
        "id": f"creps_gym/{env_class.function.name}-v0",
        "entry_point": f"{_SUITE}:{env_class.__name__}",
        "vector_entry_point": f"{_SUITE}:{vector_class.__name__}",
        "kwargs": {"dim": 15, "context_dim": 1, "instance": 0},
    }
    for env_class, vector_class in ENV_CLASSES
]
