"""The learning history of a run: one :class:`IterationRecord` per iteration, with JSON and CSV round-trips.

Floats are written with ``repr`` precision, so both formats round-trip bit for bit. In JSON, NaN is written
as ``null`` and infinities as the strings ``"inf"`` and ``"-inf"`` (the files stay standard JSON).
Wall times are the only part of a history that differs between two runs with the same seed;
:meth:`History.equals` ignores them by default.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from creps_gym._files import write_atomically
from creps_gym._validation import load_json

__all__ = ["History", "IterationRecord", "atomic_write_text", "decode_float", "encode_float"]

FIELDS = ("iteration", "episodes", "mean_return", "eval_return", "eval_regret", "wall_time")
_DIAG = "diag."


def encode_float(value: float) -> float | str | None:
    """A float as a standard-JSON value: NaN -> None, ±inf -> "inf"/"-inf"."""
    value = float(value)
    if math.isnan(value):
        return None
    if math.isinf(value):
        return "inf" if value > 0 else "-inf"
    return value


def decode_float(value: Any) -> float:
    """Inverse of :func:`encode_float`."""
    return math.nan if value is None else float(value)


def atomic_write_text(path: str | os.PathLike[str], text: str) -> Path:
    """Write ``text`` to ``path`` through a new temporary file in the same folder and a rename.

    ``path`` itself is replaced (a link there is not followed); ``OSError`` naming it if it cannot be.
    """
    return write_atomically(path, text.encode("utf-8"))


def _same_float(a: float, b: float) -> bool:
    return (math.isnan(a) and math.isnan(b)) or np.float64(a).tobytes() == np.float64(b).tobytes()


@dataclass
class IterationRecord:
    """What one iteration produced.

    Attributes
    ----------
    iteration : int
        1-based iteration number.
    episodes : int
        Training episodes used so far (evaluation episodes are not counted).
    mean_return : float
        Mean return of this iteration's samples.
    eval_return : float
        Mean return of the recommended (mean) policy on the fixed test contexts; NaN when not evaluated.
    eval_regret : float
        Mean regret of the recommended policy; NaN when not evaluated or when the env has no regret.
    wall_time : float
        Seconds since the run started (summed over resumes).
    diagnostics : dict of str to float
        The optimiser's diagnostics after this iteration's ``tell``.
    """

    iteration: int
    episodes: int
    mean_return: float
    eval_return: float = math.nan
    eval_regret: float = math.nan
    wall_time: float = 0.0
    diagnostics: dict[str, float] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """JSON-serialisable dict (see the module docstring for non-finite floats)."""
        data: dict[str, Any] = {"iteration": int(self.iteration), "episodes": int(self.episodes)}
        for name in FIELDS[2:]:
            data[name] = encode_float(getattr(self, name))
        data["diagnostics"] = {k: encode_float(v) for k, v in self.diagnostics.items()}
        return data

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> IterationRecord:
        """Inverse of :meth:`to_dict`."""
        floats = {name: decode_float(data[name]) for name in FIELDS[2:]}
        diagnostics = {str(k): decode_float(v) for k, v in dict(data.get("diagnostics", {})).items()}
        return cls(int(data["iteration"]), int(data["episodes"]), diagnostics=diagnostics, **floats)

    def equals(self, other: IterationRecord, include_time: bool = False) -> bool:
        """Bit-for-bit equality (NaN equals NaN); wall time only if ``include_time``."""
        names = FIELDS if include_time else FIELDS[:-1]
        if any(not _same_float(getattr(self, n), getattr(other, n)) for n in names):
            return False
        if set(self.diagnostics) != set(other.diagnostics):
            return False
        return all(_same_float(v, other.diagnostics[k]) for k, v in self.diagnostics.items())


@dataclass
class History:
    """Per-iteration records of a run, plus metadata (env, optimiser, seed, ...) and the stop reason.

    Use :meth:`column` for arrays (``history.column("eval_regret")`` has shape (iterations,)).
    """

    records: list[IterationRecord] = field(default_factory=list)
    meta: dict[str, Any] = field(default_factory=dict)
    stop_reason: str | None = None

    def __len__(self) -> int:
        return len(self.records)

    def __iter__(self) -> Iterator[IterationRecord]:
        return iter(self.records)

    def append(self, record: IterationRecord) -> None:
        """Add the next iteration's record."""
        self.records.append(record)

    def column(self, name: str) -> NDArray[np.float64]:
        """One field (or ``"diag.<key>"``) over the iterations, shape (iterations,); NaN where missing."""
        if name.startswith(_DIAG):
            key = name[len(_DIAG) :]
            return np.array([r.diagnostics.get(key, math.nan) for r in self.records], dtype=np.float64)
        if name not in FIELDS:
            raise ValueError(f"name: expected one of {list(FIELDS)} or 'diag.<key>', got {name!r}")
        return np.array([getattr(r, name) for r in self.records], dtype=np.float64)

    @property
    def best_iteration(self) -> int | None:
        """The iteration whose evaluation had the highest mean return (the first on ties; None before the
        first evaluation): the one ``best_policy.npz`` of a run folder comes from."""
        best, found = -math.inf, None
        for record in self.records:
            if math.isfinite(record.eval_return) and record.eval_return > best:
                best, found = record.eval_return, record.iteration
        return found

    def equals(self, other: History, include_time: bool = False) -> bool:
        """Same records bit for bit (wall times ignored unless ``include_time``) and same stop reason."""
        return (
            len(self) == len(other)
            and self.stop_reason == other.stop_reason
            and all(a.equals(b, include_time) for a, b in zip(self.records, other.records, strict=True))
        )

    # -- JSON ------------------------------------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """JSON-serialisable dict (``best_iteration`` is derived from the records, and not read back)."""
        return {
            "meta": dict(self.meta),
            "stop_reason": self.stop_reason,
            "best_iteration": self.best_iteration,
            "records": [r.to_dict() for r in self.records],
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> History:
        """Inverse of :meth:`to_dict`."""
        records = [IterationRecord.from_dict(r) for r in data["records"]]
        meta = data.get("meta", {})
        if not isinstance(meta, dict):
            raise ValueError(f"meta: expected a JSON object, got {type(meta).__name__}")
        return cls(records, dict(meta), data.get("stop_reason"))

    def json_text(self) -> str:
        """The JSON document :meth:`to_json` writes."""
        return json.dumps(self.to_dict(), indent=1, allow_nan=False) + "\n"

    def to_json(self, path: str | os.PathLike[str]) -> Path:
        """Write the history as one JSON document (atomically)."""
        return atomic_write_text(path, self.json_text())

    @classmethod
    def from_json(cls, path: str | os.PathLike[str]) -> History:
        """Read a history written by :meth:`to_json`."""
        return cls.from_dict(load_json(Path(path).read_text(encoding="utf-8"), str(path)))

    # -- CSV -------------------------------------------------------------------------------------------------
    def to_csv(self, path: str | os.PathLike[str]) -> Path:
        """Write one row per iteration: the fields, then ``diag.<key>`` columns (metadata is not written)."""
        return atomic_write_text(path, self.csv_text())

    def csv_text(self) -> str:
        """The CSV text :meth:`to_csv` writes."""
        keys = sorted({k for r in self.records for k in r.diagnostics})
        buffer = io.StringIO()
        writer = csv.writer(buffer, lineterminator="\n")
        writer.writerow([*FIELDS, *(_DIAG + k for k in keys)])
        for r in self.records:
            values = [r.iteration, r.episodes, *(repr(float(getattr(r, n))) for n in FIELDS[2:])]
            values += [repr(float(r.diagnostics[k])) if k in r.diagnostics else "" for k in keys]
            writer.writerow(values)
        return buffer.getvalue()

    @classmethod
    def from_csv(cls, path: str | os.PathLike[str]) -> History:
        """Read a history written by :meth:`to_csv` (metadata and stop reason are not in the CSV)."""
        records = []
        with open(path, encoding="utf-8", newline="") as stream:
            for row in csv.DictReader(stream):
                diagnostics = {k[len(_DIAG) :]: float(v) for k, v in row.items() if k.startswith(_DIAG) and v}
                floats = {n: float(row[n]) for n in FIELDS[2:]}
                counts = int(row["iteration"]), int(row["episodes"])
                records.append(IterationRecord(*counts, diagnostics=diagnostics, **floats))
        return cls(records)
