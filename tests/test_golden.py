"""Golden numbers at seed 0 (regenerate with ``python scripts/regenerate_golden.py``)."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

SCRIPT = Path(__file__).resolve().parent.parent / "scripts" / "regenerate_golden.py"
spec = importlib.util.spec_from_file_location("regenerate_golden", SCRIPT)
regenerate_golden = importlib.util.module_from_spec(spec)
spec.loader.exec_module(regenerate_golden)

EXPECTED = json.loads(regenerate_golden.GOLDEN_PATH.read_text())
ACTUAL = regenerate_golden.golden_numbers()


@pytest.mark.parametrize("name", sorted(regenerate_golden.FACTORIES))
@pytest.mark.parametrize("quantity", ["first_ask", "mean_at_1_2", "cov_diagonal", "eta", "ess"])
def test_golden_numbers(name, quantity):
    # rtol allows for BLAS differences between machines, far below any algorithmic change.
    np.testing.assert_allclose(ACTUAL[name][quantity], EXPECTED[name][quantity], rtol=1e-7)


def test_golden_numbers_differ_between_optimizers():
    assert EXPECTED["creps"]["cov_diagonal"] != EXPECTED["creps-cma-old"]["cov_diagonal"]
    assert EXPECTED["creps-cma-old"]["mean_at_1_2"] != EXPECTED["creps-cma-current"]["mean_at_1_2"]
