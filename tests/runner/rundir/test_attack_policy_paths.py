"""Hostile input on the policy surfaces (issue 42, items 15 to 20): the output paths of ``policy --save``
and ``evaluate --video``, sizes set by a policy file or a flag, forged or foreign kept policies and
counters, crashes with the wrong exit code, terminal escapes and stale temporaries.

Exit codes come from ``creps_gym.cli.main`` in this process; a subprocess only where a process limit
(``RLIMIT_FSIZE``, ``RLIMIT_AS``) is the point.
"""

from __future__ import annotations

import itertools
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from helpers import EXTRAS, SPHERE, cli_command, file_size_limited

from creps_gym.cli import main
from creps_gym.errors import RunDirError
from creps_gym.optimizers import Policy
from creps_gym.runner import RunDir, resume, run

LINUX = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="sets process limits")
REACHER = "creps_gym/PlanarReacher-v1"


@pytest.fixture(scope="module")
def sphere_run(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("runs") / "sphere"
    run("c-cma-es", SPHERE, 4, None, 0, env_kwargs={"dim": 3}, run_dir=path, eval_every=1)
    return path


@pytest.fixture(scope="module")
def reacher_run(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("runs") / "reacher"
    run("c-cma-es", REACHER, 2, None, 0, run_dir=path, eval_every=1)
    return path


@pytest.fixture(scope="module")
def recorded_episode(reacher_run, tmp_path_factory) -> Path:
    """The first frames of one evaluated episode of ``reacher_run``, drawn once (``.npy``, shape
    (n, h, w, 3)) and replayed by the tests below, which are about the video file written, not the drawing
    (tests/runner/results/test_video.py checks the drawing and the progress)."""
    pytest.importorskip("imageio")
    from creps_gym.runner.results import video

    frames = []
    original = video.EpisodeVideo.__iter__

    def keep(self):  # the first 12 frames (drawn when read): enough for any file limit below
        for frame in itertools.islice(original(self), 12):
            frames.append(frame)
            yield frame

    folder = tmp_path_factory.mktemp("episode")
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(video.EpisodeVideo, "__iter__", keep)
        assert main(["evaluate", str(reacher_run), "--contexts", "1", "--video", str(folder / "v.gif")]) == 0
    np.save(folder / "frames.npy", np.stack(frames))
    return folder / "frames.npy"


#: ``creps-gym ARGS`` in a process whose videos replay the frames of a ``.npy`` file (sys.argv[1]).
REPLAY = (
    "import sys\nimport numpy as np\nfrom creps_gym.cli import main\n"
    "from creps_gym.runner.results import video\n"
    "frames = np.load(sys.argv[1])\nvideo.EpisodeVideo.__iter__ = lambda self: iter(frames)\n"
    "sys.exit(main(sys.argv[2:]))"
)


def _replay(monkeypatch: pytest.MonkeyPatch, recorded: Path) -> None:
    from creps_gym.runner.results import video

    frames = np.load(recorded)
    monkeypatch.setattr(video.EpisodeVideo, "__iter__", lambda self: iter(frames))


def _other_run(tmp_path: Path, source: Path) -> Path:
    other = tmp_path / "other"
    shutil.copytree(source, other)
    return other


def _snapshot(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir()) if p.is_file() and not p.is_symlink()}


# -- item 15: every output path follows the rules -o follows -------------------------------------------------
def _plant(tmp_path: Path, kind: str, other: Path) -> Path:
    if kind == "fifo":
        os.mkfifo(tmp_path / "out.npz")
        return tmp_path / "out.npz"
    if kind == "device-link":
        (tmp_path / "out.npz").symlink_to(os.devnull)
        return tmp_path / "out.npz"
    if kind == "folder":
        (tmp_path / "out.npz").mkdir()
        return tmp_path / "out.npz"
    return other / kind  # another run's own file


@pytest.mark.parametrize(
    ("kind", "expected"),
    [
        ("fifo", "expected a regular file or a new file, got a FIFO"),
        ("device-link", "got a character device"),
        ("folder", "got a directory"),
        (RunDir.CHECKPOINT, "expected a file outside a run directory's own files"),
        (RunDir.LOG, "expected a file outside a run directory's own files"),
        (RunDir.BEST_POLICY, "expected a file outside a run directory's own files"),
    ],
)
def test_policy_save_refuses_what_o_refuses_and_writes_nothing(tmp_path, capsys, sphere_run, kind, expected):
    other = _other_run(tmp_path, sphere_run)
    target = _plant(tmp_path, kind, other)
    before, kind_before = _snapshot(other), os.lstat(target).st_mode
    assert main(["policy", str(sphere_run), "--save", str(target)]) == 2
    err = capsys.readouterr().err
    assert "argument --save: expected" in err and expected in err and str(target.name) in err, err
    assert _snapshot(other) == before and os.lstat(target).st_mode == kind_before
    assert RunDir.open(other).load_checkpoint() is not None  # the other run still resumes


def test_policy_save_follows_a_link_and_names_its_target(tmp_path, capsys, sphere_run):
    (tmp_path / "link.npz").symlink_to(tmp_path / "target.npz")
    assert main(["policy", str(sphere_run), "--save", str(tmp_path / "link.npz")]) == 0
    out = capsys.readouterr().out
    assert f"{tmp_path / 'target.npz'} (through the link {tmp_path / 'link.npz'})" in out
    assert (tmp_path / "link.npz").is_symlink() and Policy.load(tmp_path / "target.npz").n_params == 3


@LINUX
def test_a_child_under_a_file_size_limit_leaves_no_cut_bytecode_behind(tmp_path):
    """The suite's children share one bytecode cache where PYTHONDONTWRITEBYTECODE is set (tests/conftest.py):
    a child under ``ulimit -f`` must not write there, or a ``.pyc`` cut at the limit breaks later children."""
    keywords = file_size_limited(1024)
    keywords["env"]["PYTHONPYCACHEPREFIX"] = str(tmp_path)
    done = subprocess.run([sys.executable, "-c", "import json.decoder"], timeout=60, **keywords)
    assert done.returncode == 0 and list(tmp_path.rglob("*.pyc")) == []


@LINUX
@pytest.mark.slow
def test_a_policy_save_that_cannot_be_written_names_the_file(tmp_path, sphere_run):
    target = tmp_path / "big.npz"
    result = subprocess.run(
        cli_command("policy", sphere_run, "--save", target),
        capture_output=True,
        text=True,
        timeout=120,
        **file_size_limited(1024),
    )
    assert result.returncode == 2, result.stderr
    assert f"argument --save: cannot write {target}: File too large" in result.stderr
    assert not target.exists() and sorted(os.listdir(tmp_path)) == []


def test_policy_save_in_python_refuses_a_fifo_and_follows_a_link(tmp_path, sphere_run):
    policy = Policy.load(sphere_run / RunDir.BEST_POLICY)
    os.mkfifo(tmp_path / "fifo.npz")
    match = r"path: expected a regular file or a new file, got a FIFO .*fifo\.npz"
    with pytest.raises(ValueError, match=match):
        policy.save(tmp_path / "fifo.npz")
    (tmp_path / "link.npz").symlink_to(tmp_path / "target.npz")
    assert policy.save(tmp_path / "link.npz") == tmp_path / "target.npz"
    assert Policy.load(tmp_path / "target.npz").equals(policy)


def test_the_runner_never_writes_its_policy_through_a_planted_link(tmp_path, sphere_run):
    other = _other_run(tmp_path, sphere_run)
    outside = tmp_path / "outside.npz"
    outside.write_bytes(b"keep")
    (other / RunDir.POLICY).unlink()
    (other / RunDir.POLICY).symlink_to(outside)  # resume completes the finished run's missing file
    with pytest.raises(RunDirError, match=r"policy\.npz: expected a regular file, got a symbolic link"):
        resume(other)
    assert outside.read_bytes() == b"keep"


@EXTRAS
@pytest.mark.parametrize(
    ("name", "expected"),
    [
        ("video.mp4.npz", "expected a file name ending in .mp4 or .gif, got"),
        (RunDir.CHECKPOINT, "expected a file name ending in .mp4 or .gif"),
        (RunDir.PLOT, "expected a file name ending in .mp4 or .gif"),
        ("folder.mp4", "expected a regular file or a new file, got a directory"),
        ("fifo.gif", "expected a regular file or a new file, got a FIFO"),
    ],
)
def test_evaluate_video_refuses_what_o_refuses_and_reports_no_success(
    tmp_path, capsys, reacher_run, name, expected
):
    other = _other_run(tmp_path, reacher_run)
    (tmp_path / "video.mp4.npz").write_bytes((other / RunDir.CHECKPOINT).read_bytes())
    (tmp_path / "folder.mp4").mkdir()
    os.mkfifo(tmp_path / "fifo.gif")
    reader = os.open(tmp_path / "fifo.gif", os.O_RDONLY | os.O_NONBLOCK)  # a writer never blocks on it
    target = other / name if name in RunDir.FILES else tmp_path / name
    before, outside = _snapshot(other), _snapshot(tmp_path)
    try:
        assert main(["evaluate", str(reacher_run), "--contexts", "2", "--video", str(target)]) == 2
    finally:
        os.close(reader)
    captured = capsys.readouterr()
    assert f"argument --video: {expected}" in captured.err and '"video"' not in captured.out
    assert _snapshot(other) == before and _snapshot(tmp_path) == outside


@EXTRAS
@LINUX
@pytest.mark.parametrize("suffix", [".mp4", ".gif"])
@pytest.mark.slow
def test_a_video_cut_by_a_full_disk_is_an_error_naming_the_file(
    tmp_path, reacher_run, recorded_episode, suffix
):
    target = tmp_path / f"video{suffix}"
    args = ["evaluate", reacher_run, "--contexts", 2, "--video", target]
    result = subprocess.run(
        [sys.executable, "-c", REPLAY, recorded_episode, *map(str, args)],
        capture_output=True,
        text=True,
        timeout=120,
        **file_size_limited(4096),
    )
    assert result.returncode == 2, result.stderr
    assert f"argument --video: cannot write {target}: " in result.stderr and '"video"' not in result.stdout
    assert sorted(os.listdir(tmp_path)) == []  # neither the video nor its temporary


@EXTRAS
@pytest.mark.parametrize("suffix", [".mp4", ".gif"])
def test_a_video_is_written_whole_through_a_temporary(
    tmp_path, capsys, monkeypatch, reacher_run, recorded_episode, suffix
):
    from creps_gym.cli.policy import check_video_file

    _replay(monkeypatch, recorded_episode)
    target = tmp_path / f"video{suffix}"
    assert main(["evaluate", str(reacher_run), "--contexts", "2", "--video", str(target)]) == 0
    assert f'"video": "{target}"' in capsys.readouterr().out
    check_video_file(target)
    assert sorted(os.listdir(tmp_path)) == [target.name]
    cut = tmp_path / f"cut{suffix}"
    cut.write_bytes(target.read_bytes()[: target.stat().st_size // 2])
    with pytest.raises(OSError, match="the video written is incomplete"):
        check_video_file(cut)


# -- item 19: terminal escapes and litter -------------------------------------------------------------------
@pytest.mark.parametrize(
    ("env", "kwargs"), [("\x1b[2Jcreps_gym/Sphere-v0", {}), (SPHERE, {"dim\x1b[31m": 1})], ids=["id", "kwarg"]
)
def test_text_from_a_policy_file_is_printed_escaped(tmp_path, capsys, sphere_run, env, kwargs):
    policy = Policy.load(sphere_run / RunDir.BEST_POLICY)
    forged = Policy(policy.features, policy.coefficients, env=env, env_kwargs=kwargs, source=policy.source)
    forged.save(tmp_path / "forged.npz")
    assert main(["evaluate", str(tmp_path / "forged.npz")]) == 3
    err = capsys.readouterr().err
    assert "\x1b" not in err and "\\x1b" in err and "forged.npz names an env that cannot be made" in err


def test_resume_of_a_finished_run_removes_its_stale_temporaries(tmp_path, sphere_run):
    other = _other_run(tmp_path, sphere_run)
    stale = [other / f".{RunDir.POLICY}.99999.tmp", other / f".{RunDir.BEST_POLICY}.99999.tmp"]
    for path in stale:
        path.write_bytes(b"cut")
    (other / "user.tmp").write_bytes(b"mine")
    resume(other)
    assert not any(path.exists() for path in stale) and (other / "user.tmp").read_bytes() == b"mine"
