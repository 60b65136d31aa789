"""The numeric stack a process computes on, beyond package versions: the BLAS numpy calls (library,
version, kernel architecture) and the SIMD instruction sets numpy's own loops dispatch to.

Both change the last bits of a result, and an optimiser amplifies such bits over hundreds of iterations
into a different run: the same code, seed and package versions give other numbers on an AVX-512 CPU than on
an AVX2 one. The study runs committed before 2026-11-29 were computed on an AMD EPYC whose OpenBLAS ran its
Haswell kernels and whose numpy dispatched up to ``X86_V3`` (AVX2, FMA); later ones on an Intel Xeon with
that stack pinned. :data:`COMMITTED` names the stack, and :func:`pinned_environment` gives the environment
variables under which any x86-64 CPU with AVX2 and FMA computes on it (what the test suite sets, so
that its bit-for-bit checks of committed runs hold on such a CPU). torch's own kernels (ATen's CPU
capability, its BLAS) are not pinned by them: a BoTorch run is the same only on the same CPU.
:func:`differences` says what separates this process's stack from a recorded one.
"""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Mapping
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import Any

__all__ = ["COMMITTED", "blas", "differences", "numpy_simd", "pinned_environment"]

#: The committed runs' stack where a record does not say (records before the SIMD level was recorded, and
#: those without a BLAS entry): OpenBLAS's Haswell kernels and numpy's dispatch up to X86_V3.
COMMITTED = {"blas_architecture": "Haswell", "simd": ("X86_V3",)}

#: The variables that restrict numpy's dispatch (a process asked for the CPU's own targets runs without).
_NUMPY_FEATURE_VARIABLES = ("NPY_DISABLE_CPU_FEATURES", "NPY_ENABLE_CPU_FEATURES")
_REPO = Path(__file__).resolve().parents[1]


def pinned_environment(features: set[str] | None = None, enabled: list[str] | None = None) -> dict[str, str]:
    """Environment variables that make a process started with them compute on :data:`COMMITTED`.

    Parameters
    ----------
    features : set of str, optional
        The CPU's features as numpy names them (``AVX2``, ``FMA3``, ``AVX512F`` ...).
    enabled : list of str, optional
        numpy's dispatch targets enabled on this CPU (:func:`numpy_simd` of a process started without the
        variables). Both are asked of a fresh Python process when None (on any operating system).

    Returns
    -------
    dict
        Where the CPU has AVX2 and FMA: ``OPENBLAS_CORETYPE`` (Haswell) and, where numpy dispatches above
        X86_V3 here (every target after it; ``AVX512F`` ... before numpy 2.4), ``NPY_DISABLE_CPU_FEATURES``
        naming exactly those targets (numpy warns about a name it does not dispatch to). Empty elsewhere:
        Haswell kernels would not run there, and other architectures have other kernels, so a bit-for-bit
        check of a committed run is skipped there. Both variables are read when numpy is first imported:
        they act on a process started with them.
    """
    if features is None or enabled is None:
        asked_targets, asked_features = _numpy_cpu()
        features = asked_features if features is None else features
        enabled = asked_targets if enabled is None else enabled
    if not {"AVX2", "FMA3"} <= features:
        return {}
    if "X86_V3" in enabled:  # numpy 2.4 on: the targets in ascending order, so all after it
        above = enabled[enabled.index("X86_V3") + 1 :]
    else:
        above = [name for name in enabled if name.startswith("AVX512")]
    pinned = {"OPENBLAS_CORETYPE": "Haswell"}
    return pinned | ({"NPY_DISABLE_CPU_FEATURES": " ".join(above)} if above else {})


def numpy_simd() -> list[str]:
    """numpy's dispatch targets enabled in this process (e.g. ``["X86_V3"]``), in numpy's order."""
    dispatch, features = _cpu_tables()
    return [name for name in dispatch if features.get(name)]


