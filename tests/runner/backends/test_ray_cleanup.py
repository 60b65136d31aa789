"""A run that started its own Ray leaves no process behind after a kill -9 (issue 15, item 19).

The watchdog (:mod:`creps_gym.runner.backends.watchdog`) is tested on plain processes, then on a real Ray
started by a real driver process that is killed with SIGKILL.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from creps_gym.runner.backends.watchdog import Watchdog, process_stat, process_tree

pytestmark = pytest.mark.skipif(not os.path.isdir("/proc"), reason="the watchdog needs Linux's /proc")
ROOT = Path(__file__).resolve().parents[3]


def _driver(tmp_path: Path, body: str) -> subprocess.Popen:
    """A Python driver process running ``body``, with this checkout first on its path."""
    script = tmp_path / "driver.py"
    script.write_text(textwrap.dedent(body))
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    return subprocess.Popen(
        [sys.executable, str(script)], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, env=env
    )


def _ray_driver(tmp_path: Path, body: str) -> subprocess.Popen:
    """:func:`_driver` for a body that uses Ray (the test is skipped without it)."""
    pytest.importorskip("ray")
    return _driver(tmp_path, body)


def _alive(tracked: dict[int, int]) -> list[int]:
    stats = {pid: process_stat(pid) for pid in tracked}
    return [pid for pid, start in tracked.items() if stats[pid] is not None and stats[pid][1] == start]


def _wait_until_gone(tracked: dict[int, int], seconds: float) -> list[int]:
    deadline = time.monotonic() + seconds
    while _alive(tracked) and time.monotonic() < deadline:
        time.sleep(0.2)
    left = _alive(tracked)
    for pid in left:  # never leak processes into the other tests, even when this one fails
        os.kill(pid, signal.SIGKILL)
    return left


def test_a_released_watchdog_exits_and_touches_nothing():
    sleeper = subprocess.Popen(["sleep", "30"])
    try:
        watchdog = Watchdog.start([sleeper.pid])
        watchdog.release()
        watchdog.release()  # idempotent
        assert watchdog.process.returncode == 0 and sleeper.poll() is None
    finally:
        sleeper.kill()
        sleeper.wait()
    assert Watchdog.start([]) is None


@pytest.mark.slow
def test_the_watchdog_stops_the_watched_tree_when_the_driver_is_killed(tmp_path):
    driver = _driver(
        tmp_path,
        """
        import subprocess, time
        from creps_gym.runner.backends.watchdog import Watchdog
        shell = subprocess.Popen(["sh", "-c", "sleep 60 & wait"])
        watchdog = Watchdog.start([shell.pid])
        time.sleep(1.0)  # the watchdog records the shell's child
        print(shell.pid, watchdog.process.pid, flush=True)
        time.sleep(60)
        """,
    )
    shell, watchdog = (int(pid) for pid in driver.stdout.readline().split())
    tracked = process_tree([shell])
    assert len(tracked) == 2  # the shell and its sleep
    tracked[watchdog] = process_stat(watchdog)[1]
    driver.kill()
    driver.wait()
    assert _wait_until_gone(tracked, 10.0) == []


@pytest.mark.slow
def test_a_killed_driver_leaves_no_ray_process_behind(tmp_path):
    driver = _ray_driver(
        tmp_path,
        """
        import time
        from creps_gym.runner import run

        def pause(record, history):
            print("iteration", record.iteration, flush=True)
            time.sleep(0.2)

        run("creps-cma-old", "creps_gym/Sphere-v0", 100000, 10, 0, env_kwargs={"dim": 3}, backend="ray",
            workers=2, callbacks=[pause])
        """,
    )
    try:
        for line in driver.stdout:
            if line.startswith("iteration 3"):
                break
        time.sleep(1.0)  # the watchdog polls every 0.5 s
        tracked = process_tree([driver.pid])
        del tracked[driver.pid]
        names = [Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ") for pid in tracked]
        watchdog = b"creps_gym/runner/backends/watchdog.py"
        assert any(b"raylet" in n for n in names) and any(watchdog in n for n in names)
        assert any(n.startswith(b"ray::") for n in names)  # the raylet's agents (DashboardAgent, ...)
    finally:
        driver.kill()
        driver.wait()
    assert _wait_until_gone(tracked, 20.0) == []


@pytest.mark.slow
def test_a_local_ray_is_started_once_per_process_and_stopped_at_its_exit(tmp_path):
    """Issue 31: the second run of a process reuses the local Ray the first started; exit stops it."""
    driver = _ray_driver(
        tmp_path,
        f"""
        import json, os
        import ray
        from creps_gym.runner import run
        from creps_gym.runner.backends.watchdog import child_pids

        def cluster(path):
            return next(e for e in map(json.loads, open(path + "/log.jsonl")) if e["event"] == "ray")

        args = ("creps-cma-old", "creps_gym/Sphere-v0", 2, 10, 0)
        kwargs = dict(env_kwargs={{"dim": 3}}, backend="ray", workers=2)
        run(*args, **kwargs, run_dir={str(tmp_path / "one")!r})
        after_first = ray.is_initialized()
        run(*args, **kwargs, run_dir={str(tmp_path / "two")!r})
        first, second = (cluster({str(tmp_path)!r} + name) for name in ("/one", "/two"))
        print(after_first, first["ray"], first["address"] == second["address"], flush=True)
        print(*child_pids(os.getpid()), flush=True)
        """,
    )
    try:
        reused = driver.stdout.readline().split()
        children = [int(pid) for pid in driver.stdout.readline().split()]
        tracked = process_tree(children)
    finally:
        driver.wait(timeout=120)
    assert reused == ["True", "local", "True"]
    assert driver.returncode == 0 and len(tracked) >= 2  # Ray's processes and the watchdog
    assert _wait_until_gone(tracked, 30.0) == []  # the exit shut Ray down and released the watchdog
