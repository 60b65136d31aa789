"""The optimiser options of a study's run (:attr:`benchmarks.study_tools.RunSpec.options`): their names are
checked against the registered optimiser's config fields, and they are kept as sorted (name, value) pairs, so
that a run's key does not depend on the order they were given in."""

from __future__ import annotations

import math
import sys
from collections.abc import Mapping
from dataclasses import fields, is_dataclass
from typing import Any

from creps_gym.optimizers import optimizer_names
from creps_gym.optimizers.registry import optimizer_class

__all__ = [
    "C3_METHODS",
    "C3_PIN",
    "CBO_FIT_PIN",
    "CBO_FLOOR_PIN",
    "CBO_KEPT_PINS",
    "CBO_LOG_PIN",
    "CBO_PINS",
    "OWN_OPTIONS",
    "RESTART_PIN",
    "canonical_options",
    "config_fields",
    "options_dict",
    "pin_c3",
]

#: Options a :class:`RunSpec` sets through its own fields, the runner or the study, not through ``options``.
OWN_OPTIONS = ("max_interpolation", "divide_by_z", "max_std_growth", "seed", "initial_mean", "initial_cov")
#: The committed ``c-cma-es`` runs were computed with C3, the mean fit's ridge towards 0, the default until
#: issue 45 (now C3r, ``ridge_centre="old"``): the studies pin their columns to it, so those runs stay the
#: runs of their specs (``benchmarks/pin_defaults.py`` wrote the pin into them; docs/algorithms.md, C3r).
C3_PIN = (("ridge_centre", "zero"),)
#: The registered optimisers that take the pin (``c-cma-es-surrogate`` shares C-CMA-ES's config).
C3_METHODS = ("c-cma-es", "c-cma-es-surrogate")
#: The committed ``c-bo`` runs (the low-budget study's c-bo columns, on c-bo's own GP and on the libraries')
#: were computed with the refits on the 256 most recent episodes, c-bo's default until 2026-11-30 (now
#: every episode up to 1024, then a spread: ``fit_subset``, Eq. G3a of ``creps_gym/optimizers/gp_model.py``).
#: The study pins its c-bo columns to it, so those runs stay the runs of their specs
#: (``benchmarks/pin_defaults.py`` wrote the pin into them); ``benchmarks/low_budget/refit_data.py``
#: measures the new default beside them.
CBO_FIT_PIN = (("fit_points", 256), ("fit_subset", "recent"))
#: The committed ``c-bo`` runs were computed with the log transform's scale at the median gap, c-bo's
#: default until 2026-11-30 (now the lower quartile: ``log_quantile``, Eq. G6 of
#: ``creps_gym/optimizers/gp_trend.py``). Every c-bo column carries it beside :data:`CBO_FIT_PIN`
#: (:data:`CBO_PINS`); ``benchmarks/low_budget/recommenders.py --options`` measures the new default.
CBO_LOG_PIN = (("log_quantile", 0.5),)
#: The committed ``c-bo`` runs were computed with MES's sampled maxima floored at the candidates' largest
#: posterior mean, c-bo's rule until 2026-11-30 (now also five noise standard deviations above the inputs
#: the model holds at the asked context: ``mes_floor``, Eq. A4 of ``creps_gym/optimizers/acquisitions.py``;
#: the same bits where no context repeats, as in the study's continuous draws). Every c-bo
#: column carries it too; ``benchmarks/low_budget/recommenders.py --options`` measures the new default.
CBO_FLOOR_PIN = (("mes_floor", "candidates"),)
#: The pins of every c-bo column.
CBO_PINS = (*CBO_FIT_PIN, *CBO_LOG_PIN, *CBO_FLOOR_PIN)
#: The pins a replay of a c-bo column with c-bo's refit defaults keeps
#: (``benchmarks/low_budget/columns.py``'s ``unpinned``): those replays were measured before these defaults
#: changed, and their documents do not name them.
CBO_KEPT_PINS = (*CBO_LOG_PIN, *CBO_FLOOR_PIN)
#: The ``c-cma-es`` restart defaults before issue 33: ``keep_best=False`` and ``restart_baseline_loss=
#: "squared"`` (the former None for the squared baseline every such run used). The committed runs that
#: restarted were computed with them; ``benchmarks/restart_defaults.py`` pins them (its ``FORMER``) and
#: the studies' "former restarts" columns run with them.
RESTART_PIN = (("keep_best", False), ("restart_baseline_loss", "squared"))


def options_dict(options: Any) -> dict[str, Any]:
    """Optimiser options given as (name, value) pairs (a stored document's lists too) or a mapping, as a
    dict; None or empty: {}."""
    if not options:
        return {}
    return dict(options.items()) if isinstance(options, Mapping) else {name: value for name, value in options}


def pin_c3(method: str, options: Any = ()) -> tuple[tuple[str, Any], ...]:
    """``options`` (pairs or a mapping) as sorted pairs, with :data:`C3_PIN` added for a method of
    :data:`C3_METHODS` that does not set ``ridge_centre`` itself."""
    pairs = options_dict(options)
    if method in C3_METHODS:
        pairs = {**dict(C3_PIN), **pairs}
    return tuple(sorted(pairs.items()))


def canonical_options(method: str, options: Any) -> tuple[tuple[str, Any], ...]:
    """``options`` as sorted (name, value) pairs, each name a config field of the optimiser ``method``."""
    pairs = list(options.items()) if isinstance(options, Mapping) else [tuple(p) for p in options]
    if not pairs:
        return ()
    names = [pair[0] for pair in pairs]
    known = config_fields(method) - set(OWN_OPTIONS)
    if any(len(pair) != 2 for pair in pairs) or len(set(names)) != len(names) or not set(names) <= known:
        raise ValueError(
            f"options: expected distinct (name, value) pairs with names in {sorted(known)} (the options of "
            f"{method!r}), got {options!r}"
        )
    for name, value in pairs:
        if not isinstance(value, bool | int | float | str) or (
            isinstance(value, float) and math.isnan(value)
        ):
            raise ValueError(f"options: expected a bool, int, float or str for {name!r}, got {value!r}")
    return tuple(sorted(pairs))


def config_fields(method: str) -> set[str]:
    """The config fields of the registered optimiser ``method`` (its ``config_class``, else the dataclass
    ``<class name>Config`` of its module, e.g. ``CCMAESConfig``); none for a baseline or an unknown name."""
    if method not in optimizer_names():
        return set()
    cls = optimizer_class(method)
    default = getattr(sys.modules[cls.__module__], f"{cls.__name__}Config", None)
    config = getattr(cls, "config_class", default)
    return (
        {f.name for f in fields(config)} - {"n_params", "n_context_dims"} if is_dataclass(config) else set()
    )
