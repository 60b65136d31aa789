"""A run directory is untrusted input: no imports, no foreign checkpoints, clear errors, one writer."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from helpers import SPHERE, cli_command, cli_in_process

from creps_gym.cli import main
from creps_gym.errors import RunDirError, RunDirWarning
from creps_gym.runner import History, RunDir, load_history, resume, run

NO_STAGNATION = 10**9  # iterations: the optimiser's stagnation stop never fires

SETTINGS = {
    "iterations": 6,
    "samples_per_iteration": 10,
    "env_kwargs": {"dim": 3},
    "eval_every": 2,
    "checkpoint_every": 2,
}
PAYLOAD = "import pathlib\npathlib.Path(__file__).with_name('PAYLOAD_RAN').write_text('yes')\n"


class Stop(Exception):
    """Raised by a callback to leave a run unfinished (as a crash would)."""


def make_run(path: Path, *, seed: int = 0, stop_after: int | None = None, **changes) -> Path:
    """A finished run in ``path``, or one that crashed after ``stop_after`` iterations."""
    settings = {**SETTINGS, **changes}

    def crash(record, history):
        if stop_after is not None and record.iteration >= stop_after:
            raise Stop

    try:
        run("creps-cma-old", SPHERE, seed=seed, run_dir=path, callbacks=[crash], **settings)
    except Stop:
        pass
    return path


def uninterrupted(seed: int = 0, **changes) -> History:
    return run("creps-cma-old", SPHERE, seed=seed, **{**SETTINGS, **changes})


cli = cli_in_process  # the commands' behaviour; processes below only where a test needs one


def wait_for(ready, process: subprocess.Popen, what: str, timeout: float = 60.0) -> None:
    deadline = time.monotonic() + timeout
    while not ready():
        if process.poll() is not None or time.monotonic() > deadline:
            process.kill()
            pytest.fail(f"{what}: the process ended or timed out: {process.communicate()[1]}")
        time.sleep(0.005)


def iterations_logged(path: Path) -> int:
    log = path / RunDir.LOG
    return (
        sum(line.startswith(b'{"iteration"') for line in log.read_bytes().splitlines()) if log.exists() else 0
    )


def edit_config(path: Path, **changes) -> None:
    document = json.loads((path / RunDir.CONFIG).read_text())
    document["config"].update(changes)
    (path / RunDir.CONFIG).write_text(json.dumps(document))


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
def test_resume_never_imports_a_module_named_by_config_json(tmp_path, module, entry):
    """In a process started in the run folder (the process boundary; every other name in process below)."""
    out = make_run(tmp_path / "run", stop_after=3)
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
            capture_output=True, text=True, cwd=out, timeout=120,
        )  # fmt: skip
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
    tmp_path, monkeypatch, module, entry
):
    """Every name, in this process, with the run folder first on ``sys.path`` as ``python -c`` ("") and
    ``python -m`` (the folder) put it."""
    out = make_run(tmp_path / "run", stop_after=3)
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
def test_no_string_in_the_env_kwargs_imports_a_module(tmp_path, monkeypatch, module, env, kwargs, field):
    out = make_run(tmp_path / "run", stop_after=3)
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


def test_an_unregistered_id_behind_an_imported_module_is_refused(tmp_path):
    out = make_run(tmp_path / "run", stop_after=3)
    edit_config(out, env="os:Foo-v0")  # os is imported, and registers nothing
    result = cli("resume", out, "--no-plot")
    assert result.returncode == 3 and "Traceback" not in result.stderr
    assert "env: expected a registered env id, got 'os:Foo-v0'" in result.stderr


@pytest.mark.parametrize(
    ("changes", "match"),
    [
        ({"initial_std": [1.0, 2.0]}, "initial_std: expected a number or 3 numbers"),
        ({"optimizer_options": {"epsilon": -1.0}}, "epsilon"),
    ],
)
def test_config_values_the_optimizer_refuses_are_a_damaged_run_directory(tmp_path, changes, match):
    out = make_run(tmp_path / "run")
    edit_config(out, **changes)
    (out / RunDir.CHECKPOINT).unlink()
    with pytest.raises(RunDirError, match=f"config.json: the env or the optimiser refuses its .*{match}"):
        resume(out)
    result = cli("resume", out, "--no-plot")
    assert result.returncode == 3 and "Traceback" not in result.stderr


def test_env_kwargs_and_optimizer_from_a_run_directory_import_nothing(tmp_path, monkeypatch):
    out = make_run(tmp_path / "run", stop_after=3)
    (out / "evil_payload.py").write_text(PAYLOAD)
    monkeypatch.syspath_prepend(str(out))
    # creps_gym/PointMazeGoal-v0 hands its `env` keyword to gymnasium.make
    edit_config(out, env="creps_gym/PointMazeGoal-v0", env_kwargs={"env": "evil_payload:X-v0"})
    with pytest.raises(RunDirError, match=r"env_kwargs\.env: expected no reference to a module"):
        resume(out)
    edit_config(out, env=SPHERE, env_kwargs={"dim": 3}, optimizer="evil_payload:Optimizer")
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
    missing = cli_command("resume", out, "--import", "no_such_module_xyz")
    result = subprocess.run(missing, capture_output=True, text=True, timeout=120)
    assert result.returncode == 2 and "argument --import: expected an importable module" in result.stderr


# -- item 14: a checkpoint belongs to its run -------------------------------------------------------------
@pytest.mark.parametrize(
    "other", [{"seed": 2}, {"env_kwargs": {"dim": 4}}, {"iterations": 10}], ids=["seed", "dim", "iterations"]
)
def test_a_checkpoint_copied_from_another_run_is_refused_at_once(tmp_path, other):
    mine = make_run(tmp_path / "mine", seed=1, stop_after=3)
    theirs = make_run(tmp_path / "theirs", **{"seed": 1, **other})
    shutil.copy(theirs / RunDir.CHECKPOINT, mine / RunDir.CHECKPOINT)
    before = (mine / RunDir.LOG).read_bytes()
    result = cli("resume", mine, "--no-plot")
    assert result.returncode == 3 and "Traceback" not in result.stderr
    assert f"{mine / RunDir.CHECKPOINT}: expected the checkpoint of the run configured in config.json" in (
        result.stderr
    )
    assert (mine / RunDir.LOG).read_bytes() == before  # refused before anything ran


def test_a_folder_with_a_checkpoint_and_no_config_is_not_a_run(tmp_path):
    old = make_run(tmp_path / "old", iterations=8)
    (old / RunDir.CONFIG).unlink()
    checkpoint = (old / RunDir.CHECKPOINT).read_bytes()
    assert main(["resume", str(old), "--no-plot"]) == 3
    args = ["run", "--env", SPHERE, "--optimizer", "creps-cma-old", "--iterations", "4", "--samples", "12"]
    args += ["--seed", "0", "--env-kwarg", "dim=3", "--out", str(old), "--no-plot"]
    assert main(args) == 3 and (old / RunDir.CHECKPOINT).read_bytes() == checkpoint
    with pytest.raises(FileExistsError, match=r"but no config\.json"):
        run("creps-cma-old", SPHERE, 4, 10, 0, env_kwargs={"dim": 3}, run_dir=old)
    assert main([*args, "--overwrite"]) == 0  # the user says so: the old files go
    assert len(History.from_json(old / RunDir.HISTORY_JSON)) == 4


# -- item 1: damaged files get a clear error naming the file (exit code 3) -------------------------------
def truncate(path: Path) -> None:
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])


def flip_bit(path: Path) -> None:
    data = bytearray(path.read_bytes())
    data[len(data) // 2] ^= 0x10
    path.write_bytes(bytes(data))


@pytest.mark.parametrize(
    ("name", "damage"),
    [
        (RunDir.CHECKPOINT, truncate),
        (RunDir.CHECKPOINT, lambda p: p.write_bytes(b"")),
        (RunDir.CHECKPOINT, flip_bit),
        (RunDir.CONFIG, truncate),
        (RunDir.CONFIG, lambda p: p.write_text("[]")),
    ],
    ids=[
        "checkpoint-truncated",
        "checkpoint-empty",
        "checkpoint-bit-flip",
        "config-truncated",
        "config-list",
    ],
)
def test_a_damaged_file_gives_exit_code_3_naming_the_file(tmp_path, capsys, name, damage):
    out = make_run(tmp_path / "run", stop_after=3)
    damage(out / name)
    assert main(["resume", str(out), "--no-plot"]) == 3
    error = capsys.readouterr().err
    assert f"{out / name}: damaged or not written by creps_gym (" in error
    assert ("delete it to restart" if name == RunDir.CHECKPOINT else "restore it from a backup") in error


# -- item 2: a finished run can always be completed --------------------------------------------------------
@pytest.mark.parametrize("damage", ["missing", "truncated"])
def test_resume_rewrites_missing_or_damaged_result_files(tmp_path, damage):
    out = make_run(tmp_path / "run")
    results = (RunDir.HISTORY_JSON, RunDir.HISTORY_CSV, RunDir.IOH)
    expected = {name: (out / name).read_bytes() for name in results}
    for name in results:
        (out / name).unlink() if damage == "missing" else truncate(out / name)
    assert main(["resume", str(out), "--no-plot"]) == 0
    for name in results:
        if name == RunDir.HISTORY_JSON:
            assert json.loads((out / name).read_bytes()) == json.loads(expected[name])
        else:
            assert (out / name).read_bytes() == expected[name], name
    assert History.from_json(out / RunDir.HISTORY_JSON).equals(uninterrupted())
    assert RunDir.open(out).read_log()[1][-1]["rewritten"] == list(results)


# -- item 3: no silent loss in load_history, export and plot ---------------------------------------------
def damage_log_line(path: Path, iteration: int) -> None:
    lines = path.read_text().splitlines(keepends=True)
    index = next(i for i, line in enumerate(lines) if line.startswith(f'{{"iteration": {iteration},'))
    lines[index] = lines[index].replace('"mean_return": -', '"mean_return": -1')  # a changed value
    path.write_text("".join(lines))


def test_a_damaged_log_line_ends_the_history_before_it_and_a_resume_refuses_it(tmp_path):
    """The checkpoint holds no history (O(1) checkpoints): a log line lost before it cannot be recovered."""
    out = make_run(tmp_path / "run", stop_after=5)  # checkpoint at 4, iterations 5 logged after it
    expected = uninterrupted().records[:5]
    assert History(load_history(out).records).equals(History(expected))
    damage_log_line(out / RunDir.LOG, 2)
    said = r"damaged lines \[3\]; logged iterations 3 to 5 follow a gap and are left out; the history has "
    with pytest.warns(RunDirWarning, match=said + r"iterations 1 to 1$"):
        history = load_history(out)
    assert History(history.records).equals(History(expected[:1]))
    lost = r"log.jsonl: damaged .*iterations 1 to 4 are not all intact \(damaged lines \[3\]\)\); the"
    with pytest.raises(RunDirError, match=lost):
        resume(out)


def test_a_resume_refuses_a_log_edited_before_the_checkpoint(tmp_path):
    """A changed record whose line checksum was recomputed still differs from the checkpoint's checksum."""
    out = make_run(tmp_path / "run", stop_after=5)
    lines = (out / RunDir.LOG).read_text().splitlines(keepends=True)
    index = next(i for i, line in enumerate(lines) if line.startswith('{"iteration": 2,'))
    entry = json.loads(lines[index])
    entry.pop("crc32")
    entry["mean_return"] += 1.0
    RunDir.open(out).append_log(entry)  # a well-formed line: the last copy of iteration 2 counts
    edited = r"log.jsonl: damaged .*iterations 1 to 4 differ from those checkpointed"
    with pytest.raises(RunDirError, match=edited):
        resume(out)


