"""The machine's resources as an attack surface: failing writes (full disk, read-only file system, file
size limits), a second writer, Ctrl-C, stale temporaries and sizes that would exhaust memory (issue 30
item 10, issue 16 items 2 and 6, issue 15 item 15): each is named, refused up front or loses nothing. The
runs attacked are the shared ``templates`` of ``conftest.py``, copied per test.
"""

from __future__ import annotations

import errno
import os
import resource
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from helpers import SPHERE, cli_command, cli_in_process, file_size_limited, run_argv
from rundir_setup import (
    POSIX,
    checked_cli,
    edit_config,
    one_error_naming,
)

from creps_gym.cli import main
from creps_gym.errors import RunDirWarning
from creps_gym.runner import History, RunDir, resume, run


def six_iterations(out) -> list:
    """``creps-gym run`` of 6 CREPS-CMA iterations on the 2-D sphere into ``out``, checkpointing every 2."""
    short = ("--env-kwarg", "dim=2", "--samples", 10, "--eval-every", 2, "--checkpoint-every", 2)
    return run_argv(out, *short, "--no-progress", "--no-plot", optimizer="creps-cma-old", iterations=6)


# -- item 10: operating-system errors are named, and lose nothing --------------------------------------------
@POSIX
@pytest.mark.parametrize("code", [errno.ENOSPC, errno.EROFS, errno.EFBIG])
@pytest.mark.parametrize("failing", ["log", "checkpoint"])
def test_a_write_that_fails_stops_the_run_with_exit_3_and_resume_is_bit_identical(
    tmp_path, capsys, monkeypatch, templates, code, failing
):
    out = tmp_path / "run"
    calls = {"n": 0}
    if failing == "log":
        from creps_gym.runner.rundir import files

        real = files._write_all

        def write_all(fd, data):
            calls["n"] += bytes(data[:2]) != b"PK"  # the policy files (zips) are not counted
            if calls["n"] == 6:  # config.json, versions.json, "start", iterations 1, 2 (checkpoint), 3
                raise OSError(code, os.strerror(code))
            real(fd, data)

        monkeypatch.setattr(files, "_write_all", write_all)
    else:
        import creps_gym.runner.rundir as rundir

        real_save = rundir.save_state

        def save(flat, path):
            calls["n"] += 1
            if calls["n"] == 2:
                raise OSError(code, os.strerror(code))
            return real_save(flat, path)

        monkeypatch.setattr(rundir, "save_state", save)
    exit_code, error = checked_cli(capsys, *six_iterations(out))
    assert exit_code == 3
    name = RunDir.LOG if failing == "log" else RunDir.CHECKPOINT
    assert f"({os.strerror(code)}, {errno.errorcode[code]})" in one_error_naming(error, out / name)
    assert not [p for p in out.iterdir() if p.name.endswith(".tmp")]
    monkeypatch.undo()
    assert resume(out).equals(templates["history"])  # nothing lost


@POSIX
@pytest.mark.slow
def test_a_file_size_limit_gives_exit_3_not_a_signal_and_resume_is_bit_identical(tmp_path, templates):
    out = tmp_path / "run"

    command = cli_command(*six_iterations(out))  # `ulimit -f 2`: log.jsonl outgrows it
    done = subprocess.run(command, capture_output=True, text=True, timeout=120, **file_size_limited(2048))
    assert done.returncode == 3, (done.returncode, done.stderr)  # not -SIGXFSZ
    assert "File too large, EFBIG" in one_error_naming(done.stderr, out)
    assert resume(out).equals(templates["history"])


NO_STAGNATION = 10**9  # iterations: the optimiser's stagnation stop never fires


def endless_run(out, iterations: int, *extra, seed: int = 0) -> list:
    """``creps-gym run`` of CREPS-CMA on the sphere into ``out``, no stagnation stop, then ``extra``."""
    never = ("--opt", f"tolstagnation={NO_STAGNATION}")
    return run_argv(out, *never, *extra, optimizer="creps-cma-old", iterations=iterations, seed=seed)


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


