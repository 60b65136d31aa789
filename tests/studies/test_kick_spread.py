"""Why a kick run settles or not (issue 32, ``benchmarks/kick/spread.py``): the late fall rate and the final
search spread of each run, gathered into ``results.json`` and rendered in the study's and the selectors'
tables."""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from benchmarks.kick import report, run, selector_table, spread, study
from creps_gym.optimizers.registry import make_optimizer
from creps_gym.optimizers.state_files import load_state, save_state


def test_the_late_fall_rate_averages_the_last_batches_or_all_of_them() -> None:
    batch = [[-9.0, 1.0]] * 50 + [[-1.0, 0.25]] * 150 + [[-1.0, 0.75]] * 50  # 250 batches
    assert spread.late_fall_rate(batch) == (150 * 0.25 + 50 * 0.75) / 200  # the first 50 are left out
    assert spread.late_fall_rate(batch, last=50) == 0.75
    assert spread.late_fall_rate([[0.0, 0.5], [0.0, 0.0]]) == 0.25  # fewer than 200: all of them
    assert spread.late_fall_rate([]) is None
    for bad in ([[0.0, 1.5]], [[0.0, float("nan")]], [[0.0]], [[0.0, -0.1]]):
        with pytest.raises(ValueError, match="batch: expected"):
            spread.late_fall_rate(bad)
    with pytest.raises(ValueError, match="last: expected a positive int, got 0"):
        spread.late_fall_rate(batch, last=0)


def test_the_final_spread_is_the_step_size_times_the_rms_standard_deviation(tmp_path: Path) -> None:
    path = tmp_path / "c-cma-es-trial0.npz"
    save_state({"cov": np.diag([9.0, 0.0, 3.0, 4.0]), "step_size": 0.5, "iteration": 7}, path)
    assert spread.final_spread(path, 7) == 1.0  # 0.5 · √((9 + 0 + 3 + 4) / 4)
    assert spread.final_spread(path, 8) is None  # a checkpoint of another iteration is not the final one
    save_state({"cov": np.diag([9.0, 0.0, 3.0, 4.0]), "iteration": 7}, path)
    assert spread.final_spread(path, 7) == 2.0  # no step size: σ = 1
    assert spread.final_spread(tmp_path / "creps-trial0.npz", 7) is None  # no checkpoint


@pytest.mark.parametrize("name", ["c-cma-es", "creps-cma-old"])
def test_the_final_spread_of_a_real_checkpoint_is_its_policys(name: str, tmp_path: Path) -> None:
    optimizer = make_optimizer(name, 4, 1, seed=0, initial_cov=0.25)
    rng = np.random.default_rng(0)
    for _ in range(5):
        contexts = rng.uniform(3.0, 12.0, size=(12, 1))
        params = optimizer.ask(contexts)
        optimizer.tell(contexts, params, -np.sum(params**2, axis=1))
    optimizer.save(tmp_path / "run.npz")
    expected = np.sqrt(np.mean(np.diag(optimizer.policy.covariance)))
    assert spread.final_spread(tmp_path / "run.npz", 5) == pytest.approx(expected, rel=1e-12)
    assert abs(expected - 0.5) > 1e-3  # it moved from the start, √0.25


def test_a_checkpoint_that_is_a_link_too_large_or_not_one_is_refused(tmp_path: Path, monkeypatch) -> None:
    good = tmp_path / "good.npz"
    save_state({"cov": np.eye(2), "step_size": 1.0, "iteration": 1}, good)
    link = tmp_path / "link.npz"
    link.symlink_to(good)
    with pytest.raises(ValueError, match="checkpoint: expected a regular file"):
        spread.final_spread(link, 1)  # never followed
    bad = tmp_path / "bad.npz"
    np.savez(bad, cov=np.eye(2))  # no state document
    with pytest.raises(ValueError, match=re.escape(f"checkpoint {bad}")):
        spread.final_spread(bad, 1)
    save_state({"cov": np.ones(3), "iteration": 1}, bad)
    with pytest.raises(ValueError, match="expected a square 'cov'"):
        spread.final_spread(bad, 1)
    save_state({"cov": np.eye(2), "step_size": -1.0, "iteration": 1}, bad)
    with pytest.raises(ValueError, match=r"expected a positive 'step_size', got -1\.0"):
        spread.final_spread(bad, 1)
    monkeypatch.setattr(spread, "MAX_CHECKPOINT_BYTES", good.stat().st_size - 1)
    with pytest.raises(ValueError, match="expected at most"):
        spread.final_spread(good, 1)


def _run(
    folder: Path, name: str, trial: int, falls: list[float], cov: Any, contexts: str = "arcsine"
) -> None:
    """A finished precision run of 3 iterations whose batches fell at ``falls``, with a final checkpoint
    of ``cov`` (none if None)."""
    document = {
        "experiment": "precision",
        "name": name,
        "features": "affine",
        "options": {},
        "trial": trial,
        "samples": 20,
        "budget_iterations": 3,
        "iterations": 3,
        "episodes": 60,
        "stopped": [],
        "setting": {"env": study.ENV_IDS["precision"], "contexts": contexts},
        "values": [1.0] * 10,
        "history": {"batch": [[-1.0, f] for f in falls], "evaluations": [[3, [1.0] * 10]]},
    }
    (folder / "runs" / "precision").mkdir(parents=True, exist_ok=True)
    (folder / "runs" / "precision" / f"{name}-trial{trial}.json").write_text(json.dumps(document))
    if cov is not None:
        save_state({"cov": cov, "iteration": 3}, folder / "runs" / "precision" / f"{name}-trial{trial}.npz")


