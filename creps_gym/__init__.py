"""creps_gym: contextual direct policy search (CREPS, CREPS-CMA) and contextual episodic Gymnasium envs.

Abdolmaleki et al., "Contextual Direct Policy Search With Regularized Covariance Matrix Estimation",
J. Intell. Robot. Syst. (2019), doi:10.1007/s10846-018-0968-4.

Importing the package registers the ``creps_gym/...`` environment ids with Gymnasium.
"""

from importlib.metadata import PackageNotFoundError, version
from typing import Any

from creps_gym import envs  # noqa: F401  (registers the environment ids)
from creps_gym.envs.registration import registered_ids

try:
    __version__ = version("creps-gym")
except PackageNotFoundError:  # pragma: no cover - running from a source tree without install
    __version__ = "0.0.0"

__all__ = ["Policy", "__version__", "load_policy", "registered_ids"]


def __getattr__(name: str) -> Any:
    """``Policy`` and ``load_policy``, imported on first use (``import creps_gym`` stays light)."""
    if name == "Policy":
        from creps_gym.optimizers.policy_file import Policy

        return Policy
    if name == "load_policy":
        from creps_gym.runner.policy_store import load_policy

        return load_policy
    raise AttributeError(f"module 'creps_gym' has no attribute {name!r}")
