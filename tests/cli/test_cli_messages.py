"""What a new user meets on the command line (issue 42, items 2-9), through ``creps_gym.cli.main``.

Each test fails on the code before the issue: ``--import`` for ``policy``/``evaluate``, run-owned ``--opt``
names, env keyword and env id messages, missing run folders, ``--context-selector fixed`` options, the
MuJoCo backend error, deprecated ids and ``list``, a Ctrl-C after the last iteration, and ``run --help``.
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from helpers import EXTRAS, SPHERE, marked

import creps_gym
from creps_gym.cli import main
from creps_gym.cli.types import key_value
from creps_gym.optimizers import registry
from creps_gym.runner import RunConfig, RunDir, run

ROOT = Path(__file__).resolve().parents[2]
GUIDE = (ROOT / "docs" / "writing_an_adapter.md").read_text()
#: The guide's optimiser module, under names no other test uses.
MODULE = (
    re.search(r"```python\n(.*?)```", GUIDE.split("## Your own optimiser from the command line", 1)[1], re.S)
    .group(1)
    .replace("my-search", "cwd-search-42")
)


def run_args(out, *extra, optimizer="creps", iterations=1):
    """A short run of the Sphere with p = 2."""
    head = ["run", "--env", SPHERE, "--env-kwarg", "dim=2", "--optimizer", optimizer]
    return [
        *head,
        "--iterations",
        str(iterations),
        "--seed",
        "0",
        "--out",
        str(out),
        "--no-progress",
        "--no-plot",
        *extra,
    ]


# -- item 2: your own optimiser in every command ----------------------------------------------------------
@pytest.fixture
def cwd_module(tmp_path, monkeypatch):
    """A folder holding the guide's module, as the current directory; sys.path and registries restored."""
    (tmp_path / "cwd_search_42.py").write_text(MODULE)
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "path", [p for p in sys.path if p not in ("", str(tmp_path))])
    monkeypatch.setattr(registry, "_REGISTRY", dict(registry._REGISTRY))
    yield tmp_path
    sys.modules.pop("cwd_search_42", None)


def _forget_module(monkeypatch, folder):
    """As a new process: the module not imported, the optimiser not registered, cwd not on sys.path."""
    sys.modules.pop("cwd_search_42", None)
    registry._REGISTRY.pop("cwd-search-42", None)
    sys.path[:] = [p for p in sys.path if p != str(folder)]


def test_policy_and_evaluate_import_a_module_from_the_current_folder(cwd_module, monkeypatch, capsys):
    args = run_args("runs/x", "--import", "cwd_search_42", optimizer="cwd-search-42", iterations=3)
    assert main(args) == 0, capsys.readouterr().err
    for command in (["policy", "runs/x"], ["evaluate", "runs/x", "--contexts", "3"]):
        _forget_module(monkeypatch, cwd_module)
        capsys.readouterr()
        code = main([*command, "--import", "cwd_search_42"])
        out, err = capsys.readouterr()
        assert code == 0, err
        assert json.loads(out)["env"] == SPHERE


@pytest.mark.parametrize(
    "command",
    [["resume", "runs/x"], ["evaluate", "runs/x"], ["export", "runs/x", "-o", "x.csv"]],
)
def test_a_missing_import_is_named_for_the_command_that_needs_it(cwd_module, monkeypatch, capsys, command):
    assert main(run_args("runs/x", "--import", "cwd_search_42", optimizer="cwd-search-42")) == 0
    _forget_module(monkeypatch, cwd_module)
    capsys.readouterr()
    assert main(command) == 3
    err = capsys.readouterr().err
    assert f"`creps-gym {command[0]} --import MODULE`" in err, err
    assert command[0] == "resume" or "creps-gym resume" not in err


# -- item 3: optimiser options that the run sets ----------------------------------------------------------
@pytest.mark.parametrize(
    ("option", "flag"),
    [("initial_cov=4", "--initial-std"), ("initial_mean=1", "--initial-mean"), ("seed=5", "--seed")],
)
def test_run_owned_optimizer_options_are_refused_naming_the_run_flag(tmp_path, capsys, option, flag):
    assert main(run_args(tmp_path / "r", "--opt", option)) == 2
    err = capsys.readouterr().err
    key = option.split("=")[0]
    assert f"argument --opt: expected no '{key}', which the run sets: use {flag} " in err, err
    assert "multiple values" not in err and not (tmp_path / "r").exists()
    with pytest.raises(ValueError, match=rf"optimizer_options: expected no '{key}'.*{key}="):
        RunConfig(SPHERE, "creps", 1, None, 0, optimizer_options=dict([key_value(option)]))


