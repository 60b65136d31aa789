"""Fuzz the run-directory files and the checkpoint's runner state.

Every corruption ends in a :class:`RunDirError` (exit code 3 on the command line), or in the very result
an intact run directory gives (said with a :class:`RunDirWarning` where something was rebuilt or left out):
never in another exception, and never in a different result.
"""

from __future__ import annotations

import json
import shutil
import tempfile
import warnings
import zlib
from pathlib import Path

import pytest
from helpers import SPHERE

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from creps_gym.errors import RunDirError, RunDirWarning  # noqa: E402
from creps_gym.optimizers.base import load_state, save_state  # noqa: E402
from creps_gym.runner import History, RunDir, load_history, resume, run  # noqa: E402

SETTINGS = {"iterations": 4, "samples_per_iteration": 10, "env_kwargs": {"dim": 2}, "eval_every": 2,
            "checkpoint_every": 2}  # fmt: skip
FUZZ = settings(max_examples=30, deadline=None)


class Stop(Exception):
    """Raised by a callback to leave a run unfinished (as a crash would)."""


def _stop_at_3(record, history):
    if record.iteration == 3:
        raise Stop


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """A finished run, an unfinished one (checkpoint at 2, iterations 1-3 logged) and the expected history."""
    root = tmp_path_factory.mktemp("fuzz")
    run("creps-cma-old", SPHERE, seed=0, run_dir=root / "finished", **SETTINGS)
    try:
        run("creps-cma-old", SPHERE, seed=0, run_dir=root / "unfinished", callbacks=[_stop_at_3], **SETTINGS)
    except Stop:
        pass
    return {"finished": root / "finished", "unfinished": root / "unfinished"}, run(
        "creps-cma-old", SPHERE, seed=0, **SETTINGS
    )


corruptions = st.one_of(
    st.tuples(st.just("truncate"), st.floats(0, 1)),
    st.tuples(st.just("flip"), st.floats(0, 1), st.integers(0, 7)),
    st.tuples(st.just("replace"), st.binary(max_size=64)),
)


def corrupt(path: Path, corruption: tuple) -> None:
    data = bytearray(path.read_bytes())
    kind = corruption[0]
    if kind == "truncate":
        data = data[: int(corruption[1] * len(data))]
    elif kind == "flip" and data:
        data[min(int(corruption[1] * len(data)), len(data) - 1)] ^= 1 << corruption[2]
    elif kind == "replace":
        data = bytearray(corruption[1])
    path.write_bytes(bytes(data))


def copy_of(template: Path, into: str) -> Path:
    target = Path(into) / "run"
    shutil.copytree(template, target)
    return target


@FUZZ
@given(
    which=st.sampled_from(
        [("unfinished", n) for n in (RunDir.CHECKPOINT, RunDir.CONFIG, RunDir.LOG)]
        + [("finished", n) for n in (RunDir.CHECKPOINT, RunDir.CONFIG, RunDir.HISTORY_JSON, RunDir.IOH)]
    ),
    corruption=corruptions,
)
def test_resume_of_a_corrupted_run_directory_refuses_or_gives_the_intact_result(runs, which, corruption):
    templates, expected = runs
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
        [("unfinished", n) for n in (RunDir.CHECKPOINT, RunDir.CONFIG, RunDir.LOG)]
        + [("finished", n) for n in (RunDir.CHECKPOINT, RunDir.HISTORY_JSON, RunDir.LOG)]
    ),
    corruption=corruptions,
)
def test_load_history_of_a_corrupted_run_directory_refuses_or_says_what_it_left_out(runs, which, corruption):
    templates, expected = runs
    complete = 3 if which[0] == "unfinished" else 4
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


values = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-3, 10),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=4),
    st.lists(st.integers(0, 4), max_size=3),
    st.dictionaries(st.text(max_size=3), st.integers(), max_size=2),
)


@FUZZ
@given(
    key=st.sampled_from(
        ["iteration", "episodes", "elapsed", "env_rng", "log_crc", "stop_reason", "format", "fingerprint"]
    ),
    value=values,
)
@pytest.mark.slow
def test_resume_refuses_checkpoint_runner_state_that_no_run_wrote(runs, key, value):
    templates, expected = runs
    with tempfile.TemporaryDirectory() as folder:
        out = copy_of(templates["unfinished"], folder)
        state = load_state(out / RunDir.CHECKPOINT)
        state[key] = value
        save_state(state, out / RunDir.CHECKPOINT)
        try:
            history = resume(out)
        except RunDirError as exc:
            assert str(out / RunDir.CHECKPOINT) in str(exc)
            return
    assert history.equals(expected)  # e.g. another (finite, >= 0) elapsed time: only wall times differ


@FUZZ
@given(index=st.integers(0, 2), field=st.sampled_from(["iteration", "episodes", "mean_return"]), value=values)
def test_resume_refuses_a_log_with_edited_records_before_the_checkpoint(runs, index, field, value):
    """The history is rebuilt from the log: an edit with a valid line checksum is still caught."""
    templates, expected = runs
    with tempfile.TemporaryDirectory() as folder:
        out = copy_of(templates["unfinished"], folder)
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
