"""Links, FIFOs, devices, oversized and special files, and output paths as an attack surface (issue 30,
items 2, 3 and 5): nothing is read from a FIFO or device or written through a planted link, ``-o`` writes
what the user named, and text from a run folder is shown literally.

Each hostile case checks the exit code, one error line naming the file, that nothing outside the run
directory changed (a snapshot of a sibling folder the links point into), that no process is left behind,
and that it ends in bounded time. The runs attacked are the shared ``templates`` of ``conftest.py``.
"""

from __future__ import annotations

import json
import os
import resource
import shutil
import subprocess
import time

import pytest
from helpers import SPHERE, cli_command
from rundir_setup import (
    POSIX,
    checked_cli,
    hostile,
    one_error_naming,
    snapshot,
)

from creps_gym.cli import main
from creps_gym.errors import RunDirError
from creps_gym.runner import RunDir, run
from creps_gym.runner.results.export import write_iohanalyzer
from creps_gym.runner.rundir.references import escape_text

# -- item 2: nothing is written (or read) through a link planted in a run directory --------------------------
LINKED = [
    RunDir.LOCK,
    RunDir.LOG,
    RunDir.PLOT,
    RunDir.CHECKPOINT,
    RunDir.CONFIG,
    RunDir.HISTORY_JSON,
    RunDir.HISTORY_CSV,
    RunDir.IOH,
]


@POSIX
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


@POSIX
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
@POSIX
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


@POSIX
@pytest.mark.slow
def test_a_log_linked_to_dev_zero_is_not_read_until_memory_runs_out(place, tmp_path):
    out = place("crashed")
    (out / RunDir.LOG).unlink()
    (out / RunDir.LOG).symlink_to("/dev/zero")

    def limit_memory():
        resource.setrlimit(resource.RLIMIT_AS, (3 << 30, 3 << 30))

    start = time.monotonic()
    done = subprocess.run(
        cli_command("export", out, "-o", tmp_path / "e.csv"),
        capture_output=True,
        text=True,
        timeout=120,
        preexec_fn=limit_memory,
    )
    assert time.monotonic() - start < 120
    assert done.returncode == 3, done.stderr
    one_error_naming(done.stderr, out / RunDir.LOG)


@POSIX
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


@POSIX
def test_an_oversized_log_is_refused_with_exit_code_3(place, tmp_path, capsys):
    from creps_gym.runner.rundir import files

    out = place("crashed")
    with open(out / RunDir.LOG, "r+b") as stream:
        stream.truncate(files.DEFAULT_LIMIT + 1)  # sparse: a hole of zeros, nothing is written
    code, error = hostile(capsys, tmp_path, "export", out, "-o", tmp_path / "e.csv")
    assert code == 3
    assert "expected at most" in one_error_naming(error, out / RunDir.LOG)


# -- item 3: -o writes what the user named -------------------------------------------------------------------
@POSIX
def test_export_writes_through_a_link_and_prints_the_file_written(place, tmp_path, capsys):
    out = place("finished")
    target, link = tmp_path / "outside" / "target.csv", tmp_path / "link.csv"
    target.write_text("old\n")
    link.symlink_to(target)
    code, _ = checked_cli(capsys, "export", out, "-o", link)
    assert code == 0
    assert link.is_symlink() and target.read_text().startswith("evaluations,value")
    # (cli() consumed the output: run it again to see what is printed)
    assert main(["export", str(out), "-o", str(link)]) == 0
    assert capsys.readouterr().out.strip() == f"IOHanalyzer CSV: {target} (through the link {link})"


