"""Safe file IO, the ground floor under every file the package reads or writes (standard library only).

Two operations, written once and used by the runner's run directories (:mod:`creps_gym.runner.rundir.files`,
:mod:`creps_gym.runner.results.outputs`) and the optimisers' files (:mod:`creps_gym.optimizers.policy_io`,
:mod:`creps_gym.optimizers.state_files`):

* **A bounded read that follows no link** (:func:`open_regular`, :func:`open_bounded`,
  :func:`read_bounded`). The file is opened with ``O_NOFOLLOW`` and ``O_NONBLOCK`` and checked again on
  the open descriptor: a symbolic link, a FIFO, a device, a socket or a folder in its place is refused
  (a FIFO never blocks the reader), and a file larger than its limit is refused before it is read, then
  read to at most its limit (a file that grows meanwhile is refused too).
* **Outputs the user names** (:func:`output_target`): a symbolic link is followed (its target is
  replaced), a target that is not a regular file is refused.
* **An atomic write** (:func:`replace_atomically`, :func:`write_atomically`): a new temporary file
  ``.NAME.PID.tmp`` beside the target, created with ``O_EXCL | O_NOFOLLOW`` (never through a link planted
  there), filled, synced and renamed over the target, so a crash never leaves a half-written file; the
  temporary is removed whatever happens.

Each caller words its own refusals (a run directory's file raises
:class:`~creps_gym.errors.RunDirError`, a policy file a ``ValueError``): a :class:`Bound` holds the limit,
``refuse`` (``(path, what it is in words) -> exception``) and ``too_large`` (``(path, limit, size) ->
exception``, ``size`` None when the file grew past the limit while it was read). Any other
operating-system error is raised as it is, for the caller to name the file and the cause.
"""

from __future__ import annotations

import errno
import os
import stat
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO

__all__ = [
    "Bound",
    "file_kind",
    "open_bounded",
    "open_regular",
    "output_target",
    "read_bounded",
    "replace_atomically",
    "temporary_beside",
    "write_atomically",
]

MiB = 1 << 20
#: Flags of every read or write of an existing file: never through a link, never blocking on a FIFO.
NO_FOLLOW = getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0)
#: Flags of a new temporary file: created here and now, never through a link.
NEW_FILE = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0)

Refuse = Callable[[Path, str], Exception]
TooLarge = Callable[[Path, int, "int | None"], Exception]

_KINDS = (
    (stat.S_ISLNK, "a symbolic link"),
    (stat.S_ISDIR, "a directory"),
    (stat.S_ISFIFO, "a FIFO"),
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
    (stat.S_ISSOCK, "a socket"),
)


def file_kind(mode: int) -> str:
    """What an ``st_mode`` is, in words ("a regular file", "a symbolic link", "a FIFO", ...)."""
    if stat.S_ISREG(mode):
        return "a regular file"
    return next((text for test, text in _KINDS if test(mode)), "a special file")


def _kind_at(path: Path) -> str:
    """What is at ``path`` (not followed), in words, for a refusal after a failed open."""
    try:
        return file_kind(os.lstat(path).st_mode)
    except OSError:
        return "a special file"


def _not_regular(path: Path, kind: str) -> Exception:
    return ValueError(f"{path}: expected a regular file, got {kind}")


def _too_large(path: Path, limit: int, size: int | None) -> Exception:
    return ValueError(f"{path}: expected at most {limit} bytes, got {'more' if size is None else size}")


def open_regular(
    path: str | os.PathLike[str],
    flags: int = os.O_RDONLY,
    mode: int = 0o644,
    *,
    refuse: Refuse = _not_regular,
) -> int:
    """A descriptor of the regular file ``path`` opened with ``flags``, never through a link (see above).

    Raises
    ------
    FileNotFoundError
        It is missing (and ``flags`` has no ``O_CREAT``).
    Exception
        ``refuse(path, kind)``: it is not a regular file (a link, a FIFO, a folder, ...).
    OSError
        Any other failure to open it, as raised.
    """
    path = Path(path)
    try:
        fd = os.open(path, flags | NO_FOLLOW, mode)
    except FileNotFoundError:
        raise
    except OSError as exc:
        if exc.errno in (errno.ELOOP, errno.ENXIO, errno.EISDIR):  # a link, a socket, a folder
            raise refuse(path, _kind_at(path)) from None
        raise
    found = os.fstat(fd).st_mode
    if not stat.S_ISREG(found):
        os.close(fd)
        raise refuse(path, file_kind(found))
    return fd


@dataclass(frozen=True)
class Bound:
    """A bounded read's limit (bytes) and how its caller words a refusal (see the module docstring)."""

    limit: int
    refuse: Refuse = _not_regular
    too_large: TooLarge = _too_large


