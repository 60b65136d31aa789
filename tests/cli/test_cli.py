"""The ``creps-gym`` command line: each command in process (``cli_in_process``), and through a real
subprocess where the test is about the process (the console script, signals, the environment)."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from dataclasses import fields
from pathlib import Path

import pytest
from helpers import EXTRAS, SPHERE, cli_in_process, run_argv

import creps_gym
from creps_gym.cli import main
from creps_gym.optimizers import CREPSCMAConfig, optimizer_names
from creps_gym.runner import History, RunDir

cli = cli_in_process  # the commands' behaviour; a process only where the test is about one


def run_args(out, *extra, seed=0):
    """A 6-iteration CREPS-CMA run of the 4-D sphere into ``out``, then ``extra``."""
    short = ("--samples", 10, "--env-kwarg", "dim=4", "--eval-every", 2)
    return run_argv(out, *short, *extra, optimizer="creps-cma-old", iterations=6, seed=seed)


def test_console_script_is_installed():
    # The script of the interpreter running the tests (a venv's), else the one on PATH: another Python's
    # script on PATH may belong to a stale install.
    beside = Path(sys.executable).with_name("creps-gym")
    script = str(beside) if beside.is_file() else shutil.which("creps-gym")
    if script is None:
        pytest.skip("creps-gym is not on PATH (package not installed with pip)")
    result = subprocess.run([script, "--help"], capture_output=True, text=True, timeout=60, check=False)
    assert result.returncode == 0 and "Exit codes" in result.stdout


def test_list_shows_envs_with_spaces_and_aligned_optimizers_without_rest_markup():
    result = cli("list")
    assert result.returncode == 0, result.stderr
    assert "out of date" not in result.stderr  # the older kick versions are listed, not used
    assert "`" not in result.stdout and ":class:" not in result.stdout
    envs, optimizers = result.stdout.split("Optimizers:\n")
    env_lines, optimizer_lines = envs.splitlines()[1:], optimizers.splitlines()
    start = optimizer_lines[0].index("description")  # each description starts below the header's
    assert all(line[start - 2 : start] == "  " and line[start] != " " for line in optimizer_lines[1:])
    sphere = env_lines.index(f"  {SPHERE}  context [0, 3]  θ [-5, 5]^15  initial N(0, 2.5^2)")
    assert env_lines[sphere + 1] == "      Sphere: contextual version, x = theta + A s."
    ids = [line.split()[0] for line in env_lines if line.startswith("  ") and not line.startswith("   ")]
    assert ids == creps_gym.registered_ids()
    for name in optimizer_names():
        assert any(line.split()[:1] == [name] and len(line.split()) > 1 for line in optimizer_lines), name


def test_version_flag(capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["--version"])
    assert exit_info.value.code == 0 and capsys.readouterr().out == f"creps-gym {creps_gym.__version__}\n"


@pytest.mark.parametrize(
    ("flag", "typo", "hint"),
    [
        ("--env", "creps_gym/Spere-v0", "(did you mean 'creps_gym/Sphere-v0'"),
        ("--env", "Rosenbrock-v0", "(did you mean 'creps_gym/Rosenbrock-v0'?)"),
        ("--optimizer", "creps-cma", "(did you mean 'creps-cma-old' or 'creps-cma-csa' or 'creps'?)"),
        ("--optimizer", "nevergrd", "(did you mean 'nevergrad'?)"),
    ],
)
def test_a_mistyped_env_or_optimizer_gets_did_you_mean(tmp_path, capsys, flag, typo, hint):
    args = [str(a) for a in run_args(tmp_path / "run")]
    args[args.index(flag) + 1] = typo
    try:  # argparse exits for an optimiser name; the env id is checked after parsing (--import first)
        code = main(args)
    except SystemExit as exit_info:
        code = exit_info.code
    assert code == 2 and hint in capsys.readouterr().err


#: The options of the default optimiser, as its error message lists them (the config's init fields).
CREPS_CMA_OPTIONS = sorted(
    f.name for f in fields(CREPSCMAConfig) if f.init and f.name not in ("n_params", "n_context_dims")
)
BAD_FLAGS = [
    (["--samples", "1"], "argument --samples: expected an integer >= 2, got '1'"),
    (["--iterations", "ten"], "argument --iterations: expected an integer >= 1, got 'ten'"),
    (["--env", "creps_gym/Nope-v0"], "argument --env: unknown env id 'creps_gym/Nope-v0'"),
    (["--optimizer", "adam"], "argument --optimizer: expected one of ['creps', 'creps-cma-old'"),
    (["--backend", "gpu"], "argument --backend: invalid choice: 'gpu'"),
    (["--target-regret", "-1"], "argument --target-regret: expected a positive finite number, got '-1'"),
    (
        ["--initial-std", "1,x"],
        "argument --initial-std: expected a number or comma-separated numbers, got '1,x'",
    ),
    (
        ["--opt", "epsilon"],
        "argument --opt: expected KEY=VALUE (VALUE in JSON or a plain string), got 'epsilon'",
    ),
    (["--opt", "epsilon=-1"], "argument --opt: epsilon: expected a"),  # the optimiser's own message follows
    (
        ["--opt", "bogus=1"],
        f"argument --opt: options: expected names in {CREPS_CMA_OPTIONS}, got unknown ['bogus']",
    ),
    (["--initial-mean", "centre"], "argument --initial-mean: expected 'uniform', a number or p comma"),
    (["--initial-std", "uniform"], "argument --initial-std: expected a number or comma-separated numbers"),
    (["--max-episodes", "5"], "argument --max-episodes: expected at least one iteration's samples (10)"),
    (["--env-kwarg", "dim=1"], "argument --env-kwarg: dim: expected an integer >= 2, got 1"),
]


@pytest.mark.parametrize(("flags", "expected"), BAD_FLAGS)
def test_bad_flags_name_the_flag_the_expectation_and_the_value(tmp_path, capsys, flags, expected):
    # In-process (the same main() the console script calls) to keep the suite fast; the subprocess tests
    # above and below cover the process boundary and the exit codes.
    args = run_args(tmp_path / "run")
    for flag, value in zip(flags[::2], flags[1::2], strict=True):
        if flag in args:
            args[args.index(flag) + 1] = value
        else:
            args += [flag, value]
    try:
        code = main([str(a) for a in args])
    except SystemExit as exc:  # argparse exits by itself on flag-level errors
        code = exc.code
    assert code == 2
    assert expected in capsys.readouterr().err
    assert not (tmp_path / "run" / RunDir.CHECKPOINT).exists()


def test_exit_codes_for_run_directories_and_regret_targets(tmp_path):
    out = tmp_path / "run"
    assert cli(*run_args(out, "--no-plot")).returncode == 0
    again = cli(*run_args(out, "--no-plot"))
    assert again.returncode == 3 and "holds a run" in again.stderr
    (out / "notes.txt").write_text("mine")
    replaced = cli(*run_args(out, "--no-plot", "--overwrite", "--iterations", 2))
    assert replaced.returncode == 0 and len(History.from_json(out / RunDir.HISTORY_JSON)) == 2
    assert (out / "notes.txt").read_text() == "mine"  # only the run's own files are replaced
    missing = cli("resume", tmp_path / "nothing")
    assert missing.returncode == 3 and "expected a folder with config.json" in missing.stderr
    args = run_args(tmp_path / "plane", "--target-regret", "0.1")
    args[args.index("--env") + 1] = "creps_gym/Plane-v0"
    plane = cli(*args)
    assert (
        plane.returncode == 2
        and "argument --target-regret: expected None for creps_gym/Plane-v0" in plane.stderr
    )
    usage = cli("frobnicate")
    assert usage.returncode == 2 and "invalid choice: 'frobnicate'" in usage.stderr


def test_config_json_records_the_resolved_configuration(tmp_path):
    out = tmp_path / "run"
    assert cli(*run_args(out, "--no-plot", "--opt", "epsilon=0.8", "--initial-std", "0.5")).returncode == 0
    document = json.loads((out / RunDir.CONFIG).read_text())
    config = document["config"]
    assert config["optimizer_options"] == {"epsilon": 0.8} and config["initial_std"] == 0.5
    assert config["env_kwargs"] == {"dim": 4} and config["retries"] == 2 and config["backend"] == "auto"
    assert document["meta"]["n_params"] == 4 and document["meta"]["metric"] == "regret"


def test_an_empty_out_is_refused_with_exit_2_not_taken_as_the_current_folder(tmp_path, monkeypatch, capsys):
    """Before: ``--out ""`` wrote the run into the current folder."""
    monkeypatch.chdir(tmp_path)
    argv = ["run", "--env", "creps_gym/Sphere-v0", "--optimizer", "creps", "--iterations", "1", "--seed", "0"]
    assert main([*argv, "--out", "", "--no-progress", "--no-plot"]) == 2
    assert "out: expected a directory path, got ''" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


@EXTRAS
def test_a_bad_nevergrad_optimizer_option_blames_opt_and_suggests_close_names(tmp_path, capsys):
    pytest.importorskip("nevergrad")
    args = [str(a) for a in run_args(tmp_path / "run", "--opt", "optimizer=TwoPointDE")]
    args[args.index("--optimizer") + 1] = "nevergrad"
    assert main(args) == 2
    error = capsys.readouterr().err
    assert (
        "argument --opt: optimizer: expected a name in nevergrad.optimizers.registry, got 'TwoPointDE' "
        in error
    )
    assert "(did you mean 'TwoPointsDE'" in error and "argument --optimizer" not in error
