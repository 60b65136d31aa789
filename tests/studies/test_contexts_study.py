"""The context selection study (``benchmarks/contexts``): its tasks, its summary, and that the committed
tables and docs/contexts.md are what the committed code renders from the committed results."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
from helpers import EXTRAS, python_blocks, skip_unless_stack_of

from benchmarks.contexts import report, run
from benchmarks.contexts.tasks import SteepFunction

ROOT = Path(__file__).resolve().parents[2]

RESULTS = Path(run.__file__).resolve().parent / "results"


@pytest.mark.parametrize("mode", ["quick", "full"])
def test_the_committed_tables_and_doc_are_rendered_from_the_committed_results(mode):
    document = json.loads((RESULTS / f"{mode}.json").read_text())
    assert (RESULTS / f"{mode}.md").read_text() == report.render(document)
    assert document["budgets"] == json.loads(json.dumps(run.MODES[mode]))  # the code's budgets
    keys = {
        f"{t}/{o}/{s}/{k}"
        for t in run.MODES[mode]
        if t != "trials"
        for o in run.OPTIMIZERS
        for s in run.SELECTORS
        for k in range(run.MODES[mode]["trials"])
    }
    assert set(document["runs"]) == keys and document["budgets"]["trials"] >= 3
    if mode == "full":
        text = run.DOC.read_text()
        assert report.with_headline(text, document) == text


def test_the_summary_counts_episodes_to_uniforms_final_loss():
    curve = {"episodes": [10, 20, 30, 40], "budget": [4, 10], "seconds": 0.0}
    document = {"runs": {}}
    for trial, (u, b) in enumerate(
        [([9, 6, 5, 4], [9, 4, 2, 1]), ([8, 7, 6, 5], [8, 5, 3, 2]), ([9, 8, 7, 6], [9, 6, 4, 3])]
    ):
        document["runs"][f"t/o/uniform/{trial}"] = {**curve, "loss": u}
        document["runs"][f"t/o/bandit/{trial}"] = {**curve, "loss": b}
    rows = {row["selector"]: row for row in report.summary(document, "t", "o", ["uniform", "bandit"])}
    assert rows["uniform"]["target"] == 5.0  # the median of uniform's final losses
    assert rows["uniform"]["episodes_to_target"] == 40 and rows["uniform"]["ratio"] == 1.0  # median curve
    assert rows["bandit"]["episodes_to_target"] == 20 and rows["bandit"]["ratio"] == 0.5
    assert rows["bandit"]["trials_reaching"] == 3 and rows["bandit"]["trial_episodes_mean"] == pytest.approx(
        70 / 3
    )
    assert rows["uniform"]["trials_reaching"] == 2  # trial 2 ends at 6 > 5
    assert report.first_at_or_below([1, 2], [3.0, 2.0], 1.0) is None


def test_a_steep_function_is_the_function_scaled_by_the_context():
    env = SteepFunction("Sphere", dim=3)
    ends = np.array([[0.0], [3.0]])
    assert env.weight(ends).tolist() == [1.0, 100.0]
    params = np.ones((2, 3))
    assert (env.regret(ends, params) == env.weight(ends) * env.model.regret(ends, params)).all()
    assert (env.evaluate(ends, params)[0] == -env.regret(ends, params)).all()
    assert (env.regret(ends, env.optimal_params(ends)) == 0).all()
    with pytest.raises(ValueError, match="steepness: expected a number >= 1"):
        SteepFunction("Sphere", steepness=0.5)


def test_the_doc_example_runs():
    for block in python_blocks(run.DOC):
        exec(compile(block, "docs/contexts.md", "exec"), {})


@EXTRAS  # bit for bit only on the stack that computed it (the full environment), not the lowest versions
@pytest.mark.parametrize(
    "key",
    [
        "steep-sphere/c-cma-es/bandit/1",
        "reacher/creps-cma-old/progress/0",
        "steep-rosenbrock/c-cma-es-cm0.5/bandit/0",
    ],
)
def test_a_committed_quick_run_is_what_the_code_computes(key):
    document = json.loads((RESULTS / "quick.json").read_text())
    skip_unless_stack_of({"packages": document["versions"]})  # its versions only (no BLAS entry)
    committed = document["runs"][key]
    task, optimizer, selector, trial = key.split("/")
    computed = run.one_run(task, optimizer, selector, int(trial), "quick")
    assert {**computed, "seconds": 0} == {**committed, "seconds": 0}


def test_the_damped_c_cma_es_is_c_cma_es_with_c_m_one_half():
    assert run.OPTIMIZERS["c-cma-es-cm0.5"] == ("c-cma-es", {"c_m": 0.5, "ridge_centre": "zero"})
    assert run.OPTIMIZERS["c-cma-es"] == ("c-cma-es", {"ridge_centre": "zero"})  # C3, as computed
    runs = json.loads((RESULTS / "quick.json").read_text())["runs"]
    for key in ("steep-rosenbrock/{}/bandit/0", "steep-sphere/{}/uniform/1"):  # same seed, other c_m
        assert runs[key.format("c-cma-es-cm0.5")]["loss"] != runs[key.format("c-cma-es")]["loss"]


def test_the_kick_figures_quoted_in_the_contexts_doc_are_the_kick_summarys():
    """Every "a ± b" of docs/contexts.md's kick paragraph is a cell the kick study rendered."""
    doc = (ROOT / "docs" / "contexts.md").read_text(encoding="utf-8")
    kick = doc[doc.index("**The kick's precision task**") :]
    summary = (ROOT / "benchmarks" / "kick" / "results" / "full" / "summary.md").read_text(encoding="utf-8")
    quoted = re.findall(r"\d+\.\d+ ± \d+\.\d+", kick)
    assert len(quoted) >= 8
    assert [figure for figure in quoted if figure not in summary] == []


