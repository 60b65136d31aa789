"""The order the test files run in (`tests/suite_order.py`): the longest first, by `tests/durations.json`."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import suite_order

TESTS = Path(__file__).resolve().parent


def test_every_file_the_durations_name_is_a_test_file_with_its_seconds():
    seconds = json.loads(suite_order.DURATIONS.read_text(encoding="utf-8"))
    assert suite_order.DURATIONS.parent == TESTS and len(seconds) >= 50
    for name, value in seconds.items():
        assert name.startswith("tests/") and (TESTS.parent / name).is_file(), name
        assert isinstance(value, float) and value >= 0.0, (name, value)
    assert list(seconds.values()) == sorted(seconds.values(), reverse=True)


def test_the_longest_files_go_first_each_in_one_piece_and_unlisted_ones_last(tmp_path):
    durations = tmp_path / "durations.json"
    suite_order.write_durations({"tests/c.py": 2.5, "tests/gone.py": 50.04, "tests/b.py": 9.0}, durations)
    assert json.loads(durations.read_text()) == {"tests/gone.py": 50.0, "tests/b.py": 9.0, "tests/c.py": 2.5}
    nodeids = ["tests/a.py::t1", "tests/a.py::t2", "tests/b.py::t1", "tests/b.py::t2", "tests/c.py::t[1]"]
    nodeids += ["tests/c.py::t[2]", "tests/d.py::t"]
    items = [SimpleNamespace(nodeid=nodeid) for nodeid in nodeids]
    suite_order.order_by_durations(items, durations)
    assert [item.nodeid for item in items] == [
        "tests/b.py::t1",
        "tests/b.py::t2",
        "tests/c.py::t[1]",
        "tests/c.py::t[2]",
        "tests/a.py::t1",
        "tests/a.py::t2",
        "tests/d.py::t",
    ]
    items = [SimpleNamespace(nodeid=nodeid) for nodeid in nodeids]
    suite_order.order_by_durations(items, tmp_path / "absent.json")  # no file: the collection order
    assert [item.nodeid for item in items] == nodeids
