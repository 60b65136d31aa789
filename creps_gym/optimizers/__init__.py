"""Ask/tell optimisers: CREPS, CREPS-CMA, contextual CMA-ES and contextual BO, plus adapters (pycma,
nevergrad, optuna).

Returns are maximised. Optimisers never see an environment: ``ask(contexts) -> params``,
``tell(contexts, params, returns)``, ``recommend(contexts) -> params``.
"""

from creps_gym.optimizers.base import AskTellOptimizer, ContextualOptimizer, load_state, save_state
from creps_gym.optimizers.cbo import ContextualBO
from creps_gym.optimizers.cbo_config import CBOConfig
from creps_gym.optimizers.ccmaes import CCMAES, CCMAESConfig, recommended_batch_size
from creps_gym.optimizers.creps import (
    CREPS,
    CREPSConfig,
    solve_dual,
    weighted_ml_fit,
    weighted_sample_covariance,
)
from creps_gym.optimizers.creps_cma import (
    CREPSCMA,
    CREPSCMAConfig,
    interpolation_factor,
    regularised_covariance,
)
from creps_gym.optimizers.features import (
    AffineFeatures,
    BaselineFeatures,
    FeatureMap,
    PolynomialFeatures,
    QuadraticFeatures,
    RBFFeatures,
    make_features,
    register_feature_map,
)
from creps_gym.optimizers.policies import LinearGaussianPolicy, spd_factor
from creps_gym.optimizers.policy_file import Policy
from creps_gym.optimizers.registry import (
    describe_optimizers,
    make_optimizer,
    minimum_samples,
    optimizer_names,
    recommended_samples,
    register_optimizer,
    restore_optimizer,
)

__all__ = [
    "CCMAES",
    "CREPS",
    "CREPSCMA",
    "AffineFeatures",
    "AskTellOptimizer",
    "BaselineFeatures",
    "CBOConfig",
    "CCMAESConfig",
    "CREPSCMAConfig",
    "CREPSConfig",
    "ContextualBO",
    "ContextualOptimizer",
    "FeatureMap",
    "LinearGaussianPolicy",
    "Policy",
    "PolynomialFeatures",
    "QuadraticFeatures",
    "RBFFeatures",
    "describe_optimizers",
    "interpolation_factor",
    "load_state",
    "make_features",
    "make_optimizer",
    "minimum_samples",
    "optimizer_names",
    "recommended_batch_size",
    "recommended_samples",
    "register_feature_map",
    "register_optimizer",
    "regularised_covariance",
    "restore_optimizer",
    "save_state",
    "solve_dual",
    "spd_factor",
    "weighted_ml_fit",
    "weighted_sample_covariance",
]
