"""State files: an optimiser's (or the runner's) state dict as ``.npz`` arrays plus one JSON document.

Never pickle, on either side:

* :func:`save_state` refuses, before writing anything, a state that pickle would be needed for: an array
  whose dtype is not numeric (object, string, structured, dates) or a value that is neither an array nor
  JSON (a numpy scalar such as ``np.int64``, a set, an object), with a ``TypeError`` naming the key.
* :func:`load_state` reads the zip directory before it decompresses anything: every entry must be a
  ``.npy`` array, stored as :func:`save_state` stores it (uncompressed, so no entry is larger than its
  bytes in the file: no "zip bomb"), listed in the document's manifest of arrays (``__arrays__``; an
  unknown entry is refused), and the arrays together must fit in memory. Each array's ``.npy`` header is
  checked (a numeric dtype, a shape that matches its bytes) before its data is copied out.

The container (entries, directory, arrays, JSON document) is the package's ground floor,
:mod:`creps_gym._npz`, shared with policy files; the atomic write is :mod:`creps_gym._files`'.
"""

from __future__ import annotations

import os
import zipfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np

from creps_gym._files import replace_atomically
from creps_gym._npz import container_entries, document_of, read_arrays, read_directory

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
    entries = container_entries(arrays, JSON_KEY, meta)
    path.parent.mkdir(parents=True, exist_ok=True)
    return replace_atomically(path, lambda stream: np.savez(stream, **entries))  # the layout of format /1


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
        entries = read_directory(stream, str(name))
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:
        raise ValueError(f"path: expected a creps_gym checkpoint (.npz), got {name} ({exc})") from None
    if JSON_KEY not in entries:
        raise ValueError(f"path: expected a creps_gym checkpoint with a {JSON_KEY!r} entry, got {name}")
    try:
        arrays = read_arrays(stream, entries, {JSON_KEY: "|u1", "*": f"kind:{ARRAY_KINDS}"})
        document = document_of(arrays.pop(JSON_KEY), f"{name}: {JSON_KEY}", standard=False)
        if not isinstance(document, dict):
            raise ValueError(f"a JSON {type(document).__name__}, not an object")
        manifest = document.pop(MANIFEST_KEY, None)
        keys = sorted(arrays)
        if manifest is not None and manifest != keys:
            unknown = sorted(set(keys) - set(manifest)) if isinstance(manifest, list) else keys
            what = f"unknown entries {unknown}" if unknown else f"entries {keys}"
            raise ValueError(f"{what} (its manifest {MANIFEST_KEY!r} lists {str(manifest)[:200]})")
        state: dict[str, Any] = _decode_non_finite(document)
        state.update({k: arrays[k] for k in keys})
    except (ValueError, KeyError, TypeError, UnicodeDecodeError, OSError, zipfile.BadZipFile) as exc:
        raise ValueError(f"path: expected a creps_gym checkpoint, got a damaged {name} ({exc!r})") from None
    return state