def open_bounded(path: str | os.PathLike[str], bound: Bound) -> BinaryIO:
    """The regular file ``path`` opened for reading (:func:`open_regular`); refused over ``bound.limit``."""
    path = Path(path)
    fd = open_regular(path, refuse=bound.refuse)
    size = os.fstat(fd).st_size
    if size > bound.limit:
        os.close(fd)
        raise bound.too_large(path, bound.limit, size)
    return os.fdopen(fd, "rb")


def read_bounded(path: str | os.PathLike[str], bound: Bound) -> bytes:
    """The content of the regular file ``path``, at most ``bound.limit`` bytes (:func:`open_bounded`).

    Read in chunks, to at most ``limit + 1`` bytes: a file that grows past the limit while it is read (a
    live run's log) raises ``bound.too_large(path, limit, None)``. ``OSError`` from the read as raised.
    """
    path, limit = Path(path), bound.limit
    chunks, total = [], 0
    with open_bounded(path, bound) as stream:
        while total <= limit and (chunk := stream.read(min(limit + 1 - total, 16 * MiB))):
            chunks.append(chunk)
            total += len(chunk)
    if total > limit:
        raise bound.too_large(path, limit, None)
    return b"".join(chunks)


def output_target(
    path: str | os.PathLike[str], *, name: str = "path", protected: Callable[[Path], bool] | None = None
) -> Path:
    """The file a write of the output ``path`` the user named replaces: a link's target.

    ``ValueError`` naming ``name`` for a target that is not a regular file (a FIFO, a device, a folder)
    or that ``protected`` refuses (the runner's: a run directory's own file).
    """
    target = Path(os.path.realpath(path))
    try:
        mode = os.stat(target).st_mode
    except FileNotFoundError:
        mode = None
    except OSError as exc:
        raise ValueError(f"{name}: cannot write {path} ({exc.strerror})") from None
    via = "" if target == Path(os.path.abspath(path)) else f" (the target of {path})"
    if mode is not None and not stat.S_ISREG(mode):
        kind = file_kind(mode)
        raise ValueError(f"{name}: expected a regular file or a new file, got {kind} {target}{via}")
    if protected is not None and protected(target):
        raise ValueError(
            f"{name}: expected a file outside a run directory's own files, got {target}{via}; choose "
            "another name"
        )
    return target


def temporary_beside(path: str | os.PathLike[str], keep_suffix: bool = False) -> Path:
    """The temporary file of a write of ``path``: ``.NAME.PID.tmp`` in its folder.

    With ``keep_suffix``, ``.STEM.PID.tmpSUFFIX`` (for a writer that picks the format by the suffix).
    """
    path = Path(path)
    if keep_suffix:
        return path.with_name(f".{path.stem}.{os.getpid()}.tmp{path.suffix}")
    return path.with_name(f".{path.name}.{os.getpid()}.tmp")


def replace_atomically(
    path: str | os.PathLike[str], write: Callable[[BinaryIO], Any], *, temporary: Path | None = None
) -> Path:
    """Replace ``path`` atomically with what ``write(stream)`` writes; returns ``path``.

    ``stream`` is the new temporary ``temporary`` (default :func:`temporary_beside`), opened for writing;
    a writer that writes a file by name may ignore it and write ``temporary`` instead. A temporary of this
    process id left by a killed process is removed first; the new one is created with ``O_EXCL |
    O_NOFOLLOW``, synced, renamed over ``path`` (a link at ``path`` is replaced, not followed) and removed
    whatever happens. Errors (``OSError`` and whatever ``write`` raises) propagate.
    """
    path = Path(path)
    tmp = temporary_beside(path) if temporary is None else Path(temporary)
    try:
        if os.path.lexists(tmp):  # our own temporary, left by a killed process of this id
            os.unlink(tmp)
        with os.fdopen(os.open(tmp, NEW_FILE, 0o644), "wb") as stream:
            write(stream)
            stream.flush()
            os.fsync(stream.fileno())
        os.replace(tmp, path)
    finally:
        if os.path.lexists(tmp):
            os.unlink(tmp)
    return path


def write_atomically(path: str | os.PathLike[str], data: bytes) -> Path:
    """Replace ``path`` atomically with ``data`` (:func:`replace_atomically`); returns ``path``.

    A failure is an ``OSError`` (of the same kind, e.g. ``PermissionError``) naming ``path``.
    """
    try:
        return replace_atomically(path, lambda stream: stream.write(data))
    except OSError as exc:
        raise type(exc)(exc.errno, exc.strerror, str(path)) from None