# -- item 4: env keywords, env ids, --optimiser -----------------------------------------------------------
def test_an_unknown_env_keyword_lists_the_env_keywords_with_a_did_you_mean(tmp_path, capsys):
    assert main(run_args(tmp_path / "r", "--env-kwarg", "dimm=5")) == 2
    err = capsys.readouterr().err
    assert err == (
        "creps-gym run: error: argument --env-kwarg: expected keywords of creps_gym/Sphere-v0 from "
        "['context_dim', 'dim', 'instance'], got 'dimm' (did you mean 'dim'?)\n"
    )
    assert main(run_args(tmp_path / "r", "--env-kwarg", "dim=abc")) == 2
    err = capsys.readouterr().err
    assert err == "creps-gym run: error: argument --env-kwarg: dim: expected an integer >= 2, got str 'abc'\n"


@pytest.mark.filterwarnings("ignore:.*is out of date")
@pytest.mark.parametrize("env_id", marked(creps_gym.registered_ids()))
def test_every_env_names_its_keywords_for_an_unknown_one(env_id):
    from creps_gym.runner.build import make_env

    with pytest.raises(TypeError, match=rf"^env_kwargs: expected keywords of {env_id} from \['\w+") as info:
        make_env(env_id, {"no_such_keyword": 1})
    assert "got 'no_such_keyword'" in str(info.value) and "environment creator" not in str(info.value)


def test_a_mistyped_env_id_gives_the_hint_first_then_the_ids(tmp_path, capsys):
    args = run_args(tmp_path / "r")
    args[args.index(SPHERE)] = "creps_gym/Sphre-v0"
    assert main(args) == 2
    lines = capsys.readouterr().err.splitlines()
    assert lines[0] == (
        "creps-gym run: error: argument --env: unknown env id 'creps_gym/Sphre-v0' (did you mean "
        "'creps_gym/Sphere-v0' or 'creps_gym/SharpRidge-v0' or 'creps_gym/ShiftedSphere-v0'?)"
    )
    assert all(len(line) <= 100 for line in lines[1:]) and SPHERE in "".join(lines[1:])


def test_optimiser_is_accepted_for_optimizer_and_documented(tmp_path, capsys):
    args = [("--optimiser" if a == "--optimizer" else a) for a in run_args(tmp_path / "r")]
    assert main(args) == 0, capsys.readouterr().err
    assert RunDir.open(tmp_path / "r").config().optimizer == "creps"
    with pytest.raises(SystemExit):
        main(["run", "--help"])
    assert "--optimizer OPTIMIZER, --optimiser OPTIMIZER" in capsys.readouterr().out
    assert "`--optimiser` is accepted for `--optimizer`" in (ROOT / "docs" / "runner.md").read_text()


# -- item 5: missing folders, Policy.load of a folder, overwrite=True ------------------------------------
@pytest.mark.parametrize(
    "command", [["policy"], ["evaluate"], ["resume"], ["plot", "-o", "x.png"], ["export", "-o", "x.csv"]]
)
def test_a_missing_run_folder_is_said_not_to_exist(tmp_path, capsys, command):
    missing = tmp_path / "nope"
    assert main([command[0], str(missing), *command[1:]]) == 3
    err = capsys.readouterr().err
    assert f"got {missing}, which does not exist" in err and "Errno" not in err, err


def test_policy_load_of_a_folder_points_at_load_policy(tmp_path):
    with pytest.raises(
        ValueError, match=r"expected a policy file, got the folder .*creps_gym\.load_policy\("
    ):
        creps_gym.Policy.load(tmp_path)


