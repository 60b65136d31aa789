"""State files: an optimiser's (or the runner's) state dict as ``.npz`` arrays plus one JSON document.

Never pickle, on either side:

* :func:`save_state` refuses, before writing anything, a state that pickle would be needed for: an array
  whose dtype is not numeric (object, string, structured, dates) or a value that is neither an array nor
  JSON (a numpy scalar such as ``np.int64``, a set, an object), with a ``TypeError`` naming the key.
* :func:`load_state` reads the zip directory before it decompresses anything: every entry must be a
  ``.npy`` array, stored as :func:`save_state` stores it (uncompressed, so no entry is larger than its
  bytes in the file: no "zip bomb"), listed in the document's manifest of arrays (``__arrays__``; an
  unknown entry is refused), and the arrays together must fit in memory. Arrays are then read with
  ``allow_pickle=False``.
"""

from __future__ import annotations

import json
import os
import zipfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np

from creps_gym._files import replace_atomically
from creps_gym._validation import check_fits_in_memory, load_json

__all__ = ["ARRAY_KINDS", "JSON_KEY", "MANIFEST_KEY", "load_state", "save_state"]

JSON_KEY = "__state__.json"
#: The document's key listing the array entries (files written before it existed have none).
MANIFEST_KEY = "__arrays__"
#: Array dtypes a state may hold (bool, signed and unsigned ints, floats, complex): none needs pickle.
ARRAY_KINDS = "biufc"
_NON_FINITE = {"inf": np.inf, "-inf": -np.inf, "nan": np.nan}


