"""Registration of every ``creps_gym/`` id with Gymnasium.

Each env family contributes a list of ``gymnasium.register`` keyword dicts through a ``REGISTRATIONS``
sequence in its package; this module is the single place that collects them. Registered kwargs are
JSON-serialisable. No id sets ``max_episode_steps``: a TimeLimit of 1 would mark the one step truncated.
"""

from __future__ import annotations

import importlib
from typing import Any

import gymnasium as gym

__all__ = ["all_registrations", "register_envs", "registered_ids"]

NAMESPACE = "creps_gym"


# Each module lists its ids in a module-level ``REGISTRATIONS`` list of ``gymnasium.register`` kwargs.
# Importing these modules must be cheap: MuJoCo is imported only when a MuJoCo env is made.
FAMILIES = (
    "creps_gym.envs.functions",
    "creps_gym.envs.reacher",
    "creps_gym.envs.kick",
    "creps_gym.wrappers.examples",
)


def all_registrations() -> list[dict[str, Any]]:
    registrations: list[dict[str, Any]] = []
    for module_name in FAMILIES:
        try:
            module = importlib.import_module(module_name)
        except ModuleNotFoundError as exc:  # a family not written yet
            if exc.name != module_name:
                raise
            continue
        registrations.extend(getattr(module, "REGISTRATIONS", []))
    return registrations


def register_envs() -> None:
    """Register every creps_gym id (idempotent)."""
    for entry in all_registrations():
        if entry["id"] not in gym.registry:
            gym.register(**entry)


def registered_ids() -> list[str]:
    """All ``creps_gym/`` ids currently in Gymnasium's registry, sorted."""
    return sorted(env_id for env_id in gym.registry if env_id.startswith(NAMESPACE + "/"))
