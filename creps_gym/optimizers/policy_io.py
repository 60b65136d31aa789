"""Reading and writing policy files: an ``.npz`` of float64 arrays and one JSON document, never pickle.

A policy file is untrusted input (it may come from a run folder or another machine), so reading one is
bounded and strict: a regular file opened without following a symbolic link, at most
:data:`MAX_POLICY_BYTES`; only the known entries, each stored uncompressed (a compressed entry could
declare far more than the file holds) and read to at most its declared size, each array's header checked
(dtype float64, shape matching its bytes) before anything is allocated; the JSON document at most
:data:`MAX_JSON_BYTES`, nested at most 100 levels deep, without NaN or infinity. Every failure is a
``ValueError`` naming the file. The no-follow bounded read and the atomic write are the package's
ground floor, :mod:`creps_gym._files`.
"""

from __future__ import annotations

import io
import json
import zipfile
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from creps_gym._files import Bound, output_target, read_bounded, replace_atomically
from creps_gym._validation import MAX_JSON_DEPTH

__all__ = ["MAX_JSON_BYTES", "MAX_POLICY_BYTES", "policy_bytes", "read_policy_file", "write_policy_file"]

MAX_POLICY_BYTES = 64 * 2**20
MAX_JSON_BYTES = 8 * 2**20
JSON_ENTRY = "__policy__.json"
ARRAY_ENTRIES = ("coefficients", "context_low", "context_high", "param_low", "param_high")


def policy_bytes(document: dict[str, Any], arrays: dict[str, NDArray[Any]]) -> bytes:
    """The bytes of a policy file: ``arrays`` and the JSON ``document``, stored uncompressed.

    They depend on the policy only (the entries carry a fixed date), so equal policies give equal files.
    """
    payload = json.dumps(document, sort_keys=True, allow_nan=False).encode()
    entries = {k: np.asarray(v, dtype=np.float64) for k, v in arrays.items()}
    entries[JSON_ENTRY] = np.frombuffer(payload, dtype=np.uint8)
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", compression=zipfile.ZIP_STORED) as archive:
        for name, array in entries.items():
            npy = io.BytesIO()
            np.lib.format.write_array(npy, np.ascontiguousarray(array), allow_pickle=False)
            archive.writestr(zipfile.ZipInfo(f"{name}.npy", date_time=(1980, 1, 1, 0, 0, 0)), npy.getvalue())
    return buffer.getvalue()


def write_policy_file(document: dict[str, Any], arrays: dict[str, NDArray[Any]], path: Any) -> Path:
    """Write ``arrays`` and the JSON ``document`` to ``path`` through a temporary file and a rename.

    ``path`` is an output the user named: a symbolic link is followed (its target is replaced), a target
    that is not a regular file (a FIFO, a device, a folder) is refused with a ``ValueError`` naming it, and
    a failed write is an ``OSError`` naming it. The temporary file is ``.NAME.PID.tmp`` in the target's
    folder, created new (never through a link). Returns the file written.
    """
    target = output_target(path)
    data = policy_bytes(document, arrays)
    try:
        return replace_atomically(target, lambda stream: stream.write(data))
    except OSError as exc:
        raise OSError(exc.errno, exc.strerror, str(target)) from None


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


def _array(raw: bytes, name: str) -> NDArray[Any]:
    """One ``.npy`` entry, its header checked before the data is read."""
    stream = io.BytesIO(raw)
    major, _ = np.lib.format.read_magic(stream)
    if major == 1:
        shape, fortran, dtype = np.lib.format.read_array_header_1_0(stream)
    elif major == 2:
        shape, fortran, dtype = np.lib.format.read_array_header_2_0(stream)
    else:
        raise ValueError(f"{name}: expected a .npy header of version 1 or 2, got {major}")
    wanted = np.dtype(np.uint8) if name == JSON_ENTRY else np.dtype("<f8")
    if dtype != wanted or dtype.hasobject:
        raise ValueError(f"{name}: expected dtype {wanted}, got {dtype}")
    if not all(type(n) is int and n >= 0 for n in shape) or len(shape) > 2:  # not bool
        raise ValueError(f"{name}: expected a shape of non-negative ints, at most two, got {shape}")
    count = int(np.prod(shape, dtype=object))
    if count * dtype.itemsize != len(raw) - stream.tell():
        raise ValueError(f"{name}: expected {count * dtype.itemsize} bytes of data for shape {shape}")
    array = np.frombuffer(raw, dtype=dtype, offset=stream.tell())
    array = array.reshape(shape, order="F" if fortran else "C")
    return np.array(array, dtype=dtype, order="C")  # a writable copy


