"""The low-budget study's columns (issue 44, item 5): each a registered optimiser with options and an
optional context selector, or an optimiser class outside the registry (:attr:`Method.factory`)."""

from __future__ import annotations

import dataclasses
import importlib
from dataclasses import dataclass
from typing import Any

from benchmarks.study_options import C3_PIN, CBO_FIT_PIN, CBO_PINS
from creps_gym.optimizers import make_optimizer

__all__ = ["METHODS", "PINNED_FIT_POINTS", "Method", "method_by_name", "unpinned"]


@dataclass(frozen=True)
class Method:
    """One column of the study: a registered optimiser with options, and an optional context selector.

    ``name`` is the column's label and part of every run's key (letters, digits, ``-``, ``+``, ``=``).
    ``selector`` names a registered :mod:`creps_gym.selectors` selector (built with ``selector_options``)
    that picks every batch's training contexts instead of the env's sampler; it is bound to the env's
    context box and told each batch's returns and the optimiser's diagnostics, as the runner does. An
    active selector for c-bo is one more entry, e.g. ``Method("c-bo+active", "c-bo", selector="active")``.
    ``factory`` (``"module:Class"``) builds an optimiser outside the registry (c-bo on BoTorch's or
    scikit-learn's GP, libraries the package does not depend on) with ``make_optimizer``'s arguments;
    ``optimizer`` then names the registered optimiser whose batch size it takes. ``packages`` names the
    distributions such a class uses, whose versions the runs' provenance records.
    """

    name: str
    optimizer: str
    options: tuple[tuple[str, Any], ...] = ()
    selector: str | None = None
    selector_options: tuple[tuple[str, Any], ...] = ()
    note: str = ""
    factory: str | None = None
    packages: tuple[str, ...] = ()

    def build(self, n_params: int, n_context_dims: int, seed: int, **options: Any) -> Any:
        """The column's optimiser: ``make_optimizer`` of ``optimizer``, or ``factory``'s class."""
        if self.factory is None:
            return make_optimizer(self.optimizer, n_params, n_context_dims, seed, **options)
        module, name = self.factory.split(":")
        return getattr(importlib.import_module(module), name)(n_params, n_context_dims, seed=seed, **options)


#: The study's methods (columns), in the order of the tables. The committed runs of the c-bo columns were
#: computed with the refits, the log transform's scale and MES's floor of c-bo's defaults before 2026-11-30
#: (``CBO_PINS``, study_options.py).
METHODS = (
    Method("c-bo", "c-bo", CBO_PINS, note="max-value entropy search (c-bo's default acquisition)"),
    Method("c-bo-ucb", "c-bo", (("acquisition", "ucb"), *CBO_PINS), note="GP-UCB"),
    Method(
        "c-bo+active",
        "c-bo",
        CBO_PINS,
        selector="active",
        note="max-value entropy search, active contexts",
    ),
    Method(
        "c-bo-ucb+active",
        "c-bo",
        (("acquisition", "ucb"), *CBO_PINS),
        selector="active",
        note="GP-UCB, active contexts",
    ),
    Method(
        "c-bo+quadratic",
        "c-bo",
        (("trend", "quadratic"), ("transform", "auto"), *CBO_PINS),
        note="a quadratic prior mean (Eq. G4), the returns' transform chosen by Eq. (G5)",
    ),
    Method(
        "c-bo-botorch",
        "c-bo",
        CBO_PINS,
        note="max-value entropy search on BoTorch's model and optimiser (botorch_cbo.py)",
        factory="benchmarks.low_budget.botorch_cbo:BoTorchCBO",
        packages=("torch", "botorch", "gpytorch"),
    ),
    Method(
        "c-bo-sklearn",
        "c-bo",
        CBO_PINS,
        note="max-value entropy search on scikit-learn's GaussianProcessRegressor (sklearn_cbo.py)",
        factory="benchmarks.low_budget.sklearn_cbo:SklearnCBO",
        packages=("scikit-learn",),
    ),
    Method("creps", "creps", (("epsilon", 1.0),), note="ε = 1, as Fabisch (GECCO 2019)"),
    Method("creps-cma-old", "creps-cma-old", note="the paper's CREPS-CMA"),
    # The committed runs of these two were computed with C3, the default before issue 45 (study_options.py).
    Method("c-cma-es", "c-cma-es", options=C3_PIN),
    Method("c-cma-es-surrogate", "c-cma-es-surrogate", options=C3_PIN),
)


def method_by_name(name: str) -> Method:
    """The method (row of :data:`METHODS`) called ``name``."""
    for method in METHODS:
        if method.name == name:
            return method
    raise ValueError(f"method: expected one of {[m.name for m in METHODS]}, got {name!r}")


#: The episodes a pinned c-bo column's refit sees: up to this many, its runs and the same runs without the
#: pin (:func:`unpinned`) have fitted on the same episodes, so they agree bit for bit.
PINNED_FIT_POINTS = dict(CBO_FIT_PIN)["fit_points"]


def unpinned(method: Method) -> Method:
    """The c-bo column ``method`` without :data:`~benchmarks.study_options.CBO_FIT_PIN`: c-bo's refit
    defaults. The log and floor pins stay (``CBO_KEPT_PINS``): the replays of the unpinned columns were
    measured before those defaults changed; ``--options '{"log_quantile": 0.25, "mes_floor": "observed"}'``
    adds the new ones."""
    if method.optimizer != "c-bo" or not set(CBO_FIT_PIN) <= set(method.options):
        raise ValueError(f"method: expected a c-bo column pinned to {CBO_FIT_PIN}, got {method.name!r}")
    return dataclasses.replace(method, options=tuple(p for p in method.options if p not in CBO_FIT_PIN))
