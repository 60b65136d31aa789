"""``creps-gym ask`` / ``tell``: a run driven episode by episode from the shell (issue 44, item 4).

In process through ``helpers.cli_in_process``; the crash tests drive :class:`AskTellRun` directly and
crash before each write of a whole sequence, then do what a user would: run the failed command again.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from helpers import SPHERE, cli_in_process

from creps_gym.cli import EXIT_CODES
from creps_gym.optimizers.policy_file import Policy
from creps_gym.runner import RunDir, rundir
from creps_gym.runner.config import RunConfig
from creps_gym.runner.manual import AskTellRun, Spaces
from creps_gym.runner.rundir import files
from creps_gym.runner.rundir import policies as policy_store

BOXES = [
    "--params",
    "2",
    "--param-low",
    "-1",
    "--param-high",
    "1",
    "--context-low",
    "0",
    "--context-high",
    "1",
]
#: c-bo's cheapest settings: the tests check the bookkeeping, not the search
CHEAP = {"distillation_points": 2, "starts": 1, "candidates": 16}
NEW = ["--new", "--optimizer", "c-bo", "--seed", "3", "--samples", "2", *BOXES]
NEW += [f"--opt={key}={value}" for key, value in CHEAP.items()]
CONTEXTS = [0.1, 0.9, 0.5, 0.3]


def returns_of(params: list[float], context: float) -> float:
    return -float(np.sum((np.asarray(params) - context) ** 2))


def ask(run: Path, *args: Any) -> dict[str, Any]:
    result = cli_in_process("ask", run, "--json", *args)
    assert result.returncode == 0, result.stderr
    return json.loads(result.stdout)


def tell(run: Path, *args: Any) -> dict[str, Any]:
    result = cli_in_process("tell", run, "--json", *args)
    assert result.returncode == 0, result.stderr
    return json.loads(result.stdout)


def drive(run: Path, contexts: list[float]) -> list[list[float]]:
    """Ask and tell each context in turn; the parameters asked."""
    asked = []
    for context in contexts:
        out = ask(run, "--context", context)
        asked.append(out["params"])
        tell(run, "--return", returns_of(out["params"], context), "--episode", out["episode"])
    return asked


def test_a_run_from_the_shell(tmp_path: Path) -> None:
    run = tmp_path / "robot"
    assert cli_in_process("ask", run, *NEW).returncode == 0
    first = cli_in_process("ask", run, "--context", "0.4")
    assert first.returncode == 0, first.stderr
    params = [float(x) for x in first.stdout.split()]
    assert len(params) == 2 and all(-1 <= x <= 1 for x in params)
    assert "episode 1" in first.stderr and "--episode 1 --return R" in first.stderr
    second = ask(run, "--context", "0.7")
    assert second["episode"] == 2 and second["pending"] == [1, 2]
    full = cli_in_process("ask", run, "--context", "0.5")  # the batch of 2 is fully asked
    assert full.returncode == EXIT_CODES["usage"] and "pending" in full.stderr
    pending = ask(run, "--pending")
    assert [e["episode"] for e in pending["pending"]] == [1, 2] and pending["pending"][0]["params"] == params
    which = cli_in_process("tell", run, "--return", "-0.3")
    assert which.returncode == EXIT_CODES["usage"] and "[1, 2]" in which.stderr
    assert tell(run, "--return", "-0.3", "--episode", "1")["batch_told"] is False
    again = cli_in_process(
        "tell", run, "--return", "-0.3", "--episode", "1"
    )  # a retry of a tell that was done
    assert again.returncode == EXIT_CODES["usage"] and "got 1 (told already" in again.stderr
    done = tell(run, "--return", "-0.5", "--episode", "2")
    assert done["batch_told"] and done["iteration"] == 1 and done["mean_return"] == pytest.approx(-0.4)
    policy = cli_in_process("policy", run, "--context", "0.5")  # an ask/tell run's default: its final policy
    assert policy.returncode == 0, policy.stderr
    assert json.loads(policy.stdout)["which"] == "final"
    evaluate = cli_in_process("evaluate", run)
    assert evaluate.returncode == EXIT_CODES["usage"] and "ask/tell run without --env" in evaluate.stderr
    resume = cli_in_process("resume", run)
    assert resume.returncode == EXIT_CODES["usage"] and "`creps-gym ask`" in resume.stderr
    history = RunDir.open(run).read_history()
    assert len(history) == 1 and history.records[0].episodes == 2
    options = RunDir.open(run).config().optimizer_options  # c-bo searches the box the user typed
    assert options["param_low"] == [-1.0, -1.0] and options["context_high"] == [1.0]


def test_same_seed_and_returns_give_the_same_bits(tmp_path: Path) -> None:
    runs = [tmp_path / "a", tmp_path / "b"]
    asked = []
    for run in runs:
        assert cli_in_process("ask", run, *NEW).returncode == 0
        asked.append(drive(run, CONTEXTS))
    assert asked[0] == asked[1]
    policies = [Policy.load(run / RunDir.POLICY) for run in runs]
    assert policies[0].equals(policies[1])
    other = tmp_path / "c"
    assert cli_in_process("ask", other, *NEW[:4], "4", *NEW[5:]).returncode == 0
    assert drive(other, CONTEXTS) != asked[0]


def test_a_rehearsal_on_a_registered_env_evaluates(tmp_path: Path) -> None:
    run = tmp_path / "rehearsal"
    new = ["--new", "--optimizer", "creps", "--seed", "1", "--env", SPHERE, "--env-kwarg", "dim=2"]
    out = ask(run, *new, "--context", "1.0")
    assert out["episode"] == 1 and len(out["params"]) == 2
    evaluate = cli_in_process("evaluate", run, "--contexts", "4")
    assert evaluate.returncode == 0, evaluate.stderr
    assert json.loads(evaluate.stdout)["env"] == SPHERE


@pytest.mark.parametrize(
    ("args", "flag"),
    [
        (["--context", "2.0"], "--context"),  # outside the context box
        (["--context", "0.1", "0.2"], "--context"),  # z = 1
        (["--new", "--optimizer", "c-bo", *BOXES], "--seed"),
        (["--new", "--optimizer", "cma", "--seed", "0", *BOXES], "--optimizer"),  # an adapter
        (["--new", "--optimizer", "c-bo", "--seed", "0", *BOXES[:-2]], "--context-high"),
        (["--new", "--optimizer", "c-bo", "--seed", "0", *BOXES[:-1], "-1"], "--context-high"),  # empty box
        (["--new", "--optimizer", "creps", "--seed", "0", "--samples", "2", *BOXES], "--samples"),
    ],
)
def test_bad_requests_are_usage_errors_naming_the_flag(tmp_path: Path, args: list[str], flag: str) -> None:
    run = tmp_path / "robot"
    if "--new" not in args:
        assert cli_in_process("ask", run, *NEW).returncode == 0
    result = cli_in_process("ask", run, *args)
    assert result.returncode == EXIT_CODES["usage"], result.stderr
    assert f"argument {flag}" in result.stderr


def test_extrapolate_and_clipping_and_a_failed_episode(tmp_path: Path) -> None:
    run = tmp_path / "robot"
    narrow = ["--new", "--optimizer", "creps-cma-old", "--seed", "0", "--params", "2", "--param-low", "-0.01"]
    narrow += ["--param-high", "0.01", "--context-low", "0", "--context-high", "1", "--initial-std", "1"]
    out = ask(run, *narrow, "--context", "3", "--extrapolate")
    assert out["clipped"] and all(abs(x) <= 0.01 for x in out["params"])
    assert tell(run, "--failed")["failed"]  # its slot is free again
    samples = ask(run, "--pending")["samples"]
    for episode in range(samples):
        out = ask(run, "--context", "0.5")
        assert out["episode"] == episode + 2
    assert cli_in_process("ask", run, "--context", "0.5").returncode == EXIT_CODES["usage"]
    for episode in range(samples):
        done = tell(run, "--return", str(-episode), "--episode", str(episode + 2))
    assert done["batch_told"] and done["episodes"] == samples


def test_a_second_writer_is_refused(tmp_path: Path) -> None:
    run = tmp_path / "robot"
    assert cli_in_process("ask", run, *NEW).returncode == 0
    with AskTellRun.open(run):
        result = cli_in_process("ask", run, "--context", "0.5")
    assert result.returncode == EXIT_CODES["run_dir"] and "writes this run directory" in result.stderr
    assert cli_in_process("ask", run, "--context", "0.5").returncode == 0


def test_a_finished_run_refuses_to_ask(tmp_path: Path) -> None:
    run = tmp_path / "robot"
    assert cli_in_process("ask", run, *NEW, "--iterations", "1").returncode == 0
    drive(run, CONTEXTS[:2])
    result = cli_in_process("ask", run, "--context", "0.5")
    assert result.returncode == EXIT_CODES["usage"] and "finished (stop: iterations" in result.stderr
    assert (run / RunDir.HISTORY_JSON).is_file()


# -- crashes ------------------------------------------------------------------------------------------------
class Crash(BaseException):
    """A process killed between two writes."""


def _batch_run(path: Path, reopen: bool) -> np.ndarray:
    """Three batches of 4 at fresh contexts, then 4 episodes at s = 0.5, asked one at a time and told in
    one open run (``reopen`` False: a Python user) or reopening it for every step (as the shell does);
    the last batch's parameters (4, 2)."""
    config = RunConfig(env=None, optimizer="c-bo", iterations=5, samples=4, seed=3)
    spaces = Spaces.of(param_low=[-1, -1], param_high=[1, 1], context_low=[0], context_high=[1])
    AskTellRun.create(path, config, spaces).close()
    run, rng = AskTellRun.open(path), np.random.default_rng(0)

    def next_step(run: AskTellRun) -> AskTellRun:
        if not reopen:
            return run
        run.close()
        return AskTellRun.open(path)

    try:
        for batch in range(4):
            episodes = []
            for _ in range(4):
                episodes.append(run.ask([0.5] if batch == 3 else [float(rng.uniform())]))
                run = next_step(run)
            for episode in episodes:
                run.tell(returns_of(episode.params.tolist(), float(episode.context[0])), episode.episode)
                run = next_step(run)
    finally:
        run.close()
    return np.array([episode.params for episode in episodes])


