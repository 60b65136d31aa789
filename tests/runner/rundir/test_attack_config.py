"""config.json and module references as an attack surface: nothing is imported on a run folder's word
(issue 30 item 11, issue 15 item 13), values the env or optimiser refuses are a damaged run folder, and
deep JSON gets the documented exit codes. The runs attacked are the shared ``templates`` of ``conftest.py``,
copied per test.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from helpers import SPHERE, cli_command, cli_in_process
from rundir_setup import (
    DEEP,
    POSIX,
    deadline,
    edit_config,
    hostile,
    one_error_naming,
)

from creps_gym.cli import main
from creps_gym.errors import RunDirError
from creps_gym.runner import RunDir, resume

PAYLOAD = "import pathlib\npathlib.Path(__file__).with_name('PAYLOAD_RAN').write_text('yes')\n"


cli = cli_in_process  # the commands' behaviour; processes below only where a test needs one


# -- item 13: config.json never makes resume import code --------------------------------------------------
# Gymnasium imports any text before an id's first ":", identifier or not
EVIL_MODULES = ["evil_payload", "1evil", "my-evil", "évil", "evil.payload", " evil_payload", "9"]


def plant_payload(out: Path, module: str) -> None:
    """Files that ``importlib.import_module(module)`` would run from ``out`` (a package for dotted names)."""
    payload = f"open({str(out / 'PAYLOAD_RAN')!r}, 'w').write('yes')\n"
    parts = module.split(".")
    for depth in range(1, len(parts)):
        package = out.joinpath(*parts[:depth])
        package.mkdir()
        (package / "__init__.py").write_text(payload)
    out.joinpath(*parts[:-1], f"{parts[-1]}.py").write_text(payload)


def _refused_message(module: str) -> str:
    return f"config.json: env: expected no reference to a module that is not imported (here {module!r})"


@pytest.mark.parametrize("module", ["evil_payload", "this"])
@pytest.mark.parametrize("entry", ["python-api", "python-m-cli"])
@pytest.mark.slow
def test_resume_never_imports_a_module_named_by_config_json(place, tmp_path, module, entry):
    """In a process started in the run folder (the process boundary; every other name in process below)."""
    out = place("crashed")
    plant_payload(out, module)
    edit_config(out, env=f"{module}:creps_gym/Sphere-v0")
    if entry == "python-api":  # the run directory is the current one, so sys.path[0] (`python -c`)
        code = "from creps_gym.runner import resume; resume('.')"
        command = [sys.executable, "-c", code]
        result = subprocess.run(command, capture_output=True, text=True, cwd=out, timeout=120)
        expected_code, stream = 1, result.stderr
    else:  # `python -m` puts the current directory first on sys.path too
        result = subprocess.run(
            [sys.executable, "-m", "creps_gym.cli", "resume", ".", "--no-plot"],
            capture_output=True,
            text=True,
            cwd=out,
            timeout=120,
        )
        expected_code, stream = 3, result.stderr
        assert "Traceback" not in stream
    assert not (out / "PAYLOAD_RAN").exists()
    assert "Beautiful is better than ugly" not in result.stdout
    assert result.returncode == expected_code, stream
    assert _refused_message(module) in stream
    assert "--import MODULE" in stream


@pytest.mark.parametrize("module", EVIL_MODULES)
@pytest.mark.parametrize("entry", ["python-api", "python-m-cli"])
def test_resume_in_the_run_folder_never_imports_a_module_named_by_config_json(
    place, tmp_path, monkeypatch, module, entry
):
    """Every name, in this process, with the run folder first on ``sys.path`` as ``python -c`` ("") and
    ``python -m`` (the folder) put it."""
    out = place("crashed")
    plant_payload(out, module)
    edit_config(out, env=f"{module}:creps_gym/Sphere-v0")
    monkeypatch.chdir(out)
    monkeypatch.syspath_prepend("" if entry == "python-api" else str(out))
    before = set(sys.modules)
    if entry == "python-api":
        with pytest.raises(RunDirError) as refused:
            resume(".")
        returncode, stream = 1, str(refused.value)
    else:
        result = cli("resume", ".", "--no-plot")
        returncode, stream = result.returncode, result.stderr
        assert "Traceback" not in stream
    assert not (out / "PAYLOAD_RAN").exists()
    assert not {name for name in set(sys.modules) - before if name.split(".")[0] == module.split(".")[0]}
    assert returncode == (1 if entry == "python-api" else 3), stream
    assert _refused_message(module) in stream
    assert "--import MODULE" in stream


@pytest.mark.parametrize("module", EVIL_MODULES)
@pytest.mark.parametrize(
    ("env", "kwargs", "field"),
    [
        ("creps_gym/ReacherTarget-v0", {"env": "{m}:Reacher-v5"}, "env_kwargs.env"),
        ("creps_gym/PointMazeGoal-v0", {"env": "{m}:PointMaze_UMaze-v3"}, "env_kwargs.env"),
        (SPHERE, {"dim": 3, "extra": {"deep": ["ok", {"id": "{m}:X-v0"}]}}, "env_kwargs.extra.deep[1].id"),
        (SPHERE, {"dim": 3, "{m}:key": 1}, "env_kwargs.{m}:key"),
    ],
)
def test_no_string_in_the_env_kwargs_imports_a_module(
    place, tmp_path, monkeypatch, module, env, kwargs, field
):
    out = place("crashed")
    plant_payload(out, module)
    monkeypatch.syspath_prepend(str(out))
    text = json.dumps(kwargs).replace("{m}", module)
    edit_config(out, env=env, env_kwargs=json.loads(text))
    with pytest.raises(RunDirError, match="expected no reference to a module that is not imported") as error:
        resume(out)
    assert str(error.value).startswith(f"{out / RunDir.CONFIG}: {field.replace('{m}', module)}: ")
    assert not (out / "PAYLOAD_RAN").exists() and module not in sys.modules


def test_a_module_reference_is_any_text_before_the_first_colon():
    from creps_gym.runner.rundir.references import module_reference

    assert module_reference("1evil:creps_gym/Sphere-v0") == "1evil"
    assert module_reference("évil:X:Y") == "évil"
    assert module_reference(" os :X") == " os "
    assert module_reference(":X") == ""
    assert module_reference("creps_gym/Sphere-v0") is None


def test_an_unregistered_id_behind_an_imported_module_is_refused(place, tmp_path):
    out = place("crashed")
    edit_config(out, env="os:Foo-v0")  # os is imported, and registers nothing
    result = cli("resume", out, "--no-plot")
    assert result.returncode == 3 and "Traceback" not in result.stderr
    assert "env: expected a registered env id, got 'os:Foo-v0'" in result.stderr


@pytest.mark.parametrize(
    ("changes", "match"),
    [
        ({"initial_std": [1.0, 2.0, 3.0]}, "initial_std: expected a number or 2 numbers"),
        ({"optimizer_options": {"epsilon": -1.0}}, "epsilon"),
    ],
)
def test_config_values_the_optimizer_refuses_are_a_damaged_run_directory(place, tmp_path, changes, match):
    out = place("finished")
    edit_config(out, **changes)
    (out / RunDir.CHECKPOINT).unlink()
    with pytest.raises(RunDirError, match=f"config.json: the env or the optimiser refuses its .*{match}"):
        resume(out)
    result = cli("resume", out, "--no-plot")
    assert result.returncode == 3 and "Traceback" not in result.stderr


def test_env_kwargs_and_optimizer_from_a_run_directory_import_nothing(place, tmp_path, monkeypatch):
    out = place("crashed")
    (out / "evil_payload.py").write_text(PAYLOAD)
    monkeypatch.syspath_prepend(str(out))
    # creps_gym/PointMazeGoal-v0 hands its `env` keyword to gymnasium.make
    edit_config(out, env="creps_gym/PointMazeGoal-v0", env_kwargs={"env": "evil_payload:X-v0"})
    with pytest.raises(RunDirError, match=r"env_kwargs\.env: expected no reference to a module"):
        resume(out)
    edit_config(out, env=SPHERE, env_kwargs={"dim": 2}, optimizer="evil_payload:Optimizer")
    with pytest.raises(RunDirError, match="optimizer: expected a registered optimiser name"):
        resume(out)
    assert "evil_payload" not in sys.modules and not (out / "PAYLOAD_RAN").exists()


@pytest.mark.slow
def test_a_module_named_with_import_on_the_command_line_is_trusted(tmp_path):
    package = tmp_path / "pkg"
    package.mkdir()
    (package / "my_envs.py").write_text(
        "import gymnasium\nfrom creps_gym.envs.functions.suite import SphereEnv\n"
        "gymnasium.register('MyEnvs/Sphere-v0', entry_point=SphereEnv)\n"
    )
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(package), os.environ.get("PYTHONPATH", "")])}
    out = tmp_path / "run"
    args = ["--optimizer", "creps", "--iterations", 3, "--samples", 12, "--seed", 0, "--no-plot"]
    start = cli_command("run", "--env", "MyEnvs/Sphere-v0", "--out", out, *args, "--import", "my_envs")
    assert subprocess.run(start, capture_output=True, env=env, timeout=120).returncode == 0
    (out / RunDir.HISTORY_JSON).unlink()
    refused = subprocess.run(cli_command("resume", out), capture_output=True, text=True, env=env, timeout=120)
    assert refused.returncode == 3 and "env: expected a registered env id" in refused.stderr
    allowed = cli_command("resume", out, "--import", "my_envs", "--no-plot")
    assert subprocess.run(allowed, capture_output=True, env=env, timeout=120).returncode == 0
    assert (out / RunDir.HISTORY_JSON).exists()
    result = cli("resume", out, "--import", "no_such_module_xyz")  # refused before anything is registered
    assert result.returncode == 2 and "argument --import: expected an importable module" in result.stderr


# -- item 11: deep JSON and out-of-range numbers get the documented exit codes -------------------------------
@POSIX
def test_deep_json_in_config_json_gives_exit_3(place, tmp_path, capsys):
    out = place("crashed")
    (out / RunDir.CONFIG).write_text('{"config": ' + DEEP + "}")
    code, error = hostile(capsys, tmp_path, "resume", out, "--no-progress")
    assert code == 3
    assert "nested at most" in one_error_naming(error, out / RunDir.CONFIG)


@POSIX
@pytest.mark.parametrize("flag", ["--opt", "--env-kwarg"])
def test_a_deep_json_flag_gives_exit_2(tmp_path, capsys, flag):
    flags = ["--env", SPHERE, "--optimizer", "creps-cma-old", "--iterations", "2", "--seed", "0"]
    with deadline(), pytest.raises(SystemExit) as exit_:
        main(["run", *flags, "--out", str(tmp_path / "run"), flag, "epsilon=" + DEEP])
    assert exit_.value.code == 2
    assert f"argument {flag}: epsilon: expected JSON nested at most" in capsys.readouterr().err
    assert not (tmp_path / "run").exists()
