"""Resume after a real SIGKILL: the resumed History equals an uninterrupted run's exactly."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest
from helpers import SPHERE, cli_command, cli_in_process

from creps_gym.runner import History, RunDir, resume, run

if not hasattr(signal, "SIGKILL"):  # pragma: no cover - Windows
    pytest.skip("needs SIGKILL", allow_module_level=True)

SETTINGS = {"iterations": 150, "samples": 12, "seed": 5, "checkpoint_every": 3, "eval_every": 2}


def _iterations_logged(path: Path) -> int:
    if not path.exists():
        return 0
    return sum(1 for line in path.read_text().splitlines() if line.startswith('{"iteration"'))


def _kill_when(process: subprocess.Popen, ready, what: str, timeout: float = 90.0) -> None:
    """SIGKILL ``process`` as soon as ``ready()`` holds; fail if it ends first."""
    deadline = time.monotonic() + timeout
    while not ready():
        if process.poll() is not None:
            pytest.fail(f"the run ended (code {process.returncode}) before {what}: {process.stderr.read()}")
        if time.monotonic() > deadline:
            process.kill()
            pytest.fail(f"timed out waiting for {what}")
        time.sleep(0.002)
    process.send_signal(signal.SIGKILL)
    process.wait(timeout=30)
    assert process.returncode == -signal.SIGKILL


@pytest.mark.slow
def test_sigkill_at_several_moments_then_resume_gives_the_uninterrupted_history(tmp_path):
    """The process boundary, once: a learning selector's state is checkpointed beside the optimiser's. Every
    optimiser and selector resumes after a crash at any moment in tests/runner/test_contract_resume.py."""
    optimizer, selector = "creps-cma-old", "bandit"
    out = tmp_path / "run"
    log = out / RunDir.LOG
    s = SETTINGS
    chosen = ["--context-selector", selector, "--selector-opt", "cells=5"] if selector else []
    start = cli_command(
        "run",
        "--env",
        SPHERE,
        "--optimizer",
        optimizer,
        "--iterations",
        s["iterations"],
        "--samples",
        s["samples"],
        "--seed",
        s["seed"],
        "--out",
        out,
        "--env-kwarg",
        "dim=6",
        "--checkpoint-every",
        s["checkpoint_every"],
        "--eval-every",
        s["eval_every"],
        "--no-plot",
        *chosen,
    )
    resume = cli_command("resume", out, "--no-plot")
    popen = {"stdout": subprocess.DEVNULL, "stderr": subprocess.PIPE, "text": True}
    # 1) killed as soon as the run directory exists (most likely before the first checkpoint);
    _kill_when(subprocess.Popen(start, **popen), lambda: (out / RunDir.CONFIG).exists(), "config.json")
    # 2) killed mid-run, 10 iterations later (most likely between checkpoints);
    base = _iterations_logged(log)
    _kill_when(
        subprocess.Popen(resume, **popen), lambda: _iterations_logged(log) >= base + 10, "10 iterations"
    )
    checkpointed = RunDir.open(out).load_checkpoint()[0]["iteration"]
    assert checkpointed % s["checkpoint_every"] == 0 and checkpointed < s["iterations"]
    # 3) killed again after the first resume made progress; 4) resumed to the end.
    base = _iterations_logged(log)
    _kill_when(
        subprocess.Popen(resume, **popen), lambda: _iterations_logged(log) >= base + 35, "35 iterations"
    )
    assert not (out / RunDir.HISTORY_JSON).exists()
    finished = cli_in_process("resume", out, "--no-plot")  # the last resume needs no process of its own
    assert finished.returncode == 0, finished.stderr

    whole = tmp_path / "whole"
    options = {"context_selector": selector, "context_selector_options": {"cells": 5}} if selector else {}
    expected = run(
        optimizer,
        SPHERE,
        s["iterations"],
        s["samples"],
        s["seed"],
        env_kwargs={"dim": 6},
        checkpoint_every=s["checkpoint_every"],
        eval_every=s["eval_every"],
        run_dir=whole,
        **options,
    )
    for name in (RunDir.BEST_POLICY, RunDir.POLICY):  # the policies too, bit for bit
        assert (out / name).read_bytes() == (whole / name).read_bytes()
    resumed = History.from_json(out / RunDir.HISTORY_JSON)
    assert resumed.equals(expected) and len(resumed) == s["iterations"]
    records, events = RunDir.open(out).read_log()  # re-done iterations appear twice; the last copy counts
    assert History(records, stop_reason="iterations").equals(expected)
    sessions = [e["event"] for e in events if e["event"] in ("start", "resume")]
    # (the first session may be killed before it logs its start)
    assert len(sessions) in (3, 4) and sessions[-1] == "resume" and events[-1]["event"] == "end"
    assert os.listdir(out) and not [name for name in os.listdir(out) if name.endswith(".tmp")]


def test_a_format_2_run_directory_resumes_with_its_own_context_stream(tmp_path):
    """tests/golden/run2 was written by the code before batched draws (see tests/golden/make_run2.py)."""
    golden = Path(__file__).resolve().parents[2] / "golden" / "run2"
    out = tmp_path / "run"
    shutil.copytree(golden / "run", out)
    directory = RunDir.open(out)
    assert directory.load_checkpoint()[0]["held_history"]  # a legacy checkpoint: it holds the history
    assert directory.config().context_draws == "reset"  # its config.json predates the field
    expected = History.from_json(golden / "expected_history.json")  # the old code's uninterrupted run
    resumed = resume(out)
    # Equal up to rounding, not bit for bit: the golden run was written on another machine, and OpenBLAS
    # picks its kernels by CPU (and CI's lowest-versions run has other numpy/scipy versions), so the last bits
    # may differ. Another context stream would differ in the first digit. Bit-identical resumes on one
    # machine are the other tests' subject.
    assert len(resumed) == len(expected) == 9
    assert resumed.column("episodes").tolist() == expected.column("episodes").tolist()
    for name in ("mean_return", "eval_return"):
        np.testing.assert_allclose(resumed.column(name), expected.column(name), rtol=1e-9)
    state = directory.load_checkpoint()[0]
    assert "history" not in state and state["iteration"] == 9  # the final checkpoint has today's format
    assert RunDir.open(out).read_history().equals(resumed)
