"""Contract: a run interrupted and resumed gives the uninterrupted run's history and final state, bit for bit.

Driven by the registries: every registered optimiser (the bundled adapters of pycma, nevergrad and optuna
included, marked ``extras``), every registered context selector and every env id that needs no optional
extra. Each case interrupts a run (an exception after an iteration's record, between two checkpoints or just
after one, so that the iterations since the last checkpoint are done again; for the optimisers also inside an
iteration's batch of episodes), resumes it, and compares it with one uninterrupted run built once per module
and setting: the History (``History.equals``), the kept policies and the final checkpoint's state.

Tests that check more stay beside their subject: a real SIGKILL at several moments and the old run-folder
formats (``rundir/test_resume.py``), the log's re-done records and object resumes (``test_runner.py``), the
divergence rule (``test_divergence.py``), the kept best policy (``test_policy_runner.py``), the studies'
runs (``studies/``) and Ray clusters (``backends/``).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from helpers import SPHERE, crash_at, marked, needs_extra

from creps_gym.optimizers.registry import optimizer_names
from creps_gym.runner import History, RunDir, resume, run
from creps_gym.selectors.registry import selector_names

# every optimiser: c-bo's setting is the one of the former tests/optimizers/test_cbo.py case
OPTIMIZER_RUN = {"iterations": 10, "seed": 5, "checkpoint_every": 3, "eval_contexts": 4}
OPTIMIZER_ENV = {"dim": 2, "context_dim": 1}
OPTIMIZER_SAMPLES = {"c-bo": 4}  # the others: their default sample size
# every selector: the setting of the former tests/selectors/test_selectors.py case
SELECTOR_RUN = {
    "iterations": 10,
    "samples_per_iteration": 16,
    "seed": 2,
    "checkpoint_every": 3,
    "eval_every": 2,
}
SELECTOR_ENV = {"dim": 4, "context_dim": 2}
SELECTOR_OPTIONS = {"fixed": {"contexts": [[0.5, 1.0], [2.0, 3.0]]}}
ENV_RUN = {"iterations": 5, "samples_per_iteration": None, "seed": 3, "checkpoint_every": 2}
CRASH = 7  # between the checkpoints of iterations 6 and 9: iteration 7 is done again
AFTER_CHECKPOINT = 4  # the first iteration after the checkpoint of iteration 3
UNSHARED = ("elapsed", "log_crc")  # checkpoint entries an interrupted run cannot share
CHEAP_ENVS = [name for name in gym.registry if name.startswith("creps_gym/") and not needs_extra(name)]


def _final_state(out: Path) -> dict[str, Any]:
    """The run folder's final state: its kept policies' bytes and its last checkpoint's entries, but for the
    wall time and the checksum of the log (a resumed run's log also holds its interruption)."""
    state = {k: v for k, v in RunDir.open(out).load_checkpoint()[0].items() if k not in UNSHARED}
    files = {name: (out / name).read_bytes() for name in (RunDir.BEST_POLICY, RunDir.POLICY)}
    return {"files": files, "checkpoint": state}


def _same(a: Any, b: Any) -> bool:
    """Whether two checkpoint values are equal bit for bit (arrays by dtype, shape and bytes)."""
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)):
        return isinstance(b, (list, tuple)) and len(a) == len(b) and all(map(_same, a, b))
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        a, b = np.asarray(a), np.asarray(b)
        return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()
    if isinstance(a, float) and isinstance(b, float):
        return np.float64(a).tobytes() == np.float64(b).tobytes()
    return type(a) is type(b) and a == b


def _check_resume(reference: tuple[History, dict], interrupted: Path, iterations: int) -> History:
    """Resume ``interrupted`` and compare it with the uninterrupted run's ``reference``."""
    expected, final = reference
    resumed = resume(interrupted)
    assert resumed.equals(expected) and len(resumed) == iterations
    assert RunDir.open(interrupted).read_history().equals(expected)
    state = _final_state(interrupted)
    assert state["files"] == final["files"]  # the policies, bit for bit
    assert _same(state["checkpoint"], final["checkpoint"])
    return resumed


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """``reference(key, **arguments)``: the uninterrupted run of ``run(**arguments)`` and its final state,
    built once per module and key."""
    cache: dict[str, tuple[History, dict]] = {}

    def build(key: str, **arguments: Any) -> tuple[History, dict]:
        if key not in cache:
            out = tmp_path_factory.mktemp("uninterrupted") / "run"
            cache[key] = (run(run_dir=out, **arguments), _final_state(out))
        return cache[key]

    return build


# -- every optimiser -------------------------------------------------------------------------------------
def _optimizer_arguments(name: str) -> dict[str, Any]:
    return {
        "optimizer": name,
        "env": SPHERE,
        "samples_per_iteration": OPTIMIZER_SAMPLES.get(name),
        "env_kwargs": OPTIMIZER_ENV,
        **OPTIMIZER_RUN,
    }


