"""The optimiser registry: every ask/tell optimiser the runner and the CLI know by name.

Each entry has a one-line description, a factory with the common signature
``factory(n_params, n_context_dims, seed, initial_mean, initial_cov, **options)`` and the class whose
``from_state_dict`` restores a checkpoint. Classes are imported only when an entry is used, so listing the
registry never imports an optional library. Users add their own with :func:`register_optimizer`.

====================== =====================================================================================
name                   optimiser
====================== =====================================================================================
``creps``              :class:`~creps_gym.optimizers.creps.CREPS`
``creps-cma-old``      :class:`~creps_gym.optimizers.creps_cma.CREPSCMA` with ``variant="old"``
``creps-cma-current``  :class:`~creps_gym.optimizers.creps_cma.CREPSCMA` with ``variant="current"``
``creps-cma-csa``      :class:`~creps_gym.optimizers.creps_cma.CREPSCMA` with ``step_size="csa"``
``c-cma-es``           :class:`~creps_gym.optimizers.ccmaes.CCMAES`
``c-cma-es-surrogate`` :class:`~creps_gym.optimizers.ccmaes_surrogate.CCMAESSurrogate`
``c-bo``               :class:`~creps_gym.optimizers.cbo.ContextualBO`
``cma``                :class:`~creps_gym.optimizers.adapters.pycma.CMAAdapter`
``nevergrad``          :class:`~creps_gym.optimizers.adapters.nevergrad.NevergradAdapter`
``optuna``             :class:`~creps_gym.optimizers.adapters.optuna.OptunaAdapter`
====================== =====================================================================================
"""

from __future__ import annotations

import importlib
from collections.abc import Mapping
from dataclasses import dataclass, field, fields, is_dataclass
from typing import Any

__all__ = [
    "OptimizerEntry",
    "describe_optimizers",
    "make_optimizer",
    "minimum_samples",
    "optimizer_class",
    "optimizer_names",
    "recommended_samples",
    "register_optimizer",
    "restore_optimizer",
]


@dataclass(frozen=True)
class OptimizerEntry:
    """One registered optimiser.

    Parameters
    ----------
    name : str
        Registry name (what ``creps-gym run --optimizer`` takes).
    description : str
        One line shown by ``creps-gym list``.
    target : str or type
        The optimiser class, or ``"module:Class"`` to import it lazily. The class must take
        ``(n_params, n_context_dims, *, initial_mean, initial_cov, seed, **options)`` and provide
        ``from_state_dict``.
    fixed : dict
        Keyword arguments always passed (e.g. ``{"variant": "old"}``).
    """

    name: str
    description: str
    target: str | type
    fixed: Mapping[str, Any] = field(default_factory=dict)

    def load_class(self) -> Any:
        """Import and return the optimiser class."""
        if not isinstance(self.target, str):
            return self.target
        module, _, attribute = self.target.partition(":")
        return getattr(importlib.import_module(module), attribute)


_REGISTRY: dict[str, OptimizerEntry] = {}


def register_optimizer(
    name: str,
    description: str,
    target: str | type,
    fixed: Mapping[str, Any] | None = None,
    *,
    replace: bool = False,
) -> OptimizerEntry:
    """Add an optimiser to the registry (see :class:`OptimizerEntry` for the arguments).

    Raises
    ------
    ValueError
        ``name`` is taken (and ``replace`` is False) or ``target`` is not ``"module:Class"``.
    """
    if not isinstance(name, str) or not name:
        raise TypeError(f"name: expected a non-empty str, got {name!r}")
    if name in _REGISTRY and not replace:
        raise ValueError(f"name: expected a name not yet registered, got {name!r} (pass replace=True)")
    if isinstance(target, str) and target.count(":") != 1:
        raise ValueError(f"target: expected a class or 'module:Class', got {target!r}")
    if not isinstance(target, (str, type)):
        raise TypeError(f"target: expected a class or 'module:Class', got {type(target).__name__}")
    entry = OptimizerEntry(name, description, target, dict(fixed or {}))
    _REGISTRY[name] = entry
    return entry


def optimizer_names() -> list[str]:
    """Registered optimiser names, in registration order."""
    return list(_REGISTRY)


def describe_optimizers() -> dict[str, str]:
    """Name -> one-line description of every registered optimiser."""
    return {name: entry.description for name, entry in _REGISTRY.items()}


def _entry(name: str) -> OptimizerEntry:
    if name not in _REGISTRY:
        raise ValueError(f"optimizer: expected one of {optimizer_names()}, got {name!r}")
    return _REGISTRY[name]


def optimizer_class(name: str) -> Any:
    """The class behind a registered name (imports it)."""
    return _entry(name).load_class()


def make_optimizer(
    name: str,
    n_params: int,
    n_context_dims: int,
    seed: int | None,
    initial_mean: Any = 0.0,
    initial_cov: Any = 1.0,
    **options: Any,
) -> Any:
    """Build a registered optimiser.

    Parameters
    ----------
    name : str
        A name from :func:`optimizer_names`.
    n_params, n_context_dims : int
        Dimensions p of θ and z of the context.
    seed : int or None
        Seed of the optimiser's random stream.
    initial_mean : float or array_like, shape (p,)
        Initial mean (CREPS variants also accept coefficients (k, p)).
    initial_cov : float or array_like, shape (p,) or (p, p)
        Initial covariance (adapters accept only diagonal ones).
    **options
        Optimiser-specific keyword arguments (see each class).

    Returns
    -------
    AskTellOptimizer
    """
    entry = _entry(name)
    cls = entry.load_class()
    clash = sorted(set(options) & set(entry.fixed))
    if clash:
        raise ValueError(f"options: expected no option fixed by {name!r} ({dict(entry.fixed)}), got {clash}")
    kwargs = {"initial_mean": initial_mean, "initial_cov": initial_cov, "seed": seed}
    return cls(n_params, n_context_dims, **kwargs, **entry.fixed, **options)


