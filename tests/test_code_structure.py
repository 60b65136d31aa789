"""The package's shape (DEVELOPERS.md, "Style"): modules of at most 400 lines, and no import cycles.

The import graph is read from the source with :mod:`ast`: every ``import`` statement of a module, at any
depth (a function's deferred import runs as surely as a top-level one, only later), except those under
``if TYPE_CHECKING:``, which never run.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

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
    """Module name -> the other package modules it imports."""
    graph = {}
    files = {module_name(path): path for path in PACKAGE.rglob("*.py")}
    for name, path in files.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        graph[name] = imported_modules(path.read_text(encoding="utf-8"), package, set(files)) - {name}
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
        "creps_gym.runner.vector_backend",
        "creps_gym.runner.ray_backend",
    }
    assert "creps_gym.runner.recovery" in graph["creps_gym.runner.rundir"]
    assert find_cycle(graph, "creps_gym.runner") is None


def test_the_package_has_no_import_cycle_below_its_subpackages() -> None:
    graph = import_graph()
    for package in ("creps_gym.optimizers", "creps_gym.envs", "creps_gym.wrappers", "creps_gym.movement"):
        assert find_cycle(graph, package) is None, package


MODULES = sorted(str(path.relative_to(PACKAGE)) for path in PACKAGE.rglob("*.py"))


@pytest.mark.parametrize("module", MODULES)
def test_every_module_has_at_most_400_lines(module: str) -> None:
    lines = len((PACKAGE / module).read_text(encoding="utf-8").splitlines())
    assert lines <= MAX_LINES, f"creps_gym/{module}: {lines} lines, expected at most {MAX_LINES}"
