"""Options that only an optimiser's first ``tell`` would refuse are usage errors, found before the run
directory is written (issue 15, item 11)."""

from __future__ import annotations

import pytest
from helpers import SPHERE

from creps_gym.cli import EXIT_CODES, main
from creps_gym.runner import run


def run_args(out, *extra, samples=10):
    sizes = ["--iterations", "2", "--samples", str(samples), "--seed", "0", "--env-kwarg", "dim=3"]
    return [
        "run",
        "--env",
        SPHERE,
        "--optimizer",
        "creps-cma-old",
        *sizes,
        "--out",
        str(out),
        "--no-plot",
        *extra,
    ]


def test_an_epsilon_too_large_for_the_batch_is_a_usage_error_and_leaves_nothing_behind(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(run_args(out, "--opt", "epsilon=5")) == EXIT_CODES["usage"]
    error = capsys.readouterr().err
    assert "creps-gym run: error: argument --opt: epsilon: expected < log(N) = 2.3026" in error
    assert "got 5" in error and not out.exists()
    assert main(run_args(out, "--opt", "epsilon=1")) == EXIT_CODES["ok"]  # the rerun is not blocked


def test_a_batch_too_small_for_the_features_is_a_usage_error(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(run_args(out, samples=3)) == EXIT_CODES["usage"]
    error = capsys.readouterr().err
    assert "error: argument --samples: expected a batch size that 'creps-cma-old' can learn from" in error
    assert "got 3 (returns: expected more than k + 1 = 3 samples" in error and not out.exists()


def test_the_python_api_checks_the_batch_before_writing_the_run_directory(tmp_path):
    with pytest.raises(ValueError, match=r"^epsilon: expected < log\(N\)"):
        run("creps", SPHERE, 2, 10, 0, run_dir=tmp_path / "a", optimizer_options={"epsilon": 5.0})
    with pytest.raises(ValueError, match=r"^samples: expected a batch size that 'creps' can learn from"):
        run("creps", SPHERE, 2, 3, 0, run_dir=tmp_path / "b")
    assert not list(tmp_path.iterdir())
