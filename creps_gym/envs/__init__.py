"""Contextual episodic Gymnasium environments, registered under ``creps_gym/...`` ids.

Importing :mod:`creps_gym` registers every id; ``gymnasium.make("creps_gym/Sphere-v0")`` then works.
"""

from creps_gym.envs.base import ContextualEpisodicEnv, ContextualEpisodicVectorEnv, SupportsRegret
from creps_gym.envs.evaluation import evaluate_policy, test_contexts
from creps_gym.envs.registration import register_envs

register_envs()

__all__ = [
    "ContextualEpisodicEnv",
    "ContextualEpisodicVectorEnv",
    "SupportsRegret",
    "evaluate_policy",
    "register_envs",
    "test_contexts",
]
