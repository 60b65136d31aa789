"""The checkpoint file as an attack surface: forged fields with recomputed checksums, checkpoints
copied from another run, damaged, deep or out-of-range contents (issue 30, items 1, 8, 11 and 14).

Each forgery edits a field of ``checkpoint.npz`` and recomputes its plain CRC-32 (``state_crc``), as an
adversary would; the loaded state must still be one the loop can have written. The runs attacked are the
shared ``templates`` of ``conftest.py``, copied per test.
"""

from __future__ import annotations

import json
import shutil
import tempfile
from pathlib import Path

import numpy as np
import pytest
from helpers import SPHERE, cli_in_process, forge
from rundir_setup import (
    DEEP,
    POSIX,
    SETTINGS,
    hostile,
    make_run,
    one_error_naming,
    rewrite_checkpoint,
    truncate,
)

from creps_gym.cli import main
from creps_gym.errors import RunDirError
from creps_gym.optimizers import CREPSCMA
from creps_gym.optimizers.base import load_state, save_state
from creps_gym.optimizers.state_files import JSON_KEY
from creps_gym.runner import History, RunDir, resume, run

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import given  # noqa: E402
from hypothesis import strategies as st  # noqa: E402
from rundir_setup import FUZZ, copy_of, values  # noqa: E402

TEMPLATE = {"finished": "finished", "unfinished": "crashed"}  # the shared runs: unfinished, checkpoint at 2


def _log_iterations(path: Path) -> list[int]:
    lines = [json.loads(line) for line in (path / "log.jsonl").read_text().splitlines()]
    return [entry["iteration"] for entry in lines if "event" not in entry]


@pytest.mark.parametrize(
    ("which", "stop"),
    [
        ("finished", None),  # before: a finished run of 6 ran a 7th iteration
        ("finished", "callback"),
        ("unfinished", "iterations"),  # before: iteration 2 of 6 was declared finished
        ("unfinished", "max_episodes"),  # no max_episodes configured
        ("unfinished", "target_regret"),  # no target_regret configured
        ("unfinished", "optimizer: \x1b[31mred"),  # before: the ANSI escape was printed raw
        ("unfinished", "optimizer: $\\frac{$"),  # before: the plot of the resumed run failed (exit 1)
        ("unfinished", "optimizer: tolx, min_std"),  # the loop sorts the criteria
        ("unfinished", "optimizer: "),
        ("unfinished", 3),
    ],
)
def test_a_forged_stop_reason_with_a_recomputed_checksum_is_refused(which, stop, place, capsys):
    path = place(TEMPLATE[which])
    forge(path / "checkpoint.npz", stop_reason=stop)
    before = _log_iterations(path)
    with pytest.raises(
        RunDirError, match=r"checkpoint\.npz: damaged or not written by creps_gym \(inconsistent"
    ):
        resume(path)
    assert main(["resume", str(path), "--no-progress", "--no-plot"]) == 3
    err = capsys.readouterr().err
    assert "\x1b" not in err and len(err.strip().splitlines()) == 1
    assert _log_iterations(path) == before  # nothing was run


@pytest.mark.parametrize(
    ("which", "stop", "iterations"),
    [
        ("unfinished", "callback", 2),
        ("unfinished", "optimizer: min_std, tolx", 2),
        ("unfinished", None, SETTINGS["iterations"]),
    ],
)
def test_stop_reasons_the_loop_can_write_are_still_accepted(which, stop, iterations, place):
    path = place(TEMPLATE[which])
    forge(path / "checkpoint.npz", stop_reason=stop)
    history = resume(path)
    assert len(history) == iterations and history.stop_reason == (stop or "iterations")


def test_iteration_counts_must_match_the_stop_reason(place, templates):
    """A finished run cannot be made to look unfinished by lowering its counts with the same stop reason."""
    path = place("finished")
    episodes = int(load_state(templates["crashed"] / RunDir.CHECKPOINT)["episodes"])  # those at iteration 2
    forge(path / "checkpoint.npz", iteration=2, episodes=episodes)  # "iterations" at 2 of 6
    with pytest.raises(RunDirError, match=r"checkpoint\.npz: damaged .*inconsistent runner state"):
        resume(path)


