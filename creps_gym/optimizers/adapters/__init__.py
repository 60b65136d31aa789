"""Adapters that run non-contextual minimisers (pycma, nevergrad, optuna) behind the ask/tell protocol.

The libraries are optional (``pip install creps-gym[adapters]``) and imported only when an adapter first
asks. See ``docs/writing_an_adapter.md`` to wrap another optimiser.
"""

from creps_gym.optimizers.adapters.base import MinimizerAdapter, import_optional, initial_variances
from creps_gym.optimizers.adapters.nevergrad import NevergradAdapter
from creps_gym.optimizers.adapters.optuna import OptunaAdapter
from creps_gym.optimizers.adapters.pycma import CMAAdapter

__all__ = [
    "CMAAdapter",
    "MinimizerAdapter",
    "NevergradAdapter",
    "OptunaAdapter",
    "import_optional",
    "initial_variances",
]
