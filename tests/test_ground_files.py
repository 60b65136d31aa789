"""The ground floor's safe file IO (:mod:`creps_gym._files`), directly: what every caller relies on.

The callers' own wording is tested with them (test_rundir_*, test_policy_*, test_optimizer_state).
"""

from __future__ import annotations

import os
import sys

import pytest

from creps_gym import _files

POSIX = pytest.mark.skipif(sys.platform == "win32", reason="links and FIFOs")


@POSIX
def test_a_bounded_read_refuses_a_link_a_fifo_a_folder_and_a_large_file(tmp_path):
    (tmp_path / "file").write_bytes(b"12345")
    (tmp_path / "link").symlink_to(tmp_path / "file")
    os.mkfifo(tmp_path / "fifo")
    (tmp_path / "folder").mkdir()
    bound = _files.Bound(5)
    assert _files.read_bounded(tmp_path / "file", bound) == b"12345"
    for name, kind in (("link", "a symbolic link"), ("fifo", "a FIFO"), ("folder", "a directory")):
        with pytest.raises(ValueError, match=f"{name}: expected a regular file, got {kind}"):
            _files.read_bounded(tmp_path / name, bound)
    with pytest.raises(ValueError, match="file: expected at most 4 bytes, got 5"):
        _files.read_bounded(tmp_path / "file", _files.Bound(4))
    with pytest.raises(FileNotFoundError):
        _files.read_bounded(tmp_path / "missing", bound)


def test_a_bound_words_its_callers_refusals(tmp_path):
    (tmp_path / "big").write_bytes(b"x" * 10)
    bound = _files.Bound(3, too_large=lambda path, limit, size: KeyError(f"{path.name} {limit} {size}"))
    with pytest.raises(KeyError, match="big 3 10"):
        _files.read_bounded(tmp_path / "big", bound)


@POSIX
def test_an_atomic_write_replaces_a_link_never_follows_one_and_leaves_no_temporary(tmp_path):
    outside = tmp_path / "outside"
    outside.write_bytes(b"keep")
    (tmp_path / "target").symlink_to(outside)
    planted = _files.temporary_beside(tmp_path / "target")
    planted.symlink_to(outside)  # a link where the temporary goes: removed, never written through
    assert _files.write_atomically(tmp_path / "target", b"new") == tmp_path / "target"
    assert outside.read_bytes() == b"keep" and not (tmp_path / "target").is_symlink()
    assert (tmp_path / "target").read_bytes() == b"new"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["outside", "target"]


def test_a_failed_write_leaves_the_target_and_no_temporary(tmp_path):
    (tmp_path / "target").write_bytes(b"old")

    def fail(stream):
        stream.write(b"half")
        raise RuntimeError("disk on fire")

    with pytest.raises(RuntimeError, match="disk on fire"):
        _files.replace_atomically(tmp_path / "target", fail)
    assert (tmp_path / "target").read_bytes() == b"old" and os.listdir(tmp_path) == ["target"]
    assert _files.temporary_beside(tmp_path / "a.mp4", keep_suffix=True).name == f".a.{os.getpid()}.tmp.mp4"


@POSIX
def test_an_output_target_follows_a_link_and_refuses_what_is_not_a_regular_file(tmp_path):
    (tmp_path / "link").symlink_to(tmp_path / "new")
    assert _files.output_target(tmp_path / "link") == tmp_path.resolve() / "new"
    os.mkfifo(tmp_path / "fifo")
    with pytest.raises(ValueError, match="-o: expected a regular file or a new file, got a FIFO"):
        _files.output_target(tmp_path / "fifo", name="-o")
    with pytest.raises(ValueError, match="expected a file outside a run directory's own files"):
        _files.output_target(tmp_path / "x", protected=lambda target: True)