def _encode_non_finite(value: Any) -> Any:
    """Standard JSON has no inf/NaN: store non-finite floats as {"__float__": "inf"} (and back on load)."""
    if isinstance(value, dict):
        return {k: _encode_non_finite(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_encode_non_finite(v) for v in value]
    if isinstance(value, (float, np.floating)) and not np.isfinite(value):
        return {"__float__": str(float(value))}
    return value


def _decode_non_finite(value: Any) -> Any:
    if isinstance(value, dict):
        if set(value) == {"__float__"}:
            return _NON_FINITE[value["__float__"]]
        return {k: _decode_non_finite(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_decode_non_finite(v) for v in value]
    return value


def _check_json(value: Any, where: str) -> None:
    """``TypeError`` naming ``where`` unless ``value`` is JSON (None, bool, int, float, str, list, dict)."""
    if value is None or isinstance(value, (bool, int, float, str)):
        return  # np.float64 is a float: exact in JSON
    if isinstance(value, (list, tuple)):
        for index, item in enumerate(value):
            _check_json(item, f"{where}[{index}]")
        return
    if isinstance(value, dict):
        for key, item in value.items():
            if not isinstance(key, str):
                raise TypeError(f"{where}: expected str keys (JSON), got {type(key).__name__} {key!r}")
            _check_json(item, f"{where}[{key!r}]")
        return
    hint = " (use int(...) or float(...))" if isinstance(value, np.generic) else ""
    raise TypeError(
        f"{where}: expected a numeric array or a JSON value (None, bool, int, float, str, list, dict; never "
        f"pickled), got {type(value).__module__}.{type(value).__qualname__}{hint}"
    )


def _checked_arrays(state: Mapping[str, Any]) -> dict[str, np.ndarray]:
    """The state's arrays, each with a numeric dtype; ``TypeError`` naming the first key that is not."""
    arrays = {}
    for key, value in state.items():
        if not isinstance(key, str):
            raise TypeError(f"state: expected str keys, got {type(key).__name__} {key!r}")
        if isinstance(value, np.ndarray):
            if value.dtype.kind not in ARRAY_KINDS or value.dtype.fields is not None:
                raise TypeError(
                    f"state[{key!r}]: expected a numeric array (bool, int, float or complex; never pickled), "
                    f"got dtype {value.dtype}"
                )
            arrays[key] = np.asarray(value)
        else:
            _check_json(value, f"state[{key!r}]")
    return arrays


def save_state(state: Mapping[str, Any], path: str | os.PathLike[str]) -> Path:
    """Write a state dict atomically to ``path`` (``.npz``): arrays as entries, the rest as one JSON document.

    The file is written to a new temporary file in the same folder and renamed
    (:func:`creps_gym._files.replace_atomically`), so a crash never leaves a half-written checkpoint
    behind. A state that would need pickle raises ``TypeError`` naming the key before anything is written
    (see the module docstring).
    """
    path = Path(path)
    arrays = _checked_arrays(state)
    for reserved in (JSON_KEY, MANIFEST_KEY):
        if reserved in state:
            raise ValueError(f"state: the key {reserved!r} is reserved")
    meta = _encode_non_finite({k: v for k, v in state.items() if k not in arrays})
    meta[MANIFEST_KEY] = sorted(arrays)
    payload = json.dumps(meta, sort_keys=True, allow_nan=False).encode()
    arrays[JSON_KEY] = np.frombuffer(payload, dtype=np.uint8)
    path.parent.mkdir(parents=True, exist_ok=True)
    return replace_atomically(path, lambda stream: np.savez(stream, **arrays))


def _entries(stream: BinaryIO, name: Any) -> dict[str, int]:
    """Key -> uncompressed size of every entry, read from the zip directory (nothing decompressed).

    ``ValueError`` for an entry that is not a ``.npy`` array stored uncompressed (a compressed entry can
    be far larger than the file: :func:`save_state` never compresses), or for arrays too large for memory.
    """
    with zipfile.ZipFile(stream) as archive:
        infos = archive.infolist()
    sizes: dict[str, int] = {}
    for info in infos:
        key = info.filename[:-4] if info.filename.endswith(".npy") else None
        if key is None or key in sizes:
            what = "a second entry" if key is not None else "an entry that is not a .npy array"
            raise ValueError(f"{what} {info.filename!r}")
        if info.compress_type != zipfile.ZIP_STORED or info.file_size > info.compress_size:
            raise ValueError(
                f"entry {info.filename!r}: expected an uncompressed array, got {info.compress_size} bytes "
                f"that decompress to {info.file_size}"
            )
        sizes[key] = info.file_size
    check_fits_in_memory(sum(sizes.values()), "path", str(name), "its arrays")
    return sizes


def load_state(path: str | os.PathLike[str] | BinaryIO) -> dict[str, Any]:
    """Read a state dict written by :func:`save_state` (never unpickles anything).

    ``path`` may also be a binary file opened for reading (a seekable stream), e.g. one opened without
    following links.

    A file that is not such a checkpoint (truncated, empty, a ``.npy``, a JSON document that is not an
    object or nests too deep, an unknown non-finite marker, an entry that is compressed, unknown or too
    large, see the module docstring) raises ``ValueError`` naming ``path``; a missing one
    ``FileNotFoundError``.
    """
    if not hasattr(path, "read"):
        if not Path(path).exists():
            raise FileNotFoundError(
                f"path: expected a creps_gym checkpoint (.npz), got {path}, which does not exist"
            )
        with open(path, "rb") as stream:
            return load_state(stream)
    stream, name = path, getattr(path, "name", path)
    try:
        if stream.read(6) == b"\x93NUMPY":
            raise ValueError("got a single array (.npy), not an .npz")
        stream.seek(0)
        sizes = _entries(stream, name)
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:
        raise ValueError(f"path: expected a creps_gym checkpoint (.npz), got {name} ({exc})") from None
    if JSON_KEY not in sizes:
        raise ValueError(f"path: expected a creps_gym checkpoint with a {JSON_KEY!r} entry, got {name}")
    try:
        stream.seek(0)
        with np.load(stream, allow_pickle=False) as data:
            document = load_json(data[JSON_KEY].tobytes().decode(), f"{name}: {JSON_KEY}")
            if not isinstance(document, dict):
                raise ValueError(f"a JSON {type(document).__name__}, not an object")
            manifest = document.pop(MANIFEST_KEY, None)
            keys = sorted(k for k in sizes if k != JSON_KEY)
            if manifest is not None and manifest != keys:
                unknown = sorted(set(keys) - set(manifest)) if isinstance(manifest, list) else keys
                what = f"unknown entries {unknown}" if unknown else f"entries {keys}"
                raise ValueError(f"{what} (its manifest {MANIFEST_KEY!r} lists {str(manifest)[:200]})")
            state: dict[str, Any] = _decode_non_finite(document)
            state.update({k: data[k].copy() for k in keys})
    except (ValueError, KeyError, TypeError, UnicodeDecodeError, OSError, zipfile.BadZipFile) as exc:
        raise ValueError(f"path: expected a creps_gym checkpoint, got a damaged {name} ({exc!r})") from None
    return state
