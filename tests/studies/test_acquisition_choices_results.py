"""Both acquisitions' choices from the same c-bo state (benchmarks/low_budget/acquisition_choices.py): a
replayed run is the low-budget study's run bit for bit, measuring the choices changes nothing, and the
committed table is the rendering of the committed JSON."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from helpers import EXTRAS, driven_cbo, skip_unless_stack_of

from benchmarks.low_budget import acquisition_choices, recommenders

RESULTS = Path(__file__).resolve().parents[2] / "benchmarks" / "low_budget" / "results"


@pytest.mark.slow
@EXTRAS  # bit for bit only on the stack that computed the study's run (the full environment)
def test_a_replayed_run_is_the_study_run_and_records_both_choices():
    """Rosenbrock p = 2, z = 1, seed 0, to 50 episodes: the value at 50 is the committed study run's bit for
    bit (so computing both proposals before each batch changed nothing), one record per batch after the
    initial design (6 episodes: batches at 8, 12, ..., 44)."""
    study_run = json.loads((recommenders.RUNS / "Rosenbrock-p2-z1-c-bo-s0-b500-n4.json").read_text())
    skip_unless_stack_of(study_run["provenance"])
    run = acquisition_choices.one_run("Rosenbrock-p2-z1", 0, 50)
    assert recommenders.check_against_study(run) is True
    asks = np.array(run["asks"])
    assert asks.shape == (10, 6) and asks[:, 0].tolist() == list(range(8, 48, 4))
    assert (asks[:, 1] >= 0).all() and (asks[:, 1] <= 1).all() and (asks[:, 4:] > 0).all()


def test_proposals_leave_the_optimisers_configuration_and_generator_as_they_were():
    optimizer = driven_cbo()
    config, state = optimizer.config, optimizer.rng.bit_generator.state
    chosen = acquisition_choices.proposals(optimizer, np.array([0.5]))
    assert optimizer.config is config and optimizer.rng.bit_generator.state == state
    assert set(chosen) == {"mes", "ucb"} and all(((u >= 0) & (u <= 1)).all() for u in chosen.values())
    again = acquisition_choices.proposals(optimizer, np.array([0.5]))  # the same state: the same choices
    assert all(np.array_equal(chosen[a], again[a]) for a in chosen)


def test_the_committed_table_is_the_rendering_of_the_committed_results(tmp_path):
    copy = tmp_path / "acquisition_choices.json"
    shutil.copy(RESULTS / "acquisition_choices.json", copy)
    expected = (RESULTS / "acquisition_choices.md").read_text(encoding="utf-8")
    assert acquisition_choices.render(copy) == expected
    assert "bit for bit in 50 of 50 runs" in expected  # every committed run is the study's
