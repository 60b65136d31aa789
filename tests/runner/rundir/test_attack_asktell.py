"""A hostile ask/tell run folder (``creps-gym ask``/``tell``, issue 44 item 4): planted links and FIFOs,
forged checkpoint episodes, edited spaces, oversized dimensions. The invariants of
``test_rundir_hostile``: exit code 3, one error line naming the file, nothing outside the folder changed,
bounded time."""

from __future__ import annotations

import json
import os
import shutil
import sys
from pathlib import Path

import pytest
from helpers import cli_in_process
from rundir_setup import hostile, one_error_naming, rewrite_checkpoint

from creps_gym.cli import main
from creps_gym.runner import RunDir

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="POSIX files")

NEW = ["--new", "--optimizer", "c-bo", "--seed", "0", "--samples", "2", "--params", "2", "--param-low", "-1"]
NEW += ["--param-high", "1", "--context-low", "0", "--context-high", "1", "--opt", "distillation_points=2"]


@pytest.fixture(scope="module")
def template(tmp_path_factory) -> Path:
    """An ask/tell run after one told batch, with one episode of the second pending."""
    run = tmp_path_factory.mktemp("asktell") / "run"
    steps = [["ask", run, *NEW], ["ask", run, "--context", "0.2"], ["ask", run, "--context", "0.8"]]
    steps += [
        ["tell", run, "--episode", "1", "--return", "-1"],
        ["tell", run, "--episode", "2", "--return", "-2"],
    ]
    steps += [["ask", run, "--context", "0.5"], ["ask", run, "--context", "0.6"]]
    steps += [["tell", run, "--episode", "3", "--return", "-1"]]
    for step in steps:
        assert main([str(a) for a in step]) == 0
    return run


@pytest.fixture
def place(tmp_path, template) -> Path:
    outside = tmp_path / "outside"
    outside.mkdir()
    (outside / "victim").write_bytes(b"not the run's\n")
    return Path(shutil.copytree(template, tmp_path / "run"))


TELL = ["tell", "--episode", "4", "--return", "-3"]  # completes the batch: every file is written


@pytest.mark.parametrize("name", [RunDir.LOCK, RunDir.LOG, RunDir.CHECKPOINT, RunDir.CONFIG, RunDir.POLICY])
def test_a_planted_link_is_refused(place, tmp_path, capsys, name):
    victim = tmp_path / "outside" / "victim"
    if (place / name).exists():
        shutil.copyfile(place / name, victim)
        (place / name).unlink()
    (place / name).symlink_to(victim)
    code, error = hostile(capsys, tmp_path, TELL[0], place, *TELL[1:])
    assert code == 3
    assert "expected a regular file, got a symbolic link" in one_error_naming(error, place / name)


@pytest.mark.parametrize("name", [RunDir.LOG, RunDir.CHECKPOINT, RunDir.CONFIG])
def test_a_fifo_never_blocks(place, tmp_path, capsys, name):
    (place / name).unlink()
    os.mkfifo(place / name)
    code, error = hostile(capsys, tmp_path, TELL[0], place, *TELL[1:])
    assert code == 3
    assert "got a FIFO" in one_error_naming(error, place / name)


def _forge_context(flat):
    flat["ask_tell"]["batch"][0]["context"] = [0.25]


def _forge_return(flat):
    flat["ask_tell"]["batch"][0]["value"] = "-1"


def _forge_ids(flat):
    flat["ask_tell"]["next_episode"] = 1


def _forge_spaces(flat):
    flat["ask_tell"]["spaces"]["param_high"] = [2.0, 2.0]


@pytest.mark.parametrize("forge", [_forge_context, _forge_return, _forge_ids, _forge_spaces])
def test_forged_episodes_in_the_checkpoint_are_refused(place, tmp_path, capsys, forge):
    rewrite_checkpoint(place / RunDir.CHECKPOINT, forge)  # its checksum made right: the checks must see it
    code, error = hostile(capsys, tmp_path, TELL[0], place, *TELL[1:])
    assert code == 3
    assert "damaged or not written by creps_gym" in one_error_naming(error, place / RunDir.CHECKPOINT)


@pytest.mark.parametrize("spaces", ["boxes", {"param_low": [0.0]}, "huge", "samples"])
def test_edited_spaces_in_config_json_are_refused(place, tmp_path, capsys, spaces):
    document = json.loads((place / RunDir.CONFIG).read_text())
    if spaces == "huge":  # a dimension whose covariance would not fit in memory: refused before allocating
        p = 400_000
        document["meta"]["ask_tell"].update(param_low=[-1.0] * p, param_high=[1.0] * p)
    elif spaces == "samples":  # a batch size no ask/tell run has
        document["config"]["samples"] = None
    elif spaces == "boxes":
        document["meta"]["ask_tell"]["param_high"] = [0.5, 0.5]
    else:
        document["meta"]["ask_tell"] = spaces
    (place / RunDir.CONFIG).write_text(json.dumps(document))
    code, error = hostile(capsys, tmp_path, "ask", place, "--pending")
    assert code == 3
    named = RunDir.CHECKPOINT if spaces == "boxes" else RunDir.CONFIG  # the boxes: not the checkpoint's
    one_error_naming(error, place / named)


# -- fuzz: any damage ends in exit code 3 or in the intact folder's result --------------------------------
hypothesis = pytest.importorskip("hypothesis")
from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402
from rundir_setup import corrupt, corruptions  # noqa: E402

FILES = [RunDir.CONFIG, RunDir.CHECKPOINT, RunDir.LOG, RunDir.POLICY, RunDir.VERSIONS]


@pytest.fixture(scope="module")
def intact(template, tmp_path_factory):
    """What the batch-completing tell prints, and the policy it writes, on an intact copy."""
    run = Path(shutil.copytree(template, tmp_path_factory.mktemp("intact") / "run"))
    assert main([str(a) for a in (TELL[0], run, *TELL[1:], "--json")]) == 0
    return run


@settings(max_examples=20, deadline=None)
@given(name=st.sampled_from(FILES), corruption=corruptions)
def test_damage_ends_in_exit_3_or_the_intact_result(template, intact, name, corruption):
    import tempfile

    from creps_gym.optimizers.policy_file import Policy

    with tempfile.TemporaryDirectory() as folder:
        run = Path(shutil.copytree(template, Path(folder) / "run"))
        corrupt(run / name, corruption)
        result = cli_in_process(TELL[0], run, *TELL[1:], "--json")
        code, out, error = result.returncode, result.stdout, result.stderr
        assert code in (0, 3), error
        if code == 3:
            assert len([line for line in error.splitlines() if ": error: " in line]) == 1, error
        else:
            assert Policy.load(run / RunDir.POLICY).equals(Policy.load(intact / RunDir.POLICY))
            assert json.loads(out)["mean_return"] == -2.0
