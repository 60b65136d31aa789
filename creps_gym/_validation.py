"""Input checking shared by the optimisers and the environments (numpy only).

Every check raises a ``TypeError`` or ``ValueError`` whose message names the argument, what was expected
and what was received, so that bad input never turns into a silent NaN further down.
"""

from __future__ import annotations

import json
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from typing import Any

import numpy as np
from numpy.typing import NDArray

from creps_gym.errors import ConfigError, ConfigTypeError

__all__ = [
    "MAX_COUNT",
    "as_float_array",
    "check_bool",
    "check_count",
    "check_finite",
    "check_fits_in_memory",
    "check_generator_state",
    "check_in_box",
    "check_positive_int",
    "check_real",
    "check_real_in_range",
    "check_seed",
    "config_field",
    "load_json",
]


@contextmanager
def config_field(field: str | None) -> Iterator[None]:
    """A ``ValueError`` or ``TypeError`` raised inside is about the configuration field ``field``: it is
    raised again as a :class:`ConfigError` (``ConfigTypeError`` for a ``TypeError``) of ``field``, its message
    unchanged. Nothing changes for ``field=None``, for a ``ConfigError`` (it names its own field) or for
    another subclass of ``ValueError`` (e.g. a run directory's error)."""
    try:
        yield
    except (ValueError, TypeError) as exc:
        if field is None or isinstance(exc, ConfigError) or type(exc) not in (ValueError, TypeError):
            raise
        message = str(exc)
        reason = message.removeprefix(f"{field}: ")
        kind = ConfigTypeError if isinstance(exc, TypeError) else ConfigError
        raise kind(field, reason, message) from None


def _shape_text(shape: Sequence[int | None]) -> str:
    return (
        "(" + ", ".join("n" if d is None else str(d) for d in shape) + ("," if len(shape) == 1 else "") + ")"
    )


def as_float_array(
    value: Any,
    name: str,
    shape: Sequence[int | None] | None = None,
    *,
    finite: bool = True,
) -> NDArray[np.float64]:
    """Convert ``value`` to a float64 array and check its shape and values.

    Parameters
    ----------
    value : array_like
        The user's input.
    name : str
        Argument name used in error messages.
    shape : sequence of int or None, optional
        Expected shape; ``None`` entries match any length.
    finite : bool
        Reject NaN and infinity.

    Returns
    -------
    numpy.ndarray
        A float64 array (a copy only when a conversion was needed).
    """
    if type(value) is np.ndarray and value.dtype == np.float64:
        array = value  # the hot path (batches from numpy code): nothing to convert or inspect
    else:
        array = _convert(value, name)
    if shape is not None:
        ok = array.ndim == len(shape) and all(
            e is None or e == a for e, a in zip(shape, array.shape, strict=True)
        )
        if not ok:
            raise ValueError(f"{name}: expected shape {_shape_text(shape)}, got {array.shape}")
    if finite:
        check_finite(array, name)
    return array


def _convert(value: Any, name: str) -> NDArray[np.float64]:
    """Convert non-float64 input, rejecting strings, bytes, booleans, complex and structured data."""
    if isinstance(value, (str, bytes)) or value is None:
        raise TypeError(f"{name}: expected an array of real numbers, got {type(value).__name__}")
    kind = np.asarray(value).dtype.kind
    if kind in "cUSVb":
        what = {"c": "complex", "U": "string", "S": "bytes", "V": "structured", "b": "boolean"}[kind]
        raise TypeError(f"{name}: expected an array of real numbers, got a {what} array")
    try:
        return np.asarray(value, dtype=np.float64)
    except OverflowError:  # a Python int beyond the float range
        raise ValueError(f"{name}: expected finite values, got an integer beyond the float range") from None
    except (TypeError, ValueError) as exc:
        raise TypeError(
            f"{name}: expected an array of real numbers, got {type(value).__name__} ({exc})"
        ) from None


def _as_float(value: Any, name: str) -> float:
    """``float(value)``, with a Python int beyond the float range named as a ``ValueError``."""
    try:
        return float(value)
    except OverflowError:
        raise ValueError(f"{name}: expected a finite number, got an integer beyond the float range") from None


