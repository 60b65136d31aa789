"""The set-up shared by the run-folder attack tests (``test_attack_*.py``): the runs they copy and attack,
and the checks every hostile case makes. The fixtures that build the runs once per module are in
``conftest.py``; this module holds what the tests import."""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import signal
import sys
import time
import zlib
from pathlib import Path

import pytest
from helpers import SPHERE

from creps_gym.cli import main
from creps_gym.optimizers.base import load_state, save_state
from creps_gym.runner import RunDir, run
from creps_gym.runner.backends.watchdog import child_pids

SETTINGS = {"iterations": 6, "samples_per_iteration": 10, "env_kwargs": {"dim": 2}, "eval_every": 2}
SETTINGS["checkpoint_every"] = 2
SECONDS = 30  # every hostile case must end well within this
DEEP = "[" * 100_000 + "]" * 100_000  # JSON nested deeper than any parser allows
POSIX = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="POSIX files, /proc, rlimits")


class Stop(Exception):
    """Raised by a callback to leave a run unfinished (as a crash would)."""


def make_run(path: Path, *, seed: int = 0, stop_after: int | None = None, **changes) -> Path:
    """A run of ``SETTINGS`` (with ``changes``) in ``path``: finished, or crashed after ``stop_after``
    iterations (its last checkpoint the even iteration before). The fixtures ``templates`` and ``place``
    copy the common ones; a test builds its own only for other settings."""

    def crash(record, history):
        if stop_after is not None and record.iteration >= stop_after:
            raise Stop

    with contextlib.suppress(Stop):
        run("creps-cma-old", SPHERE, seed=seed, run_dir=path, callbacks=[crash], **{**SETTINGS, **changes})
    return path


def snapshot(folder: Path) -> dict[str, tuple]:
    """Every entry under ``folder``: its kind and content (or link target), and its mode."""
    found = {}
    for path in sorted(folder.rglob("*")):
        info = path.lstat()
        content = os.readlink(path) if path.is_symlink() else path.read_bytes() if path.is_file() else None
        found[str(path.relative_to(folder))] = (info.st_mode, content, info.st_size)
    return found


@contextlib.contextmanager
def deadline(seconds: float = SECONDS):
    """Fail a call that blocks (e.g. opening a FIFO) instead of hanging the test session."""

    def expire(*_):
        raise TimeoutError(f"still running after {seconds} s")

    previous = signal.signal(signal.SIGALRM, expire)
    signal.alarm(int(seconds))
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)


def checked_cli(capsys, *args) -> tuple[int, str]:
    """Exit code and stderr of ``creps-gym ARGS`` run here; checks the hostile-case invariants."""
    start = time.monotonic()
    with deadline():
        code = main([str(a) for a in args])
    assert time.monotonic() - start < SECONDS
    error = capsys.readouterr().err
    assert "Traceback" not in error
    assert not child_pids(os.getpid()), "a process was left running"
    return code, error


def hostile(capsys, tmp_path, *args) -> tuple[int, str]:
    """:func:`checked_cli`, and nothing outside the run directory (``tmp_path/outside``) changed."""
    before = snapshot(tmp_path / "outside")
    code, error = checked_cli(capsys, *args)
    assert snapshot(tmp_path / "outside") == before
    return code, error


def one_error_naming(error: str, path: Path) -> str:
    """The one error line of ``error``, which names ``path``."""
    lines = [line for line in error.splitlines() if ": error: " in line]
    assert len(lines) == 1, error
    assert str(path) in lines[0], error
    return lines[0]


def rewrite_checkpoint(path: Path, edit) -> None:
    """Edit the loop state of a checkpoint with ``edit(flat)`` and keep its checksum right."""
    flat = load_state(path)
    edit(flat)
    state = {k: v for k, v in flat.items() if not k.startswith("optimizer.")}
    state = {k: v for k, v in state.items() if k not in ("format", "fingerprint", "state_crc")}
    flat["state_crc"] = zlib.crc32(json.dumps(state, sort_keys=True).encode())
    save_state(flat, path)


def edit_config(path: Path, **changes) -> None:
    """Change fields of the run configuration in ``path``'s config.json."""
    document = json.loads((path / RunDir.CONFIG).read_text())
    document["config"].update(changes)
    (path / RunDir.CONFIG).write_text(json.dumps(document))


def truncate(path: Path) -> None:
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])


# -- fuzzed damage: the hypothesis strategy (the fuzz tests skip without hypothesis) and its application
try:
    from hypothesis import settings
    from hypothesis import strategies as st
except ImportError:  # pragma: no cover - hypothesis is a development dependency
    FUZZ = corruptions = values = None
else:
    FUZZ = settings(max_examples=30, deadline=None)
    corruptions = st.one_of(
        st.tuples(st.just("truncate"), st.floats(0, 1)),
        st.tuples(st.just("flip"), st.floats(0, 1), st.integers(0, 7)),
        st.tuples(st.just("replace"), st.binary(max_size=64)),
    )
    values = st.one_of(  # a field's forged value
        st.none(),
        st.booleans(),
        st.integers(-3, 10),
        st.floats(allow_nan=True, allow_infinity=True),
        st.text(max_size=4),
        st.lists(st.integers(0, 4), max_size=3),
        st.dictionaries(st.text(max_size=3), st.integers(), max_size=2),
    )


def copy_of(template: Path, into: str) -> Path:
    """A copy of the run ``template`` in ``into/run`` (a fuzz example's own temporary folder)."""
    target = Path(into) / "run"
    shutil.copytree(template, target)
    return target


def corrupt(path: Path, corruption: tuple) -> None:
    """Apply one of ``corruptions`` to the file ``path``."""
    data = bytearray(path.read_bytes())
    kind = corruption[0]
    if kind == "truncate":
        data = data[: int(corruption[1] * len(data))]
    elif kind == "flip" and data:
        data[min(int(corruption[1] * len(data)), len(data) - 1)] ^= 1 << corruption[2]
    elif kind == "replace":
        data = bytearray(corruption[1])
    path.write_bytes(bytes(data))