def _cpu_tables() -> tuple[list[str], dict[str, bool]]:
    """numpy's dispatch targets (ascending) and the CPU features it detects, as this process sees them."""
    try:
        from numpy._core._multiarray_umath import __cpu_dispatch__, __cpu_features__
    except ImportError:  # numpy < 2
        from numpy.core._multiarray_umath import __cpu_dispatch__, __cpu_features__
    return list(__cpu_dispatch__), dict(__cpu_features__)


def blas() -> dict[str, Any]:
    """The BLAS numpy calls: library, version, kernel architecture and threads (threadpoolctl), else
    numpy's build configuration."""
    import numpy as np

    try:
        from threadpoolctl import threadpool_info

        pools = [pool for pool in threadpool_info() if pool.get("user_api") == "blas"]
        pools.sort(key=lambda pool: "numpy" not in str(pool.get("filepath")))  # numpy's own first (scipy
        if pools:  # may load another OpenBLAS)
            keys = {"internal_api": "library", "version": "version", "architecture": "architecture"}
            found = {new: pools[0].get(old) for old, new in keys.items()}
            return {**found, "threads": pools[0].get("num_threads")}
    except ImportError:
        pass
    try:
        config = np.show_config(mode="dicts")["Build Dependencies"]["blas"]
        return {"library": config.get("name"), "version": config.get("version"), "architecture": None}
    except (KeyError, TypeError, ValueError):
        return {"library": None, "version": None, "architecture": None}


def differences(
    packages: Mapping[str, str], record_blas: Mapping[str, Any] | None = None, simd: Any = None
) -> list[str]:
    """What separates this process's numeric stack from a recorded one (empty: the same stack).

    Parameters
    ----------
    packages : mapping
        The record's package versions; numpy's and scipy's are compared.
    record_blas : mapping, optional
        The record's ``blas`` entry; its library and version are compared where present, its architecture
        with :data:`COMMITTED`'s where absent.
    simd : list of str, optional
        The record's numpy dispatch targets; :data:`COMMITTED`'s where None.

    Returns
    -------
    list of str
        One ``"<what>: <recorded> there, <live> here"`` line per difference.
    """
    found = []
    for name in ("numpy", "scipy"):
        recorded, here = packages.get(name), _version(name)
        if (None if recorded == "not installed" else recorded) != here:
            found.append(f"{name}: {recorded} there, {here} here")
    live, recorded_blas = blas(), dict(record_blas or {})
    recorded_blas.setdefault("architecture", COMMITTED["blas_architecture"])
    for key in ("library", "version", "architecture"):
        if recorded_blas.get(key) is not None and recorded_blas[key] != live.get(key):
            found.append(f"BLAS {key}: {recorded_blas[key]} there, {live.get(key)} here")
    expected, here_simd = list(COMMITTED["simd"] if simd is None else simd), numpy_simd()
    if here_simd != expected:
        found.append(f"numpy SIMD: {' '.join(expected)} there, {' '.join(here_simd)} here")
    return found


def _version(name: str) -> str | None:
    try:
        return version(name)
    except PackageNotFoundError:
        return None


def _numpy_cpu() -> tuple[list[str], set[str]]:
    """(numpy's dispatch targets on this CPU, the CPU features numpy detects), as a fresh Python process
    without numpy's feature variables sees them (empty if it cannot tell)."""
    unpinned = {k: v for k, v in os.environ.items() if k not in _NUMPY_FEATURE_VARIABLES}
    try:  # this module run as a script (below), before this process imports numpy
        done = subprocess.run(
            [sys.executable, "-m", "benchmarks.numeric_stack"],
            capture_output=True,
            text=True,
            timeout=60,
            check=True,
            cwd=_REPO,
            env=unpinned,
        )
    except (OSError, subprocess.SubprocessError):
        return [], set()
    lines = [*done.stdout.splitlines(), "", ""]
    return lines[0].split(), set(lines[1].split())


if __name__ == "__main__":  # what a fresh process sees (for _numpy_cpu): its targets, then its CPU features
    _dispatch, _features = _cpu_tables()
    print(" ".join(name for name in _dispatch if _features.get(name)))
    print(" ".join(name for name, found in _features.items() if found))
