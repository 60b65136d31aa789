"""``benchmarks/functions/ipop.py``: IPOP's population growth against today's restarts on the contextual
Rastrigin; the committed table is rendered from the committed runs, and a committed run is what the code
computes."""

from __future__ import annotations

import json

import pytest
from helpers import skip_unless_stack_of

from benchmarks.functions import ipop

DOCUMENT = json.loads((ipop.OUT / "ipop.json").read_text(encoding="utf-8"))


def test_the_committed_table_is_rendered_from_the_committed_runs():
    assert (ipop.OUT / "ipop.md").read_text(encoding="utf-8") == ipop.render(DOCUMENT)
    assert {json.dumps(r["options"]) for r in DOCUMENT["runs"]} == {json.dumps(o) for _, o in ipop.VARIANTS}
    assert len(DOCUMENT["runs"]) == 2 * len(DOCUMENT["context_dims"]) * DOCUMENT["seeds"]


@pytest.mark.slow
def test_a_committed_ipop_run_is_what_the_code_computes():
    """The population doubles at each restart (the largest batch 50·2²), and C12 declines the restart
    that 4·E_search would not fit; the run's numbers are the committed ones, bit for bit."""
    skip_unless_stack_of(DOCUMENT["provenance"])
    (committed,) = [r for r in DOCUMENT["runs"] if (r["z"], r["seed"]) == (1, 3) and r["options"]]
    computed = ipop.one_run(1, 3, committed["options"])
    assert {**computed, "cpu_seconds": 0} == {**committed, "cpu_seconds": 0}
    assert computed["largest_batch"] == 200 and computed["restarts"] == 2