def test_a_forged_covariance_is_refused_at_load_naming_the_key(place):
    """Before: a checkpoint covariance of 1e308 was accepted and the resumed run blamed the contexts."""
    path = place("finished")
    flat = load_state(path / "checkpoint.npz")
    flat["optimizer.cov"] = np.eye(2) * 1e308
    save_state(flat, path / "checkpoint.npz")  # the optimiser's state is not in the loop's checksum
    (path / "history.json").unlink(missing_ok=True)
    with pytest.raises(
        RunDirError, match=r"checkpoint\.npz: damaged .*state\['cov'\]: expected a covariance whose"
    ):
        resume(path)


# -- item 14: a checkpoint belongs to its run -------------------------------------------------------------
@pytest.mark.parametrize(
    "other", [{"seed": 2}, {"env_kwargs": {"dim": 4}}, {"iterations": 10}], ids=["seed", "dim", "iterations"]
)
def test_a_checkpoint_copied_from_another_run_is_refused_at_once(tmp_path, other):
    mine = make_run(tmp_path / "mine", seed=1, stop_after=3)
    theirs = make_run(tmp_path / "theirs", **{"seed": 1, **other})
    shutil.copy(theirs / RunDir.CHECKPOINT, mine / RunDir.CHECKPOINT)
    before = (mine / RunDir.LOG).read_bytes()
    result = cli_in_process("resume", mine, "--no-plot")
    assert result.returncode == 3 and "Traceback" not in result.stderr
    assert f"{mine / RunDir.CHECKPOINT}: expected the checkpoint of the run configured in config.json" in (
        result.stderr
    )
    assert (mine / RunDir.LOG).read_bytes() == before  # refused before anything ran


def test_a_folder_with_a_checkpoint_and_no_config_is_not_a_run(tmp_path):
    old = make_run(tmp_path / "old", iterations=8, env_kwargs={"dim": 3})
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
def test_a_damaged_file_gives_exit_code_3_naming_the_file(place, tmp_path, capsys, name, damage):
    out = place("crashed")
    damage(out / name)
    assert main(["resume", str(out), "--no-plot"]) == 3
    error = capsys.readouterr().err
    assert f"{out / name}: damaged or not written by creps_gym (" in error
    assert ("delete it to restart" if name == RunDir.CHECKPOINT else "restore it from a backup") in error


@POSIX
def test_a_deep_json_in_an_optimizer_npz_is_a_value_error_naming_the_file(tmp_path):
    path = tmp_path / "optimizer.npz"
    np.savez(path, **{JSON_KEY: np.frombuffer(DEEP.encode(), dtype=np.uint8)})
    with pytest.raises(ValueError, match=f"{path}.*nested at most"):
        CREPSCMA.load(path)


@POSIX
@pytest.mark.parametrize("value", [-1, 2**200])
def test_a_generator_state_out_of_range_gives_exit_3_naming_the_checkpoint(place, tmp_path, capsys, value):
    out = place("crashed")

    def edit(flat):
        flat["env_rng"]["state"]["state"] = value

    rewrite_checkpoint(out / RunDir.CHECKPOINT, edit)
    code, error = hostile(capsys, tmp_path, "resume", out, "--no-progress")
    assert code == 3
    one_error_naming(error, out / RunDir.CHECKPOINT)


@FUZZ
@given(
    key=st.sampled_from(
        ["iteration", "episodes", "elapsed", "env_rng", "log_crc", "stop_reason", "format", "fingerprint"]
    ),
    value=values,
)
@pytest.mark.slow
def test_resume_refuses_checkpoint_runner_state_that_no_run_wrote(templates, key, value):
    expected = templates["history"]
    with tempfile.TemporaryDirectory() as folder:
        out = copy_of(templates["crashed"], folder)
        state = load_state(out / RunDir.CHECKPOINT)
        state[key] = value
        save_state(state, out / RunDir.CHECKPOINT)
        try:
            history = resume(out)
        except RunDirError as exc:
            assert str(out / RunDir.CHECKPOINT) in str(exc)
            return
    assert history.equals(expected)  # e.g. another (finite, >= 0) elapsed time: only wall times differ