def test_export_of_a_damaged_history_json_rebuilds_it_and_warns(tmp_path, capsys):
    out = make_run(tmp_path / "run")
    expected = (out / RunDir.IOH).read_text()
    truncate(out / RunDir.HISTORY_JSON)
    assert main(["export", str(out), "-o", str(tmp_path / "ioh.csv")]) == 0
    error = capsys.readouterr().err
    assert f"creps-gym export: warning: {out / RunDir.HISTORY_JSON}: damaged (JSONDecodeError" in error
    assert (tmp_path / "ioh.csv").read_text() == expected


# -- item 5: one writer per run directory; only the run's own temporaries are removed ---------------------
@pytest.mark.slow
def test_a_second_writer_is_refused_while_the_first_lives(tmp_path):
    out = tmp_path / "run"
    # no stagnation stop: with it the run may end within seconds, while the live run must outlast the test
    args = ["--env", SPHERE, "--optimizer", "creps-cma-old", "--iterations", 100000, "--samples", 12,
            "--seed", 0, "--opt", f"tolstagnation={NO_STAGNATION}"]  # fmt: skip
    live = subprocess.Popen(
        cli_command("run", *args, "--out", out, "--checkpoint-every", 1, "--no-plot"),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        wait_for(lambda: (out / RunDir.CHECKPOINT).exists(), live, "first checkpoint")
        second = cli("resume", out, "--no-plot", timeout=60)
        assert second.returncode == 3, second.stderr
        assert f"process {live.pid} on " in second.stderr
        assert f"writes this run directory (lock file {out / RunDir.LOCK})" in second.stderr
        overwrite = cli("run", *args, "--out", out, "--overwrite", "--no-plot", timeout=60)
        assert overwrite.returncode == 3 and "writes this run directory" in overwrite.stderr
        assert live.poll() is None  # the live run was not disturbed
    finally:
        live.send_signal(signal.SIGKILL)
        live.wait(timeout=30)
    # the lock of the killed process is taken over (a shorter run: its checkpoint no longer matches)
    edit_config(out, iterations=3)
    (out / RunDir.CHECKPOINT).unlink()
    with pytest.warns(
        RunDirWarning, match=f"took over the lock of process {live.pid} on .*, which no longer runs"
    ):
        assert len(resume(out)) == 3
    assert not (out / RunDir.LOCK).exists()


def test_only_the_runs_own_temporary_files_are_removed(tmp_path):
    out = make_run(tmp_path / "run", stop_after=3)
    mine = ["notes.tmp", ".hidden.tmp", "checkpoint.tmp", ".config.json.tmp"]
    theirs = [".history.json.123.tmp", "checkpoint.npzab12_x9q.tmp"]  # left by a killed writer
    for name in mine + theirs:
        (out / name).write_text("x")
    resume(out)
    assert sorted(p.name for p in out.iterdir() if p.name.endswith(".tmp")) == sorted(mine)
    for name in theirs:
        (out / name).write_text("x")
    assert main(["run", "--env", SPHERE, "--optimizer", "creps", "--iterations", "2", "--samples", "12",
                 "--seed", "0", "--out", str(out), "--overwrite", "--no-plot"]) == 0  # fmt: skip
    assert sorted(p.name for p in out.iterdir() if p.name.endswith(".tmp")) == sorted(mine)


# -- issue 16.2: --out means what it says -------------------------------------------------------------------
def test_out_refuses_a_folder_that_is_neither_empty_nor_a_run(tmp_path, capsys):
    folder = tmp_path / "photos"
    folder.mkdir()
    (folder / "holiday.jpg").write_text("x")
    args = ["run", "--env", SPHERE, "--optimizer", "creps", "--iterations", "2", "--samples", "12"]
    for extra in ([], ["--overwrite"]):
        assert main([*args, "--seed", "0", "--out", str(folder), "--no-plot", *extra]) == 3
        assert "which holds other files (holiday.jpg); choose another directory" in capsys.readouterr().err
    assert sorted(os.listdir(folder)) == ["holiday.jpg"]
    with pytest.raises(FileExistsError, match="holds other files"):
        run("creps", SPHERE, 2, 12, 0, run_dir=folder)
    empty = tmp_path / "empty"
    empty.mkdir()
    assert len(run("creps", SPHERE, 2, 12, 0, run_dir=empty)) == 2
    with pytest.raises(FileExistsError, match="holds a run"):
        run("creps", SPHERE, 3, 12, 0, run_dir=empty)
    assert len(run("creps", SPHERE, 3, 12, 0, run_dir=empty, overwrite=True)) == 3


# -- issue 16.6: Ctrl-C leaves a checkpoint ---------------------------------------------------------------
@pytest.mark.skipif(sys.platform == "win32", reason="needs SIGINT to a subprocess")
@pytest.mark.slow
def test_ctrl_c_checkpoints_so_that_resume_loses_nothing(tmp_path):
    out = tmp_path / "run"
    # Long enough that the run is still going when the signal comes (an iteration takes about 2 ms): the
    # stagnation stop is off, since with it the run would end on its own after 186 iterations.
    args = ["--env", SPHERE, "--optimizer", "creps-cma-old", "--iterations", 3000, "--samples", 10,
            "--seed", 3, "--env-kwarg", "dim=3", "--checkpoint-every", 100000, "--eval-every", 2,
            "--opt", f"tolstagnation={NO_STAGNATION}"]  # fmt: skip
    process = subprocess.Popen(
        cli_command("run", *args, "--out", out, "--no-plot"),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        # A shell without job control starts background jobs with SIGINT ignored, and the child would inherit
        # that (`nohup pytest &` failed this test): restore the default, so Python installs its handler.
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    wait_for(lambda: iterations_logged(out) >= 5, process, "5 iterations")
    process.send_signal(signal.SIGINT)
    _, stderr = process.communicate(timeout=60)
    assert process.returncode == 130, stderr
    assert b"interrupted" in stderr and b"Traceback" not in stderr
    records, _ = RunDir.open(out).read_log()
    state = RunDir.open(out).load_checkpoint()[0]
    assert 5 <= state["iteration"] == records[-1].iteration < 3000  # nothing done after the checkpoint
    assert main(["resume", str(out), "--no-plot"]) == 0
    expected = run(
        "creps-cma-old", SPHERE, 3000, 10, 3, env_kwargs={"dim": 3}, eval_every=2,
        optimizer_options={"tolstagnation": NO_STAGNATION},
    )  # fmt: skip
    assert History.from_json(out / RunDir.HISTORY_JSON).equals(expected)


# -- issue 15 item 15: sizes that would exhaust the machine are refused up front ---------------------------
def limited_memory(gigabytes: float):
    def limit():  # so that a missing guard fails with MemoryError instead of hurting the machine
        import resource

        resource.setrlimit(resource.RLIMIT_AS, (int(gigabytes * 2**30),) * 2)

    return limit


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc/meminfo, sets RLIMIT_AS")
@pytest.mark.parametrize(
    ("flags", "expected"),
    [
        (
            ["--env-kwarg", "dim=1000000000"],
            "argument --env-kwarg: dim: expected a size whose arrays fit in memory",
        ),
        (["--env-kwarg", "dim=60000"], "argument --env-kwarg: expected a size whose arrays fit in memory"),
        (["--samples", "10000000000"], "argument --samples: expected a size whose arrays fit in memory"),
        (
            ["--eval-contexts", "100000000000"],
            "argument --eval-contexts: expected a size whose arrays fit in memory",
        ),
        (
            ["--env-kwarg", "context_dim=1000000000000"],
            "argument --env-kwarg: context_dim: expected a size whose arrays fit in memory",
        ),
    ],
    ids=["function-arrays", "covariance", "batch", "evaluation", "context-arrays"],
)
@pytest.mark.slow
def test_sizes_that_would_exhaust_memory_are_refused_before_allocating(tmp_path, flags, expected):
    args = ["run", "--env", SPHERE, "--optimizer", "creps-cma-old", "--iterations", 2, "--samples", 12]
    args += ["--seed", 0, "--out", tmp_path / "run", "--no-plot"]
    for flag, value in zip(flags[::2], flags[1::2], strict=True):
        args = args[: args.index(flag)] + args[args.index(flag) + 2 :] if flag in args else args
        args += [flag, value]
    result = subprocess.run(
        cli_command(*args), capture_output=True, text=True, timeout=120, preexec_fn=limited_memory(6)
    )
    assert result.returncode == 2 and expected in result.stderr, result.stderr
    assert "GiB available" in result.stderr and not (tmp_path / "run").exists()


def test_a_rotated_function_too_big_for_memory_is_refused_by_the_env():
    import gymnasium as gym

    with pytest.raises(ValueError, match=r"dim: expected a size whose arrays fit in memory \(the instance's"):
        gym.make("creps_gym/ShiftedRotatedElliptic-v0", dim=2_000_000)  # 2 p x p rotation matrices: 64 TB


def test_a_reacher_with_too_many_basis_functions_for_memory_is_refused_by_the_env():
    import gymnasium as gym

    with pytest.raises(ValueError, match=r"n_basis: expected a size whose arrays fit in memory .*got 10{11}"):
        gym.make("creps_gym/PlanarReacher-v0", n_basis=10**11)
