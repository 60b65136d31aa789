"""creps_gym: contextual direct policy search (CREPS, CREPS-CMA) and contextual episodic Gymnasium envs.

Abdolmaleki et al., "Contextual Direct Policy Search With Regularized Covariance Matrix Estimation",
J. Intell. Robot. Syst. (2019), doi:10.1007/s10846-018-0968-4.

Importing the package registers the ``creps_gym/...`` environment ids with Gymnasium: at once when
Gymnasium is already imported, else as soon as it is (so ``import creps_gym`` alone imports neither
Gymnasium nor numpy, and ``creps-gym --help`` starts fast). The subpackages and :func:`registered_ids`
are imported on first use.
"""

import sys


def _module_run_by_dash_m(argv: list) -> str | None:
    """The target of ``python [options] -m TARGET`` in the interpreter's own command line, or None where it
    cannot be read (``-X``/``-W`` take a value; short flags may be joined, as in ``-Bm``)."""
    args = iter(argv[1:])
    for arg in args:
        if not arg.startswith("-") or arg.startswith("--") or arg == "-":
            return None
        for index, flag in enumerate(arg[1:], start=2):
            if flag in "WX":
                if index == len(arg):
                    next(args, None)
                break
            if flag == "c":
                return None
            if flag == "m":
                return arg[index:] or next(args, None)
    return None


def _drop_cwd_when_run_as_module() -> None:
    """``python -m creps_gym.cli`` (the form the docs use) puts the current directory first on ``sys.path``
    and runs this file before any other code of the package: drop that entry here, before any import can
    search it, so that no file in the working directory (a run folder, say: a ``json.py``, ``copy.py`` or
    ``argparse.py``) ever runs. ``--import MODULE`` looks there last (:mod:`creps_gym.cli`).

    ``sys.argv[0]`` is ``"-m"`` only while ``-m`` locates its target, that is while it imports the target's
    packages. The entry stays where the target is read from ``sys.orig_argv`` and lies outside this package
    (another package that imports this one). The current directory comes from the built-in ``posix``/``nt``
    module, which no file can shadow (``os`` is not loaded yet under ``python -S``).
    """
    if sys.argv[:1] != ["-m"] or getattr(sys.flags, "safe_path", False) or not sys.path:
        return
    target = _module_run_by_dash_m(list(getattr(sys, "orig_argv", [])))
    if target is not None and target != __name__ and not target.startswith(__name__ + "."):
        return
    builtin = __import__("posix" if "posix" in sys.builtin_module_names else "nt")
    if sys.path[0] in ("", builtin.getcwd()):
        del sys.path[0]


_drop_cwd_when_run_as_module()

import copy  # noqa: E402  (after the sys.path guard above)
import importlib  # noqa: E402
import importlib.abc  # noqa: E402
import importlib.util  # noqa: E402
from typing import Any  # noqa: E402

__all__ = ["Policy", "__version__", "load_policy", "registered_ids"]

_LAZY = {
    "registered_ids": "creps_gym.envs.registration",
    "Policy": "creps_gym.optimizers.policy_file",  # the learned policy, loadable anywhere
    "load_policy": "creps_gym.runner.rundir.policies",
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
    """Register every ``creps_gym/`` id from :data:`creps_gym._table.REGISTRATIONS`.

    The table holds only data (entry points are ``"module:Class"`` strings), so this imports no env
    module: Gymnasium may be imported for the first time *by* one of them (``import creps_gym.wrappers``),
    which registering through :mod:`creps_gym.envs` would import again half-initialised.
    """
    from creps_gym import _table as table

    for entry in getattr(table, "REGISTRATIONS", ()):  # none while `listing --write` makes the table
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
