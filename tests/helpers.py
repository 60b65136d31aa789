"""Helpers shared by several test modules (imported as ``from helpers import ...``)."""

from __future__ import annotations

import re
import sys
from pathlib import Path
from typing import Any

import gymnasium as gym
import pytest
from gymnasium.error import DependencyNotInstalled

SPHERE = "creps_gym/Sphere-v0"


def make_or_skip(env_id: str, vector: bool = False, **kwargs: Any) -> Any:
    """``gym.make`` (or ``gym.make_vec``) an id, skipping the test when an optional extra is missing."""
    try:
        return gym.make_vec(env_id, **kwargs) if vector else gym.make(env_id, **kwargs)
    except (DependencyNotInstalled, ModuleNotFoundError) as exc:  # an optional extra (MuJoCo, robotics)
        pytest.skip(f"{env_id}: optional dependency not installed ({exc})")


def python_blocks(path: Path) -> list[str]:
    """The ```python code blocks of a Markdown file, in order."""
    return re.findall(r"```python\n(.*?)```", Path(path).read_text(), flags=re.DOTALL)


def cli_command(*args: Any) -> list[str]:
    """The command line of ``creps-gym`` with ``args``, run through the current interpreter."""
    return [sys.executable, "-m", "creps_gym.cli", *map(str, args)]


# -- the `extras` marker: tests that need an optional extra; CI's lowest-versions environment runs the others
EXTRAS = pytest.mark.extras
_EXTRA_ENV_MODULES = ("creps_gym.envs.kick", "creps_gym.wrappers")  # MuJoCo, Gymnasium(-Robotics) MuJoCo envs


def needs_extra(env_or_optimizer: str) -> bool:
    """Whether a registered env id or optimiser name needs an optional extra (MuJoCo, a library)."""
    from creps_gym.optimizers.adapters import MinimizerAdapter
    from creps_gym.optimizers.registry import optimizer_class, optimizer_names

    if env_or_optimizer in optimizer_names():  # the bundled adapters wrap pycma, nevergrad and optuna
        return issubclass(optimizer_class(env_or_optimizer), MinimizerAdapter)
    entry_point = gym.spec(env_or_optimizer).entry_point
    return isinstance(entry_point, str) and entry_point.startswith(_EXTRA_ENV_MODULES)


def marked(names: Any) -> list[Any]:
    """Parameters for ``pytest.mark.parametrize``, the ones that need an optional extra marked ``extras``."""
    return [pytest.param(name, marks=EXTRAS) if needs_extra(name) else name for name in names]