@POSIX
@pytest.mark.parametrize("kind", ["fifo", "directory", "own-log", "own-history-through-a-link"])
@pytest.mark.parametrize("command", ["export", "plot"])
def test_output_not_a_regular_file_or_a_run_file_is_refused(place, tmp_path, capsys, kind, command):
    if command == "plot":
        pytest.importorskip("matplotlib")
    out = place("finished")
    target = {
        "fifo": tmp_path / "fifo",
        "directory": tmp_path / "folder",
        "own-log": out / RunDir.LOG,
        "own-history-through-a-link": tmp_path / "link",
    }[kind]
    if kind == "fifo":
        os.mkfifo(target)
    elif kind == "directory":
        target.mkdir()
    elif kind == "own-history-through-a-link":
        target.symlink_to(out / RunDir.HISTORY_JSON)
    before = snapshot(tmp_path)
    code, error = checked_cli(capsys, command, out, "-o", target)
    assert code == 2
    assert "argument -o/--output: expected a" in one_error_naming(error, target.resolve())
    assert snapshot(tmp_path) == before


@POSIX
@pytest.mark.slow
def test_plot_without_an_extension_writes_a_png_to_exactly_that_path(place, tmp_path, capsys):
    pytest.importorskip("matplotlib")
    out = place("finished")
    assert main(["plot", str(out), "-o", str(tmp_path / "curves")]) == 0
    assert capsys.readouterr().out.strip() == f"plot: {tmp_path / 'curves'}"
    assert (tmp_path / "curves").read_bytes().startswith(b"\x89PNG")
    assert not (tmp_path / "curves.png").exists()


@POSIX
def test_write_iohanalyzer_refuses_a_run_directorys_own_file(place, templates):
    out = place("finished")
    with pytest.raises(ValueError, match="outside a run directory's own files"):
        write_iohanalyzer([templates["history"]], out / RunDir.IOH)


@POSIX
@pytest.mark.parametrize("name", [RunDir.HISTORY_CSV, RunDir.LOCK, RunDir.LOG])
def test_a_folder_where_a_run_file_should_be_gives_exit_3_naming_it(place, tmp_path, capsys, name):
    out = place("finished" if name == RunDir.HISTORY_CSV else "crashed")
    (out / name).unlink(missing_ok=True)
    (out / name).mkdir()
    code, error = hostile(capsys, tmp_path, "resume", out, "--no-progress")
    assert code == 3
    assert "got a directory" in one_error_naming(error, out / name)


@POSIX
@pytest.mark.parametrize("command", ["resume", "run"])
def test_a_path_component_too_long_gives_exit_3_naming_it(tmp_path, capsys, command):
    out = tmp_path / ("x" * 300)
    flags = ["--env", SPHERE, "--optimizer", "creps-cma-old", "--iterations", "2", "--seed", "0", "--out"]
    code, error = checked_cli(capsys, *(["resume"] if command == "resume" else ["run", *flags]), out)
    assert code == 3
    assert "File name too long" in one_error_naming(error, out)


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


@pytest.mark.parametrize("text", ["$\\frac{$", "\x1b[31mred\x1b[0m", "a\nb $x$"])
@pytest.mark.slow
def test_plot_shows_text_from_a_run_folder_literally(place, templates, tmp_path, text, capsys):
    """Before: a stop reason or optimiser name with mathtext made ``plot`` exit 2 (matplotlib's parser)."""
    pytest.importorskip("matplotlib")
    path = place("finished")
    (path / "checkpoint.npz").unlink()  # history.json is then read as it is
    document = json.loads((templates["finished"] / "history.json").read_text())
    document["stop_reason"], document["meta"]["optimizer"] = text, text
    (path / "history.json").write_text(json.dumps(document))
    assert main(["plot", str(path), "-o", str(tmp_path / "plot.png")]) == 0, capsys.readouterr().err
    assert (tmp_path / "plot.png").stat().st_size > 0


def test_escape_text_shows_control_characters_as_escapes():
    assert escape_text("optimizer: tolx") == "optimizer: tolx"
    assert escape_text("\x1b[31mred\nx\u200b") == "\\x1b[31mred\\nx\\u200b"
    assert escape_text(None) == "None"
