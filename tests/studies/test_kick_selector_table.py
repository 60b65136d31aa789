"""The kick study's table of training contexts (issue 32): the study's folder and its ``--contexts`` folders
in one section of ``results/<mode>/summary.md``, rendered from ``results.json`` alone."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

pytest.importorskip("mujoco")

from benchmarks.kick import report, run, selector_table, study

pytestmark = pytest.mark.extras
POINTS = {"precision": 10, "flexibility": 28}


def _write_run(
    folder: Path,
    experiment: str,
    name: str,
    trial: int,
    contexts: str,
    curve: list[Any],
    features: str = "affine",
) -> None:
    """A finished run whose mean policy's metric is ``value`` at every point at each ``[iteration, value]``
    of ``curve``, the last one being its end."""
    samples, points = (20, 10) if experiment == "precision" else (100, 28)
    iterations, final = curve[-1]
    document = {
        "experiment": experiment,
        "name": name,
        "features": features,
        "options": {},
        "trial": trial,
        "samples": samples,
        "budget_iterations": iterations,
        "iterations": iterations,
        "episodes": iterations * samples,
        "stopped": [],
        "setting": {"env": study.ENV_IDS[experiment], "contexts": contexts, "features": features},
        "values": [final] * points,
        "history": {"batch": [], "evaluations": [[i, [v] * points] for i, v in curve]},
    }
    (folder / "runs" / experiment).mkdir(parents=True, exist_ok=True)
    (folder / "runs" / experiment / f"{name}-trial{trial}.json").write_text(json.dumps(document))


@pytest.fixture
def folders(tmp_path: Path) -> Path:
    """``full`` (the study: arcsine precision, uniform flexibility) and ``full-bandit`` beside it."""
    full, bandit = tmp_path / "full", tmp_path / "full-bandit"
    _write_run(full, "precision", "c-cma-es", 0, "arcsine", [[50, 2.0], [100, 0.55], [150, 0.4], [200, 0.5]])
    _write_run(full, "precision", "c-cma-es", 1, "arcsine", [[50, 1.0], [100, 0.8], [150, 0.9], [200, 0.7]])
    _write_run(full, "precision", "creps", 0, "arcsine", [[50, 3.0], [100, 2.0], [150, 2.5], [200, 2.6]])
    _write_run(bandit, "precision", "c-cma-es", 0, "bandit", [[50, 0.55], [100, 0.3], [150, 0.2], [200, 0.3]])
    _write_run(bandit, "precision", "c-cma-es", 1, "bandit", [[50, 0.9], [100, 0.7], [150, 1.2], [200, 0.8]])
    history = {"setting": {"env": study.ENV_IDS["precision"], "contexts": "bandit"}, "batch": [[0, 0]] * 30}
    (bandit / "runs" / "precision" / "c-cma-es-trial2.history.json").write_text(json.dumps(history))
    _write_run(full, "flexibility", "c-cma-es", 0, "uniform", [[50, 3.0], [100, 5.0]])
    _write_run(bandit, "flexibility", "c-cma-es", 0, "bandit", [[50, 6.0], [100, 6.5]])
    _write_run(tmp_path / "full-sobol", "precision", "c-cma-es", 0, "bandit", [[50, 0.1]])  # not a law
    (tmp_path / "full-progress").symlink_to(bandit, target_is_directory=True)  # not followed
    return full


def test_the_section_compares_every_contexts_folder_with_the_study_by_episodes_to_its_final_value(
    folders: Path,
) -> None:
    assert selector_table.comparison_folders(folders) == [folders.parent / "full-bandit"]
    document = report.collect(folders, "full", run.MODES["full"])
    data = document["selectors"]
    assert data["folders"] == ["full", "full-bandit"]
    precision = data["precision"]
    assert precision["reference"] == study.TRAINING["precision"] == "arcsine"
    assert [(r["method"], r["contexts"], r["folder"]) for r in precision["rows"]] == [
        ("c-cma-es", "arcsine", "full"),
        ("c-cma-es", "bandit", "full-bandit"),
    ]  # creps has no --contexts run: no row
    curve = precision["rows"][1]["curves"][0]  # the history's evaluations, then the end
    assert [i for i, _ in curve] == [50, 100, 150, 200]
    assert [v for _, v in curve] == pytest.approx([0.55, 0.3, 0.2, 0.3])
    assert precision["in_progress"] == {"full-bandit": {"c-cma-es-trial2": 30}}
    lines = report.summary_text(document).splitlines()
    start = lines.index("### Precision")
    assert "Resolution: 50 iterations × 20 episodes = 1,000 episodes." in lines[start:]
    assert (
        "Reference (arcsine, the study's training law), final error: c-cma-es 0.60 m (`results/full`)."
        in lines
    )
    # The arcsine mean curve reaches its own final value (0.60 m) at its end; trial 0 alone at 100.
    assert (
        "| c-cma-es | arcsine | affine | `results/full` | 2 | 0.60 ± 0.10 m | 0.50, 0.70 | 4,000 "
        "| 2,000, not reached | 1.00 | 4,000 | 1.00 | — | — |" in lines
    )
    # The bandit's mean curve: 0.725 at 50, 0.50 at 100 (≤ 0.60): 2,000 episodes, half arcsine's 4,000;
    # 0.70 at 150, so it stays at or below 0.60 only from 200 on.
    assert (
        "| c-cma-es | bandit | affine | `results/full-bandit` | 2 | 0.55 ± 0.25 m | 0.30, 0.80 | 2,000 "
        "| 1,000, not reached | 0.50 | 4,000 | 1.00 | — | — |" in lines
    )
    assert any(
        line.startswith("*Uniform draws*: not in these folders;") and "`bd108c5`" in line for line in lines
    )
    assert (
        "In progress in `results/full-bandit` (checkpoint, no result yet): c-cma-es-trial2 (30 iterations)."
        in lines
    )
    flexibility = lines[lines.index("### Flexibility") :]
    assert "Resolution: 50 iterations × 100 episodes = 5,000 episodes." in flexibility
    # A distance is reached from below: the bandit's 6.0 m at iteration 50 is past uniform's 5.00 m.
    assert (
        "| c-cma-es | bandit | affine | `results/full-bandit` | 1 | 6.50 ± 0.00 m | 6.50 | 5,000 | 5,000 "
        "| 0.50 | 5,000 | 0.50 | — | — |" in flexibility
    )
    assert not any(line.startswith("*Uniform draws*") for line in flexibility)  # uniform is flexibility's own


def test_episodes_to_reach_and_to_stay_past_a_target() -> None:
    curve = [[50, 2.0], [100, 0.5], [150, 0.7]]
    assert selector_table.episodes_to_reach(curve, 0.6, 20, lower_is_better=True) == 2000
    assert selector_table.episodes_to_reach(curve, 0.4, 20, lower_is_better=True) is None
    assert selector_table.episodes_to_reach(curve, 0.7, 100, lower_is_better=False) == 5000
    assert selector_table.episodes_to_reach([], 0.7, 100, lower_is_better=False) is None
    # ... and from which it stays past it: none if the last point is not.
    assert selector_table.episodes_to_stay(curve, 0.8, 20, lower_is_better=True) == 2000
    assert selector_table.episodes_to_stay(curve, 0.6, 20, lower_is_better=True) is None
    assert selector_table.episodes_to_stay([[50, 2.0], [100, 0.5], [150, 2.5]], 1.0, 1, False) == 150


@pytest.mark.slow
def test_full_render_only_renders_the_section_when_a_contexts_folder_exists(folders: Path) -> None:
    pytest.importorskip("matplotlib")
    assert run.main(["--full", "--render-only", "--out", str(folders)]) == 0
    document = json.loads((folders / "results.json").read_text())
    assert document["selectors"]["folders"] == ["full", "full-bandit"]
    text = (folders / "summary.md").read_text()
    assert text == report.summary_text(document)
    assert f"## {selector_table.SECTION}" in text
    bandit = folders.parent / "full-bandit"  # rendered again from the same run files, on its own
    assert (bandit / "summary.md").read_text() == report.summary_text(
        json.loads((bandit / "results.json").read_text())
    )
    assert "- precision/c-cma-es-trial2: 30" in (bandit / "summary.md").read_text()
    assert "selectors" not in report.collect(folders.parent / "full-bandit", "full", run.MODES["full"])
    for path in selector_table.comparison_folders(folders):
        path.rename(path.with_name("elsewhere"))
    assert run.main(["--full", "--render-only", "--out", str(folders)]) == 0
    assert selector_table.SECTION not in (folders / "summary.md").read_text()  # none: no section


def test_the_flexibility_targets_table_gives_each_trials_peak_its_drop_and_the_oracle_fractions(
    folders: Path,
) -> None:
    document = report.collect(folders, "full", run.MODES["full"])
    assert document["selectors"]["flexibility"]["oracle_mean"] is None  # the fixture has no oracle runs
    lines = report.summary_text(document).splitlines()
    assert any(line.startswith("Flexibility targets") and "Oracle: incomplete" in line for line in lines)
    # uniform's curve 3.0, 5.0 peaks at its end; the bandit's 6.0, 6.5 too: no drop, no fraction.
    assert "| c-cma-es | bandit | affine | 1 | 6.50 ± 0.00 m | 6.50 | 0.00 | 0.00 m | — | — |" in lines
    rows = [
        {
            "method": "c-cma-es",
            "contexts": "bandit",
            "features": "rbf",
            "finals": [5.0, 7.0, 6.0],
            "curves": [[[50, 6.5], [100, 5.0]], [[50, 4.0], [100, 7.0]], [[50, 8.0], [100, 6.0]]],
        },
    ]
    table = selector_table.peak_table({"rows": rows, "oracle_mean": 10.0})
    assert "Oracle: 10.00 m averaged over the grid." in table[0]
    # peaks 6.5, 7.0, 8.0; drops 1.5, 0.0, 2.0; final mean 6.0 (0.60 of 10 m), best peak 8.0 (0.80).
    assert (
        "| c-cma-es | bandit | rbf | 3 | 6.00 ± 0.82 m | 6.50, 7.00, 8.00 | 1.50, 0.00, 2.00 | 2.00 m "
        "| 0.60 | 0.80 |" in table
    )


def test_a_selector_is_measured_against_uniform_draws_with_its_own_mean_features() -> None:
    def row(contexts: str, features: str, folder: str, finals: list[float], curves: list) -> dict:
        return {
            "method": "creps-cma-old",
            "contexts": contexts,
            "features": features,
            "folder": folder,
            "samples": 100,
            "budget_iterations": 700,
            "finals": finals,
            "curves": curves,
        }

    rows = [
        row("uniform", "rbf", "full", [4.0], [[[50, 2.0], [700, 4.0]]]),
        row("uniform", "quadratic", "full-features-quadratic", [7.0, 8.0], [[[700, 7.0]], [[700, 8.0]]]),
        # mean curve 6.0, 7.5, 7.0, 8.0: first reaches 7.5 m at iteration 100, stays from iteration 200 on.
        row(
            "bandit",
            "quadratic",
            "full-bandit-features-quadratic",
            [8.5, 7.5],
            [
                [[50, 6.0], [100, 8.0], [150, 7.0], [200, 8.0]],
                [[50, 6.0], [100, 7.0], [150, 7.0], [200, 8.0]],
            ],
        ),
        row("bandit", "affine", "full-bandit", [5.0], [[[50, 5.0]]]),  # no uniform affine row: left out
    ]
    table = selector_table.same_features_table("flexibility", {"rows": rows})
    body = [line for line in table if line.startswith("| creps-cma-old")]
    assert body == [
        "| creps-cma-old | bandit | quadratic | `results/full-bandit-features-quadratic` "
        "| 7.50 m (`results/full-features-quadratic`) | 8.00 m | 10,000 | 0.14 | 20,000 | 0.29 |"
    ]
    rows[2]["curves"] = [[[50, 6.0], [700, 7.0]], [[50, 6.0], [700, 7.0]]]  # never reaches 7.5 m
    table = selector_table.same_features_table("flexibility", {"rows": rows})
    body = [line for line in table if "bandit" in line]
    assert body[0].endswith("| not reached | — | not reached | — |")
    assert selector_table.same_features_table("flexibility", {"rows": rows[:2]}) == []  # no selector row


def test_bandit_cells_sums_the_discounted_counts_and_rewards_per_x_row(tmp_path: Path, capsys) -> None:
    from benchmarks.kick import bandit_cells

    counts = [1.0, 1.0, 0.0, 2.0] + [1.0] * 4 + [2.0] * 4 + [0.0] * 4  # row-major (x_B, y_B) cells
    sums = [0.5, 0.5, 0.0, 1.0] + [0.1] * 4 + [0.4] * 4 + [0.0] * 4
    shares, rewards = bandit_cells.row_shares({"counts": counts, "sums": sums})
    assert shares.tolist() == pytest.approx([4 / 16, 4 / 16, 8 / 16, 0.0])
    assert rewards[:3].tolist() == pytest.approx([0.5, 0.1, 0.2]) and np.isnan(rewards[3])
    with pytest.raises(ValueError, match="expected positive episode counts"):
        bandit_cells.row_shares({"counts": [0.0] * 16, "sums": [0.0] * 16})
    runs = tmp_path / "runs" / "flexibility"
    runs.mkdir(parents=True)
    state = {"counts": counts, "sums": sums}
    (runs / "c-cma-es-trial0.selector.json").write_text(json.dumps({"690": state, "700": state}))
    (runs / "c-cma-es-trial0.json").write_text("{}")  # finished
    (runs / "c-cma-es-trial1.selector.json").write_text(json.dumps({"10": state}))  # in progress: left out
    assert bandit_cells.main(["--folder", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert (
        "c-cma-es-trial0 at iteration 700: shares 0.25, 0.25, 0.50, 0.00; mean reward 0.5, 0.1, 0.2, nan"
        in out
    )
    assert "trial1" not in out


def test_features_folders_join_the_comparison_with_their_features_named(folders: Path) -> None:
    quadratic, rbf = folders.parent / "full-features-quadratic", folders.parent / "full-bandit-features-rbf"
    _write_run(quadratic, "flexibility", "c-cma-es", 0, "uniform", [[50, 4.0], [100, 7.0]], "quadratic")
    _write_run(rbf, "flexibility", "c-cma-es", 0, "bandit", [[50, 2.0], [100, 4.0]], "rbf")
    assert selector_table.comparison_folders(folders) == [folders.parent / "full-bandit", quadratic, rbf]
    data = report.collect(folders, "full", run.MODES["full"])["selectors"]
    assert data["folders"] == ["full", "full-bandit", "full-features-quadratic", "full-bandit-features-rbf"]
    assert [(r["contexts"], r["features"], r["folder"]) for r in data["flexibility"]["rows"]] == [
        ("uniform", "affine", "full"),  # the reference: the study's own folder comes first
        ("uniform", "quadratic", "full-features-quadratic"),
        ("bandit", "affine", "full-bandit"),
        ("bandit", "rbf", "full-bandit-features-rbf"),
    ]
    lines = report.summary_text(report.collect(folders, "full", run.MODES["full"])).splitlines()
    # The quadratic curve passes the affine reference's 5.00 m at iteration 100 (10,000 episodes, the
    # reference's whole budget of 100 x 100); the RBF one never does.
    assert (
        "| c-cma-es | uniform | quadratic | `results/full-features-quadratic` | 1 | 7.00 ± 0.00 m | 7.00 "
        "| 10,000 | 10,000 | 1.00 | 10,000 | 1.00 | — | — |" in lines
    )
    assert (
        "| c-cma-es | bandit | rbf | `results/full-bandit-features-rbf` | 1 | 4.00 ± 0.00 m | 4.00 "
        "| not reached | not reached | — | not reached | — | — | — |" in lines
    )
    assert "| c-cma-es | uniform | quadratic | 1 | 7.00 ± 0.00 m | 7.00 | 0.00 | 0.00 m | — | — |" in lines


def test_only_the_study_folders_row_is_a_reference(folders: Path) -> None:
    # A features folder's uniform row is compared with the study's, never used as the reference itself.
    (folders / "runs" / "flexibility" / "c-cma-es-trial0.json").unlink()
    quadratic = folders.parent / "full-features-quadratic"
    _write_run(quadratic, "flexibility", "c-cma-es", 0, "uniform", [[50, 4.0], [100, 7.0]], "quadratic")
    lines = report.summary_text(report.collect(folders, "full", run.MODES["full"])).splitlines()
    flexibility = lines[lines.index("### Flexibility") :]
    assert not any(line.startswith("Reference (uniform") for line in flexibility)
    assert (
        "| c-cma-es | uniform | quadratic | `results/full-features-quadratic` | 1 | 7.00 ± 0.00 m | 7.00 "
        "| — (no reference run) | — | — | — | — | — | — |" in flexibility
    )
