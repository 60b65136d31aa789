"""Reading and writing policy files: an ``.npz`` of float64 arrays and one JSON document, never pickle.

A policy file is untrusted input (it may come from a run folder or another machine), so reading one is
bounded and strict: a regular file opened without following a symbolic link, at most
:data:`MAX_POLICY_BYTES`; only the known entries, each stored uncompressed (a compressed entry could
declare far more than the file holds) and read to at most its declared size, each array's header checked
(dtype float64, shape matching its bytes) before anything is allocated; the JSON document at most
:data:`MAX_JSON_BYTES`, nested at most 100 levels deep, without NaN or infinity. Every failure is a
``ValueError`` naming the file. The no-follow bounded read and the atomic write are the package's
ground floor, :mod:`creps_gym._files`, and so is the ``.npz`` + JSON container, :mod:`creps_gym._npz`.
"""

from __future__ import annotations

import io
import zipfile
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from creps_gym._files import Bound, output_target, read_bounded, write_atomically
from creps_gym._npz import container_bytes, container_entries, document_of, read_arrays, read_directory

__all__ = ["MAX_JSON_BYTES", "MAX_POLICY_BYTES", "policy_bytes", "read_policy_file", "write_policy_file"]

MAX_POLICY_BYTES = 64 * 2**20
MAX_JSON_BYTES = 8 * 2**20
JSON_ENTRY = "__policy__.json"
ARRAY_ENTRIES = ("coefficients", "context_low", "context_high", "param_low", "param_high")


def policy_bytes(document: dict[str, Any], arrays: dict[str, NDArray[Any]]) -> bytes:
    """The bytes of a policy file: ``arrays`` (as float64) and the JSON ``document``, stored uncompressed.

    They depend on the policy only (the entries carry a fixed date), so equal policies give equal files.
    """
    floats = {k: np.asarray(v, dtype=np.float64) for k, v in arrays.items()}
    return container_bytes(container_entries(floats, JSON_ENTRY, document))


def write_policy_file(document: dict[str, Any], arrays: dict[str, NDArray[Any]], path: Any) -> Path:
    """Write ``arrays`` and the JSON ``document`` to ``path`` through a temporary file and a rename.

    ``path`` is an output the user named: a symbolic link is followed (its target is replaced), a target
    that is not a regular file (a FIFO, a device, a folder) is refused with a ``ValueError`` naming it, and
    a failed write is an ``OSError`` naming it. The temporary file is ``.NAME.PID.tmp`` in the target's
    folder, created new (never through a link). Returns the file written.
    """
    target = output_target(path)
    data = policy_bytes(document, arrays)
    return write_atomically(target, data)


def _not_regular(path: Path, kind: str) -> ValueError:
    return ValueError(f"path: expected a regular policy file, got {kind}: {path} (not a regular file)")


def _too_large(path: Path, limit: int, size: int | None) -> ValueError:
    got = "more" if size is None else size
    return ValueError(f"path: expected a policy file of at most {limit} bytes, got {got}: {path}")


def _read_bytes(path: Path) -> bytes:
    """The bytes of a regular file (no symbolic link followed, no FIFO opened for good), bounded."""
    try:
        return read_bounded(path, Bound(MAX_POLICY_BYTES, _not_regular, _too_large))
    except FileNotFoundError:
        raise
    except OSError as exc:
        raise ValueError(
            f"path: expected a regular policy file, got a file that cannot be read: {path} ({exc.strerror})"
        ) from None


def read_policy_file(path: Any) -> tuple[Any, dict[str, NDArray[np.float64]]]:
    """The JSON document and the arrays of a policy file (see the module docstring for the checks).

    Returns
    -------
    document : JSON value (the caller checks it)
    arrays : dict of str to float64 ndarray
    """
    path = Path(path)
    stream = io.BytesIO(_read_bytes(path))
    try:
        entries = read_directory(stream, str(path))
        allowed = (*ARRAY_ENTRIES, JSON_ENTRY)
        if not set(entries) <= set(allowed) or JSON_ENTRY not in entries:
            names = [info.filename for info in entries.values()]
            raise ValueError(f"expected entries among {sorted(f'{n}.npy' for n in allowed)}, got {names}")
        if entries[JSON_ENTRY].file_size > MAX_JSON_BYTES:
            got = entries[JSON_ENTRY].file_size
            raise ValueError(f"{JSON_ENTRY}.npy: expected at most {MAX_JSON_BYTES} bytes, got {got}")
        arrays = read_arrays(stream, entries, {JSON_ENTRY: "|u1", "*": "<f8"})
        document = document_of(arrays.pop(JSON_ENTRY), JSON_ENTRY)
        for name, array in arrays.items():
            if array.ndim > 2:
                raise ValueError(f"{name}.npy: expected a shape of at most two dimensions, got {array.shape}")
    except (ValueError, KeyError, EOFError, OSError, RecursionError, zipfile.BadZipFile, UnicodeError) as exc:
        raise ValueError(f"path: expected a creps_gym policy file (.npz), got {path} ({exc})") from None
    except (RuntimeError, NotImplementedError) as exc:  # zipfile: encrypted, unknown compression
        raise ValueError(f"path: expected a creps_gym policy file (.npz), got {path} ({exc})") from None
    return document, arrays
