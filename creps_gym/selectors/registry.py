"""Registered context selectors by name, and how a name and its options become a selector.

A run names its selector (``RunConfig.context_selector``) and gives its options as JSON data
(``context_selector_options``); a run directory's ``config.json`` may name only a registered selector, and
its options are checked here as data (names against the selector's keywords, values by the selector).
"""

from __future__ import annotations

import inspect
import math
from collections.abc import Mapping
from typing import Any

from creps_gym._validation import config_field
from creps_gym.errors import ConfigError, ConfigTypeError
from creps_gym.selectors.active import ActiveContextSelector
from creps_gym.selectors.bandit import LearningProgressBandit
from creps_gym.selectors.base import BetaSelector, EnvSelector, FixedSelector, UniformSelector
from creps_gym.selectors.progress import KernelProgressSelector

__all__ = ["SELECTORS", "ArcsineSelector", "check_options", "make_selector", "selector_names"]


class ArcsineSelector(BetaSelector):
    """Beta(1/2, 1/2) draws in the box: the arcsine law (a :class:`BetaSelector` without options)."""

    name = "arcsine"

    def __init__(self) -> None:
        super().__init__(0.5, 0.5)


#: Name -> selector class; a class is built with the run's ``context_selector_options`` as keywords.
SELECTORS: dict[str, type] = {
    "env": EnvSelector,
    "uniform": UniformSelector,
    "arcsine": ArcsineSelector,
    "beta": BetaSelector,
    "fixed": FixedSelector,
    "bandit": LearningProgressBandit,
    "progress": KernelProgressSelector,
    "active": ActiveContextSelector,
}


#: An example value of each required selector option, for the message that says it is missing.
OPTION_EXAMPLES = {("fixed", "contexts"): "'contexts=[[0.5], [1.5]]': one list of z numbers per context"}


def selector_names() -> list[str]:
    """The registered selector names."""
    return list(SELECTORS)


def _check_data(value: Any, where: str) -> None:
    """Refuse anything that is not JSON data (finite numbers, strings, bools, None, lists, dicts)."""
    if isinstance(value, float) and not math.isfinite(value):
        raise ValueError(f"{where}: expected a finite number, got {value!r}")
    if isinstance(value, (list, tuple)):
        for k, item in enumerate(value):
            _check_data(item, f"{where}[{k}]")
    elif isinstance(value, dict):
        for key, item in value.items():
            if not isinstance(key, str):
                raise TypeError(f"{where}: expected str keys, got {key!r}")
            _check_data(item, f"{where}.{key}")
    elif value is not None and not isinstance(value, (bool, int, float, str)):
        raise TypeError(f"{where}: expected JSON data, got {type(value).__name__}")


def check_options(name: Any, options: Any) -> dict[str, Any]:
    """``options`` as a dict if ``name`` is registered and every option is one of its keywords, as data."""
    if not isinstance(name, str) or name not in SELECTORS:
        raise ConfigError("context_selector", f"expected one of {selector_names()}, got {name!r}")
    if not isinstance(options, Mapping):
        raise ConfigTypeError("context_selector_options", f"expected a dict, got {type(options).__name__}")
    parameters = inspect.signature(SELECTORS[name]).parameters
    accepted = [p for p in parameters if p != "self"]
    missing = [p for p in accepted if parameters[p].default is inspect.Parameter.empty and p not in options]
    if missing:
        example = OPTION_EXAMPLES.get((name, missing[0]), f"{missing[0]}=VALUE")
        raise ConfigError(
            "context_selector_options",
            f"expected the option {missing[0]!r} of {name!r}, got none (e.g. --selector-opt {example})",
        )
    for key, value in options.items():
        if key not in accepted:
            raise ConfigError(
                "context_selector_options", f"expected options of {name!r} from {accepted}, got {key!r}"
            )
        with config_field("context_selector_options"):
            _check_data(value, f"context_selector_options.{key}")
    return dict(options)


def make_selector(name: str, options: Mapping[str, Any] | None = None) -> Any:
    """The registered selector ``name`` built with ``options`` (checked: see :func:`check_options`)."""
    options = check_options(name, {} if options is None else options)
    return SELECTORS[name](**options)
