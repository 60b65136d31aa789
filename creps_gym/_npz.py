"""The ``.npz`` + JSON container under checkpoints and policy files: numeric arrays and one JSON document.

A container is a zip of ``.npy`` entries: one per array, and the JSON document as a 1-D ``uint8`` entry
(UTF-8, keys sorted, no NaN or infinity). Nothing in it is ever pickled, and a container is untrusted
input, so it is read in this order, nothing allocated before its size is checked:

1. :func:`read_directory`: the zip directory only (nothing decompressed). Every entry is a ``.npy``
   array, named once and stored uncompressed (a compressed entry could declare far more than the file
   holds: no "zip bomb"), each at most its limit, all of them together within memory.
2. :func:`read_arrays`: each entry read to at most its declared size, its ``.npy`` header checked (a
   dtype of the kinds allowed, no object or structured dtype, a shape that matches its bytes) before
   its data is copied out.
3. :func:`document_of`: the JSON entry decoded as standard JSON nested at most
   :data:`~creps_gym._validation.MAX_JSON_DEPTH` levels.

Each failure is a ``ValueError`` saying what is wrong; the caller names the file (a checkpoint's reader
says "checkpoint", a policy file's "policy file"). Writing: :func:`container_entries` (the arrays and the
document as entries) and :func:`container_bytes` (stored, with a fixed date: equal contents give equal
bytes, as policy files are written); checkpoints write the same entries with ``numpy.savez``, the layout
they have had since their first format. The files are written and read through :mod:`creps_gym._files`.
"""

from __future__ import annotations

import io
import json
import zipfile
from collections.abc import Mapping
from typing import Any, BinaryIO

import numpy as np
from numpy.typing import NDArray

from creps_gym._validation import check_fits_in_memory, load_json

__all__ = ["container_bytes", "container_entries", "document_of", "read_arrays", "read_directory"]

#: The fixed date of every entry :func:`container_bytes` writes.
FIXED_DATE = (1980, 1, 1, 0, 0, 0)


def container_entries(
    arrays: Mapping[str, NDArray[Any]], json_entry: str, document: Any
) -> dict[str, NDArray[Any]]:
    """The entries of a container: ``arrays`` in their order, then ``document`` as the entry ``json_entry``.

    The document is written with its keys sorted and without NaN or infinity (``ValueError``).
    """
    payload = json.dumps(document, sort_keys=True, allow_nan=False).encode()
    entries = dict(arrays)
    entries[json_entry] = np.frombuffer(payload, dtype=np.uint8)
    return entries


def container_bytes(entries: Mapping[str, NDArray[Any]]) -> bytes:
    """The bytes of a container of ``entries``: stored uncompressed, each entry dated :data:`FIXED_DATE`."""
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", compression=zipfile.ZIP_STORED) as archive:
        for name, array in entries.items():
            npy = io.BytesIO()
            np.lib.format.write_array(npy, np.ascontiguousarray(array), allow_pickle=False)
            archive.writestr(zipfile.ZipInfo(f"{name}.npy", date_time=FIXED_DATE), npy.getvalue())
    return buffer.getvalue()


def read_directory(stream: BinaryIO, name: str, limit: int | None = None) -> dict[str, zipfile.ZipInfo]:
    """Entry name (without ``.npy``) -> its zip record, from the directory of the container ``stream``.

    ``ValueError`` for an entry that is not a ``.npy`` array, a second entry of one name, an entry that
    is not stored uncompressed or is larger than ``limit`` bytes, or arrays too large for memory
    (``name`` is the file, for that message). ``zipfile.BadZipFile`` for a stream that is no zip.
    """
    with zipfile.ZipFile(stream) as archive:
        infos = archive.infolist()
    found: dict[str, zipfile.ZipInfo] = {}
    for info in infos:
        key = info.filename[:-4] if info.filename.endswith(".npy") else None
        if key is None or key in found:
            what = "a second entry" if key is not None else "an entry that is not a .npy array"
            raise ValueError(f"{what} {info.filename!r}")
        if info.compress_type != zipfile.ZIP_STORED or info.file_size != info.compress_size:
            raise ValueError(
                f"entry {info.filename!r}: expected an uncompressed array, got "
                f"{info.compress_size} bytes that decompress to {info.file_size}"
            )
        if limit is not None and info.file_size > limit:
            raise ValueError(f"entry {info.filename!r}: expected at most {limit} bytes, got {info.file_size}")
        found[key] = info
    check_fits_in_memory(sum(info.file_size for info in found.values()), "path", name, "its arrays")
    return found


