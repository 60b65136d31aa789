"""No file in the working directory runs, however the CLI is started (issue 42, item 14).

``python -m creps_gym.cli`` (the form the docs use) puts the current directory first on ``sys.path``, and
Python runs ``creps_gym/__init__.py`` before any code of the CLI. A run folder that holds a ``json.py``,
``copy.py``, ``shlex.py`` or ``argparse.py`` must never have it imported. The shadows here cover every
standard-library module (and the core dependencies) that the interpreter has not imported before ``-m``
starts: those few (``os``, ``importlib``, ...) Python itself imports before any package code can run.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from helpers import cli_command, run_argv

#: A module that leaves a mark when it is imported, and fails loudly.
SHADOW = (
    "open(__file__ + '.imported', 'w').close()\nraise SystemExit('shadow ' + __name__ + ' was imported')\n"
)
THIRD_PARTY = ("numpy", "scipy", "gymnasium", "matplotlib", "tqdm", "mujoco", "cma")


def _loaded_before_dash_m() -> set[str]:
    """The modules an interpreter has loaded when ``-m`` starts locating its target (runpy's included)."""
    code = "import runpy, sys; print(' '.join(sys.modules))"
    listed = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return {name.split(".")[0] for name in listed.stdout.split()}


def _shadow_everything(folder: Path) -> list[str]:
    names = sorted((set(sys.stdlib_module_names) | set(THIRD_PARTY)) - _loaded_before_dash_m())
    names = [name for name in names if name.isidentifier() and not name.startswith("_")] + [
        "__future__",
        "_compat_pickle",
    ]
    for name in names:
        (folder / f"{name}.py").write_text(SHADOW)
    return names


def _marks(folder: Path) -> list[str]:
    return sorted(path.name for path in folder.glob("*.imported"))


@pytest.fixture(scope="module")
def shadowed_run(tmp_path_factory) -> Path:
    """A finished run whose folder then gets a shadow for every module name the CLI could import."""
    folder = tmp_path_factory.mktemp("hole") / "run"
    command = cli_command(*run_argv(folder, "--no-plot", env_kwargs=("dim=2",)))
    made = subprocess.run(command, capture_output=True, text=True, timeout=180)
    assert made.returncode == 0, made.stderr
    names = _shadow_everything(folder)
    assert {"json", "copy", "shlex", "argparse", "numpy", "__future__"} <= set(names)
    return folder


@pytest.mark.parametrize(
    "args",
    [
        ("--help",),
        ("list",),
        ("resume", ".", "--no-plot"),
        ("policy", ".", "--context", "0.5"),
        ("export", "."),
    ],
    ids=["help", "list", "resume", "policy", "export"],
)
@pytest.mark.parametrize("form", ["-m", "-Bm", "-W ignore -m"])
@pytest.mark.slow
def test_python_dash_m_in_a_run_folder_imports_nothing_from_it(shadowed_run, args, form):
    command = cli_command(*args)
    command[1:2] = form.split()  # [python, -m, creps_gym.cli, ...] with the interpreter's flags
    result = subprocess.run(command, capture_output=True, text=True, cwd=shadowed_run, timeout=180)
    assert _marks(shadowed_run) == [], result.stderr
    assert "shadow" not in result.stderr
    if args[0] in ("--help", "list"):
        assert result.returncode == 0, result.stderr


def test_another_packages_dash_m_keeps_its_folder_on_the_path(tmp_path):
    """The guard drops the entry only for ``-m`` targets inside creps_gym: a package of the working
    directory that imports creps_gym still finds its sibling modules."""
    (tmp_path / "mypkg").mkdir()
    (tmp_path / "mypkg" / "__init__.py").write_text("import creps_gym\nimport sibling\n")
    (tmp_path / "mypkg" / "main.py").write_text("print('ran')\n")
    (tmp_path / "sibling.py").write_text("")
    result = subprocess.run(
        [sys.executable, "-m", "mypkg.main"], capture_output=True, text=True, cwd=tmp_path, timeout=60
    )
    assert result.returncode == 0 and result.stdout.strip() == "ran", result.stderr


@pytest.mark.parametrize(
    ("argv", "expected"),
    [
        (["python", "-m", "creps_gym.cli", "run"], "creps_gym.cli"),
        (["python", "-mcreps_gym.cli"], "creps_gym.cli"),
        (["python", "-Bm", "creps_gym.cli"], "creps_gym.cli"),
        (["python", "-X", "importtime", "-W", "ignore", "-m", "x.y"], "x.y"),
        (["python", "-Ximporttime", "-m", "x"], "x"),
        (["python", "-c", "pass", "-m", "x"], None),
        (["python", "script.py", "-m", "x"], None),
        (["python", "--check-hash-based-pycs", "always", "-m", "x"], None),
    ],
)
def test_the_dash_m_target_is_read_from_the_interpreters_command_line(argv, expected):
    import creps_gym

    assert creps_gym._module_run_by_dash_m(argv) == expected