def test_run_into_a_run_names_overwrite_true_in_python_and_overwrite_in_the_cli(tmp_path, capsys):
    folder = tmp_path / "r"
    run("creps", SPHERE, 1, None, 0, run_dir=folder, env_kwargs={"dim": 2})
    with pytest.raises(FileExistsError, match="pass overwrite=True to replace it") as info:
        run("creps", SPHERE, 1, None, 0, run_dir=folder, env_kwargs={"dim": 2})
    assert "--overwrite" not in str(info.value)
    assert main(run_args(folder)) == 3
    err = capsys.readouterr().err
    assert "pass --overwrite to replace it" in err and "overwrite=True" not in err


# -- item 6: --context-selector fixed ---------------------------------------------------------------------
def test_fixed_selector_without_contexts_names_the_option(tmp_path, capsys):
    assert main(run_args(tmp_path / "r", "--context-selector", "fixed")) == 2
    err = capsys.readouterr().err
    assert "argument --selector-opt: expected the option 'contexts' of 'fixed', got none" in err, err
    assert "positional argument" not in err


def test_fixed_contexts_of_the_wrong_shape_name_the_env_z(tmp_path, capsys):
    args = run_args(tmp_path / "r", "--context-selector", "fixed", "--selector-opt", "contexts=[0.5,1.0,1.5]")
    args[args.index(SPHERE)] = "creps_gym/PlanarReacher-v1"  # z = 2
    args[args.index("dim=2")] = "position_weight=1.0"  # a keyword of the reacher
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "contexts: expected shape (n, 2), one row of 2 numbers per context, got (3,)" in err, err
    from creps_gym.selectors import make_selector

    selector = make_selector("fixed", {"contexts": [[0.5, 1.0, 1.5]]})
    with pytest.raises(ValueError, match=r"expected shape \(n, 2\).*got \(1, 3\)"):
        selector.bind(np.zeros(2), np.full(2, 2.0), None)
    flat = make_selector("fixed", {"contexts": [0.5, 1.5]})  # z = 1: one context per number
    flat.bind(np.zeros(1), np.full(1, 3.0), None)
    assert flat.select(np.random.default_rng(0), 3).tolist() == [[0.5], [1.5], [0.5]]


# -- item 7: the MuJoCo backend, deprecated ids, `list` ---------------------------------------------------
def _python(env, *args):
    return subprocess.run([sys.executable, *args], env=env, capture_output=True, text=True, timeout=120)


@pytest.mark.slow
def test_a_gl_library_that_does_not_load_gives_the_projects_short_error_first(tmp_path):
    fake = tmp_path / "fake" / "mujoco"
    fake.mkdir(parents=True)  # mujoco as it fails when MUJOCO_GL=osmesa and libOSMesa is missing
    (fake / "__init__.py").write_text(
        "raise AttributeError(\"'NoneType' object has no attribute 'glGetError'\")\n"
    )
    env = {**os.environ, "MUJOCO_GL": "osmesa", "PYTHONPATH": os.pathsep.join([str(fake.parent), str(ROOT)])}
    done = _python(env, "-c", "import creps_gym.envs.kick.model")
    last = done.stderr.strip().splitlines()[-1]
    assert done.returncode == 1 and last.startswith(
        "RuntimeError: MUJOCO_GL=osmesa: mujoco cannot be imported"
    )
    assert "libosmesa6" in last and "glGetError" in last  # the cause, in the message
    assert str(fake) not in done.stderr and len(done.stderr.splitlines()) < 12, done.stderr
    command = [sys.executable, "-m", "creps_gym.cli", *run_args(tmp_path / "r")]
    command[command.index(SPHERE)] = "creps_gym/KickPrecision-v1"
    cli = _python(env, *command[1:])
    assert cli.returncode == 1 and cli.stderr.startswith(
        "creps-gym run: run failed: RuntimeError: MUJOCO_GL=osmesa"
    )
    assert len(cli.stderr.splitlines()) == 1, cli.stderr


def test_import_mujoco_leaves_a_missing_mujoco_to_the_extras(monkeypatch):
    from creps_gym.envs import opengl

    monkeypatch.setitem(sys.modules, "mujoco", None)  # `import mujoco` fails: not installed
    monkeypatch.setenv("MUJOCO_GL", "osmesa")
    with pytest.raises(ImportError):
        opengl.import_mujoco()


