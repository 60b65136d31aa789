"""The order the test files run in (``tests/conftest.py``): the longest first, by ``tests/durations.json``."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import conftest

TESTS = Path(__file__).resolve().parent


def test_every_file_the_durations_name_is_a_test_file_with_its_seconds():
    seconds = json.loads(conftest.DURATIONS.read_text(encoding="utf-8"))
    assert conftest.DURATIONS.parent == TESTS and len(seconds) >= 50
    for name, value in seconds.items():
        assert name.startswith("tests/") and (TESTS.parent / name).is_file(), name
        assert isinstance(value, float) and value >= 0.0, (name, value)
    assert list(seconds.values()) == sorted(seconds.values(), reverse=True)


def test_the_longest_files_go_first_each_in_one_piece_and_unlisted_ones_last(monkeypatch, tmp_path):
    durations = tmp_path / "durations.json"
    durations.write_text(json.dumps({"tests/b.py": 9.0, "tests/c.py": 2.5, "tests/gone.py": 50.0}))
    monkeypatch.setattr(conftest, "DURATIONS", durations)
    nodeids = ["tests/a.py::t1", "tests/a.py::t2", "tests/b.py::t1", "tests/c.py::t[1]", "tests/c.py::t[2]"]
    nodeids += ["tests/b.py::t2", "tests/d.py::t"]
    items = [SimpleNamespace(nodeid=nodeid) for nodeid in nodeids]
    conftest.pytest_collection_modifyitems(None, items)
    assert [item.nodeid for item in items] == [
        "tests/b.py::t1",
        "tests/b.py::t2",
        "tests/c.py::t[1]",
        "tests/c.py::t[2]",
        "tests/a.py::t1",
        "tests/a.py::t2",
        "tests/d.py::t",
    ]
    monkeypatch.setattr(conftest, "DURATIONS", tmp_path / "absent.json")  # no file: the collection order
    items = [SimpleNamespace(nodeid=nodeid) for nodeid in nodeids]
    conftest.pytest_collection_modifyitems(None, items)
    assert [item.nodeid for item in items] == nodeids
