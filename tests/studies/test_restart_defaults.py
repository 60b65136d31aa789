"""``benchmarks/restart_defaults.py``: which committed runs the restart defaults of issue 33 touch, and the
documents pinned to the former defaults are the runs of their pinned spec."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from benchmarks import restart_defaults
from benchmarks.contextual_bbo.protocol import ProtocolSpec
from benchmarks.study_options import pin_c3
from benchmarks.study_runner import run_all
from benchmarks.study_tools import RunSpec


def _document(method: str = "c-cma-es", options=(), **extra) -> dict:
    return {"spec": {"method": method, "options": options}, **extra}


def test_a_run_is_touched_unless_it_cannot_restart_or_pins_both_options():
    assert restart_defaults.affected(_document())
    assert restart_defaults.affected(_document("c-cma-es-surrogate"))
    assert restart_defaults.affected(_document(options=[["keep_best", True]]))  # the loss still changes
    assert restart_defaults.affected(_document(options={"restart_baseline_loss": "huber"}))
    assert not restart_defaults.affected(_document(options=[["restarts", 0]]))
    assert not restart_defaults.affected(_document(options=restart_defaults.FORMER))
    assert not restart_defaults.affected(_document("creps-cma-old"))
    assert not restart_defaults.affected(_document(restarts=0.0))  # recorded: it never restarted
    assert restart_defaults.affected(_document(restarts=0.0), recorded=False)
    assert restart_defaults.affected(_document(restarts=2.0))


def test_a_pinned_document_has_the_key_of_its_pinned_spec():
    spec = RunSpec("Rosenbrock", 2, 5, "c-cma-es", 0, 100_000)
    key, document = restart_defaults.pinned("scaling", {"spec": {**spec.__dict__, "options": ()}, "hit": 7})
    pinned = RunSpec(**document["spec"])
    assert key == pinned.key and pinned.options == restart_defaults.FORMER and document["hit"] == 7
    assert key == "Rosenbrock-p2-z5-c-cma-es-keep_best=False-restart_baseline_loss=squared-s0-b100000-n50"
    protocol = {"function": "Sphere", "method": "c-cma-es", "seed": 3, "options": {}, "label": ""}
    key, document = restart_defaults.pinned("contextual_bbo", {"spec": protocol})
    assert key.startswith("Sphere-c-cma-es-former-restarts-s3-")
    options = tuple(document["spec"]["options"].items())
    assert ProtocolSpec(**{**document["spec"], "options": options}).key == key


def test_pin_renames_or_copies_and_reads_no_link(tmp_path, monkeypatch):
    runs = tmp_path / "scaling" / "runs"
    runs.mkdir(parents=True)
    spec = RunSpec("Rosenbrock", 2, 5, "c-cma-es", 0, 100_000)
    original = runs / f"{spec.key}.json"
    original.write_text(json.dumps({"spec": {**spec.__dict__, "options": []}, "seconds": 1.0}))
    (runs / "link.json").symlink_to(original)
    monkeypatch.setattr(restart_defaults, "HERE", tmp_path)
    assert restart_defaults.documents("scaling") == [original]
    assert restart_defaults.main(["pin", "--study", "scaling", "--copy"]) == 0
    pinned = runs / f"{restart_defaults.pinned('scaling', json.loads(original.read_text()))[0]}.json"
    assert original.exists() and pinned.exists()
    pinned.unlink()
    assert restart_defaults.main(["pin", "--study", "scaling"]) == 0
    assert not original.exists() and pinned.exists()
    assert restart_defaults.documents("scaling") == []  # a pinned run is not touched again
    with pytest.raises(ValueError, match="study: expected one of"):
        restart_defaults.documents("kick")


def _history(run: dict) -> list[tuple[int, float]]:
    return list(zip(run["episodes"], run["values"], strict=True))


@pytest.mark.slow
def test_the_committed_pinned_document_is_its_run_and_the_new_defaults_change_it(tmp_path: Path):
    """The check behind ``pin`` on a scaling run that restarts: its committed document, pinned to the
    former defaults, is what the pinned spec computes (the former None restart loss is the squared one:
    ``tests/optimizers/test_ccmaes_restarts.py``); with the new defaults the run differs."""
    former_options = pin_c3("c-cma-es", restart_defaults.FORMER)  # C3 too: the committed run's ridge
    former = RunSpec("Rosenbrock", 2, 5, "c-cma-es", 0, 100_000, options=former_options)
    # The two part at the first restart (the evaluation at 2,700 episodes): a 4,000-episode run shows it,
    # for a tenth of the whole new-default run's time (that one stops at 32,100 episodes, after 6 s).
    default = RunSpec("Rosenbrock", 2, 5, "c-cma-es", 0, 4_000, options=pin_c3("c-cma-es"))
    pinned, new = run_all([former, default], tmp_path, workers=1, log=lambda line: None)
    path = restart_defaults.HERE / "scaling" / "runs" / f"{former.key}.json"
    committed = json.loads(path.read_text(encoding="utf-8"))
    # Bit for bit on the stack that computed it; elsewhere OpenBLAS's kernels change the last bits only
    # (benchmarks/scaling/README.md, "what is bit-reproducible"), on this short p = 2 run.
    np.testing.assert_allclose(pinned["values"], committed["values"], rtol=1e-9)
    assert pinned["episodes"] == committed["episodes"]
    assert pinned["stop_reason"] == committed["stop_reason"] == "optimizer: tolstagnation"
    assert _history(new) != _history(pinned)[: len(new["values"])]