def check_in_box(values: NDArray[np.float64], low: Any, high: Any, name: str, hint: str = "") -> None:
    """``ValueError`` naming ``name`` and the first value of ``values`` (n, z) outside the box [low, high]
    (per dimension), with ``hint`` appended to the message."""
    outside = (values < low) | (values > high)
    if outside.any():
        row, col = (int(i) for i in np.argwhere(outside)[0])
        low, high = np.broadcast_to(low, values.shape[1:]), np.broadcast_to(high, values.shape[1:])
        raise ValueError(
            f"{name}: expected values in the context box [{low[col]}, {high[col]}] in dimension {col}, "
            f"got {values[row, col]}{hint}"
        )


def check_finite(array: NDArray[np.float64], name: str) -> None:
    """Raise ``ValueError`` naming the first non-finite entry of ``array``."""
    if not np.isfinite(array).all():
        bad = np.argwhere(~np.isfinite(array))[0]
        where = tuple(int(i) for i in bad)
        raise ValueError(
            f"{name}: expected finite values, got {array[where] if where else array} at index {where}"
        )


def check_positive_int(value: Any, name: str, minimum: int = 1) -> int:
    """Return ``value`` as an int, or raise if it is not an integer ``>= minimum``."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise TypeError(f"{name}: expected an integer >= {minimum}, got {type(value).__name__} {value!r}")
    if value < minimum:
        raise ValueError(f"{name}: expected an integer >= {minimum}, got {value}")
    return int(value)


#: Largest counter (iterations, restarts, generations, episodes) a state may hold: every count up to it is
#: exact as a float (diagnostics are floats), and no run comes near it.
MAX_COUNT = 2**53


def check_count(value: Any, name: str, maximum: int = MAX_COUNT) -> int:
    """``value`` as an int in ``[0, maximum]``; ``TypeError`` (not an integer: 1.5, 1e308, a str) or
    ``ValueError`` (negative, or above ``maximum``: 10**400) naming ``name`` otherwise."""
    count = check_positive_int(value, name, minimum=0)
    if count > maximum:
        shown = count if count < 10**30 else f"an integer of {len(str(count))} digits"
        raise ValueError(f"{name}: expected an integer of at most {maximum}, got {shown}")
    return count


def check_generator_state(state: Any, name: str) -> Any:
    """``state`` if it is a PCG64 state a ``numpy.random.Generator`` can have written, else ``ValueError``
    naming ``name``. Checked here because numpy itself differs: recent versions raise ``OverflowError`` for
    a word outside [0, 2**128), older ones (1.23) take ``-1`` silently as another state."""
    inner = state.get("state") if isinstance(state, dict) else None
    words = [inner.get("state"), inner.get("inc")] if isinstance(inner, dict) else [None]
    if not (
        isinstance(state, dict)
        and state.get("bit_generator") == "PCG64"
        and all(type(w) is int and 0 <= w < 2**128 for w in words)
        and state.get("has_uint32") in (0, 1)
        and type(state.get("uinteger")) is int
        and 0 <= state["uinteger"] < 2**32
    ):
        raise ValueError(f"{name}: expected a PCG64 state with 128-bit words, got {str(state)[:200]}")
    return state


def check_seed(value: Any, name: str = "seed") -> int | None:
    """Return a seed as an int >= 0, or None; raise ``TypeError``/``ValueError`` naming ``name`` otherwise."""
    if value is None:
        return None
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise TypeError(f"{name}: expected an int >= 0 or None, got {type(value).__name__}")
    if value < 0:
        raise ValueError(f"{name}: expected an int >= 0 or None, got {value}")
    return int(value)


def check_real_in_range(
    value: Any,
    name: str,
    low: float,
    high: float,
    *,
    low_inclusive: bool = False,
    high_inclusive: bool = True,
) -> float:
    """Return ``value`` as a finite float in the interval between ``low`` and ``high``, else raise.

    The bounds are open or closed as the flags say; the error message prints the interval accordingly.
    """
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise TypeError(f"{name}: expected a real number, got {type(value).__name__} {value!r}")
    number = _as_float(value, name)
    above = low <= number if low_inclusive else low < number
    below = number <= high if high_inclusive else number < high
    if not (np.isfinite(number) and above and below):
        interval = f"{'[' if low_inclusive else '('}{low}, {high}{']' if high_inclusive else ')'}"
        raise ValueError(f"{name}: expected a finite value in {interval}, got {value!r}")
    return number


def check_real(value: Any, name: str, *, minimum: float = 0.0, strict: bool = False) -> float:
    """Return ``value`` as a finite float ``>= minimum`` (``> minimum`` if ``strict``), else raise."""
    relation = f"{'>' if strict else '>='} {minimum:g}"
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise TypeError(f"{name}: expected a real number {relation}, got {type(value).__name__} {value!r}")
    number = _as_float(value, name)
    if not np.isfinite(number) or number < minimum or (strict and number == minimum):
        raise ValueError(f"{name}: expected a finite value {relation}, got {value!r}")
    return number


def check_bool(value: Any, name: str) -> bool:
    """Return ``value`` as a bool, or raise ``TypeError`` (ints such as 0 and 1 are not accepted)."""
    if not isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{name}: expected a bool, got {type(value).__name__} {value!r}")
    return bool(value)


#: The share of the available memory that one allocation plan may claim (see :func:`check_fits_in_memory`).
MEMORY_FRACTION = 0.8


def _read_int(path: str, field: str | None = None) -> int | None:
    """An integer from a /proc or /sys file (one ``field:`` line of it, in kB), or None if unreadable."""
    try:
        with open(path, encoding="ascii") as stream:
            text = stream.read()
    except OSError:
        return None
    if field is None:
        return int(text) if text.strip().isdigit() else None
    for line in text.splitlines():
        name, _, value = line.partition(":")
        if name == field and value.split() and value.split()[0].isdigit():
            return int(value.split()[0]) * 1024
    return None


def available_memory() -> int | None:
    """Bytes this process may still allocate, or None where unknown (not Linux).

    The smallest of the system's ``MemAvailable``, the cgroup's limit minus its usage, and the address-space
    limit (``ulimit -v``) minus the process's current size.
    """
    limits = [_read_int("/proc/meminfo", "MemAvailable")]
    cgroup_max, cgroup_now = (
        _read_int("/sys/fs/cgroup/memory.max"),
        _read_int("/sys/fs/cgroup/memory.current"),
    )
    if cgroup_max is not None and cgroup_now is not None:
        limits.append(cgroup_max - cgroup_now)
    try:
        import resource

        soft = resource.getrlimit(resource.RLIMIT_AS)[0]
        size = _read_int("/proc/self/status", "VmSize")
        if soft != resource.RLIM_INFINITY and size is not None:
            limits.append(soft - size)
    except (ImportError, OSError, ValueError):  # pragma: no cover - not POSIX
        pass
    known = [max(0, limit) for limit in limits if limit is not None]
    return min(known) if known else None


def check_fits_in_memory(n_bytes: float, name: str, value: Any, what: str) -> None:
    """Refuse, before allocating, a size whose arrays need over :data:`MEMORY_FRACTION` of the free memory.

    Parameters
    ----------
    n_bytes : float
        Estimated bytes of the arrays ``value`` leads to.
    name : str
        The argument that sets the size (named in the error).
    value : Any
        Its value (shown in the error).
    what : str
        What needs the memory, e.g. ``"the rotation matrix (p x p floats)"``.
    """
    free = available_memory()
    if free is not None and n_bytes > MEMORY_FRACTION * free:
        raise ValueError(
            f"{name}: expected a size whose arrays fit in memory ({what} need {n_bytes / 2**30:.3g} GiB; "
            f"{free / 2**30:.3g} GiB available, of which {MEMORY_FRACTION:.0%} may be used), got {value!r}"
        )


#: Deepest nesting of JSON arrays and objects read from a file or a flag (creps_gym writes depth 4 at most).
MAX_JSON_DEPTH = 100


def load_json(
    text: str | bytes, source: str, max_depth: int = MAX_JSON_DEPTH, *, standard: bool = False
) -> Any:
    """``json.loads(text)``; a ``ValueError`` naming ``source`` if it nests deeper than ``max_depth``.

    Deep nesting would otherwise raise ``RecursionError`` here or in any recursive code that reads it.
    With ``standard``, ``NaN`` and ``Infinity`` (which Python's ``json`` reads) are a ``ValueError`` too.
    """
    expected = f"{source}: expected JSON nested at most {max_depth} levels deep"

    def refuse(constant: str) -> None:
        raise ValueError(f"expected standard JSON, got {constant}")

    try:
        document = json.loads(text, parse_constant=refuse) if standard else json.loads(text)
    except RecursionError:
        raise ValueError(f"{expected}, got deeper") from None
    stack = [(document, 1)]
    while stack:
        value, depth = stack.pop()
        if isinstance(value, (dict, list)):
            if depth > max_depth:
                raise ValueError(f"{expected}, got {depth} levels")
            children = value.values() if isinstance(value, dict) else value
            stack.extend((child, depth + 1) for child in children)
    return document
