"""The one way the runner opens files: run-directory files never followed, outputs written where named.

**Run-directory files** (:func:`read_run_file`, :func:`open_run_file`, :func:`append_run_file`,
:func:`write_run_file`). A run directory is untrusted input, so each of its files is either absent or a
regular file: a symbolic link, a FIFO, a device, a socket or a directory in a file's place raises
:class:`~creps_gym.errors.RunDirError` naming the file (CLI exit code 3). Files are opened with
``O_NOFOLLOW`` and ``O_NONBLOCK`` and checked again on the open descriptor, so a link planted in a run
directory never makes the runner read or write anything outside it, and a FIFO never blocks it. Reads are
bounded: a file larger than its limit (:data:`LIMITS`, :data:`DEFAULT_LIMIT`) is refused before it is
read. Writes are atomic (a new temporary file in the same folder, then a rename) or appends. The safe
opening, the bounded read and the atomic write are the package's ground floor, :mod:`creps_gym._files`;
this module words their refusals for a run directory. An
operating-system error (disk full, read-only file system, file size limit, name too long) is a
:class:`RunDirError` naming the file and the cause.

**Outputs** (:func:`write_output`: ``plot -o``, ``export -o``, :func:`~creps_gym.runner.plot_histories`'s
path). The user names them, so a symbolic link is followed and its target is replaced (atomically); a
target that is not a regular file (a FIFO, a device, a directory) and a run directory's own file are
refused with a ``ValueError`` (CLI exit code 2). :mod:`creps_gym.runner.results.outputs` applies these
rules to every output option (``-o``, ``policy --save``, ``evaluate --video``).

**JSON** (:func:`json_document`): a document nested deeper than :data:`MAX_DEPTH` is a ``ValueError``,
never a ``RecursionError``.
"""

from __future__ import annotations

import errno
import os
import stat
from collections.abc import Callable
from pathlib import Path
from typing import Any, BinaryIO

from creps_gym import _files
from creps_gym._files import file_kind, output_target
from creps_gym._validation import MAX_JSON_DEPTH as MAX_DEPTH
from creps_gym._validation import load_json
from creps_gym.errors import RunDirError

__all__ = [
    "DEFAULT_LIMIT",
    "LIMITS",
    "MAX_DEPTH",
    "append_run_file",
    "check_regular",
    "file_kind",
    "json_document",
    "open_binary",
    "open_run_file",
    "os_failure",
    "output_target",
    "read_run_file",
    "write_output",
    "write_run_file",
]

MiB = 1 << 20
#: Largest size read from a run directory's file, by name (bytes); other files: :data:`DEFAULT_LIMIT`.
#: Generous for real runs: a log line is about 0.5 kB, so 1 GiB holds about two million iterations.
LIMITS = {"config.json": 16 * MiB, "versions.json": 16 * MiB, "run.lock": 4096}
DEFAULT_LIMIT = 1024 * MiB


def _refuse(path: Path, kind: str) -> RunDirError:
    return RunDirError(
        f"{path}: expected a regular file, got {kind} (a run directory's files are never followed or read "
        "unless they are regular files); remove it, or restore the run directory from a backup"
    )


#: What to do after an operating-system error on a run directory's file.
RESUME = (
    "the files written before it are intact: free space or fix the file, then `creps-gym resume` "
    "continues from the last checkpoint"
)


def os_failure(path: str | os.PathLike[str], exc: OSError, doing: str, advice: str = RESUME) -> RunDirError:
    """The error for an operating-system failure on a run directory's file: names it and the cause."""
    cause = exc.strerror or type(exc).__name__
    code = errno.errorcode.get(exc.errno or 0, "")
    return RunDirError(f"{path}: cannot {doing} ({cause}{', ' + code if code else ''}); {advice}")


def check_regular(path: str | os.PathLike[str]) -> bool:
    """Whether ``path`` exists (as a regular file); :class:`RunDirError` if it is anything else."""
    path = Path(path)
    try:
        mode = os.lstat(path).st_mode
    except FileNotFoundError:
        return False
    except OSError as exc:
        raise os_failure(path, exc, "read it") from None
    if not stat.S_ISREG(mode):
        raise _refuse(path, file_kind(mode))
    return True


