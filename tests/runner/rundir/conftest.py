"""The one set-up of the run-folder attack tests: the runs they attack, built once per module and copied
per test (helpers they import are in ``rundir_setup.py``)."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from helpers import SPHERE
from rundir_setup import SETTINGS, make_run

from creps_gym.runner import run


@pytest.fixture(scope="module")
def templates(tmp_path_factory):
    """Runs to copy (never to change): ``finished``; ``crashed`` after iteration 3 (checkpoint at 2,
    iterations 1-3 logged); ``other``, seed 1 crashed after 4; ``history``, the uninterrupted history."""
    root = tmp_path_factory.mktemp("templates")
    return {
        "finished": make_run(root / "finished"),
        "crashed": make_run(root / "crashed", stop_after=3),
        "other": make_run(root / "other", seed=1, stop_after=4),
        "history": run("creps-cma-old", SPHERE, seed=0, **SETTINGS),
    }


@pytest.fixture
def place(tmp_path, templates):
    """``place(name)``: a copy of a template run in ``tmp_path/run``; ``tmp_path/outside`` holds victims
    (a file ``victim``) that no hostile case may change."""
    outside = tmp_path / "outside"
    outside.mkdir()
    (outside / "victim").write_bytes(b"not the run's\n")

    def copy(name: str) -> Path:
        return Path(shutil.copytree(templates[name], tmp_path / "run"))

    return copy
