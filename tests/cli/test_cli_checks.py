"""Options that only an optimiser's first ``tell`` would refuse are usage errors, found before the run
directory is written (issue 15, item 11)."""

from __future__ import annotations

import pytest
from helpers import SPHERE, run_argv

from creps_gym.cli import EXIT_CODES, main
from creps_gym.optimizers import CCMAES
from creps_gym.runner import run


def run_args(out, *extra, samples=10):
    """A 2-iteration CREPS-CMA run of the 3-D sphere into ``out``, then ``extra``."""
    short = ("--samples", samples, "--env-kwarg", "dim=3", "--no-plot")
    return run_argv(out, *short, *extra, optimizer="creps-cma-old")


def test_an_epsilon_too_large_for_the_batch_is_a_usage_error_and_leaves_nothing_behind(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(run_args(out, "--opt", "epsilon=5")) == EXIT_CODES["usage"]
    error = capsys.readouterr().err
    assert "creps-gym run: error: argument --opt: epsilon: expected < log(N) = 2.3026" in error
    assert "got 5" in error and not out.exists()
    assert main(run_args(out, "--opt", "epsilon=1")) == EXIT_CODES["ok"]  # the rerun is not blocked


def test_a_batch_below_the_optimizers_minimum_is_a_usage_error(tmp_path, capsys):
    """Below the minimum workable batch (10 for p = 3, z = 1) the search diverges: exit 2 naming
    ``--samples`` and the minimum, and nothing written; the minimum itself is accepted."""
    out = tmp_path / "run"
    for samples in (3, 9):
        assert main(run_args(out, samples=samples)) == EXIT_CODES["usage"]
        error = capsys.readouterr().err
        assert (
            "error: argument --samples: expected at least 10 episodes per iteration for 'creps-cma-old' "
            f"with 3 parameters and 1 context dimension(s) (smaller batches diverge; see docs/optimizers.md, "
            f"'Batch size'), got {samples}"
        ) in error
        assert not out.exists()
    assert main(run_args(out, samples=10)) == EXIT_CODES["ok"]


def test_the_python_api_checks_the_batch_before_writing_the_run_directory(tmp_path):
    with pytest.raises(ValueError, match=r"^epsilon: expected < log\(N\)"):
        run("creps", SPHERE, 2, 12, 0, run_dir=tmp_path / "a", optimizer_options={"epsilon": 5.0})
    with pytest.raises(ValueError, match=r"^samples_per_iteration: expected at least 12 episodes per iter"):
        run("creps", SPHERE, 2, 3, 0, run_dir=tmp_path / "b")
    with pytest.raises(ValueError, match=r"^samples_per_iteration: .* at least 12 .* for CCMAES .*got 11"):
        run(CCMAES(15, 1, seed=0), SPHERE, 2, 11, 0, env_kwargs={"dim": 15})  # objects too
    assert not list(tmp_path.iterdir())


def test_the_small_batch_command_of_issue_31_exits_2_naming_the_minimum(tmp_path, capsys):
    """``--samples 5`` for c-cma-es on a 5-D Sphere diverged (regret 11.5 -> 3.5e9, exit 0); now refused."""
    args = [
        "run",
        "--env",
        SPHERE,
        "--env-kwarg",
        "dim=5",
        "--optimizer",
        "c-cma-es",
        "--samples",
        "5",
        "--iterations",
        "400",
        "--seed",
        "0",
        "--out",
        str(tmp_path / "s5"),
        "--no-plot",
    ]
    assert main(args) == EXIT_CODES["usage"]
    error = capsys.readouterr().err
    assert "argument --samples: expected at least 10 episodes per iteration for 'c-cma-es'" in error
    assert not (tmp_path / "s5").exists()


def test_every_native_optimizer_has_a_minimum_batch_and_adapters_have_none():
    from creps_gym.optimizers import minimum_samples

    for name in ("creps", "creps-cma-old", "creps-cma-current", "creps-cma-csa", "c-cma-es"):
        assert minimum_samples(name, 5, 1) == 10  # measured in docs/optimizers.md, 'Batch size'
    assert minimum_samples("cma", 5, 1) is None  # no import of pycma: the adapter's class decides
    sizes = ((2, 1), (15, 1), (5, 3), (4, 0))
    assert [minimum_samples("c-cma-es", p, z) for p, z in sizes] == [10, 12, 20, 8]
