"""The package's shape (DEVELOPERS.md, "Architecture" and "Style"): the dependency rule, no import cycles,
modules of at most 400 lines and functions of at most 60, each rule checked once over the whole package and
every breach listed in one failure message.

The import graph is read from the source with :mod:`ast`: every ``import`` statement of a module, at any
depth (a function's deferred import runs as surely as a top-level one, only later), except those under
``if TYPE_CHECKING:``, which never run.
"""

from __future__ import annotations

import ast
import functools
import sys
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "creps_gym"
MAX_LINES = 400


def module_name(path: Path) -> str:
    """The dotted name of a module file of the package (``creps_gym.runner`` for its ``__init__.py``)."""
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _type_checking_only(node: ast.AST) -> bool:
    """Whether ``node`` is an ``if TYPE_CHECKING:`` (or ``typing.TYPE_CHECKING``) block."""
    if not isinstance(node, ast.If):
        return False
    test = node.test
    return getattr(test, "id", getattr(test, "attr", None)) == "TYPE_CHECKING"


def imported_modules(source: str, package: str, modules: set[str]) -> set[str]:
    """The modules of ``modules`` that code ``source``, whose relative imports start from ``package``,
    imports when it runs."""
    found: set[str] = set()

    def visit(node: ast.AST) -> None:
        if _type_checking_only(node):
            for child in node.orelse:  # type: ignore[attr-defined]
                visit(child)
            return
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:  # relative: from ``package``, up ``level - 1`` packages
                parts = package.split(".")
                anchor = ".".join(parts[: len(parts) - node.level + 1])
                base = f"{anchor}.{base}" if base else anchor
            submodules = {f"{base}.{alias.name}" for alias in node.names} & modules
            # `from package import module` needs the package's ``__init__`` only as the module's parent,
            # which every import of the module runs; a name from the package itself needs all of it.
            found.update(submodules if len(submodules) == len(node.names) else {base, *submodules})
        for child in ast.iter_child_nodes(node):
            visit(child)

    visit(ast.parse(source))
    return found & modules


def import_graph() -> dict[str, set[str]]:
    """Module name -> the other package modules it imports (a copy of the graph read once per process)."""
    return {name: set(modules) for name, modules in _import_graph().items()}


@functools.cache
def _import_graph() -> dict[str, frozenset[str]]:
    graph = {}
    files = {module_name(path): path for path in PACKAGE.rglob("*.py")}
    for name, path in files.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        graph[name] = frozenset(
            imported_modules(path.read_text(encoding="utf-8"), package, set(files)) - {name}
        )
    return graph


def find_cycle(graph: dict[str, set[str]], within: str) -> list[str] | None:
    """A cycle among the modules whose names start with ``within`` (its modules in order), or None."""
    nodes = {name for name in graph if name == within or name.startswith(within + ".")}
    state: dict[str, int] = {}  # 1: on the current path, 2: done
    path: list[str] = []

    def visit(name: str) -> list[str] | None:
        state[name] = 1
        path.append(name)
        for other in sorted(graph[name] & nodes):
            if state.get(other) == 1:
                return [*path[path.index(other) :], other]
            if other not in state and (cycle := visit(other)) is not None:
                return cycle
        state[name] = 2
        path.pop()
        return None

    for name in sorted(nodes):
        if name not in state and (cycle := visit(name)) is not None:
            return cycle
    return None


def test_the_import_graph_reader_sees_deferred_imports_and_skips_type_checking_ones() -> None:
    modules = {"pkg", "pkg.a", "pkg.b", "pkg.c", "pkg.d"}
    source = (
        "from typing import TYPE_CHECKING\n"
        "import pkg.a\n"
        "if TYPE_CHECKING:\n    from pkg import b\n"
        "def f():\n    from pkg import c\n"
        "from .d import x\n"
    )
    assert imported_modules(source, "pkg", modules) == {"pkg.a", "pkg.c", "pkg.d"}
    assert imported_modules("from pkg import c, run", "pkg", modules) == {"pkg", "pkg.c"}
    graph = {"p.a": {"p.b"}, "p.b": {"p.c"}, "p.c": {"p.a"}, "q": {"p.a"}}
    assert find_cycle(graph, "p") == ["p.a", "p.b", "p.c", "p.a"]
    assert find_cycle({**graph, "p.c": set()}, "p") is None


def test_the_runner_has_no_import_cycle() -> None:
    """``backends`` builds the vector and Ray backends, which import the shared pieces from ``episodes``;
    ``rundir`` imports ``recovery``, which needs ``RunDir`` for annotations only."""
    graph = import_graph()
    assert graph["creps_gym.runner.backends"] >= {
        "creps_gym.runner.backends.vector",
        "creps_gym.runner.backends.ray",
    }
    assert "creps_gym.runner.rundir.recovery" in graph["creps_gym.runner.rundir"]
    assert find_cycle(graph, "creps_gym.runner") is None