def test_a_deprecated_id_warns_once_without_terminal_escapes(tmp_path, capsys):
    args = run_args(tmp_path / "r")
    args[args.index(SPHERE)] = "creps_gym/PlanarReacher-v0"
    args[args.index("dim=2")] = "position_weight=1.0"  # a keyword of the reacher
    assert main(args) == 0
    err = capsys.readouterr().err
    assert err.count("creps-gym run: warning: The environment creps_gym/PlanarReacher-v0 is out of date") == 1
    assert "\x1b" not in err and "WARN:" not in err, repr(err)


def test_list_fits_in_100_columns_and_marks_the_deprecated_ids(capsys):
    from creps_gym._table import ENVS
    from creps_gym.listing import deprecated_ids

    assert main(["list"]) == 0
    out = capsys.readouterr().out
    assert max(len(line) for line in out.splitlines()) <= 100
    ids = [row[0] for row in ENVS]
    old = deprecated_ids(ids)
    assert old["creps_gym/PlanarReacher-v0"] == "creps_gym/PlanarReacher-v1"
    assert (
        old["creps_gym/KickFlexibility-v0"]
        == old["creps_gym/KickFlexibility-v1"]
        == "creps_gym/KickFlexibility-v2"
    )
    blocks = re.split(r"\n(?=  \S)", out.split("Optimizers:")[0])[1:]
    assert [block.split()[0] for block in blocks] == ids
    for block in blocks:
        env_id = block.split()[0]
        marked_as = re.search(r"\(deprecated: use (\S+)\)", block)
        assert (marked_as and marked_as.group(1)) == old.get(env_id), block


# -- item 8: a Ctrl-C after the last iteration ------------------------------------------------------------
@pytest.fixture
def python_sigint():
    """Python's own SIGINT handler for the test: a process started in the background by a shell without job
    control (``nohup ... &``, some CI runners) inherits SIGINT ignored, which the run rightly leaves alone,
    so the Ctrl-C these tests simulate would never arrive."""
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, previous)


def _interrupt_first(function):
    def interrupted(*args, **kwargs):
        signal.raise_signal(signal.SIGINT)  # as a Ctrl-C arriving while this runs
        return function(*args, **kwargs)

    return interrupted


@pytest.mark.usefixtures("python_sigint")
def test_ctrl_c_while_the_results_are_written_lets_the_run_finish(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(RunDir, "write_results", _interrupt_first(RunDir.write_results))
    assert main(run_args(tmp_path / "r")) == 0
    err = capsys.readouterr().err
    assert "the run has finished" in err and (tmp_path / "r" / "history.json").exists()


@EXTRAS  # the plot needs matplotlib
@pytest.mark.slow
@pytest.mark.usefixtures("python_sigint")
def test_ctrl_c_while_the_plot_is_drawn_exits_0_with_the_plot(tmp_path, capsys, monkeypatch):
    from creps_gym.runner.results import plots

    monkeypatch.setattr(plots, "plot_run_dirs", _interrupt_first(plots.plot_run_dirs))
    args = [a for a in run_args(tmp_path / "r") if a != "--no-plot"]
    assert main(args) == 0
    assert "the run has finished" in capsys.readouterr().err
    assert (tmp_path / "r" / RunDir.PLOT).stat().st_size > 0


# -- item 9: run --help ------------------------------------------------------------------------------------
def _run_help(capsys) -> str:
    with pytest.raises(SystemExit):
        main(["run", "--help"])
    return " ".join(capsys.readouterr().out.split())  # argparse wraps lines


def test_run_help_says_what_each_unset_default_means(capsys):
    text = _run_help(capsys)
    assert "default None" not in text and "default: None" not in text
    meanings = {"--max-episodes": "no limit", "--max-time": "no limit", "--workers": "one per CPU"}
    meanings["--initial-mean"] = "the env-declared mean"
    for flag, meaning in meanings.items():
        assert re.search(rf"{flag} [A-Z_]+ [^(]*\(default: [^)]*{meaning}", text), flag


def test_the_opt_example_of_run_help_is_accepted_by_the_readme_optimizer(capsys):
    readme = (ROOT / "README.md").read_text()
    optimizer = re.search(r"creps-gym run .*?--optimizer (\S+)", readme).group(1)
    example = re.search(r"e\.g\. --opt (\S+=\S+)", _run_help(capsys)).group(1)
    key, value = key_value(example)
    registry.make_optimizer(optimizer, 4, 1, 0, **{key: value})  # the option checks of the optimiser
