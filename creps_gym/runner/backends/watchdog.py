"""A watchdog that stops the processes a run started (its local Ray) if the run's process dies first.

:meth:`Watchdog.start` launches this file as a separate Python process (standard library only, nothing
else is imported) with the ids of the processes to watch. The watchdog records them and, every half
second, their descendants (with their start times, so a recycled process id is never touched). The run
holds the write end of a pipe: :meth:`Watchdog.release` writes ``done`` and the watchdog exits quietly.
If the pipe closes without it, or the watchdog's parent changes, the run's process died (e.g. ``kill -9``):
the watchdog sends SIGTERM to every recorded process still alive, SIGKILL after 2 s, and exits
(:meth:`Watchdog.stop_watched` does the same on purpose). :func:`process_tree` and :func:`terminate` are
the same steps for a caller that stops a process tree itself (the tests' Ray cluster).

It needs Linux's ``/proc``; elsewhere :meth:`Watchdog.start` returns None and nothing is watched.
"""

from __future__ import annotations

import os
import select
import signal
import subprocess
import sys
import time
from collections.abc import Sequence

__all__ = ["Watchdog", "add_descendants", "child_pids", "process_stat", "process_tree", "terminate"]

POLL_SECONDS = 0.5
GRACE_SECONDS = 2.0


def process_stat(pid: int) -> tuple[int, int] | None:
    """(parent id, start time) of a live process, from ``/proc/<pid>/stat``; None if gone or a zombie."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as file:
            data = file.read()
    except OSError:
        return None
    fields = data[data.rindex(b")") + 2 :].split()  # fields 3.. of proc(5): state, ppid, ..., starttime
    return None if fields[0] in (b"Z", b"X") else (int(fields[1]), int(fields[19]))


def _table() -> dict[int, tuple[int, int]]:
    """Every live process: id -> (parent id, start time)."""
    table = {}
    for name in os.listdir("/proc"):
        if name.isdigit() and (stat := process_stat(int(name))) is not None:
            table[int(name)] = stat
    return table


def child_pids(pid: int) -> set[int]:
    """Ids of the live children of ``pid`` (empty where ``/proc`` does not exist)."""
    if not os.path.isdir("/proc"):
        return set()
    return {child for child, (parent, _) in _table().items() if parent == pid}


def add_descendants(tracked: dict[int, int]) -> None:
    """Add the live descendants of the tracked processes to ``tracked`` (id -> start time)."""
    table = _table()
    frontier = [pid for pid, start in tracked.items() if table.get(pid, (0, -1))[1] == start]
    while frontier:
        parents = set(frontier)
        frontier = [pid for pid, (ppid, _) in table.items() if ppid in parents and pid not in tracked]
        tracked.update({pid: table[pid][1] for pid in frontier})


def _signal_alive(tracked: dict[int, int], signum: int) -> int:
    """Send ``signum`` to the tracked processes that still run; returns how many got it."""
    sent = 0
    for pid, start in tracked.items():
        stat = process_stat(pid)
        if stat is not None and stat[1] == start:
            try:
                os.kill(pid, signum)
                sent += 1
            except OSError:
                pass
    return sent


def process_tree(roots: Sequence[int]) -> dict[int, int]:
    """The live processes ``roots`` and all their descendants: id -> start time (empty without /proc)."""
    if not os.path.isdir("/proc"):
        return {}
    tracked = {pid: stat[1] for pid in roots if (stat := process_stat(pid)) is not None}
    add_descendants(tracked)
    return tracked


def terminate(tracked: dict[int, int], grace: float = GRACE_SECONDS) -> None:
    """SIGTERM the tracked processes (id -> start time) still alive, SIGKILL those left after ``grace`` s.

    ``grace=0`` sends SIGKILL at once. A process whose id was recycled (another start time) is never touched.
    """
    if grace > 0 and _signal_alive(tracked, signal.SIGTERM):
        deadline = time.monotonic() + grace
        while time.monotonic() < deadline and _signal_alive(tracked, 0):
            time.sleep(0.1)
    _signal_alive(tracked, signal.SIGKILL)


def _watch(read_fd: int, parent: int, roots: Sequence[int]) -> None:
    """The watchdog's loop (runs in its own process)."""
    tracked = process_tree(roots)
    while True:
        add_descendants(tracked)
        ready, _, _ = select.select([read_fd], [], [], POLL_SECONDS)
        if ready:
            if os.read(read_fd, 16).startswith(b"done"):
                return  # released: the run shut its processes down itself
            break  # end of file: the run's process is gone
        if os.getppid() != parent:
            break
    add_descendants(tracked)
    terminate(tracked)


class Watchdog:
    """Handle of a running watchdog process; see the module docstring."""

    def __init__(self, process: subprocess.Popen, write_fd: int) -> None:
        self.process = process
        self._write_fd: int | None = write_fd

    @classmethod
    def start(cls, pids: Sequence[int]) -> Watchdog | None:
        """Watch ``pids`` and their descendants; None where ``/proc`` does not exist or ``pids`` is empty."""
        if not pids or not os.path.isdir("/proc"):
            return None
        read_fd, write_fd = os.pipe()
        command = [sys.executable, "-I", os.path.abspath(__file__), str(read_fd), str(os.getpid())]
        process = subprocess.Popen(
            command + [str(int(pid)) for pid in pids],
            pass_fds=(read_fd,),
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            start_new_session=True,  # a Ctrl-C to the run's terminal must not kill the watchdog first
        )
        os.close(read_fd)
        return cls(process, write_fd)

    def stop_watched(self) -> None:
        """Make the watchdog stop the watched processes now, as when the run dies, and wait until it has."""
        if self._write_fd is None:
            return
        os.close(self._write_fd)  # end of file without "done"
        self._write_fd = None
        self.process.wait(timeout=GRACE_SECONDS + 30)

    def release(self) -> None:
        """Tell the watchdog the run ended normally: it exits without touching anything (idempotent)."""
        if self._write_fd is None:
            return
        try:
            os.write(self._write_fd, b"done")
        finally:
            os.close(self._write_fd)
            self._write_fd = None
        try:
            self.process.wait(timeout=5)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()


if __name__ == "__main__":
    _watch(int(sys.argv[1]), int(sys.argv[2]), [int(arg) for arg in sys.argv[3:]])