def test_a_batch_asked_a_row_at_a_time_is_told_in_one_open_run_and_spreads_at_one_context(
    tmp_path: Path,
) -> None:
    """Each ask is one more row of the batch (``ask_more``): told in the same open run (before, its tell
    refused the batch's earlier rows as never asked), the same bits as reopening the run for every step,
    and c-bo's kriging believer spreads the four episodes asked at one context."""
    in_one = _batch_run(tmp_path / "one", reopen=False)
    assert in_one.tobytes() == _batch_run(tmp_path / "shell", reopen=True).tobytes()
    distances = np.linalg.norm(in_one[:, None] - in_one[None, :], axis=2)[np.triu_indices(4, 1)]
    assert distances.min() > 1e-3


def _steps() -> list[tuple[str, float]]:
    """Ask two episodes, tell them (one batch), twice: the run finishes (iterations=2)."""
    steps = []
    for pair in (CONTEXTS[:2], CONTEXTS[2:]):
        steps += [("ask", c) for c in pair] + [("tell", c) for c in pair]
    return steps


def _new(path: Path) -> None:
    config = RunConfig(env=None, optimizer="c-bo", iterations=2, samples=2, seed=5, optimizer_options=CHEAP)
    spaces = Spaces.of(param_low=[-1, -1], param_high=[1, 1], context_low=[0], context_high=[1])
    AskTellRun.create(path, config, spaces).close()