def test_the_package_has_no_import_cycle_below_its_subpackages() -> None:
    graph = import_graph()
    for package in ("creps_gym.optimizers", "creps_gym.envs", "creps_gym.wrappers", "creps_gym.movement"):
        assert find_cycle(graph, package) is None, package


MAX_FUNCTION_LINES = 60
#: The third-party libraries the core may import at a module's top level.
CORE_LIBRARIES = {"numpy", "scipy", "gymnasium"}
#: Where MuJoCo may be imported: the MuJoCo envs (the kick, the registered Gymnasium(-Robotics) examples)
#: and the OpenGL backend chooser they call first.
MUJOCO_HOMES = ("creps_gym.envs.kick", "creps_gym.envs.opengl", "creps_gym.wrappers.examples")


def external_imports(source: str) -> list[tuple[str, bool]]:
    """(top-level module name, deferred) of every absolute import of ``source`` outside ``creps_gym``;
    deferred: inside a function, so it runs only when that function is called (each source parsed once)."""
    return list(_external_imports(source))


@functools.cache
def _external_imports(source: str) -> tuple[tuple[str, bool], ...]:
    found: list[tuple[str, bool]] = []

    def visit(node: ast.AST, deferred: bool) -> None:
        if _type_checking_only(node):
            return
        if isinstance(node, ast.Import):
            found.extend((alias.name.split(".")[0], deferred) for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and not node.level and node.module:
            found.append((node.module.split(".")[0], deferred))
        inner = deferred or isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda))
        for child in ast.iter_child_nodes(node):
            visit(child, inner)

    visit(ast.parse(source), False)
    return tuple((name, deferred) for name, deferred in found if name != "creps_gym")


#: The optional libraries (import name: distribution in ``pyproject.toml``'s extras): imported only where
#: they are needed, inside the function that needs them, never at a module's top level of the core.
OPTIONAL_LIBRARIES = {
    "cma": "cma",
    "nevergrad": "nevergrad",
    "optuna": "optuna",
    "sklearn": "scikit-learn",
    "matplotlib": "matplotlib",
    "tqdm": "tqdm",
    "imageio": "imageio",
    "mujoco": "mujoco",
    "gymnasium_robotics": "gymnasium-robotics",
    "ray": "ray",
    "torch": "torch",
    "botorch": "botorch",
}


#: The package's ground floor: modules every layer may import, the optimisers included (they import no
#: other package module, and no third-party library beyond numpy).
GROUND_FLOOR = ("creps_gym._validation", "creps_gym._files", "creps_gym._npz", "creps_gym.errors")
#: Ground-floor modules that import the standard library only (no numpy: ``creps-gym --help`` imports them).
STDLIB_ONLY = ("creps_gym._files", "creps_gym.errors")


def _modules() -> dict[str, Path]:
    return {module_name(path): path for path in sorted(PACKAGE.rglob("*.py"))}


def _within(name: str, *packages: str) -> bool:
    return any(name == package or name.startswith(package + ".") for package in packages)


def _library_breach(module: str, library: str, deferred: bool) -> str | None:
    """Why ``module`` may not import the third-party ``library`` (None: it may)."""
    core = {"numpy", "scipy"} if _within(module, "creps_gym.optimizers") else CORE_LIBRARIES
    if library in core:
        return None
    if library == "mujoco":
        return None if _within(module, *MUJOCO_HOMES) else f"imports mujoco (only {', '.join(MUJOCO_HOMES)})"
    if library not in OPTIONAL_LIBRARIES:
        return f"imports {library}, which is neither a core dependency nor an optional extra"
    return None if deferred else f"imports the optional {library} at its top level (import it where used)"


