"""Context wrappers and the episodic conversion of step-based Gymnasium tasks.

* Context wrappers (:mod:`~creps_gym.wrappers.contexts`, vector counterparts in
  :mod:`~creps_gym.wrappers.vector`): :class:`FixedContexts`, :class:`SampleContexts`, :class:`HideContext`,
  :class:`NormalizeParams`, :class:`OffsetParams` (:mod:`~creps_gym.wrappers.offset`); samplers and
  named splits in :mod:`~creps_gym.wrappers.samplers`.
* Episodic conversion (:mod:`~creps_gym.wrappers.episodic`): :class:`EpisodicEnv` runs a whole inner episode
  per parameter vector with a controller (:mod:`~creps_gym.wrappers.controllers`) and reads/imposes the
  context through an accessor (:mod:`~creps_gym.wrappers.access`).
* Registered ecosystem examples: :mod:`~creps_gym.wrappers.examples`.

Importing this package imports neither MuJoCo nor Gymnasium-Robotics.
"""

from creps_gym.wrappers.access import ContextAccess, GoalContext, QposContext, make_context_access
from creps_gym.wrappers.contexts import FixedContexts, HideContext, NormalizeParams, SampleContexts
from creps_gym.wrappers.controllers import (
    Controller,
    DMPController,
    LinearFeedbackController,
    TrackingDMPController,
    make_controller,
)
from creps_gym.wrappers.episodic import EpisodicEnv, EpisodicVectorEnv
from creps_gym.wrappers.offset import OffsetParams
from creps_gym.wrappers.samplers import (
    BetaContexts,
    ContextSampler,
    GaussianContexts,
    UniformContexts,
    context_splits,
)
from creps_gym.wrappers.vector import (
    FixedContextsVector,
    HideContextVector,
    NormalizeParamsVector,
    SampleContextsVector,
)

__all__ = [
    "BetaContexts",
    "ContextAccess",
    "ContextSampler",
    "Controller",
    "DMPController",
    "EpisodicEnv",
    "EpisodicVectorEnv",
    "FixedContexts",
    "FixedContextsVector",
    "GaussianContexts",
    "GoalContext",
    "HideContext",
    "HideContextVector",
    "LinearFeedbackController",
    "NormalizeParams",
    "NormalizeParamsVector",
    "OffsetParams",
    "QposContext",
    "SampleContexts",
    "SampleContextsVector",
    "TrackingDMPController",
    "UniformContexts",
    "context_splits",
    "make_context_access",
    "make_controller",
]