def _play(path: Path, log: dict[float, Any]) -> None:
    """Do the steps not done yet (a user runs the failed command again; `ask --pending` says which)."""
    for kind, context in _steps():
        with AskTellRun.open(path) as run:
            known = {float(e.context[0]): e for e in run.batch}
            if kind == "ask" and context not in log:
                log[context] = run.ask([context]).params.tolist()
            elif kind == "tell" and context in known and known[context].pending:
                run.tell(returns_of(log[context], context), known[context].episode)


def _count_writes(monkeypatch: pytest.MonkeyPatch, crash_at: int | None) -> list[int]:
    """Patch every write of a run folder to count (and to crash before the ``crash_at``-th)."""
    count = [0]

    def counted(function: Any) -> Any:
        def write(*args: Any, **kwargs: Any) -> Any:
            count[0] += 1
            if count[0] == crash_at:
                raise Crash
            return function(*args, **kwargs)

        return write

    monkeypatch.setattr(files, "append_run_file", counted(files.append_run_file))
    monkeypatch.setattr(files, "write_run_file", counted(files.write_run_file))
    monkeypatch.setattr(policy_store, "write_run_file", counted(policy_store.write_run_file))
    monkeypatch.setattr(rundir.RunDir, "save_checkpoint", counted(rundir.RunDir.save_checkpoint))
    return count