def read_arrays(
    stream: BinaryIO, entries: Mapping[str, zipfile.ZipInfo], dtypes: Mapping[str, str]
) -> dict[str, NDArray[Any]]:
    """The arrays of ``entries`` (from :func:`read_directory`), each a writable C-ordered copy.

    ``dtypes``: entry name -> the dtype it must have (``"<f8"``) or, prefixed ``"kind:"``, the dtype
    kinds it may have (``"kind:biufc"``); the key ``"*"`` holds the rule of the other entries.
    """
    with zipfile.ZipFile(stream) as archive:
        arrays = {}
        for key, info in entries.items():
            with archive.open(info) as entry:
                raw = entry.read(info.file_size + 1)
            if len(raw) != info.file_size:
                raise ValueError(f"entry {info.filename!r}: expected {info.file_size} bytes, got {len(raw)}")
            arrays[key] = _array(raw, info.filename, dtypes.get(key, dtypes["*"]))
    return arrays


def _header(stream: io.BytesIO, name: str) -> tuple[tuple[Any, ...], bool, np.dtype[Any]]:
    major, _ = np.lib.format.read_magic(stream)
    if major == 1:
        return np.lib.format.read_array_header_1_0(stream)
    if major == 2:
        return np.lib.format.read_array_header_2_0(stream)
    raise ValueError(f"{name}: expected a .npy header of version 1 or 2, got {major}")


def _array(raw: bytes, name: str, rule: str) -> NDArray[Any]:
    """One ``.npy`` entry, its header checked against ``rule`` (see :func:`read_arrays`) before its data."""
    stream = io.BytesIO(raw)
    shape, fortran, dtype = _header(stream, name)
    if rule.startswith("kind:"):
        allowed = dtype.kind in rule[5:] and dtype.fields is None and not dtype.hasobject
        expected = f"a numeric dtype (kinds {rule[5:]!r})"
    else:
        allowed, expected = dtype == np.dtype(rule) and not dtype.hasobject, f"dtype {np.dtype(rule)}"
    if not allowed:
        raise ValueError(f"{name}: expected {expected}, got {dtype}")
    if not all(type(n) is int and n >= 0 for n in shape):  # not bool
        raise ValueError(f"{name}: expected a shape of non-negative ints, got {shape}")
    count = int(np.prod(shape, dtype=object))
    if count * dtype.itemsize != len(raw) - stream.tell():
        raise ValueError(f"{name}: expected {count * dtype.itemsize} bytes of data for shape {shape}")
    array = np.frombuffer(raw, dtype=dtype, count=count, offset=stream.tell())
    return np.array(array.reshape(shape, order="F" if fortran else "C"), dtype=dtype, order="C")


def document_of(payload: NDArray[Any], source: str, *, standard: bool = True) -> Any:
    """The JSON document of a container's JSON entry ``payload`` (1-D ``uint8``), read from ``source``.

    ``ValueError`` for another shape, text that is not UTF-8 or, with ``standard``, not standard JSON
    (NaN, infinity), or nesting deeper than :data:`~creps_gym._validation.MAX_JSON_DEPTH`.
    """
    if payload.ndim != 1 or payload.dtype != np.uint8:
        got = f"{payload.dtype} of shape {payload.shape}"
        raise ValueError(f"{source}: expected a 1-D uint8 array, got {got}")
    return load_json(payload.tobytes().decode("utf-8"), source, standard=standard)
