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