def open_run_file(path: str | os.PathLike[str], flags: int = os.O_RDONLY, mode: int = 0o644) -> int:
    """A descriptor of a run directory's regular file (see the module docstring), never through a link.

    ``FileNotFoundError`` if it is missing (and ``flags`` has no ``O_CREAT``).
    """
    path = Path(path)
    check_regular(path)
    try:
        return _files.open_regular(path, flags, mode, refuse=_refuse)  # a link or FIFO planted since
    except FileNotFoundError:
        raise
    except OSError as exc:
        raise os_failure(path, exc, "open it") from None


def _too_large(path: Path, most: int, size: int | None) -> RunDirError:
    if size is None:  # grown while it was read
        return RunDirError(f"{path}: expected at most {most} bytes, got more")
    return RunDirError(
        f"{path}: expected at most {most} bytes, got {size} (not written by a creps_gym run); remove "
        "it, or restore the run directory from a backup"
    )


def _bound(path: Path, limit: int | None) -> _files.Bound:
    """A run directory file's read bound: ``limit``, else its own (:data:`LIMITS`), refused as damage."""
    return _files.Bound(LIMITS.get(path.name, DEFAULT_LIMIT) if limit is None else limit, _refuse, _too_large)


def open_binary(path: str | os.PathLike[str], limit: int | None = None) -> BinaryIO:
    """A run directory's regular file opened for reading, its size checked against its limit."""
    path = Path(path)
    check_regular(path)
    try:
        return _files.open_bounded(path, _bound(path, limit))
    except FileNotFoundError:
        raise
    except OSError as exc:
        raise os_failure(path, exc, "open it") from None


def read_run_file(path: str | os.PathLike[str], limit: int | None = None) -> bytes:
    """The content of a run directory's regular file, at most its limit (:data:`LIMITS`) in bytes."""
    path = Path(path)
    check_regular(path)
    try:  # read in chunks: a live run's log may grow meanwhile
        return _files.read_bounded(path, _bound(path, limit))
    except FileNotFoundError:
        raise
    except OSError as exc:
        raise os_failure(path, exc, "read it") from None


def _write_all(fd: int, data: bytes) -> None:
    view = memoryview(data)
    while view:
        view = view[os.write(fd, view) :]


def append_run_file(path: str | os.PathLike[str], data: bytes) -> None:
    """Append ``data`` to a run directory's file (created if missing); a line cut by a crash is closed."""
    path = Path(path)
    fd = open_run_file(path, os.O_RDWR | os.O_APPEND | os.O_CREAT)
    try:
        size = os.fstat(fd).st_size
        if size and os.pread(fd, 1, size - 1) != b"\n":
            data = b"\n" + data
        _write_all(fd, data)
    except OSError as exc:
        raise os_failure(path, exc, "append to it") from None
    finally:
        os.close(fd)


def write_run_file(path: str | os.PathLike[str], data: bytes) -> Path:
    """Replace a run directory's file (absent or regular, see the module docstring) atomically."""
    path = Path(path)
    check_regular(path)
    try:
        return _files.write_atomically(path, data)
    except OSError as exc:
        raise os_failure(path, exc, "write it") from None


def write_output(
    path: str | os.PathLike[str],
    data: bytes,
    *,
    name: str = "path",
    protected: Callable[[Path], bool] | None = None,
) -> Path:
    """Write a file the user named (see the module docstring); returns the file written.

    A symbolic link is followed: its target is replaced. ``ValueError`` naming ``name`` for a target that
    is not a regular file or that ``protected`` refuses (a run directory's own file); ``OSError`` naming
    the file for a target that cannot be written (a full disk, a read-only file system, ...).
    """
    return _files.write_atomically(output_target(path, name=name, protected=protected), data)


def json_document(text: str | bytes, source: str) -> Any:
    """``json.loads(text)``; a ``ValueError`` naming ``source`` if it nests deeper than :data:`MAX_DEPTH`."""
    return load_json(text, source, MAX_DEPTH)