def dependency_breaches() -> list[str]:
    """Every import that breaks DEVELOPERS.md's dependency rule, as ``module: what``."""
    graph, breaches, stdlib = import_graph(), [], set(sys.stdlib_module_names)
    for name, path in _modules().items():
        for library, deferred in external_imports(path.read_text(encoding="utf-8")):
            if library not in stdlib and (why := _library_breach(name, library, deferred)):
                breaches.append(f"{name}: {why}")
            if library not in stdlib and name in STDLIB_ONLY:
                breaches.append(
                    f"{name}: imports {library} (the command line's start-up needs it stdlib-only)"
                )
        if _within(name, "creps_gym.optimizers"):
            others = sorted(m for m in graph[name] if not _within(m, "creps_gym.optimizers", *GROUND_FLOOR))
            breaches += [
                f"{name}: imports {m} (optimizers: only numpy, scipy, the ground floor)" for m in others
            ]
        if name in GROUND_FLOOR:
            upper = sorted(m for m in graph[name] if m not in GROUND_FLOOR and m != "creps_gym")
            breaches += [
                f"{name}: imports {m} (the ground floor imports only the ground floor)" for m in upper
            ]
        if _within(name, "creps_gym.envs", "creps_gym.wrappers", "creps_gym.movement", "creps_gym.selectors"):
            joined = sorted(m for m in graph[name] if _within(m, "creps_gym.optimizers", "creps_gym.runner"))
            breaches += [f"{name}: imports {m} (only the runner joins envs and optimizers)" for m in joined]
    return breaches


def test_the_dependency_rule_holds() -> None:
    """Optimisers import only numpy, scipy and the ground floor (an optional library only where used);
    envs, wrappers, movement and selectors never import the optimisers or the runner; MuJoCo only in the
    MuJoCo envs; every optional library the package imports is declared in ``pyproject.toml``."""
    breaches = dependency_breaches()
    assert not breaches, "the dependency rule is broken:\n" + "\n".join(breaches)
    declared = (PACKAGE.parent / "pyproject.toml").read_text(encoding="utf-8")
    used = {
        lib for path in _modules().values() for lib, _ in external_imports(path.read_text(encoding="utf-8"))
    }
    missing = sorted(OPTIONAL_LIBRARIES[lib] for lib in used & set(OPTIONAL_LIBRARIES))
    missing = [distribution for distribution in missing if f'"{distribution}' not in declared]
    assert not missing, f"optional libraries imported but not declared in pyproject.toml: {missing}"


def test_the_dependency_rule_names_each_kind_of_breach() -> None:
    source = "import numpy\nimport ray\ndef f():\n    import cma\n    import requests\n"
    assert external_imports(source) == [("numpy", False), ("ray", False), ("cma", True), ("requests", True)]
    assert _library_breach("creps_gym.optimizers.x", "gymnasium", False) is not None
    assert _library_breach("creps_gym.envs.x", "gymnasium", False) is None
    assert "top level" in _library_breach("creps_gym.optimizers.x", "cma", False)
    assert _library_breach("creps_gym.optimizers.adapters.x", "cma", True) is None
    assert "mujoco" in _library_breach("creps_gym.runner.x", "mujoco", True)
    assert _library_breach("creps_gym.envs.kick.env", "mujoco", False) is None
    assert "neither" in _library_breach("creps_gym.envs.x", "requests", True)


def function_lengths(source: str) -> list[tuple[str, int]]:
    """(qualified name, lines without its docstring) of every function of ``source``."""
    found: list[tuple[str, int]] = []

    def visit(node: ast.AST, prefix: str) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                lines = child.end_lineno - child.lineno + 1
                first = child.body[0]
                if isinstance(first, ast.Expr) and isinstance(getattr(first, "value", None), ast.Constant):
                    lines -= first.end_lineno - first.lineno + 1
                found.append((f"{prefix}{child.name}", lines))
                visit(child, f"{prefix}{child.name}.")
            elif isinstance(child, ast.ClassDef):
                visit(child, f"{prefix}{child.name}.")
            else:
                visit(child, prefix)

    visit(ast.parse(source), "")
    return found


#: Where the size limits apply: the package, and the benchmarks' study code.
SIZED = (PACKAGE, PACKAGE.parent / "benchmarks")


def test_modules_and_functions_are_small() -> None:
    """Every module of the package and of ``benchmarks/`` of at most 400 lines and every function of at
    most 60 (its docstring not counted), all breaches in one message."""
    breaches = []
    for path in (path for folder in SIZED for path in sorted(folder.rglob("*.py"))):
        source, where = path.read_text(encoding="utf-8"), path.relative_to(PACKAGE.parent)
        if (lines := len(source.splitlines())) > MAX_LINES:
            breaches.append(f"{where}: {lines} lines (a module: at most {MAX_LINES})")
        for function, length in function_lengths(source):
            if length > MAX_FUNCTION_LINES:
                breaches.append(
                    f"{where}: {function}: {length} lines (a function: at most {MAX_FUNCTION_LINES})"
                )
    assert not breaches, "too large:\n" + "\n".join(breaches)


def test_the_function_length_counts_code_not_the_docstring() -> None:
    source = 'class A:\n    def f(self):\n        """Doc.\n\n        More."""\n        return 1\n'
    assert function_lengths(source) == [("A.f", 2)]
