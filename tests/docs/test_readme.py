"""Every ```python block of the README runs, in order, so the examples cannot rot."""

from __future__ import annotations

import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest
from helpers import python_blocks

README = Path(__file__).resolve().parents[2] / "README.md"
BLOCKS = python_blocks(README)


def test_readme_has_python_examples():
    assert BLOCKS, "the README lost its Python examples"


@pytest.mark.parametrize("index", range(len(BLOCKS)))
@pytest.mark.slow
def test_readme_python_block_runs(index, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    namespace: dict = {"__name__": "__readme__"}
    for block in BLOCKS[: index + 1]:  # later blocks may use names defined earlier
        exec(compile(block, f"README.md block {index}", "exec"), namespace)


# -- the README's first two commands: a light install for the main job, the full one for the tests
ROOT = README.parent
_COMMANDS = re.search(r"```bash\n(.*?)```", README.read_text(encoding="utf-8"), flags=re.DOTALL).group(1)
MAIN_LINE, TEST_LINE = _COMMANDS.splitlines()[:2]
# the import name of every distribution in pyproject.toml's extras (the test tools aside)
_MODULES = {
    "mujoco": "mujoco",
    "gymnasium-robotics": "gymnasium_robotics",
    "matplotlib": "matplotlib",
    "cma": "cma",
    "nevergrad": "nevergrad",
    "optuna": "optuna",
    "ray": "ray",
    "tqdm": "tqdm",
    "imageio": "imageio",
    "imageio-ffmpeg": "imageio_ffmpeg",
}


def _extras() -> dict[str, set[str]]:
    """pyproject.toml's extras: name -> distribution names (``creps-gym[...]`` expanded)."""
    text = (ROOT / "pyproject.toml").read_text(encoding="utf-8")
    section = text.split("[project.optional-dependencies]", 1)[1].split("\n[", 1)[0]
    raw = {
        name: re.findall(r'"([A-Za-z0-9_.-]+?)(?:\[([a-z,]+)\])?[<>=!~;"]', body)
        for name, body in re.findall(r"^(\w+) = \[(.*?)\]$", section, flags=re.MULTILINE | re.DOTALL)
    }

    def expand(name: str) -> set[str]:
        deps = set()
        for dist, inner in raw[name]:
            deps |= {d for extra in inner.split(",") for d in expand(extra)} if inner else {dist}
        return deps

    return {name: expand(name) for name in raw}


def _installed_extras(line: str) -> list[str]:
    match = re.fullmatch(r'pip install -e "\.\[([a-z,]+)\]" && .*', line)
    assert match, line
    return match.group(1).split(",")


def test_the_main_job_installs_only_plot_and_cli_and_the_tests_install_everything():
    assert _installed_extras(MAIN_LINE) == ["plot", "cli"]
    assert MAIN_LINE.split(" && ")[1].startswith("creps-gym run")
    assert TEST_LINE == 'pip install -e ".[all,test]" && python -m pytest'
    extras = _extras()
    assert set(extras["all"]) == {d for name in extras if name not in ("all", "test") for d in extras[name]}
    assert set(extras["all"]) == set(_MODULES), "name the import module of each new extra's distribution"
    prose = README.read_text(encoding="utf-8").split("```", 3)[2]  # the paragraph after the commands
    assert 'pip install -e ".[all]"' in prose
    for name in ("mujoco", "ray", "adapters", "video"):  # what [all] adds, each named
        assert f"`{name}`" in prose, name


def test_ci_runs_the_readmes_test_command_exactly():
    lines = [line for line in (ROOT / ".ci" / "run").read_text(encoding="utf-8").splitlines() if line.strip()]
    assert lines[-1] == TEST_LINE


_BLOCKED_RUN = """
import importlib.abc, sys
BLOCKED = set(sys.argv[1].split(","))
class Block(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in BLOCKED:
            raise ModuleNotFoundError(f"No module named {name!r} (blocked: not in the install)", name=name)
        return None
sys.meta_path.insert(0, Block())
from creps_gym.cli import main
sys.exit(main(sys.argv[2:]))
"""


@pytest.mark.extras
@pytest.mark.slow
def test_the_main_job_runs_with_the_light_install_alone(tmp_path):
    """The README's main job, with every module of the extras its install line leaves out made missing."""
    pytest.importorskip("matplotlib")
    pytest.importorskip("tqdm")
    extras = _extras()
    light = {_MODULES[dist] for name in _installed_extras(MAIN_LINE) for dist in extras[name]}
    blocked = sorted(set(_MODULES.values()) - light)
    argv = shlex.split(MAIN_LINE.split(" && ")[1])[1:]
    argv[argv.index("--out") + 1] = str(tmp_path / "run")
    command = [sys.executable, "-c", _BLOCKED_RUN, ",".join(blocked), *argv]
    out = subprocess.run(command, capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert out.returncode == 0, out.stderr[-3000:]
    assert "stop: target_regret" in out.stdout and (tmp_path / "run" / "learning_curve.png").is_file()
    assert "blocked" not in out.stdout + out.stderr
