"""Forged run folders (issue 30, item 8): checksums anyone can recompute do not make forged fields pass.

Each forgery edits a field of ``checkpoint.npz`` and recomputes its plain CRC-32 (``state_crc``), as an
adversary would; the loaded state must still be one the loop can have written, and text from a run folder
is shown escaped (never raw ANSI codes, never matplotlib mathtext).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from helpers import crash_at, forge

from creps_gym.cli import main
from creps_gym.errors import RunDirError
from creps_gym.optimizers import load_state, save_state
from creps_gym.runner import resume, run
from creps_gym.runner.rundir.references import escape_text

SPHERE = "creps_gym/Sphere-v0"


@pytest.fixture(scope="module")
def finished(tmp_path_factory) -> Path:
    """A finished run of 3 iterations (stop reason "iterations")."""
    path = tmp_path_factory.mktemp("finished")
    run("creps", SPHERE, 3, 10, 0, env_kwargs={"dim": 2}, run_dir=path)
    return path


@pytest.fixture(scope="module")
def unfinished(tmp_path_factory) -> Path:
    """A run of 4 iterations whose last checkpoint is iteration 2 of 4 (stop reason None)."""
    path = tmp_path_factory.mktemp("unfinished")
    with pytest.raises(RuntimeError, match="crash"):
        run(
            "creps",
            SPHERE,
            4,
            10,
            0,
            env_kwargs={"dim": 2},
            run_dir=path,
            checkpoint_every=1,
            callbacks=[crash_at(3)],
        )
    return path


def _copy(source: Path, target: Path) -> Path:
    target.mkdir()
    for name in ("config.json", "versions.json", "log.jsonl", "checkpoint.npz"):
        (target / name).write_bytes((source / name).read_bytes())
    return target


def _log_iterations(path: Path) -> list[int]:
    lines = [json.loads(line) for line in (path / "log.jsonl").read_text().splitlines()]
    return [entry["iteration"] for entry in lines if "event" not in entry]


@pytest.mark.parametrize(
    ("which", "stop"),
    [
        ("finished", None),  # before: a finished run of 3 ran a 4th iteration
        ("finished", "callback"),
        ("unfinished", "iterations"),  # before: iteration 2 of 4 was declared finished
        ("unfinished", "max_episodes"),  # no max_episodes configured
        ("unfinished", "target_regret"),  # no target_regret configured
        ("unfinished", "optimizer: \x1b[31mred"),  # before: the ANSI escape was printed raw
        ("unfinished", "optimizer: $\\frac{$"),  # before: the plot of the resumed run failed (exit 1)
        ("unfinished", "optimizer: tolx, min_std"),  # the loop sorts the criteria
        ("unfinished", "optimizer: "),
        ("unfinished", 3),
    ],
)
def test_a_forged_stop_reason_with_a_recomputed_checksum_is_refused(
    which, stop, finished, unfinished, tmp_path, capsys
):
    path = _copy(finished if which == "finished" else unfinished, tmp_path / "run")
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
    [("unfinished", "callback", 2), ("unfinished", "optimizer: min_std, tolx", 2), ("unfinished", None, 4)],
)
def test_stop_reasons_the_loop_can_write_are_still_accepted(which, stop, iterations, unfinished, tmp_path):
    path = _copy(unfinished, tmp_path / "run")
    forge(path / "checkpoint.npz", stop_reason=stop)
    history = resume(path)
    assert len(history) == iterations and history.stop_reason == (stop or "iterations")


def test_iteration_counts_must_match_the_stop_reason(finished, tmp_path):
    """A finished run cannot be made to look unfinished by lowering its counts with the same stop reason."""
    path = _copy(finished, tmp_path / "run")
    forge(path / "checkpoint.npz", iteration=2, episodes=16)  # "iterations" at 2 of 3
    with pytest.raises(RunDirError, match=r"checkpoint\.npz: damaged .*inconsistent runner state"):
        resume(path)


@pytest.mark.parametrize("text", ["$\\frac{$", "\x1b[31mred\x1b[0m", "a\nb $x$"])
@pytest.mark.slow
def test_plot_shows_text_from_a_run_folder_literally(finished, tmp_path, text, capsys):
    """Before: a stop reason or optimiser name with mathtext made ``plot`` exit 2 (matplotlib's parser)."""
    pytest.importorskip("matplotlib")
    path = _copy(finished, tmp_path / "run")
    (path / "checkpoint.npz").unlink()  # history.json is then read as it is
    document = json.loads((finished / "history.json").read_text())
    document["stop_reason"], document["meta"]["optimizer"] = text, text
    (path / "history.json").write_text(json.dumps(document))
    assert main(["plot", str(path), "-o", str(tmp_path / "plot.png")]) == 0, capsys.readouterr().err
    assert (tmp_path / "plot.png").stat().st_size > 0


def test_escape_text_shows_control_characters_as_escapes():
    assert escape_text("optimizer: tolx") == "optimizer: tolx"
    assert escape_text("\x1b[31mred\nx\u200b") == "\\x1b[31mred\\nx\\u200b"
    assert escape_text(None) == "None"


def test_a_forged_covariance_is_refused_at_load_naming_the_key(finished, tmp_path):
    """Before: a checkpoint covariance of 1e308 was accepted and the resumed run blamed the contexts."""
    path = _copy(finished, tmp_path / "run")
    flat = load_state(path / "checkpoint.npz")
    flat["optimizer.cov"] = np.eye(2) * 1e308
    save_state(flat, path / "checkpoint.npz")  # the optimiser's state is not in the loop's checksum
    (path / "history.json").unlink(missing_ok=True)
    with pytest.raises(
        RunDirError, match=r"checkpoint\.npz: damaged .*state\['cov'\]: expected a covariance whose"
    ):
        resume(path)
