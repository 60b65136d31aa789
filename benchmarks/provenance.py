"""Where a study's results were computed: the provenance record every study stores with its results.

:func:`provenance` describes this process: Python and the package versions a study depends on, creps_gym's
git commit (with ``-dirty`` when its source differs from the commit), the CPU and the BLAS library numpy
runs on (OpenBLAS picks its kernels per CPU at run time: ``blas.architecture``) and numpy's SIMD dispatch
(``simd``: :mod:`benchmarks.numeric_stack`). Results computed before the record existed carry
:func:`unrecorded` instead, which says so. :func:`provenance_text` renders the records of a study's runs
as one Markdown paragraph.

Why the CPU and BLAS matter: a matrix product's last bits depend on the kernel OpenBLAS picks for the CPU,
an exponential's on the instruction set numpy's loop runs (and on numpy's and pycma's versions), and the
optimisers amplify such differences over thousands of iterations, so runs are bit-identical only on the
same stack; on another one they agree statistically.
"""

from __future__ import annotations

import datetime
import os
import platform
import subprocess
import sys
from collections import Counter
from collections.abc import Iterable, Sequence
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import Any

from benchmarks.numeric_stack import blas, numpy_simd

__all__ = [
    "CORE_PACKAGES",
    "REQUIRED",
    "group_by_record",
    "is_recorded",
    "provenance",
    "provenance_text",
    "unrecorded",
]

#: Packages every study depends on; a study adds those it uses (mujoco, cma, nevergrad, optuna).
CORE_PACKAGES = ("numpy", "scipy", "gymnasium")
#: Keys a recorded provenance always has (``packages`` has ``python`` and :data:`CORE_PACKAGES`).
REQUIRED = ("packages", "creps_gym_commit", "cpu", "cpu_count", "platform", "blas", "date")
_REPO = Path(__file__).resolve().parents[1]


def provenance(packages: Sequence[str] = ()) -> dict[str, Any]:
    """The provenance of results computed by this process.

    Parameters
    ----------
    packages : sequence of str
        Distribution names the study uses besides :data:`CORE_PACKAGES` (e.g. ``"cma"``, ``"mujoco"``);
        a missing one is recorded as ``"not installed"``.

    Returns
    -------
    dict
        ``recorded`` (True), ``packages`` (name -> version, with ``python``), ``creps_gym_commit`` (the
        repository's HEAD when this module was imported, i.e. the code this process runs, ``-dirty`` if a
        tracked ``.py`` file of ``creps_gym/`` or ``benchmarks/`` differed from it; None outside a git
        checkout), ``cpu`` (model name), ``cpu_count``, ``platform``, ``blas`` (the BLAS numpy calls:
        library, version and the kernel architecture chosen for this CPU where threadpoolctl can tell),
        ``simd`` (numpy's dispatch targets enabled, :func:`benchmarks.numeric_stack.numpy_simd`; records
        before it was recorded lack it) and ``date`` (UTC, ISO 8601).
    """
    found = {"python": sys.version.split()[0]}
    for name in (*CORE_PACKAGES, *packages):
        try:
            found[name] = version(name)
        except PackageNotFoundError:
            found[name] = "not installed"
    return {
        "recorded": True,
        "packages": found,
        "creps_gym_commit": _COMMIT,
        "cpu": _cpu_model(),
        "cpu_count": os.cpu_count(),
        "platform": platform.platform(),
        "blas": blas(),
        "simd": numpy_simd(),
        "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
    }


def unrecorded(note: str = "computed before provenance was recorded (issue 31)") -> dict[str, Any]:
    """The record of results whose versions and CPU are unknown, with ``note`` saying why."""
    return {"recorded": False, "note": note}


def is_recorded(record: Any) -> bool:
    """Whether ``record`` is a complete recorded provenance (see :data:`REQUIRED`)."""
    if not isinstance(record, dict) or record.get("recorded") is not True:
        return False
    packages = record.get("packages", {})
    return all(key in record for key in REQUIRED) and all(
        packages.get(name) for name in ("python", *CORE_PACKAGES)
    )


def group_by_record(sources: dict[str, Any]) -> list[dict[str, Any]]:
    """``{name: provenance record or None}`` grouped as ``[{"record": record, "runs": [names]}]``, one entry
    per distinct record (None becomes :func:`unrecorded`), in order of first appearance."""
    groups: list[dict[str, Any]] = []
    for name, record in sources.items():
        record = record if is_recorded(record) else unrecorded()
        group = next((g for g in groups if g["record"] == record), None)
        if group is None:
            groups.append({"record": record, "runs": [name]})
        else:
            group["runs"].append(name)
    return groups


def provenance_text(records: Iterable[Any], what: str = "runs") -> str:
    """One Markdown paragraph on where the ``what`` were computed: one line per distinct stack (packages,
    CPU, BLAS, commit) with its count, and the count recorded before provenance existed (None or an
    :func:`unrecorded` record)."""
    stacks: Counter[str] = Counter()
    unknown: Counter[str] = Counter()  # by what is known of them: a record's "partial" text, else nothing
    for record in records:
        if is_recorded(record):
            stacks[_stack_text(record)] += 1
        else:
            partial = record.get("partial") if isinstance(record, dict) else None
            unknown[partial or "computed before provenance was recorded (versions and CPU unknown)"] += 1

    def counted(count: int) -> str:
        return f"{count} {what if count != 1 else what.removesuffix('s')}"

    lines = [f"- {counted(n)}: {stack}" for stack, n in sorted(stacks.items(), key=lambda s: -s[1])]
    lines += [f"- {counted(n)}: {text}" for text, n in unknown.items()]
    return "Computed on (provenance):\n\n" + "\n".join(lines)


def _stack_text(record: dict[str, Any]) -> str:
    packages = ", ".join(f"{name} {v}" for name, v in record["packages"].items())
    entry = record["blas"]
    blas_text = " ".join(str(entry[k]) for k in ("library", "version", "architecture") if entry.get(k))
    commit = record["creps_gym_commit"] or "unknown"
    cpu = f"{record['cpu']} ({record['cpu_count']} cores)"
    simd = f", numpy SIMD {' '.join(record['simd'])}" if record.get("simd") else ""
    return f"{packages}; CPU {cpu}, BLAS {blas_text}{simd}; creps_gym {commit}"


def _git_commit() -> str | None:
    """HEAD of the repository holding this file, ``-dirty`` if its code differs; None without git."""
    try:
        head = subprocess.run(
            ["git", "rev-parse", "HEAD"], cwd=_REPO, capture_output=True, text=True, timeout=10, check=True
        ).stdout.strip()
        changes = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no", "--", "creps_gym", "benchmarks"],
            cwd=_REPO,
            capture_output=True,
            text=True,
            timeout=30,
            check=True,
        ).stdout
    except (OSError, subprocess.SubprocessError):
        return None
    # The study's own outputs (run documents, renderings) are not code.
    code = [line for line in changes.splitlines() if line[3:].endswith(".py")]
    return head + ("-dirty" if code else "") if head else None


#: The code this process runs: the commit when the study imported this module (a long run's HEAD may move).
_COMMIT = _git_commit()


def _cpu_model() -> str:
    """The CPU's model name (``/proc/cpuinfo`` on Linux), else what :mod:`platform` knows."""
    try:
        for line in Path("/proc/cpuinfo").read_text(encoding="utf-8", errors="replace").splitlines():
            if line.startswith("model name"):
                return line.partition(":")[2].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown"
