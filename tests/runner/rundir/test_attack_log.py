"""The log and the history as an attack surface: corrupted, edited, foreign, hand-written or deep log
lines and history files (issue 30 items 3, 8 and 11, and fuzzed damage): a load or resume refuses them
naming the file, or gives the intact result, or says what it left out. The runs attacked are the shared
``templates`` of ``conftest.py``, copied per test.
"""

from __future__ import annotations

import json
import tempfile
import warnings
import zlib
from pathlib import Path

import pytest
from rundir_setup import (
    DEEP,
    POSIX,
    SETTINGS,
    corrupt,
    hostile,
    make_run,
    one_error_naming,
    truncate,
)

from creps_gym.cli import main
from creps_gym.errors import RunDirError, RunDirWarning
from creps_gym.runner import History, RunDir, load_history, resume

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import given  # noqa: E402
from hypothesis import strategies as st  # noqa: E402
from rundir_setup import FUZZ, copy_of, corruptions, values  # noqa: E402


@FUZZ
@given(
    which=st.sampled_from(
        [("crashed", n) for n in (RunDir.CHECKPOINT, RunDir.CONFIG, RunDir.LOG)]
        + [("finished", n) for n in (RunDir.CHECKPOINT, RunDir.CONFIG, RunDir.HISTORY_JSON, RunDir.IOH)]
    ),
    corruption=corruptions,
)
def test_resume_of_a_corrupted_run_directory_refuses_or_gives_the_intact_result(templates, which, corruption):
    expected = templates["history"]
    with tempfile.TemporaryDirectory() as folder:
        out = copy_of(templates[which[0]], folder)
        corrupt(out / which[1], corruption)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RunDirWarning)
                history = resume(out)
        except RunDirError as exc:
            assert str(out) in str(exc)  # names the file
            return
        assert history.equals(expected)
        assert History.from_json(out / RunDir.HISTORY_JSON).equals(expected)


@FUZZ
@given(
    which=st.sampled_from(
        [("crashed", n) for n in (RunDir.CHECKPOINT, RunDir.CONFIG, RunDir.LOG)]
        + [("finished", n) for n in (RunDir.CHECKPOINT, RunDir.HISTORY_JSON, RunDir.LOG)]
    ),
    corruption=corruptions,
)
def test_load_history_of_a_corrupted_run_directory_refuses_or_says_what_it_left_out(
    templates, which, corruption
):
    expected = templates["history"]
    complete = 3 if which[0] == "crashed" else SETTINGS["iterations"]
    with tempfile.TemporaryDirectory() as folder:
        out = copy_of(templates[which[0]], folder)
        corrupt(out / which[1], corruption)
        kept = (out / which[1]).read_bytes()
        # a log cut at a line's end looks like the log of a run killed earlier: nothing tells them apart
        clean_cut = which[1] == RunDir.LOG and corruption[0] == "truncate" and kept.endswith(b"\n")
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                history = load_history(out)
            except RunDirError:
                return
    said = any(issubclass(w.category, RunDirWarning) for w in caught)
    assert len(history) <= complete and (len(history) == complete or said or clean_cut)
    assert History(history.records).equals(History(expected.records[: len(history)]))


@FUZZ
@given(index=st.integers(0, 2), field=st.sampled_from(["iteration", "episodes", "mean_return"]), value=values)
def test_resume_refuses_a_log_with_edited_records_before_the_checkpoint(templates, index, field, value):
    """The history is rebuilt from the log: an edit with a valid line checksum is still caught."""
    expected = templates["history"]
    with tempfile.TemporaryDirectory() as folder:
        out = copy_of(templates["crashed"], folder)
        lines = (out / RunDir.LOG).read_text().splitlines(keepends=True)
        numbers = [i for i, line in enumerate(lines) if line.startswith('{"iteration"')]
        entry = json.loads(lines[numbers[min(index, 1)]])  # iterations 1 and 2 precede the checkpoint
        entry.pop("crc32")
        entry[field] = value
        try:
            text = json.dumps(entry, allow_nan=False)
        except ValueError:
            return  # not a line a writer could produce
        lines[numbers[min(index, 1)]] = json.dumps({**entry, "crc32": zlib.crc32(text.encode())}) + "\n"
        (out / RunDir.LOG).write_text("".join(lines))
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RunDirWarning)
                history = resume(out)
        except RunDirError:
            return
    assert history.equals(expected)


# -- item 2: a finished run can always be completed --------------------------------------------------------
@pytest.mark.parametrize("damage", ["missing", "truncated"])
def test_resume_rewrites_missing_or_damaged_result_files(place, templates, tmp_path, damage):
    out = place("finished")
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
    assert History.from_json(out / RunDir.HISTORY_JSON).equals(templates["history"])
    assert RunDir.open(out).read_log()[1][-1]["rewritten"] == list(results)