def recommended_samples(optimizer: str | Any, n_params: int, n_context_dims: int) -> int:
    """The batch size N to use when the user gives none, for a registry name or an optimiser object.

    The optimiser's class decides through a ``recommended_batch_size(n_params, n_context_dims)`` method
    (contextual CMA-ES's rule for this package's optimisers, CMA-ES's 4 + ⌊3 ln p⌋ for the adapters);
    classes without one get :func:`creps_gym.optimizers.ccmaes.recommended_batch_size`.
    """
    cls = optimizer_class(optimizer) if isinstance(optimizer, str) else type(optimizer)
    rule = getattr(cls, "recommended_batch_size", None)
    if rule is None:
        from creps_gym.optimizers.ccmaes import recommended_batch_size as rule
    return int(rule(n_params, n_context_dims))


def minimum_samples(optimizer: str | Any, n_params: int, n_context_dims: int) -> int | None:
    """The smallest batch size the runner accepts for a registry name or an optimiser object, or None.

    The optimiser's class decides through a ``minimum_batch_size(n_params, n_context_dims)`` method (every
    native optimiser has one: :meth:`creps_gym.optimizers.policies.PolicyAccess.minimum_batch_size`);
    classes without one (the adapters, users' own optimisers) get None: no minimum beyond two.
    """
    cls = optimizer_class(optimizer) if isinstance(optimizer, str) else type(optimizer)
    rule = getattr(cls, "minimum_batch_size", None)
    return None if rule is None else int(rule(n_params, n_context_dims))


def restore_optimizer(name: str, state: Mapping[str, Any]) -> Any:
    """Rebuild a registered optimiser from its ``state_dict()``; the state must be one of ``name``'s (a
    ``creps-cma-csa`` state is not a ``creps-cma-old`` one, although both are ``CREPSCMA``).

    Every option that some name of the same class fixes must have ``name``'s value: its fixed one, else the
    config's default.
    """
    entry = _entry(name)
    optimizer = entry.load_class().from_state_dict(state)
    config = getattr(optimizer, "config", None)
    if config is None or not is_dataclass(config):
        return optimizer
    defaults = {f.name: f.default for f in fields(config)}
    keys = {key for other in _REGISTRY.values() if other.target == entry.target for key in other.fixed}
    expected = {key: entry.fixed.get(key, defaults.get(key, _MISSING)) for key in sorted(keys)}
    got = {key: getattr(config, key, _MISSING) for key in expected}
    if got != expected:
        raise ValueError(f"state: expected a state of {name!r}, with {expected}, got one with {got}")
    return optimizer


_MISSING = object()

_DEFAULTS = (
    (
        "creps",
        "Contextual REPS: KL-bounded weights, weighted ML mean and covariance (premature convergence)",
        "creps_gym.optimizers.creps:CREPS",
        {},
    ),
    (
        "creps-cma-old",
        "CREPS-CMA, old-mean variant: rank-mu covariance around the sampling mean (Eq. 16)",
        "creps_gym.optimizers.creps_cma:CREPSCMA",
        {"variant": "old"},
    ),
    (
        "creps-cma-current",
        "CREPS-CMA, current-mean variant: rank-mu covariance around the new mean (Eq. 13)",
        "creps_gym.optimizers.creps_cma:CREPSCMA",
        {"variant": "current"},
    ),
    (
        "creps-cma-csa",
        "CREPS-CMA with step-size control: CREPS weights and mean, CMA covariance and CSA",
        "creps_gym.optimizers.creps_cma:CREPSCMA",
        {"step_size": "csa"},
    ),
    (
        "c-cma-es",
        "Contextual CMA-ES: rank weights on context-baselined returns, step-size control (CSA)",
        "creps_gym.optimizers.ccmaes:CCMAES",
        {},
    ),
    (
        "c-cma-es-surrogate",
        "C-CMA-ES with a linear-quadratic surrogate of the return, used while it ranks",
        "creps_gym.optimizers.ccmaes_surrogate:CCMAESSurrogate",
        {},
    ),
    (
        "c-bo",
        "Contextual Bayesian optimisation: a GP over (s, theta), MES or UCB at each s (50-500 episodes)",
        "creps_gym.optimizers.cbo:ContextualBO",
        {},
    ),
    (
        "cma",
        "pycma CMA-ES (non-contextual: ignores the context; extra 'adapters')",
        "creps_gym.optimizers.adapters.pycma:CMAAdapter",
        {},
    ),
    (
        "nevergrad",
        "nevergrad optimiser, TwoPointsDE by default (non-contextual; extra 'adapters')",
        "creps_gym.optimizers.adapters.nevergrad:NevergradAdapter",
        {},
    ),
    (
        "optuna",
        "optuna TPE sampler, ask-and-tell (non-contextual; extra 'adapters')",
        "creps_gym.optimizers.adapters.optuna:OptunaAdapter",
        {},
    ),
)
for _name, _description, _target, _fixed in _DEFAULTS:
    register_optimizer(_name, _description, _target, _fixed)