# -- item 5: one writer per run directory; only the run's own temporaries are removed ---------------------
@pytest.mark.slow
def test_a_second_writer_is_refused_while_the_first_lives(tmp_path):
    out = tmp_path / "run"
    # no stagnation stop: with it the run may end within seconds, while the live run must outlast the test
    args = endless_run(out, 100000, "--samples", 12)
    live = subprocess.Popen(
        cli_command(*args, "--checkpoint-every", 1, "--no-plot"),
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
        overwrite = cli(*args, "--overwrite", "--no-plot", timeout=60)
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


def test_only_the_runs_own_temporary_files_are_removed(place, tmp_path):
    out = place("crashed")
    mine = ["notes.tmp", ".hidden.tmp", "checkpoint.tmp", ".config.json.tmp"]
    theirs = [".history.json.123.tmp", "checkpoint.npzab12_x9q.tmp"]  # left by a killed writer
    for name in mine + theirs:
        (out / name).write_text("x")
    resume(out)
    assert sorted(p.name for p in out.iterdir() if p.name.endswith(".tmp")) == sorted(mine)
    for name in theirs:
        (out / name).write_text("x")
    assert (
        main(
            [
                "run",
                "--env",
                SPHERE,
                "--optimizer",
                "creps",
                "--iterations",
                "2",
                "--samples",
                "12",
                "--seed",
                "0",
                "--out",
                str(out),
                "--overwrite",
                "--no-plot",
            ]
        )
        == 0
    )
    assert sorted(p.name for p in out.iterdir() if p.name.endswith(".tmp")) == sorted(mine)


# -- issue 16.6: Ctrl-C leaves a checkpoint ---------------------------------------------------------------
@pytest.mark.skipif(sys.platform == "win32", reason="needs SIGINT to a subprocess")
@pytest.mark.slow
def test_ctrl_c_checkpoints_so_that_resume_loses_nothing(tmp_path):
    out, iterations = tmp_path / "run", 1000
    # Long enough that the run is still going when the signal comes (an iteration takes about 2 ms, so 1,000
    # take 2 s after the 5th): the stagnation stop is off, since with it the run would end after 186.
    args = endless_run(out, iterations, "--samples", 10, "--env-kwarg", "dim=3", "--eval-every", 2, seed=3)
    args += ["--checkpoint-every", 100000]
    process = subprocess.Popen(
        cli_command(*args, "--no-plot"),
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
    assert 5 <= state["iteration"] == records[-1].iteration < iterations  # nothing done after the checkpoint
    assert main(["resume", str(out), "--no-plot"]) == 0
    expected = run(
        "creps-cma-old",
        SPHERE,
        iterations,
        10,
        3,
        env_kwargs={"dim": 3},
        eval_every=2,
        optimizer_options={"tolstagnation": NO_STAGNATION},
    )
    assert History.from_json(out / RunDir.HISTORY_JSON).equals(expected)


# -- issue 15 item 15: sizes that would exhaust the machine are refused up front ---------------------------
def limited_memory(gigabytes: float):
    def limit():  # so that a missing guard fails with MemoryError instead of hurting the machine

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


@POSIX
def test_the_threat_model_in_the_runner_guide_quotes_the_limits_the_code_applies():
    from creps_gym._validation import MAX_JSON_DEPTH
    from creps_gym.runner.rundir import files

    guide = (Path(__file__).resolve().parents[3] / "docs" / "runner.md").read_text(encoding="utf-8")
    section = guide[guide.index("### Threat model") : guide.index("- **No code from a run directory.**")]
    quoted = " ".join(section.split())
    assert files.LIMITS == {"config.json": 16 << 20, "versions.json": 16 << 20, "run.lock": 4096}
    assert "`config.json` and `versions.json` 16 MiB, `run.lock` 4 kB, every other file 1 GiB" in quoted
    assert files.DEFAULT_LIMIT == 1 << 30 and f"more than {MAX_JSON_DEPTH} levels deep" in quoted
