"""One writing session of a run directory: its lock file and a Ctrl-C that waits for the iteration's end.

**Lock.** ``run.lock`` holds the writer's process id and host name under an exclusive ``flock``. A second
writer (``run``, ``resume``) is refused while the first one lives; the kernel drops the ``flock`` of a killed
process, so a lock file left behind by a ``kill -9`` is taken over (with a :class:`RunDirWarning`). The file
is deleted when the session ends. Where ``fcntl`` is missing (Windows), an existing lock file is refused
and must be deleted by hand once its process is gone.

**Ctrl-C.** While a run with a directory iterates, the first SIGINT only sets a flag: the runner completes
the current iteration, checkpoints and then raises ``KeyboardInterrupt`` (exit code 130), so ``resume``
loses nothing. A second SIGINT interrupts at once (the iterations since the last checkpoint are redone).
Once the last iteration is done the run has finished: a first SIGINT while its result files are written
(and, from the command line, while its plot is drawn) is noted and the writing goes on; the run returns
(exit code 0).
"""

from __future__ import annotations

import json
import os
import signal
import socket
import sys
import threading
import warnings
from pathlib import Path
from types import FrameType
from typing import Any

try:
    import fcntl
except ImportError:  # pragma: no cover - Windows
    fcntl = None  # type: ignore[assignment]

from creps_gym.errors import RunDirError, RunDirWarning
from creps_gym.runner.rundir.files import open_run_file, os_failure

__all__ = ["DeferredInterrupt", "RunLock"]


class RunLock:
    """The lock file of a run directory (see the module docstring)."""

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = Path(path)
        self._fd: int | None = None

    @property
    def held(self) -> bool:
        """Whether this object holds the lock."""
        return self._fd is not None

    def _owner(self, fd: int) -> str:
        os.lseek(fd, 0, os.SEEK_SET)
        try:
            owner = json.loads(os.read(fd, 4096).decode("utf-8") or "{}")
            return f"process {int(owner['pid'])} on {owner['host']}"
        except (ValueError, KeyError, TypeError):
            return "an unknown process"

    def _refuse(self, owner: str) -> RunDirError:
        return RunDirError(
            f"{self.path.parent}: expected no other writer, but {owner} writes this run directory (lock file "
            f"{self.path}); wait until it ends or stop it (the lock of a killed process is taken over)"
        )

    def _open_locked(self) -> int:
        """A descriptor of the lock file on disk, with the ``flock`` held."""
        while True:
            fd = open_run_file(self.path, os.O_RDWR | os.O_CREAT)  # never through a link
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                owner = self._owner(fd)
                os.close(fd)
                raise self._refuse(owner) from None
            try:  # a writer that just ended may have deleted the file we opened: then lock the new one
                if os.fstat(fd).st_ino == os.lstat(self.path).st_ino:
                    return fd
            except FileNotFoundError:
                pass
            os.close(fd)

    def acquire(self) -> None:
        """Take the lock (no-op if held); :class:`RunDirError` naming the live writer if another holds it."""
        if self._fd is not None:
            return
        if fcntl is None:  # pragma: no cover - Windows
            try:
                fd = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_EXCL, 0o644)
            except FileExistsError:
                raise self._refuse(f"the process in {self.path} (delete the file if it is gone)") from None
        else:
            fd = self._open_locked()
            if os.fstat(fd).st_size:
                warnings.warn(
                    f"{self.path}: took over the lock of {self._owner(fd)}, which no longer runs",
                    RunDirWarning,
                    stacklevel=3,
                )
        try:
            os.ftruncate(fd, 0)
            os.lseek(fd, 0, os.SEEK_SET)
            os.write(fd, json.dumps({"pid": os.getpid(), "host": socket.gethostname()}).encode())
        except OSError as exc:  # e.g. a full disk
            os.close(fd)

            raise os_failure(self.path, exc, "write the lock file") from None
        self._fd = fd

    def release(self) -> None:
        """Delete the lock file and drop the lock (no-op if not held)."""
        if self._fd is None:
            return
        fd, self._fd = self._fd, None
        try:
            if os.fstat(fd).st_ino == os.lstat(self.path).st_ino:
                self.path.unlink()
        except FileNotFoundError:
            pass
        finally:
            os.close(fd)  # drops the flock


class DeferredInterrupt:
    """Context manager: the first SIGINT sets :attr:`requested` instead of raising (see the module docstring).

    It changes nothing outside the main thread or when SIGINT has a handler other than Python's default.
    """

    #: What the first SIGINT prints while the run iterates; :attr:`message` may change once it has finished.
    ITERATING = "interrupted; finishing this iteration and checkpointing (Ctrl-C again stops at once)"
    FINISHING = "interrupted after the last iteration: the run has finished; writing its results"

    def __init__(self, enabled: bool = True, message: str = ITERATING) -> None:
        self.enabled = enabled
        self.requested = False
        self.message = message
        self._previous: Any = None

    def _handle(self, signum: int, frame: FrameType | None) -> None:
        if self.requested:
            raise KeyboardInterrupt
        self.requested = True
        print(f"creps-gym: {self.message}", file=sys.stderr)

    def __enter__(self) -> DeferredInterrupt:
        active = threading.current_thread() is threading.main_thread()
        if self.enabled and active and signal.getsignal(signal.SIGINT) is signal.default_int_handler:
            self._previous = signal.signal(signal.SIGINT, self._handle)
        return self

    def __exit__(self, *exc: Any) -> None:
        if self._previous is not None:
            signal.signal(signal.SIGINT, self._previous)
            self._previous = None