def _result(path: Path, log: dict[float, Any]) -> tuple[Any, ...]:
    history = RunDir.open(path).read_history()
    return log, [r.to_dict() for r in history.records], history.stop_reason, Policy.load(path / RunDir.POLICY)


@pytest.mark.slow
def test_a_crash_before_any_write_loses_nothing_and_counts_nothing_twice(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    _new(tmp_path / "clean")
    with monkeypatch.context() as patch:
        count = _count_writes(patch, None)
        clean_log: dict[float, Any] = {}
        _play(tmp_path / "clean", clean_log)
    clean = _result(tmp_path / "clean", clean_log)
    assert count[0] > 20 and clean[2] == "iterations" and len(clean[1]) == 2
    for crash_at in range(1, count[0] + 1):
        path = tmp_path / f"crash{crash_at}"
        _new(path)
        log: dict[float, Any] = {}
        with monkeypatch.context() as patch:
            _count_writes(patch, crash_at)
            with pytest.raises(Crash):
                _play(path, log)
        _play(path, log)
        found = _result(path, log)
        assert found[0] == clean[0], crash_at  # the same parameters asked, bit for bit
        for a, b in zip(found[1], clean[1], strict=True):  # one record per batch, the same but wall time
            assert {**a, "wall_time": 0} == {**b, "wall_time": 0}, crash_at
        assert found[2] == clean[2] and found[3].equals(clean[3]), crash_at


def test_a_damaged_log_is_refused_before_the_batch_is_told(tmp_path: Path) -> None:
    run = tmp_path / "robot"
    assert cli_in_process("ask", run, *NEW).returncode == 0
    drive(run, CONTEXTS[:2])  # iteration 1 logged
    first = ask(run, "--context", "0.5")
    tell(run, "--return", "-1", "--episode", str(first["episode"]))
    second = ask(run, "--context", "0.6")
    log = run / RunDir.LOG
    lines = log.read_text().splitlines()
    record = next(i for i, line in enumerate(lines) if '"iteration": 1' in line and "event" not in line)
    lines[record] = lines[record].replace('"episodes": 2', '"episodes": 3')
    log.write_text("\n".join(lines) + "\n")
    before = (run / RunDir.CHECKPOINT).read_bytes()
    result = cli_in_process("tell", run, "--return", "-2", "--episode", second["episode"])
    assert result.returncode == EXIT_CODES["run_dir"] and str(log) in result.stderr
    assert (run / RunDir.CHECKPOINT).read_bytes() == before  # nothing was told


KILLED = """
import os, signal, sys
from creps_gym.runner import rundir
from creps_gym.runner.manual import AskTellRun

def killed(*args, **kwargs):  # after the ask's log line, before its checkpoint
    os.kill(os.getpid(), signal.SIGKILL)

rundir.RunDir.save_checkpoint = killed
AskTellRun.open(sys.argv[1]).ask([0.5])
"""


@pytest.mark.slow
@pytest.mark.skipif(not hasattr(__import__("signal"), "SIGKILL"), reason="POSIX signals")
def test_a_process_killed_mid_ask_leaves_its_lock_to_the_next_command(tmp_path: Path) -> None:
    import shutil
    import subprocess
    import sys

    run, clean = tmp_path / "robot", tmp_path / "clean"
    assert cli_in_process("ask", run, *NEW).returncode == 0
    shutil.copytree(run, clean)
    killed = subprocess.run([sys.executable, "-c", KILLED, str(run)], capture_output=True, timeout=120)
    assert killed.returncode == -9 and (run / RunDir.LOCK).exists()  # the lock file of a dead process
    again = cli_in_process("ask", run, "--context", "0.5", "--json")
    assert again.returncode == 0 and "took over the lock" in again.stderr
    assert json.loads(again.stdout)["params"] == ask(clean, "--context", "0.5")["params"]
    assert json.loads(again.stdout)["episode"] == 1
