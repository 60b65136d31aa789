"""The lines of a run's ``log.jsonl``: their checksums, and the chain that makes an iteration this run's.

Each line is one JSON object that ends with ``"crc32"``, the CRC-32 of the rest (:func:`entry_crc`), so a
damaged line is found. An iteration record's line also carries ``"chain"`` (:func:`record_chain`): the
CRC-32 of the record after the run's fingerprint after the checksum of the iterations before it. Lines
after the last checkpoint (which the checkpoint's ``log_crc`` does not cover) are read as this run's only
if their chain matches, so a line copied from another run or written by hand is left out. (It is a
checksum, not a signature: it tells copies and hand-made lines apart, it does not stop a forger who
recomputes it.) A checkpoint keeps :func:`history_crc`, the checksum of records 1..k (:func:`chain_crc`
extends it by one record). Logs written before the chain existed have none: their iterations up to the last
checkpoint are read as before, the ones after it are left out (``resume`` redoes them anyway).
"""

from __future__ import annotations

import json
import zlib
from typing import Any

from creps_gym._validation import load_json
from creps_gym.runner.history import IterationRecord

__all__ = ["chain_crc", "entry_crc", "history_crc", "log_line", "parse_log", "record_chain"]


def entry_crc(entry: dict[str, Any], *, sort_keys: bool = False) -> int:
    """The CRC-32 of ``entry``'s JSON text."""
    return zlib.crc32(json.dumps(entry, allow_nan=False, sort_keys=sort_keys).encode())


def record_chain(fingerprint: str, log_crc: int, entry: dict[str, Any]) -> int:
    """The ``"chain"`` of an iteration's line: the CRC-32 of ``entry`` (its record's ``to_dict()``) after
    the run's ``fingerprint`` after ``log_crc``, the checksum of the iterations before it (as a
    checkpoint keeps it, :func:`creps_gym.runner.rundir.log_chain.history_crc`)."""
    seed = zlib.crc32(fingerprint.encode(), log_crc)
    return zlib.crc32(json.dumps(entry, allow_nan=False).encode(), seed)


def log_line(entry: dict[str, Any]) -> bytes:
    """One line of the log: ``entry`` and its ``"crc32"``."""
    return (json.dumps({**entry, "crc32": entry_crc(entry)}, allow_nan=False) + "\n").encode("utf-8")


def parse_log(
    data: bytes, source: str
) -> tuple[dict[int, IterationRecord], list[dict[str, Any]], list[int], dict[int, int | None]]:
    """Records (the last copy of each iteration), events, damaged (1-based) line numbers and each kept
    record's ``"chain"`` (None if its line has none)."""
    records: dict[int, IterationRecord] = {}
    events: list[dict[str, Any]] = []
    bad: list[int] = []
    chains: dict[int, int | None] = {}
    for number, line in enumerate(data.splitlines(), 1):
        try:
            entry = load_json(line.decode("utf-8"), source)
            if entry.pop("crc32", None) not in (None, entry_crc(entry)):  # (older logs have none)
                raise ValueError("checksum mismatch")
            if "event" in entry:
                events.append(entry)
            else:
                chain = entry.pop("chain", None)
                record = IterationRecord.from_dict(entry)
                records[record.iteration] = record
                chains[record.iteration] = chain
        except (ValueError, KeyError, TypeError, AttributeError):
            bad.append(number)
    return records, events, bad, chains


def chain_crc(crc: int, entry: dict[str, Any]) -> int:
    """``crc`` (the checksum of a history's records so far) extended by one record's ``to_dict()``."""
    return zlib.crc32(json.dumps(entry, allow_nan=False).encode(), crc)


def history_crc(records: list[IterationRecord]) -> int:
    """The checksum a checkpoint keeps of the records 1..k of its history (see :func:`chain_crc`)."""
    crc = 0
    for record in records:
        crc = chain_crc(crc, record.to_dict())
    return crc
