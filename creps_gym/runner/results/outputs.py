"""Output paths the user names (``-o``, ``policy --save``, ``evaluate --video``): one set of rules.

:func:`check_output_path` checks a path before anything is computed, like ``-o``
(:func:`creps_gym.runner.rundir.files.output_target`): a symbolic link is followed and its target replaced, a
target that is not a regular file (a FIFO, a device, a folder) and a run directory's own file
(``checkpoint.npz``, ``log.jsonl``, ... of any run folder) are refused with a ``ValueError`` naming the
option (CLI exit code 2). :func:`write_output_with` writes a file that a library writes by name (a video)
through a new temporary file beside the target and a rename (:func:`creps_gym._files.replace_atomically`),
and never reports a file that was not written: an error names the file.
"""

from __future__ import annotations

import errno
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any, BinaryIO

from creps_gym._files import replace_atomically, temporary_beside
from creps_gym.runner.rundir import RunDir
from creps_gym.runner.rundir.files import output_target

__all__ = ["check_output_path", "write_output_with"]


def check_output_path(
    path: str | os.PathLike[str], flag: str, suffixes: tuple[str, ...] | None = None
) -> Path:
    """The file an output option will replace (a link's target), checked before anything is computed.

    Parameters
    ----------
    path : path-like
        What the user named.
    flag : str
        The option, named in every error (``"-o/--output"``, ``"--save"``, ``"--video"``).
    suffixes : tuple of str, optional
        The file name endings the writer understands (lower case, e.g. ``(".mp4", ".gif")``): a writer that
        picks its format by the name would otherwise write another format (a ``.npz``, a ``.png``).

    Raises
    ------
    ValueError
        Naming ``flag``: a wrong suffix, a target that is not a regular file (a FIFO, a device, a folder),
        or a run directory's own file (``checkpoint.npz``, ``log.jsonl``, ... of a run folder).
    """
    if suffixes is not None and Path(path).suffix.lower() not in suffixes:
        raise ValueError(f"{flag}: expected a file name ending in {' or '.join(suffixes)}, got {path}")
    return output_target(path, name=flag, protected=RunDir.owns)


def write_output_with(
    path: str | os.PathLike[str],
    write: Callable[[Path], Any],
    flag: str,
    suffixes: tuple[str, ...] | None = None,
) -> Path:
    """Write an output file with ``write(temporary)``, a writer that opens a file by name, then rename it.

    The path is checked like :func:`check_output_path`; the temporary ``.STEM.PID.tmpSUFFIX`` (the
    suffix kept, so that the writer picks the format by it) is created new in the target's folder, never
    through a link. Returns the file written (a link's target).

    Raises
    ------
    ValueError
        See :func:`check_output_path`.
    OSError
        Naming the target: it cannot be written (a full disk, a read-only folder), or ``write`` raised
        ``OSError`` or ``RuntimeError``, or left the temporary empty. Nothing is left behind.
    """
    target = check_output_path(path, flag, suffixes)
    tmp = temporary_beside(target, keep_suffix=True)

    def write_by_name(_: BinaryIO) -> None:
        write(tmp)
        if os.lstat(tmp).st_size == 0:
            raise OSError(errno.EIO, "nothing was written")

    try:
        return replace_atomically(target, write_by_name, temporary=tmp)
    except (OSError, RuntimeError) as exc:
        cause = (exc.strerror if isinstance(exc, OSError) else None) or str(exc) or type(exc).__name__
        code = errno.errorcode.get(exc.errno or 0, "") if isinstance(exc, OSError) else ""
        raise OSError(
            getattr(exc, "errno", None) or errno.EIO, f"{cause}{', ' + code if code else ''}", str(target)
        ) from None