@pytest.mark.slow
def test_the_difficulty_probe_measures_cells_and_its_committed_table_and_doc_figures_are_its_own():
    from benchmarks.contexts import difficulty_probe as probe

    contexts = probe.grid(np.zeros(2), np.full(2, 2.0), 4)  # cell centres 0.25, 0.75, 1.25, 1.75
    assert contexts.shape == (16, 2) and np.allclose(contexts[:4, 1], [0.25, 0.75, 1.25, 1.75])
    losses = np.where((contexts[:, 0] < 1) & (contexts[:, 1] < 1), 4.0, 1.0)  # one hard quadrant
    per_cell = probe.cell_losses(contexts, losses, np.zeros(2), np.full(2, 2.0), 2)
    assert per_cell.tolist() == [4.0, 1.0, 1.0, 1.0]
    assert probe.unevenness(per_cell) == {"worst_over_median": 4.0, "worst_quarter_share": 4.0 / 7.0}
    assert probe.unevenness(np.ones(8))["worst_quarter_share"] == 0.25  # even: a quarter's share
    with pytest.raises(ValueError, match="per_cell"):
        probe.unevenness(np.array([1.0, -1.0]))
    with pytest.raises(ValueError, match="positive median"):
        probe.unevenness(np.array([0.0, 0.0, 1.0]))
    with pytest.raises(ValueError, match="empty cells"):
        probe.cell_losses(contexts[:1], losses[:1], np.zeros(2), np.full(2, 2.0), 2)
    document = json.loads(probe.PATH.read_text())
    assert probe.TABLE.read_text() == probe.render(document)
    assert {"versions", "cpu"} <= set(document) and len(document["trials"]) >= 3
    # One committed run computed again: bit-identical on the same stack; CI's lowest numpy differs in the
    # last bits, hence the relative tolerance.
    committed = document["runs"]["steep-sphere/c-cma-es/0"]
    again = probe.one_probe("steep-sphere", "c-cma-es", 0)
    assert again["worst_cell"] == committed["worst_cell"]
    for key in ("per_cell", "worst_over_median", "worst_quarter_share"):
        assert again[key] == pytest.approx(committed[key], rel=1e-9, abs=0.0)
    doc = run.DOC.read_text(encoding="utf-8")
    start = doc.index("**Where uniform training leaves its loss**")
    paragraph = doc[start : doc.index("\n- **", start)]
    table = probe.TABLE.read_text()
    assert [x for x in re.findall(r"\d\.\d\d", paragraph) if x not in table] == []
    readme = (ROOT / "benchmarks" / "README.md").read_text(encoding="utf-8")
    quoted = readme[readme.index("difficulty_probe.py") : readme.index("medians over 5 trials")]
    assert [x for x in re.findall(r"\d\.\d\d", quoted) if x not in table] == []
    worst = {key: tuple(r["worst_cell"]) for key, r in document["runs"].items()}
    steep_end = sum(cell == (3,) for key, cell in worst.items() if key.startswith("steep-"))
    reacher = [cell for key, cell in worst.items() if key.startswith("reacher/")]
    assert f"in {steep_end} of 20 runs" in paragraph
    assert f"((0, 0) in {reacher.count((0, 0))} of 10 runs, (3, 3) in {reacher.count((3, 3))})" in paragraph
