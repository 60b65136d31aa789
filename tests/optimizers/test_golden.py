"""Golden numbers at seed 0 (regenerate with ``python scripts/regenerate_golden.py``)."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

SCRIPT = Path(__file__).resolve().parents[2] / "scripts" / "regenerate_golden.py"
spec = importlib.util.spec_from_file_location("regenerate_golden", SCRIPT)
regenerate_golden = importlib.util.module_from_spec(spec)
spec.loader.exec_module(regenerate_golden)

EXPECTED = json.loads(regenerate_golden.GOLDEN_PATH.read_text())


@pytest.fixture(scope="module")
def actual():
    return regenerate_golden.golden_numbers()


@pytest.mark.parametrize("name", sorted(regenerate_golden.FACTORIES))
@pytest.mark.parametrize("quantity", ["first_ask", "mean_at_1_2", "cov_diagonal", "eta", "ess"])
def test_golden_numbers(actual, name, quantity):
    # rtol allows for BLAS differences between machines, far below any algorithmic change.
    np.testing.assert_allclose(actual[name][quantity], EXPECTED[name][quantity], rtol=1e-7)


def test_the_three_optimizers_really_differ(actual):
    """Guards against the golden file recording one optimiser three times."""
    assert actual["creps"]["cov_diagonal"] != actual["creps-cma-old"]["cov_diagonal"]
    assert actual["creps-cma-old"]["mean_at_1_2"] != actual["creps-cma-current"]["mean_at_1_2"]
