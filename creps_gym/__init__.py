"""creps_gym: contextual direct policy search (CREPS, CREPS-CMA) and contextual episodic Gymnasium envs.

Abdolmaleki et al., "Contextual Direct Policy Search With Regularized Covariance Matrix Estimation",
J. Intell. Robot. Syst. (2019), doi:10.1007/s10846-018-0968-4.

Importing the package registers the ``creps_gym/...`` environment ids with Gymnasium: at once when
Gymnasium is already imported, else as soon as it is (so ``import creps_gym`` alone imports neither
Gymnasium nor numpy, and ``creps-gym --help`` starts fast). The subpackages and :func:`registered_ids`
are imported on first use.
"""

from __future__ import annotations

import copy
import importlib
import importlib.abc
import importlib.util
import sys
from typing import Any

__all__ = ["Policy", "__version__", "load_policy", "registered_ids"]

_LAZY = {
    "registered_ids": "creps_gym.envs.registration",
    "Policy": "creps_gym.optimizers.policy_file",  # the learned policy, loadable anywhere
    "load_policy": "creps_gym.runner.policy_store",
}
_SUBPACKAGES = ("envs", "movement", "optimizers", "runner", "selectors", "wrappers")


class _RegisterAfterGymnasium(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Registers the ids right after Gymnasium's own module runs (the first ``import gymnasium``)."""

    def find_spec(self, name: str, path: Any = None, target: Any = None) -> Any:
        if name != "gymnasium":
            return None
        sys.meta_path.remove(self)  # once; the real finders locate Gymnasium
        spec = importlib.util.find_spec(name)
        if spec is None or spec.loader is None:
            return spec
        self._loader = spec.loader
        spec.loader = self
        return spec

    def create_module(self, spec: Any) -> Any:
        return self._loader.create_module(spec)

    def exec_module(self, module: Any) -> None:
        module.__loader__ = module.__spec__.loader = self._loader  # Gymnasium's own loader from now on
        self._loader.exec_module(module)
        _register_ids(module)


def _register_ids(gymnasium: Any) -> None:
    """Register every ``creps_gym/`` id from :data:`creps_gym.cli_table.REGISTRATIONS`.

    The table holds only data (entry points are ``"module:Class"`` strings), so this imports no env
    module: Gymnasium may be imported for the first time *by* one of them (``import creps_gym.wrappers``),
    which registering through :mod:`creps_gym.envs` would import again half-initialised.
    """
    from creps_gym import cli_table

    for entry in getattr(cli_table, "REGISTRATIONS", ()):  # none while `listing --write` makes the table
        if entry["id"] not in gymnasium.registry:
            gymnasium.register(**copy.deepcopy(entry))


def _register_when_gymnasium_loads() -> None:
    if "gymnasium" in sys.modules:
        _register_ids(sys.modules["gymnasium"])
    elif not any(isinstance(finder, _RegisterAfterGymnasium) for finder in sys.meta_path):
        sys.meta_path.insert(0, _RegisterAfterGymnasium())


def __getattr__(name: str) -> Any:
    if name == "__version__":
        from importlib.metadata import PackageNotFoundError, version

        try:
            value = version("creps-gym")
        except PackageNotFoundError:  # pragma: no cover - running from a source tree without install
            value = "0.0.0"
        globals()[name] = value
        return value
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    if name in _SUBPACKAGES:
        return importlib.import_module(f"creps_gym.{name}")
    raise AttributeError(f"module 'creps_gym' has no attribute {name!r}")


_register_when_gymnasium_loads()