def _optimizer_params() -> list[Any]:
    """Every registered optimiser crashed after iteration 7 (re-doing iteration 7) and after iteration 4 (the
    first after a checkpoint); c-bo (about 20 s a case: its model grows with every episode) only after 7,
    marked ``slow``."""
    params = []
    for param in marked(optimizer_names()):
        name = param if isinstance(param, str) else param.values[0]
        marks = () if isinstance(param, str) else param.marks
        if name == "c-bo":
            params.append(pytest.param(name, CRASH, marks=[*marks, pytest.mark.slow]))
        else:
            params += [pytest.param(name, crash, marks=marks) for crash in (AFTER_CHECKPOINT, CRASH)]
    return params


@pytest.mark.parametrize(("name", "crash"), _optimizer_params())
def test_every_optimiser_resumes_to_the_uninterrupted_history_and_state(name, crash, reference, tmp_path):
    arguments = _optimizer_arguments(name)
    expected = reference(f"optimizer:{name}", **arguments)
    with pytest.raises(RuntimeError, match="crash"):
        run(run_dir=tmp_path / "run", callbacks=[crash_at(crash)], **arguments)
    checkpointed = RunDir.open(tmp_path / "run").load_checkpoint()[0]["iteration"]
    every = OPTIMIZER_RUN["checkpoint_every"]
    assert checkpointed == (crash - 1) // every * every  # 6 (crash after 7) or 3 (after 4)
    resumed = _check_resume(expected, tmp_path / "run", OPTIMIZER_RUN["iterations"])
    assert resumed.records[-1].iteration == OPTIMIZER_RUN["iterations"]


def _mid_iteration_params() -> list[Any]:
    """Every registered optimiser but c-bo (whose after-7 case is already ``slow``)."""
    return [p for p in marked(optimizer_names()) if p != "c-bo"]


@pytest.mark.parametrize("name", _mid_iteration_params())
def test_every_optimiser_resumes_after_a_crash_inside_an_iteration(name, reference, tmp_path, monkeypatch):
    """Interrupted inside iteration 7's batch of episodes, between the optimiser's ask and its tell."""
    arguments = _optimizer_arguments(name)
    expected = reference(f"optimizer:{name}", **arguments)
    env_class = type(gym.make(SPHERE, **OPTIMIZER_ENV).unwrapped)
    objective, calls = env_class._objective, {"made": 0, "crash": None}

    def crashing(self: Any, contexts: Any, params: Any) -> Any:
        calls["made"] += 1
        if calls["made"] == calls["crash"]:
            raise KeyboardInterrupt
        return objective(self, contexts, params)

    def after_six(record: Any, history: Any) -> None:  # the next evaluation is iteration 7's batch
        if record.iteration == CRASH - 1:
            calls["crash"] = calls["made"] + 1

    monkeypatch.setattr(env_class, "_objective", crashing)
    with pytest.raises(KeyboardInterrupt):
        run(run_dir=tmp_path / "run", callbacks=[after_six], **arguments)
    monkeypatch.undo()
    assert calls["made"] == calls["crash"]
    assert RunDir.open(tmp_path / "run").load_checkpoint()[0]["iteration"] == 6
    assert len(RunDir.open(tmp_path / "run").read_log()[0]) == 6  # iteration 7 left no record
    _check_resume(expected, tmp_path / "run", OPTIMIZER_RUN["iterations"])


# -- every context selector --------------------------------------------------------------------------------
@pytest.mark.parametrize("name", selector_names())
def test_every_selector_resumes_to_the_uninterrupted_history_and_state(name, reference, tmp_path):
    arguments = {
        "optimizer": "creps-cma-old",
        "env": SPHERE,
        "env_kwargs": SELECTOR_ENV,
        "context_selector": name,
        "context_selector_options": SELECTOR_OPTIONS.get(name, {}),
        **SELECTOR_RUN,
    }
    expected = reference(f"selector:{name}", **arguments)

    def interrupt(record, history):  # Ctrl-C after iteration 7's record
        if record.iteration == CRASH:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run(run_dir=tmp_path, callbacks=[interrupt], **arguments)
    state = RunDir.open(tmp_path).load_checkpoint()[0]
    assert state["iteration"] == 6 and "selector" in state and "selector_rng" in state
    _check_resume(expected, tmp_path, SELECTOR_RUN["iterations"])
    config = json.loads((tmp_path / RunDir.CONFIG).read_text())["config"]
    assert config["context_selector"] == name


# -- every cheap env id ------------------------------------------------------------------------------------
@pytest.mark.parametrize("env_id", CHEAP_ENVS)
@pytest.mark.filterwarnings("ignore:.*is out of date:DeprecationWarning")  # the older versions, as registered
def test_every_env_resumes_to_the_uninterrupted_history_and_state(env_id, reference, tmp_path):
    arguments = {"optimizer": "creps-cma-old", "env": env_id, **ENV_RUN}
    expected = reference(f"env:{env_id}", **arguments)
    with pytest.raises(RuntimeError, match="crash"):
        run(run_dir=tmp_path / "run", callbacks=[crash_at(3)], **arguments)
    assert RunDir.open(tmp_path / "run").load_checkpoint()[0]["iteration"] == 2
    _check_resume(expected, tmp_path / "run", ENV_RUN["iterations"])
