"""Suite-wide test set-up: one BLAS thread per test process, and the ``slow`` marker for the development
subset.

``python -m pytest`` runs everything (CI runs exactly that). ``python -m pytest -m "not slow"`` is the
development subset: it leaves out the tests marked ``@pytest.mark.slow`` and every test of the modules below,
which run whole studies, notebooks, Ray clusters, killed processes or recorded videos. Their behaviour is
still covered on every CI run.
"""

from __future__ import annotations

import os
import sys

import pytest

# One BLAS thread per test process: the suite runs two workers on CI's two cores, and each worker's BLAS
# threads would oversubscribe them (OpenBLAS spins while it waits: c-bo's small Cholesky factorisations ran
# up to 20x slower). Set before numpy is imported (the workers import it with the test modules, after this
# file); subprocesses inherit it. A user's own environment setting is kept.
if "numpy" not in sys.modules:
    for _variable in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(_variable, "1")

#: Test modules whose every test is slow: they run a study's scripts, notebooks, Ray, killed processes or
#: MuJoCo videos.
SLOW_MODULES = frozenset(
    {
        "test_benchmark_scripts.py",
        "test_contexts_study.py",
        "test_contextual_bbo_study.py",
        "test_kick_study.py",
        "test_kick_selector_table.py",
        "test_notebooks.py",
        "test_ray_backend.py",
        "test_ray_cleanup.py",
        "test_ray_cluster.py",
        "test_resume.py",
        "test_restart_defaults.py",
        "test_restart_portfolio_study.py",
        "test_study_provenance.py",
        "test_video.py",
    }
)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    for item in items:
        if item.path.name in SLOW_MODULES:
            item.add_marker(pytest.mark.slow)