# -- item 3: no silent loss in load_history, export and plot ---------------------------------------------
def damage_log_line(path: Path, iteration: int) -> None:
    lines = path.read_text().splitlines(keepends=True)
    index = next(i for i, line in enumerate(lines) if line.startswith(f'{{"iteration": {iteration},'))
    lines[index] = lines[index].replace('"mean_return": -', '"mean_return": -1')  # a changed value
    path.write_text("".join(lines))


def test_a_damaged_log_line_ends_the_history_before_it_and_a_resume_refuses_it(templates, tmp_path):
    """The checkpoint holds no history (O(1) checkpoints): a log line lost before it cannot be recovered."""
    out = make_run(tmp_path / "run", stop_after=5)  # checkpoint at 4, iterations 5 logged after it
    expected = templates["history"].records[:5]
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


def test_export_of_a_damaged_history_json_rebuilds_it_and_warns(place, tmp_path, capsys):
    out = place("finished")
    expected = (out / RunDir.IOH).read_text()
    truncate(out / RunDir.HISTORY_JSON)
    assert main(["export", str(out), "-o", str(tmp_path / "ioh.csv")]) == 0
    error = capsys.readouterr().err
    assert f"creps-gym export: warning: {out / RunDir.HISTORY_JSON}: damaged (JSONDecodeError" in error
    assert (tmp_path / "ioh.csv").read_text() == expected


# -- item 8: a run's history is its own ----------------------------------------------------------------------
def iteration_lines(path: Path) -> list[bytes]:
    return [line for line in path.read_bytes().splitlines(True) if line.startswith(b'{"iteration"')]


def _check_iteration_3_is_refused(out) -> None:
    """The history read from ``out`` warns that its iteration 3 is not the run's and stops before it."""
    with pytest.warns(RunDirWarning, match="iteration 3 is not this run's"):
        history = load_history(out)
    assert len(history) == 2


@POSIX
def test_log_lines_copied_from_another_run_are_not_exported(place, templates, tmp_path):
    out = place("crashed")  # checkpoint at 2, iteration 3 logged after it
    lines = (out / RunDir.LOG).read_bytes().splitlines(True)
    own = iteration_lines(out / RunDir.LOG)[2]
    foreign = iteration_lines(templates["other"] / RunDir.LOG)[2:4]  # seed 1's iterations 3 and 4
    (out / RunDir.LOG).write_bytes(b"".join(line for line in lines if line != own) + b"".join(foreign))
    _check_iteration_3_is_refused(out)


@POSIX
def test_a_hand_written_log_line_without_its_checksums_is_not_exported(place, tmp_path):
    out = place("crashed")
    entry = json.loads(iteration_lines(out / RunDir.LOG)[2])
    del entry["crc32"], entry["chain"]
    entry["mean_return"] = 0.0
    with open(out / RunDir.LOG, "a") as stream:
        stream.write(json.dumps(entry) + "\n")
    _check_iteration_3_is_refused(out)


@POSIX
def test_the_runs_own_lines_after_the_checkpoint_are_read_and_a_resume_is_bit_identical(place, templates):
    out = place("crashed")
    assert len(load_history(out)) == 3
    assert resume(out).equals(templates["history"])


@POSIX
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


@POSIX
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


@POSIX
def test_a_deep_log_line_is_a_damaged_line(place, tmp_path, capsys):
    out = place("crashed")
    lines = (out / RunDir.LOG).read_text().splitlines(True)
    lines[2] = DEEP + "\n"  # iteration 2, before the checkpoint
    (out / RunDir.LOG).write_text("".join(lines))
    code, error = hostile(capsys, tmp_path, "resume", out, "--no-progress")
    assert code == 3
    assert "damaged lines [3]" in one_error_naming(error, out / RunDir.LOG)


@POSIX
def test_a_deep_history_json_is_rebuilt_from_the_log(place, tmp_path, capsys, templates):
    out = place("finished")
    (out / RunDir.HISTORY_JSON).write_text(DEEP)
    code, error = hostile(capsys, tmp_path, "export", out, "-o", tmp_path / "e.csv")
    assert code == 0
    assert f"{out / RunDir.HISTORY_JSON}: damaged" in error and "nested at most" in error


@POSIX
def test_history_from_json_of_deep_json_is_a_value_error_naming_the_file(tmp_path):
    (tmp_path / "h.json").write_text(DEEP)
    with pytest.raises(ValueError, match=r"h\.json: expected JSON nested at most"):
        History.from_json(tmp_path / "h.json")
