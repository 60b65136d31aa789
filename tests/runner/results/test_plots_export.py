"""Learning-curve plots, the IOHanalyzer export and the run directory's versions and permission modes."""

from __future__ import annotations

import csv
import json
import math
import stat

import numpy as np
import pytest
from helpers import EXTRAS, SPHERE

from creps_gym.cli import main
from creps_gym.runner import RunDir, run
from creps_gym.runner.results.export import IOH_COLUMNS, write_iohanalyzer
from creps_gym.runner.results.plots import load_history, plot_run_dirs

pytestmark = EXTRAS  # matplotlib


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """Two runs on Sphere p = 3 (one meets its target) and one on Sphere p = 4, in run directories."""
    root = tmp_path_factory.mktemp("runs")
    small = {"eval_every": 1, "eval_contexts": 4}
    for name, seed, dim in (("a", 0, 3), ("b", 1, 3), ("c", 0, 4)):
        run(
            "creps-cma-old",
            SPHERE,
            8,
            10,
            seed,
            env_kwargs={"dim": dim},
            run_dir=root / name,
            target_regret=2.0,
            **small,
        )
    return root


def test_the_learning_curve_names_the_env_shows_the_target_and_the_stop_reasons(runs):
    pytest.importorskip("matplotlib")
    figure = plot_run_dirs([runs / "a", runs / "b"])
    assert figure._suptitle.get_text() == f"{SPHERE} (p = 3, z = 1)"
    left, right = figure.get_axes()
    assert left.get_yscale() == "symlog" and right.get_yscale() == "log"
    reasons = sorted(str(load_history(runs / n).stop_reason) for n in "ab")
    texts = legend_texts(figure)
    assert texts[0].startswith("creps-cma-old (n=2; stop: ") and all(r in texts[0] for r in reasons)
    target = [line for line in right.get_lines() if line.get_linestyle() == "--"]
    assert len(target) == 1 and np.allclose(target[0].get_ydata(), 2.0)
    assert texts[1:] == ["target regret 2"]


def legend_texts(figure):
    """The texts of the figure's one legend (below the panels)."""
    (legend,) = [legend for sub in figure.subfigs for legend in sub.legends]
    return [text.get_text() for text in legend.get_texts()]


@pytest.mark.slow
def test_plot_and_export_refuse_to_mix_envs_unless_told(runs, tmp_path, capsys):
    mixed = [str(runs / "a"), str(runs / "c")]
    for command, out in (("plot", "mixed.png"), ("export", "mixed.csv")):
        assert main([command, *mixed, "-o", str(tmp_path / out)]) == 2
        error = capsys.readouterr().err
        assert "expected runs of one env" in error and "(p = 3, z = 1)" in error and "(p = 4, z = 1)" in error
        assert not (tmp_path / out).exists()
        assert main([command, *mixed, "-o", str(tmp_path / out), "--mix-envs"]) == 0
        assert (tmp_path / out).stat().st_size > 0
    with pytest.raises(ValueError, match="expected runs of one env"):
        write_iohanalyzer([load_history(p) for p in mixed], tmp_path / "api.csv")


def _read_like_iohanalyzer(path):
    """IOHanalyzer's custom-CSV conventions: a header row, the function values as the only required
    column, and optional evaluation counter, function, algorithm, dimension and run columns; rows of one run
    (function, algorithm, dimension, run) have increasing evaluation counts; values are numbers."""
    with open(path, newline="") as stream:
        rows = list(csv.DictReader(stream))
    runs: dict[tuple, list[tuple[int, float]]] = {}
    for row in rows:
        key = (row["function_id"], row["algorithm_id"], int(row["dimension"]), row["run_id"])
        runs.setdefault(key, []).append((int(row["evaluations"]), float(row["value"])))
    for points in runs.values():
        counts = [count for count, _ in points]
        assert counts == sorted(set(counts)) and all(math.isfinite(v) for _, v in points)
    return runs


def test_the_export_follows_iohanalyzers_csv_conventions(runs, tmp_path):
    out = tmp_path / "ioh.csv"
    histories = [load_history(runs / n) for n in "ab"]
    write_iohanalyzer(histories, out)
    assert out.read_text().splitlines()[0] == ",".join(IOH_COLUMNS)
    loaded = _read_like_iohanalyzer(out)
    assert sorted(loaded) == [(SPHERE, "creps-cma-old", 3, "0"), (SPHERE, "creps-cma-old", 3, "1")]
    for history in histories:
        points = loaded[(SPHERE, "creps-cma-old", 3, str(history.meta["seed"]))]
        assert points == [(r.episodes, r.eval_regret) for r in history]  # every evaluation, exactly


def test_versions_record_the_adapter_libraries_and_run_files_share_one_mode(runs):
    versions = json.loads((runs / "a" / RunDir.VERSIONS).read_text())
    for package in ("cma", "nevergrad", "optuna", "ray", "gymnasium-robotics", "numpy"):
        assert versions[package] and versions[package] != "not installed", package
    files = [p for p in (runs / "a").iterdir() if p.is_file()]
    assert {RunDir.CHECKPOINT, RunDir.CONFIG, RunDir.HISTORY_JSON} <= {p.name for p in files}
    assert len({stat.S_IMODE(p.stat().st_mode) for p in files}) == 1, {
        p.name: oct(p.stat().st_mode) for p in files
    }


def test_a_run_without_regret_plots_its_evaluation_return_on_a_symlog_axis(tmp_path):
    """The reacher's cost falls from 18 to 0.02: on a linear axis its curve is flat after the first drop."""
    pytest.importorskip("matplotlib")
    small = {"eval_every": 2, "eval_contexts": 4, "run_dir": tmp_path / "reacher"}
    run("creps-cma-old", "creps_gym/PlanarReacher-v1", 6, 20, 0, **small)
    left, right = plot_run_dirs([tmp_path / "reacher"]).get_axes()
    assert left.get_yscale() == right.get_yscale() == "symlog"
    assert right.get_ylabel() == "mean evaluation return (symlog)"