def test_the_tables_render_both_quantities_across_trials_and_a_missing_checkpoint(tmp_path: Path) -> None:
    full, bandit = tmp_path / "full", tmp_path / "full-bandit"
    _run(full, "creps-cma-old", 0, [0.5, 0.25, 0.0], np.eye(4))  # falls 0.25, spread 1
    _run(full, "creps-cma-old", 1, [0.5, 0.5, 0.5], 9.0 * np.eye(4))  # falls 0.5, spread 3
    _run(full, "c-cma-es", 0, [0.0, 0.0, 0.0], None)  # no checkpoint
    _run(full, "c-cma-es", 1, [0.0, 0.0, 0.25], 0.01 * np.eye(4))
    _run(bandit, "creps-cma-old", 0, [0.75, 0.75, 0.75], 4.0 * np.eye(4), contexts="bandit")
    document = report.collect(full, "full", run.MODES["full"])
    entry = document["precision"]["creps-cma-old"]
    assert entry["late_fall_rate"] == [0.25, 0.5] and entry["final_spread"] == [1.0, 3.0]
    assert document["precision"]["c-cma-es"]["final_spread"] == [None, 0.1]
    text = report.summary_text(json.loads(json.dumps(document)))  # as read back from results.json
    header = "| stopped by | falls, last 200 it. | final spread (σ units) |"
    assert header in text
    assert "| 3–3 | — | 0.38 ± 0.12 | 2.00 ± 1.00 |" in text  # creps-cma-old
    assert "| 3–3 | — | 0.04 ± 0.04 | 0.10 ± 0.00 (1 of 2) |" in text  # c-cma-es: one checkpoint missing
    rows = document["selectors"]["precision"]["rows"]
    assert [(r["contexts"], r["late_fall_rate"], r["final_spread"]) for r in rows] == [
        ("arcsine", [0.25, 0.5], [1.0, 3.0]),
        ("bandit", [0.75], [2.0]),
    ]
    section = "\n".join(selector_table.comparison_section(document["selectors"], "full"))
    assert f"episodes | {spread.COLUMNS} |" in section
    assert "| 0.38 ± 0.12 | 2.00 ± 1.00 |\n" in section and "| 0.75 ± 0.00 | 2.00 ± 0.00 |\n" in section


def test_mean_and_std_says_how_many_trials_have_a_value() -> None:
    assert spread.mean_and_std([0.25, 0.75]) == "0.50 ± 0.25"
    assert spread.mean_and_std([None, 1.0, 3.0]) == "2.00 ± 1.00 (2 of 3)"
    assert spread.mean_and_std([None]) == "—"


def test_the_readme_s_reason_holds_for_the_committed_precision_runs() -> None:
    """Each statement of the README's section "CREPS-CMA-old and the 0.34 m target", on the committed data."""
    folder = Path(run.__file__).resolve().parent
    readme = (folder / "README.md").read_text(encoding="utf-8")
    section = readme.split("## CREPS-CMA-old and the 0.34 m target", 1)[1].split("\n## ", 1)[0]
    words = " ".join(section.split())  # the columns it points at, as the summary names them
    assert all(f"*{column}*" in words for column in spread.COLUMNS.split(" | "))
    document = json.loads((folder / "results" / "full" / "results.json").read_text())
    old, cma = document["precision"]["creps-cma-old"], document["precision"]["c-cma-es"]
    target = float(report.PAPER["precision"].split()[0])
    assert target == 0.34 and len(old["trials"]) >= 3
    # The spread: every trial starts at 1.00; C-CMA-ES's ends narrower, CREPS-CMA-old's wider.
    assert max(cma["final_spread"]) < 1.0 < min(old["final_spread"])
    runs = folder / "results" / "full" / "runs" / "precision"
    for trial in cma["trials"]:
        assert np.all(np.diag(load_state(runs / f"c-cma-es-trial{trial}.npz")["initial_cov"]) == 1.0)
    for trial in old["trials"]:
        state = load_state(runs / f"creps-cma-old-trial{trial}.npz")
        assert np.all(np.diag(state["initial_cov"]) == 1.0) and state["step_size"] == 1.0  # no step size
        config, diagnostics = state["config"], state["diagnostics"]
        assert config["epsilon"] == 0.5 and config["divide_by_z"] and config["variant"] == "old"
        assert diagnostics["interpolation"] < 0.05  # a small blend: λ of Eq. (14)
        assert diagnostics["ess"] >= old["samples"] / 4  # the weights keep many of the batch's samples
    # The falls: every CREPS-CMA-old trial's late fall rate is above every C-CMA-ES trial's.
    assert min(old["late_fall_rate"]) > max(cma["late_fall_rate"])
    # The mean: over the second half of each trial it swings by more than the target and never meets it.
    for curve in old["curves"]:
        late = [value for iteration, value in curve if iteration >= old["budget_iterations"] // 2]
        assert len(late) >= 10 and max(late) - min(late) > target and min(late) > target