def _finite_json(text: str) -> Any:
    """Standard JSON (no NaN or infinity) nested at most :data:`MAX_JSON_DEPTH` levels deep."""

    def refuse(constant: str) -> None:
        raise ValueError(f"expected standard JSON, got {constant}")

    expected = f"{JSON_ENTRY}: expected JSON nested at most {MAX_JSON_DEPTH} levels deep"
    try:
        document = json.loads(text, parse_constant=refuse)
    except RecursionError:
        raise ValueError(f"{expected}, got deeper") from None
    stack = [(document, 1)]
    while stack:  # deep nesting would be a RecursionError in any recursive code that reads it
        value, depth = stack.pop()
        if isinstance(value, (dict, list)):
            if depth > MAX_JSON_DEPTH:
                raise ValueError(f"{expected}, got {depth} levels")
            stack.extend(
                (child, depth + 1) for child in (value.values() if isinstance(value, dict) else value)
            )
    return document


def read_policy_file(path: Any) -> tuple[Any, dict[str, NDArray[np.float64]]]:
    """The JSON document and the arrays of a policy file (see the module docstring for the checks).

    Returns
    -------
    document : JSON value (the caller checks it)
    arrays : dict of str to float64 ndarray
    """
    path = Path(path)
    data = _read_bytes(path)
    try:
        with zipfile.ZipFile(io.BytesIO(data)) as archive:
            infos = archive.infolist()
            names = [info.filename for info in infos]
            allowed = {f"{name}.npy" for name in (*ARRAY_ENTRIES, JSON_ENTRY)}
            unknown = sorted(set(names) - allowed)
            if unknown or len(set(names)) != len(names) or f"{JSON_ENTRY}.npy" not in names:
                raise ValueError(f"expected entries among {sorted(allowed)} (no repeats), got {names}")
            entries = {}
            for info in infos:
                limit = MAX_JSON_BYTES if info.filename.startswith(JSON_ENTRY) else MAX_POLICY_BYTES
                if info.compress_type != zipfile.ZIP_STORED or info.file_size != info.compress_size:
                    raise ValueError(
                        f"{info.filename}: expected an uncompressed entry (as written), got a compressed one"
                    )
                if info.file_size > limit:
                    raise ValueError(f"{info.filename}: expected at most {limit} bytes, got {info.file_size}")
                with archive.open(info) as stream:
                    raw = stream.read(limit + 1)
                if len(raw) > limit:
                    raise ValueError(f"{info.filename}: expected at most {limit} bytes, got more")
                entries[info.filename[: -len(".npy")]] = _array(raw, info.filename[: -len(".npy")])
            payload = entries.pop(JSON_ENTRY)
            if payload.ndim != 1:
                raise ValueError(f"{JSON_ENTRY}: expected a 1-D uint8 array, got shape {payload.shape}")
            document = _finite_json(payload.tobytes().decode("utf-8"))
    except (ValueError, KeyError, EOFError, OSError, RecursionError, zipfile.BadZipFile, UnicodeError) as exc:
        raise ValueError(f"path: expected a creps_gym policy file (.npz), got {path} ({exc})") from None
    except (RuntimeError, NotImplementedError) as exc:  # zipfile: encrypted, unknown compression
        raise ValueError(f"path: expected a creps_gym policy file (.npz), got {path} ({exc})") from None
    return document, entries
