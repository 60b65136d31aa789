"""Suite-wide test set-up: one BLAS thread per test process, on the committed runs' numeric stack.

``python -m pytest`` runs everything (CI runs exactly that). ``python -m pytest -m "not slow"`` is the
development subset: it leaves out the tests marked ``@pytest.mark.slow``, each marked where it is defined
(a whole study, notebook, Ray cluster, killed process, video or long learning run: about a second or more
on a quiet machine). Their behaviour is still covered on every CI run.

The test folders mirror the package (``tests/optimizers/``, ``tests/runner/rundir/``, ...); ``tests/`` is on
pytest's ``pythonpath`` (``pyproject.toml``), so every folder imports ``helpers`` and ``flaky_envs``.
"""

from __future__ import annotations

import atexit
import os
import shutil
import sys
import tempfile

import pytest
from suite_order import DURATIONS, file_of, order_by_durations, write_durations

from benchmarks.numeric_stack import pinned_environment

# One BLAS thread per test process: the suite runs two workers on CI's two cores, and each worker's BLAS
# threads would oversubscribe them (OpenBLAS spins while it waits: c-bo's small Cholesky factorisations ran
# up to 20x slower). Set before numpy is imported (the workers import it with the test modules, after this
# file); subprocesses inherit it. A user's own environment setting is kept.
if "numpy" not in sys.modules:
    for _variable in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(_variable, "1")
    # The committed study runs' numeric stack (OpenBLAS's Haswell kernels, numpy's dispatch up to X86_V3),
    # on any x86-64 CPU with AVX2 and FMA: on an AVX-512 CPU numpy's own loops would take other paths, and
    # the tests that compute a committed run again bit for bit (helpers.skip_unless_stack_of) would
    # compute another run. Elsewhere nothing is set and those tests skip, naming what differs. Set once, in
    # the first process (a worker inherits it); a variable the user set is kept.
    if not {"OPENBLAS_CORETYPE", "NPY_DISABLE_CPU_FEATURES"} <= set(os.environ):
        for _variable, _value in pinned_environment().items():
            os.environ.setdefault(_variable, _value)

# Bytecode for the processes the suite starts (its workers and about 160 test subprocesses). Where
# PYTHONDONTWRITEBYTECODE is set (to keep the source tree free of __pycache__), each of those processes
# compiled every module it imports from source: about 70 s of CPU on a fresh clone. They write their
# bytecode to one temporary folder of this session instead (PYTHONPYCACHEPREFIX, removed at exit), so the
# tree stays clean and each module is compiled once. This process itself keeps the setting it started with.
# Without PYTHONDONTWRITEBYTECODE nothing changes: Python's default caches beside the sources.
if os.environ.get("PYTHONDONTWRITEBYTECODE") and not os.environ.get("PYTHONPYCACHEPREFIX"):
    _pycache = tempfile.mkdtemp(prefix="creps-gym-tests-pycache-")
    atexit.register(shutil.rmtree, _pycache, ignore_errors=True)
    os.environ["PYTHONPYCACHEPREFIX"] = _pycache
    del os.environ["PYTHONDONTWRITEBYTECODE"]


# -- the order test files run in: the longest first (tests/suite_order.py) --------------------------------
_SECONDS: dict[str, float] = {}  # --store-durations: each file's seconds in this run (setup, call, teardown)


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption(
        "--store-durations",
        action="store_true",
        help=f"write each test file's seconds to tests/{DURATIONS.name}, the order the files run in",
    )


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    order_by_durations(items)


def pytest_runtest_logreport(report: pytest.TestReport) -> None:
    _SECONDS[file_of(report.nodeid)] = _SECONDS.get(file_of(report.nodeid), 0.0) + report.duration


def pytest_sessionfinish(session: pytest.Session) -> None:
    if session.config.getoption("store_durations") and not hasattr(session.config, "workerinput"):
        write_durations(_SECONDS)
