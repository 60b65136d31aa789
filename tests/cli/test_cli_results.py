"""Results you can read (issue 31, item 6): groups by setting, ``--label``, legends that cover no curve,
and ``creps-gym list``'s exact boxes."""

from __future__ import annotations

import csv

import gymnasium as gym
import numpy as np
import pytest
from helpers import EXTRAS, SPHERE, cli_in_process

from creps_gym.cli import main
from creps_gym.listing import available_env_rows, box_text
from creps_gym.runner import run
from creps_gym.runner.results.groups import group_runs, load_runs
from creps_gym.runner.results.plots import plot_run_dirs

SMALL = {"eval_every": 1, "eval_contexts": 4, "env_kwargs": {"dim": 3}}


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """Sphere p = 3: two seeds at N = 10, two at N = 12, one with epsilon = 0.8; one run on p = 4."""
    root = tmp_path_factory.mktemp("settings")
    settings = [
        ("n8-0", 0, 10, {}),
        ("n8-1", 1, 10, {}),
        ("n12-0", 0, 12, {}),
        ("n12-1", 1, 12, {}),
        ("eps-0", 0, 10, {"epsilon": 0.8}),
    ]
    for name, seed, samples, options in settings:
        run(
            "creps-cma-old", SPHERE, 5, samples, seed, run_dir=root / name, optimizer_options=options, **SMALL
        )
    run("c-cma-es", SPHERE, 5, 10, 0, run_dir=root / "p4", **{**SMALL, "env_kwargs": {"dim": 4}})
    return root


def _paths(root, *names):
    return [str(root / name) for name in names]


def test_runs_are_grouped_by_their_whole_setting_not_by_optimiser(runs):
    groups, labels = group_runs(load_runs(_paths(runs, "n8-0", "n12-0", "n8-1", "eps-0", "n12-1")))
    assert list(groups) == [
        "creps-cma-old, epsilon=default, samples=10",
        "creps-cma-old, epsilon=default, samples=12",
        "creps-cma-old, epsilon=0.8, samples=10",
    ]
    assert [len(histories) for histories in groups.values()] == [2, 2, 1]
    assert labels[0] == labels[2] and labels[1] == labels[4]


def test_labels_are_given_per_run_directory_or_per_group(runs, tmp_path, capsys):
    paths = _paths(runs, "n8-0", "n12-0", "n8-1", "n12-1")
    groups, _ = group_runs(load_runs(paths), ["small", "large"])  # one per group, in first-run order
    assert {label: len(h) for label, h in groups.items()} == {"small": 2, "large": 2}
    groups, _ = group_runs(load_runs(paths), ["all", "all", "all", "all"])  # one per run: pooled on purpose
    assert {label: len(h) for label, h in groups.items()} == {"all": 4}
    out = tmp_path / "labelled.csv"
    assert main(["export", *paths, "-o", str(out), "--label", "N=8", "--label", "N=12"]) == 0
    with open(out, newline="") as file:
        ids = {(row["algorithm_id"], row["run_id"]) for row in csv.DictReader(file)}
    assert ids == {("N=8", "0"), ("N=8", "1"), ("N=12", "0"), ("N=12", "1")}
    labels = ["--label", "a", "--label", "b", "--label", "c"]
    result = cli_in_process("plot", *paths, "-o", tmp_path / "x.png", *labels)
    assert result.returncode == 2 and not (tmp_path / "x.png").exists()
    assert "argument --label: expected one per run directory (4) or one per setting group (2), got 3" in (
        result.stderr
    )


def test_the_default_export_ids_tell_the_settings_apart(runs, tmp_path):
    out = tmp_path / "groups.csv"
    assert main(["export", *_paths(runs, "n8-0", "n12-0", "n8-1"), "-o", str(out)]) == 0
    with open(out, newline="") as file:
        ids = {row["algorithm_id"] for row in csv.DictReader(file)}
    assert ids == {"creps-cma-old, samples=10", "creps-cma-old, samples=12"}


def _overlap(a, b):
    return a.x0 < b.x1 and b.x0 < a.x1 and a.y0 < b.y1 and b.y0 < a.y1


MANY = ("n8-0", "n12-0", "eps-0", "p4", "n12-1", "n8-1")


@EXTRAS
@pytest.mark.parametrize(
    ("names", "labels"),
    [(("n8-0", "n8-1"), None), (MANY, None), (MANY, ["a", "b", "c", "d", "b", "a"])],  # 1, 1 and 2 columns
)
@pytest.mark.slow
def test_the_legend_lies_in_the_figure_and_covers_no_axes(runs, tmp_path, names, labels):
    pytest.importorskip("matplotlib")
    figure = plot_run_dirs(_paths(runs, *names), tmp_path / "curves.png", mix_envs=True, labels=labels)
    figure.draw_without_rendering()  # the layout as saved
    renderer = figure._get_renderer()
    (legend,) = [legend for sub in figure.subfigs for legend in sub.legends]
    box, page = legend.get_window_extent(renderer), figure.bbox
    assert page.x0 <= box.x0 and box.x1 <= page.x1 and page.y0 <= box.y0 and box.y1 <= page.y1
    for axis in figure.get_axes():
        assert not _overlap(box, axis.get_tightbbox(renderer)), axis.get_title()
    texts = [text.get_text() for text in legend.get_texts()]
    assert len(texts) == len({*names} - {"n8-1", "n12-1"})
    assert legend._ncols == (2 if labels else 1)
    if "p4" in names and labels is None:
        assert any(" on creps_gym/Sphere-v0 (p = 4, z = 1)" in text for text in texts)


def test_list_prints_non_cubic_boxes_per_dimension():
    def box(low, high):
        return box_text(gym.spaces.Box(np.array(low), np.array(high), dtype=np.float64))

    assert box([0.15, -0.15], [0.3, 0.15]) == "[0.15, 0.3]×[-0.15, 0.15]"
    assert box([-5.0] * 15, [5.0] * 15) == "[-5, 5]^15"
    assert box([-5.0, -5.0, -5.990589492661148, -5.0], [5.0] * 4) == "[-5, 5]^2×[-5.99059, 5]×[-5, 5]"
    pytest.importorskip("mujoco")  # without it `list` marks the kick as not available
    listed = cli_in_process("list").stdout
    kick = next(line for line in listed.splitlines() if "creps_gym/KickFlexibility-v2 " in line)
    assert [cell.strip() for cell in kick.split("  ") if cell.strip()][
        1
    ] == "context [0.15, 0.3]×[-0.15, 0.15]"


def test_list_marks_envs_whose_optional_modules_are_missing(monkeypatch):
    import importlib.util

    monkeypatch.setattr(importlib.util, "find_spec", lambda name: None if name == "mujoco" else object())
    rows = available_env_rows([["a", "c", "p", "i", "d", []], ["b", "c", "p", "i", "d", ["mujoco"]]])
    assert rows[1] == ["a", "c", "p", "i", "d"]
    assert rows[2] == ["b", "?", "?", "?", "(not available: pip install creps-gym[mujoco])"]


def test_settings_that_print_alike_are_numbered_never_pooled():
    from creps_gym.runner import History, RunConfig

    configs = [RunConfig(SPHERE, "creps", 3, 8, 0, optimizer_options={"epsilon": v}) for v in (1, "1")]
    groups, labels = group_runs([(config, History()) for config in configs])
    assert labels == ["creps, epsilon=1 #1", "creps, epsilon=1 #2"] and len(groups) == 2
