"""Fast start (issue 31, item 7): what ``--help`` and ``list`` import, and the static table they print.

The times themselves are measured by ``benchmarks/cli_startup.py`` (never by a timed test); these tests
check the causes: neither command imports numpy, Gymnasium, SciPy or an optional library, ``import
creps_gym`` alone imports none of them, and the static table agrees with the live registries.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
import textwrap

import pytest
from helpers import EXTRAS, cli_command

HEAVY = ["numpy", "gymnasium", "scipy", "matplotlib", "ray", "mujoco", "tqdm", "creps_gym.envs"]


def _python(code: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True, timeout=300
    )


@pytest.mark.parametrize("argv", [["--help"], ["list"], ["run", "--help"], ["plot", "--help"]])
def test_help_and_list_import_no_heavy_module(argv):
    result = _python(
        f"""
        import json, runpy, sys
        sys.argv = ["creps-gym", *{argv!r}]
        try:
            runpy.run_module("creps_gym.cli", run_name="__main__")
        except SystemExit as exc:
            assert exc.code in (0, None), exc.code
        print(json.dumps(sorted(name for name in {HEAVY!r} if name in sys.modules)))
        """
    )
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout.splitlines()[-1]) == []


@pytest.mark.slow
def test_a_run_imports_neither_scipy_stats_nor_scipy_optimize():
    """Start-up time: ``creps-gym run`` imports the runner and every registered optimiser; scipy.stats
    (0.5 s) is never needed, scipy.optimize (0.2 s) only once c-bo fits or maximises."""
    result = _python(
        """
        import sys
        import creps_gym.cli.run, creps_gym.runner, creps_gym.optimizers
        print([name for name in ("scipy.stats", "scipy.optimize") if name in sys.modules])
        """
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout.split() == ["[]"]


def test_importing_the_package_registers_the_ids_when_gymnasium_is_imported_in_either_order():
    result = _python(
        """
        import sys
        import creps_gym
        assert "gymnasium" not in sys.modules and "numpy" not in sys.modules
        import gymnasium as gym
        assert not [name for name in sys.modules if name.startswith("creps_gym.cli")]  # the table alone
        assert gym.make("creps_gym/Sphere-v0").unwrapped.spec.id == "creps_gym/Sphere-v0"
        assert gym.__loader__.__class__.__name__ == "SourceFileLoader"  # Gymnasium's own loader is kept
        print(len(creps_gym.registered_ids()), creps_gym.envs.__name__, creps_gym.__version__ != "")
        """
    )
    assert result.returncode == 0, result.stderr
    before = _python("import gymnasium as gym, creps_gym; print(len(creps_gym.registered_ids()))")
    assert before.returncode == 0, before.stderr
    count, name, version = result.stdout.split()
    assert int(count) == int(before.stdout) > 20 and name == "creps_gym.envs" and version == "True"


@EXTRAS  # the table records which optional modules each env needs: every extra must be installed
@pytest.mark.slow
def test_the_static_table_agrees_with_the_registries_and_run_config():
    result = subprocess.run(
        [sys.executable, "-m", "creps_gym.listing", "--check"], capture_output=True, text=True, timeout=600
    )
    assert result.returncode == 0, result.stdout + result.stderr


def test_list_prints_every_row_of_the_static_table():
    from creps_gym._table import ENVS, OPTIMIZERS

    listed = subprocess.run(cli_command("list"), capture_output=True, text=True, timeout=60)
    ids = [line.split()[0] for line in listed.stdout.splitlines() if re.match(r"  \S", line)]
    assert listed.returncode == 0 and all(row[0] in ids for row in ENVS + OPTIMIZERS)


@pytest.mark.parametrize(
    "module",
    ["creps_gym.wrappers", "creps_gym.selectors", "creps_gym.envs.functions.suite", "creps_gym.runner"],
)
@pytest.mark.slow
def test_a_subpackage_that_imports_gymnasium_first_registers_every_id(module):
    """Gymnasium imported for the first time *by* a creps_gym module: the ids are registered from the
    static table (before: registering imported that module's package again, half-initialised)."""
    from creps_gym._table import REGISTRATIONS

    result = _python(
        f"""
        import {module}
        import gymnasium
        print(sorted(i for i in gymnasium.registry if i.startswith("creps_gym/")))
        """
    )
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout.replace("'", '"')) == sorted(entry["id"] for entry in REGISTRATIONS)
