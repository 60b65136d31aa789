"""A hostile run directory: planted links, FIFOs, devices, deep JSON, oversized files, forged log lines, and
operating-system errors (issue 30, items 2, 3, 5, 8, 10 and 11).

Each case checks the exit code, one error line naming the file, that nothing outside the run directory
changed (a snapshot of a sibling folder the links point into), that no process is left behind, and that
it ends in bounded time. Exit codes come from ``creps_gym.cli.main`` in this process (a subprocess only
where a process limit or a signal is the point); everything else uses the Python API.
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import resource
import shutil
import signal
import subprocess
import sys
import time
import zlib
from pathlib import Path

import numpy as np
import pytest
from helpers import SPHERE, cli_command

from creps_gym.cli import main
from creps_gym.errors import RunDirError, RunDirWarning
from creps_gym.optimizers import CREPSCMA
from creps_gym.optimizers.base import load_state, save_state
from creps_gym.optimizers.state_files import JSON_KEY
from creps_gym.runner import History, RunDir, load_history, resume, run
from creps_gym.runner.backends.watchdog import child_pids
from creps_gym.runner.results.export import write_iohanalyzer

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="POSIX files, /proc, rlimits")

SETTINGS = {"iterations": 6, "samples_per_iteration": 10, "env_kwargs": {"dim": 2}, "eval_every": 2,
            "checkpoint_every": 2}  # fmt: skip
SECONDS = 30  # every hostile case must end well within this
DEEP = "[" * 100_000 + "]" * 100_000


class Stop(Exception):
    """Raised by a callback to leave a run unfinished (as a crash would)."""


def make_run(path: Path, *, seed: int = 0, stop_after: int | None = None) -> Path:
    def crash(record, history):
        if stop_after is not None and record.iteration >= stop_after:
            raise Stop

    with contextlib.suppress(Stop):
        run("creps-cma-old", SPHERE, seed=seed, run_dir=path, callbacks=[crash], **SETTINGS)
    return path


@pytest.fixture(scope="module")
def templates(tmp_path_factory):
    """Runs to copy: finished, crashed after 3 (checkpoint at 2), seed 1 crashed after 4; the full history."""
    root = tmp_path_factory.mktemp("hostile")
    return {
        "finished": make_run(root / "finished"),
        "crashed": make_run(root / "crashed", stop_after=3),
        "other": make_run(root / "other", seed=1, stop_after=4),
        "history": run("creps-cma-old", SPHERE, seed=0, **SETTINGS),
    }


@pytest.fixture
def place(tmp_path, templates):
    """``place(name)``: a copy of a template run in ``tmp_path/run``; ``tmp_path/outside`` holds victims."""
    outside = tmp_path / "outside"
    outside.mkdir()
    (outside / "victim").write_bytes(b"not the run's\n")

    def copy(name: str) -> Path:
        return Path(shutil.copytree(templates[name], tmp_path / "run"))

    return copy


def snapshot(folder: Path) -> dict[str, tuple]:
    """Every entry under ``folder``: its kind and content (or link target), and its mode."""
    found = {}
    for path in sorted(folder.rglob("*")):
        info = path.lstat()
        content = os.readlink(path) if path.is_symlink() else path.read_bytes() if path.is_file() else None
        found[str(path.relative_to(folder))] = (info.st_mode, content, info.st_size)
    return found


@contextlib.contextmanager
def deadline(seconds: float = SECONDS):
    """Fail a call that blocks (e.g. opening a FIFO) instead of hanging the test session."""

    def expire(*_):
        raise TimeoutError(f"still running after {seconds} s")

    previous = signal.signal(signal.SIGALRM, expire)
    signal.alarm(int(seconds))
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)


def cli(capsys, *args) -> tuple[int, str]:
    """Exit code and stderr of ``creps-gym ARGS`` run here; checks the hostile-case invariants."""
    start = time.monotonic()
    with deadline():
        code = main([str(a) for a in args])
    assert time.monotonic() - start < SECONDS
    error = capsys.readouterr().err
    assert "Traceback" not in error
    assert not child_pids(os.getpid()), "a process was left running"
    return code, error


def hostile(capsys, tmp_path, *args) -> tuple[int, str]:
    """:func:`cli`, and nothing outside the run directory changed."""
    before = snapshot(tmp_path / "outside")
    code, error = cli(capsys, *args)
    assert snapshot(tmp_path / "outside") == before
    return code, error


def one_error_naming(error: str, path: Path) -> str:
    lines = [line for line in error.splitlines() if ": error: " in line]
    assert len(lines) == 1, error
    assert str(path) in lines[0], error
    return lines[0]


def rewrite_checkpoint(path: Path, edit) -> None:
    """Edit the loop state of a checkpoint with ``edit(flat)`` and keep its checksum right."""
    flat = load_state(path)
    edit(flat)
    state = {k: v for k, v in flat.items() if not k.startswith("optimizer.")}
    state = {k: v for k, v in state.items() if k not in ("format", "fingerprint", "state_crc")}
    flat["state_crc"] = zlib.crc32(json.dumps(state, sort_keys=True).encode())
    save_state(flat, path)


# -- item 2: nothing is written (or read) through a link planted in a run directory --------------------------
LINKED = [RunDir.LOCK, RunDir.LOG, RunDir.PLOT, RunDir.CHECKPOINT, RunDir.CONFIG, RunDir.HISTORY_JSON,
          RunDir.HISTORY_CSV, RunDir.IOH]  # fmt: skip


@pytest.mark.parametrize("name", LINKED)
@pytest.mark.slow
def test_resume_refuses_a_link_planted_in_the_run_directory(place, tmp_path, capsys, name):
    if name == "learning_curve.png":
        pytest.importorskip("matplotlib")  # written only where it can be drawn
    out = place("crashed")
    victim = tmp_path / "outside" / "victim"
    if (out / name).exists():  # a copy of the real file, so that following the link would go on unnoticed
        shutil.copyfile(out / name, victim)
        (out / name).unlink()
    (out / name).symlink_to(victim)
    code, error = hostile(capsys, tmp_path, "resume", out, "--no-progress")
    assert code == 3
    assert "expected a regular file, got a symbolic link" in one_error_naming(error, out / name)


def test_run_out_refuses_a_folder_holding_only_a_linked_lock(tmp_path, capsys):
    (tmp_path / "outside").mkdir()
    victim = tmp_path / "outside" / "victim"
    victim.write_text("keep me\n")
    out = tmp_path / "new"
    out.mkdir()
    (out / RunDir.LOCK).symlink_to(victim)
    flags = ["--env", SPHERE, "--env-kwarg", "dim=2", "--optimizer", "creps-cma-old", "--iterations", "2"]
    code, error = hostile(capsys, tmp_path, "run", *flags, "--seed", "0", "--out", out, "--no-progress")
    assert code == 3
    one_error_naming(error, out / RunDir.LOCK)
    assert sorted(p.name for p in out.iterdir()) == [RunDir.LOCK]


# -- item 5: FIFOs, devices and oversized files are never read -----------------------------------------------
@pytest.mark.parametrize("name", [RunDir.LOG, RunDir.CHECKPOINT, RunDir.CONFIG, RunDir.HISTORY_JSON])
@pytest.mark.parametrize("command", ["resume", "export"])
def test_a_fifo_in_a_run_directory_never_blocks(place, tmp_path, capsys, name, command):
    out = place("crashed" if name != RunDir.HISTORY_JSON else "finished")
    (out / name).unlink()
    os.mkfifo(out / name)
    args = (out, "--no-progress") if command == "resume" else (out, "-o", tmp_path / "e.csv")
    code, error = hostile(capsys, tmp_path, command, *args)
    assert code == 3
    assert "got a FIFO" in one_error_naming(error, out / name)


@pytest.mark.slow
def test_a_log_linked_to_dev_zero_is_not_read_until_memory_runs_out(place, tmp_path):
    out = place("crashed")
    (out / RunDir.LOG).unlink()
    (out / RunDir.LOG).symlink_to("/dev/zero")

    def limit_memory():
        resource.setrlimit(resource.RLIMIT_AS, (3 << 30, 3 << 30))

    start = time.monotonic()
    done = subprocess.run(cli_command("export", out, "-o", tmp_path / "e.csv"), capture_output=True,
                          text=True, timeout=120, preexec_fn=limit_memory)  # fmt: skip
    assert time.monotonic() - start < 120
    assert done.returncode == 3, done.stderr
    one_error_naming(done.stderr, out / RunDir.LOG)


def test_devices_and_oversized_files_are_refused_before_reading(tmp_path):
    from creps_gym.runner.rundir import files

    with pytest.raises(RunDirError, match="got a character device"):
        files.read_run_file("/dev/zero")
    big = tmp_path / "config.json"
    with open(big, "wb") as stream:
        stream.truncate(files.LIMITS["config.json"] + 1)  # sparse: nothing is written
    with pytest.raises(RunDirError, match=f"expected at most {files.LIMITS['config.json']} bytes"):
        files.read_run_file(big)
    assert files.DEFAULT_LIMIT >= 1 << 30  # generous: about two million iterations of log


def test_an_oversized_log_is_refused_with_exit_code_3(place, tmp_path, capsys):
    from creps_gym.runner.rundir import files

    out = place("crashed")
    with open(out / RunDir.LOG, "r+b") as stream:
        stream.truncate(files.DEFAULT_LIMIT + 1)  # sparse: a hole of zeros, nothing is written
    code, error = hostile(capsys, tmp_path, "export", out, "-o", tmp_path / "e.csv")
    assert code == 3
    assert "expected at most" in one_error_naming(error, out / RunDir.LOG)


# -- item 3: -o writes what the user named -------------------------------------------------------------------
def test_export_writes_through_a_link_and_prints_the_file_written(place, tmp_path, capsys):
    out = place("finished")
    target, link = tmp_path / "outside" / "target.csv", tmp_path / "link.csv"
    target.write_text("old\n")
    link.symlink_to(target)
    code, _ = cli(capsys, "export", out, "-o", link)
    assert code == 0
    assert link.is_symlink() and target.read_text().startswith("evaluations,value")
    # (cli() consumed the output: run it again to see what is printed)
    assert main(["export", str(out), "-o", str(link)]) == 0
    assert capsys.readouterr().out.strip() == f"IOHanalyzer CSV: {target} (through the link {link})"


@pytest.mark.parametrize("kind", ["fifo", "directory", "own-log", "own-history-through-a-link"])
@pytest.mark.parametrize("command", ["export", "plot"])
def test_output_not_a_regular_file_or_a_run_file_is_refused(place, tmp_path, capsys, kind, command):
    if command == "plot":
        pytest.importorskip("matplotlib")
    out = place("finished")
    target = {"fifo": tmp_path / "fifo", "directory": tmp_path / "folder", "own-log": out / RunDir.LOG,
              "own-history-through-a-link": tmp_path / "link"}[kind]  # fmt: skip
    if kind == "fifo":
        os.mkfifo(target)
    elif kind == "directory":
        target.mkdir()
    elif kind == "own-history-through-a-link":
        target.symlink_to(out / RunDir.HISTORY_JSON)
    before = snapshot(tmp_path)
    code, error = cli(capsys, command, out, "-o", target)
    assert code == 2
    assert "argument -o/--output: expected a" in one_error_naming(error, target.resolve())
    assert snapshot(tmp_path) == before


@pytest.mark.slow
def test_plot_without_an_extension_writes_a_png_to_exactly_that_path(place, tmp_path, capsys):
    pytest.importorskip("matplotlib")
    out = place("finished")
    assert main(["plot", str(out), "-o", str(tmp_path / "curves")]) == 0
    assert capsys.readouterr().out.strip() == f"plot: {tmp_path / 'curves'}"
    assert (tmp_path / "curves").read_bytes().startswith(b"\x89PNG")
    assert not (tmp_path / "curves.png").exists()


def test_write_iohanalyzer_refuses_a_run_directorys_own_file(place, templates):
    out = place("finished")
    with pytest.raises(ValueError, match="outside a run directory's own files"):
        write_iohanalyzer([templates["history"]], out / RunDir.IOH)


# -- item 8: a run's history is its own ----------------------------------------------------------------------
def iteration_lines(path: Path) -> list[bytes]:
    return [line for line in path.read_bytes().splitlines(True) if line.startswith(b'{"iteration"')]


def test_log_lines_copied_from_another_run_are_not_exported(place, templates, tmp_path):
    out = place("crashed")  # checkpoint at 2, iteration 3 logged after it
    lines = (out / RunDir.LOG).read_bytes().splitlines(True)
    own = iteration_lines(out / RunDir.LOG)[2]
    foreign = iteration_lines(templates["other"] / RunDir.LOG)[2:4]  # seed 1's iterations 3 and 4
    (out / RunDir.LOG).write_bytes(b"".join(line for line in lines if line != own) + b"".join(foreign))
    with pytest.warns(RunDirWarning, match="iteration 3 is not this run's"):
        history = load_history(out)
    assert len(history) == 2


def test_a_hand_written_log_line_without_its_checksums_is_not_exported(place, tmp_path):
    out = place("crashed")
    entry = json.loads(iteration_lines(out / RunDir.LOG)[2])
    del entry["crc32"], entry["chain"]
    entry["mean_return"] = 0.0
    with open(out / RunDir.LOG, "a") as stream:
        stream.write(json.dumps(entry) + "\n")
    with pytest.warns(RunDirWarning, match="iteration 3 is not this run's"):
        history = load_history(out)
    assert len(history) == 2


def test_the_runs_own_lines_after_the_checkpoint_are_read_and_a_resume_is_bit_identical(place, templates):
    out = place("crashed")
    assert len(load_history(out)) == 3
    assert resume(out).equals(templates["history"])


def test_a_history_json_that_no_checkpoint_closes_is_not_exported(place, templates):
    out = place("crashed")  # a forged history.json beside a run whose checkpoint is gone
    (out / RunDir.CHECKPOINT).unlink()
    forged = History.from_dict(templates["history"].to_dict())
    forged.records[0].mean_return, forged.stop_reason = 1.0, "iterations"
    forged.to_json(out / RunDir.HISTORY_JSON)
    with pytest.warns(RunDirWarning, match="no checkpoint.npz closes it"):
        history = load_history(out)
    assert len(history) == 3 and history.stop_reason is None and history.records[0].mean_return != 1.0


def strip_chains(path: Path) -> None:
    """The log as written before lines had a chain."""
    lines = []
    for line in path.read_bytes().splitlines():
        entry = json.loads(line)
        entry.pop("crc32")
        entry.pop("chain", None)
        lines.append(json.dumps({**entry, "crc32": zlib.crc32(json.dumps(entry).encode())}) + "\n")
    path.write_text("".join(lines))


@pytest.mark.parametrize("which", ["finished", "crashed"])
def test_a_log_written_before_the_chain_stays_readable(place, templates, which):
    out = place(which)
    strip_chains(out / RunDir.LOG)
    (out / RunDir.HISTORY_JSON).unlink(missing_ok=True)
    if which == "finished":  # its final checkpoint vouches for every iteration
        assert load_history(out).equals(templates["history"])
    else:  # iterations after the checkpoint are not provably this run's: left out, and redone by resume
        with pytest.warns(RunDirWarning, match="iteration 3 is not this run's"):
            assert len(load_history(out)) == 2
    assert resume(out).equals(templates["history"])


# -- item 10: operating-system errors are named, and lose nothing --------------------------------------------
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
    flags = ["--env", SPHERE, "--env-kwarg", "dim=2", "--optimizer", "creps-cma-old", "--iterations", "6",
             "--samples", "10", "--eval-every", "2", "--checkpoint-every", "2", "--seed", "0"]  # fmt: skip
    exit_code, error = cli(capsys, "run", *flags, "--out", out, "--no-progress", "--no-plot")
    assert exit_code == 3
    name = RunDir.LOG if failing == "log" else RunDir.CHECKPOINT
    assert f"({os.strerror(code)}, {errno.errorcode[code]})" in one_error_naming(error, out / name)
    assert not [p for p in out.iterdir() if p.name.endswith(".tmp")]
    monkeypatch.undo()
    assert resume(out).equals(templates["history"])  # nothing lost


@pytest.mark.slow
def test_a_file_size_limit_gives_exit_3_not_a_signal_and_resume_is_bit_identical(tmp_path, templates):
    out = tmp_path / "run"

    def limit_file_size():
        resource.setrlimit(resource.RLIMIT_FSIZE, (2048, 2048))  # `ulimit -f 2`: log.jsonl outgrows it

    flags = ["--env", SPHERE, "--env-kwarg", "dim=2", "--optimizer", "creps-cma-old", "--iterations", "6",
             "--samples", "10", "--eval-every", "2", "--checkpoint-every", "2", "--seed", "0"]  # fmt: skip
    command = cli_command("run", *flags, "--out", out, "--no-progress", "--no-plot")
    done = subprocess.run(command, capture_output=True, text=True, timeout=120, preexec_fn=limit_file_size)
    assert done.returncode == 3, (done.returncode, done.stderr)  # not -SIGXFSZ
    assert "File too large, EFBIG" in one_error_naming(done.stderr, out)
    assert resume(out).equals(templates["history"])


@pytest.mark.parametrize("name", [RunDir.HISTORY_CSV, RunDir.LOCK, RunDir.LOG])
def test_a_folder_where_a_run_file_should_be_gives_exit_3_naming_it(place, tmp_path, capsys, name):
    out = place("finished" if name == RunDir.HISTORY_CSV else "crashed")
    (out / name).unlink(missing_ok=True)
    (out / name).mkdir()
    code, error = hostile(capsys, tmp_path, "resume", out, "--no-progress")
    assert code == 3
    assert "got a directory" in one_error_naming(error, out / name)


@pytest.mark.parametrize("command", ["resume", "run"])
def test_a_path_component_too_long_gives_exit_3_naming_it(tmp_path, capsys, command):
    out = tmp_path / ("x" * 300)
    flags = ["--env", SPHERE, "--optimizer", "creps-cma-old", "--iterations", "2", "--seed", "0", "--out"]
    code, error = cli(capsys, *(["resume"] if command == "resume" else ["run", *flags]), out)
    assert code == 3
    assert "File name too long" in one_error_naming(error, out)


# -- item 11: deep JSON and out-of-range numbers get the documented exit codes -------------------------------
def test_deep_json_in_config_json_gives_exit_3(place, tmp_path, capsys):
    out = place("crashed")
    (out / RunDir.CONFIG).write_text('{"config": ' + DEEP + "}")
    code, error = hostile(capsys, tmp_path, "resume", out, "--no-progress")
    assert code == 3
    assert "nested at most" in one_error_naming(error, out / RunDir.CONFIG)


def test_a_deep_log_line_is_a_damaged_line(place, tmp_path, capsys):
    out = place("crashed")
    lines = (out / RunDir.LOG).read_text().splitlines(True)
    lines[2] = DEEP + "\n"  # iteration 2, before the checkpoint
    (out / RunDir.LOG).write_text("".join(lines))
    code, error = hostile(capsys, tmp_path, "resume", out, "--no-progress")
    assert code == 3
    assert "damaged lines [3]" in one_error_naming(error, out / RunDir.LOG)


def test_a_deep_history_json_is_rebuilt_from_the_log(place, tmp_path, capsys, templates):
    out = place("finished")
    (out / RunDir.HISTORY_JSON).write_text(DEEP)
    code, error = hostile(capsys, tmp_path, "export", out, "-o", tmp_path / "e.csv")
    assert code == 0
    assert f"{out / RunDir.HISTORY_JSON}: damaged" in error and "nested at most" in error


@pytest.mark.parametrize("flag", ["--opt", "--env-kwarg"])
def test_a_deep_json_flag_gives_exit_2(tmp_path, capsys, flag):
    flags = ["--env", SPHERE, "--optimizer", "creps-cma-old", "--iterations", "2", "--seed", "0"]
    with deadline(), pytest.raises(SystemExit) as exit_:
        main(["run", *flags, "--out", str(tmp_path / "run"), flag, "epsilon=" + DEEP])
    assert exit_.value.code == 2
    assert f"argument {flag}: epsilon: expected JSON nested at most" in capsys.readouterr().err
    assert not (tmp_path / "run").exists()


def test_history_from_json_of_deep_json_is_a_value_error_naming_the_file(tmp_path):
    (tmp_path / "h.json").write_text(DEEP)
    with pytest.raises(ValueError, match=r"h\.json: expected JSON nested at most"):
        History.from_json(tmp_path / "h.json")


def test_a_deep_json_in_an_optimizer_npz_is_a_value_error_naming_the_file(tmp_path):
    path = tmp_path / "optimizer.npz"
    np.savez(path, **{JSON_KEY: np.frombuffer(DEEP.encode(), dtype=np.uint8)})
    with pytest.raises(ValueError, match=f"{path}.*nested at most"):
        CREPSCMA.load(path)


@pytest.mark.parametrize("value", [-1, 2**200])
def test_a_generator_state_out_of_range_gives_exit_3_naming_the_checkpoint(place, tmp_path, capsys, value):
    out = place("crashed")

    def edit(flat):
        flat["env_rng"]["state"]["state"] = value

    rewrite_checkpoint(out / RunDir.CHECKPOINT, edit)
    code, error = hostile(capsys, tmp_path, "resume", out, "--no-progress")
    assert code == 3
    one_error_naming(error, out / RunDir.CHECKPOINT)


def test_the_threat_model_in_the_runner_guide_quotes_the_limits_the_code_applies():
    from creps_gym._validation import MAX_JSON_DEPTH
    from creps_gym.runner.rundir import files

    guide = (Path(__file__).resolve().parents[3] / "docs" / "runner.md").read_text(encoding="utf-8")
    section = guide[guide.index("### Threat model") : guide.index("- **No code from a run directory.**")]
    quoted = " ".join(section.split())
    assert files.LIMITS == {"config.json": 16 << 20, "versions.json": 16 << 20, "run.lock": 4096}
    assert "`config.json` and `versions.json` 16 MiB, `run.lock` 4 kB, every other file 1 GiB" in quoted
    assert files.DEFAULT_LIMIT == 1 << 30 and f"more than {MAX_JSON_DEPTH} levels deep" in quoted
