"""The runner's ``divergence`` stop (issue 31): 10 evaluations in a row worse than the first by more than
``divergence`` (1000) times its size stop any optimiser's run with the reason ``"divergence"``."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from creps_gym.cli import EXIT_CODES, main
from creps_gym.runner import RunConfig, run
from creps_gym.runner.divergence import WINDOW, DivergenceWatch, evaluation_loss

ROOT = Path(__file__).resolve().parents[2]
# c-cma-es at a batch above its recommended 48 diverges on Different Powers with z = 3 (seed 4 of the study)
DIVERGING = {
    "env": "creps_gym/DifferentPowers-v0",
    "env_kwargs": {"dim": 15, "context_dim": 3},
    "samples": 50,
    "seed": 4,
}


def _observe(watch: DivergenceWatch, losses: list[float]) -> list[bool]:
    return [watch.observe(loss) for loss in losses]


def test_the_rule_needs_window_consecutive_evaluations_beyond_the_factor():
    beyond = [1.0] + [1002.0] * (WINDOW - 1)
    assert _observe(DivergenceWatch(1000.0), [*beyond, 1002.0]) == [False] * WINDOW + [True]
    interrupted = [1.0] + [1002.0] * (WINDOW - 1) + [900.0] + [1002.0] * (WINDOW - 1)
    assert not any(_observe(DivergenceWatch(1000.0), interrupted))  # one evaluation back within the factor
    assert not any(_observe(DivergenceWatch(1000.0), [1.0] + [1000.9] * 30))  # L - L0 must exceed 1000 |L0|
    assert not any(_observe(DivergenceWatch(None), [1.0] + [1e300] * 30))  # None: never
    assert not any(_observe(DivergenceWatch(1000.0), [0.0] + [1e300] * 30))  # no scale: never
    nan_between = [1.0] + [1002.0, math.nan] * WINDOW
    assert _observe(DivergenceWatch(1000.0), nan_between)[-2]  # NaN (no evaluation) neither counts nor resets


def test_returns_count_through_minus_the_return_and_a_replay_equals_the_live_watch():
    assert evaluation_loss(-3.0, math.nan) == 3.0 and evaluation_loss(-3.0, 0.5) == 0.5
    losses = [evaluation_loss(r, math.nan) for r in [-18.0] + [-18.0 * 1002] * 12]  # a return falling 1000x
    live = DivergenceWatch(1000.0)
    assert _observe(live, losses)[-3] and not _observe(DivergenceWatch(1000.0), losses)[WINDOW - 1]
    replayed = DivergenceWatch(1000.0).replay(losses[:7])
    assert _observe(replayed, losses[7:]) == _observe(DivergenceWatch(1000.0), losses)[7:]


@pytest.mark.slow
def test_a_diverging_c_cma_es_run_without_restarts_stops_with_the_reason_divergence():
    """A legal batch (50 >= the recommended 48) that diverges: regret 2.2e6 at the first evaluation, past
    2.2e9 from iteration 25 on; stopped at iteration 34. With ``divergence=None`` it runs on."""
    options = {k: v for k, v in DIVERGING.items() if k not in ("env", "samples", "seed")}
    options["optimizer_options"] = {"restarts": 0}  # no restart left: the rule stops the run
    history = run(
        "c-cma-es",
        DIVERGING["env"],
        60,
        DIVERGING["samples"],
        DIVERGING["seed"],
        context_draws="reset",
        **options,
    )
    regret = history.column("eval_regret")
    assert history.stop_reason == "divergence" and len(history) == 34
    assert (regret[-WINDOW:] - regret[0] > 1000 * regret[0]).all()
    assert not (regret[-WINDOW - 1] - regret[0] > 1000 * regret[0])
    unchecked = run(
        "c-cma-es",
        DIVERGING["env"],
        40,
        DIVERGING["samples"],
        DIVERGING["seed"],
        context_draws="reset",
        divergence=None,
        **options,
    )
    assert unchecked.stop_reason == "iterations" and len(unchecked) == 40
    np.testing.assert_array_equal(unchecked.column("eval_regret")[:34], regret)  # nothing else changes


@pytest.mark.slow
def test_with_a_restart_left_the_rule_restarts_the_search_and_the_run_reaches_its_target():
    """The default ``c-cma-es`` (3 restarts): where the rule fires (iteration 34, as above) the runner calls
    ``restart()`` instead of stopping; the Huber restart (C11) then reaches the target, and the samples
    before the restart are the run without restarts'."""
    options = {k: v for k, v in DIVERGING.items() if k not in ("env", "samples", "seed")}
    args = ("c-cma-es", DIVERGING["env"], 600, DIVERGING["samples"], DIVERGING["seed"])
    history = run(*args, context_draws="reset", target_regret=1e-5, **options)
    restarts = history.column("diag.restarts")
    assert restarts[33] == 1.0 and restarts[32] == 0.0  # restarted at iteration 34, where it would stop
    assert history.stop_reason == "target_regret" and history.records[-1].eval_regret <= 1e-5
    plain = run(
        *args[:3],
        DIVERGING["samples"],
        DIVERGING["seed"],
        context_draws="reset",
        optimizer_options={"restarts": 0},
        **options,
    )
    np.testing.assert_array_equal(history.column("eval_regret")[:34], plain.column("eval_regret"))


def test_restart_is_refused_with_a_pending_ask_and_without_restarts_left():
    from creps_gym.optimizers import CCMAES, CREPS

    optimizer = CCMAES(3, 1, restarts=1, seed=0)
    contexts = np.zeros((8, 1))
    params = optimizer.ask(contexts)
    with pytest.raises(RuntimeError, match="restart\\(\\): expected no pending ask"):
        optimizer.restart()
    optimizer.tell(contexts, params, -np.sum(params**2, axis=1))
    assert optimizer.diagnostics["step_size"] != optimizer.config.initial_step_size
    assert optimizer.restart() and optimizer.restarts_done == 1 and optimizer.diagnostics["restarts"] == 1.0
    diagnostics = optimizer.diagnostics  # they describe the new search, not the abandoned one
    assert diagnostics["step_size"] == optimizer.step_size == optimizer.config.initial_step_size
    assert diagnostics["path_sigma_ratio"] == 0.0
    assert diagnostics["search_scale"] == pytest.approx(optimizer.step_size)  # C = I again
    assert np.array_equal(optimizer.coefficients, optimizer.config.initial_mean)
    before = optimizer.state_dict()
    assert not optimizer.restart() and optimizer.restarts_done == 1  # none left: nothing changes
    after = optimizer.state_dict()
    assert after.keys() == before.keys()
    assert all(np.array_equal(after[key], value) for key, value in before.items())
    assert CREPS(3, 1).restart() is False  # an optimiser without restarts: the rule stops its run


def test_a_replayed_history_that_went_on_after_the_rule_fired_counts_again():
    losses = [1.0] + [1002.0] * (WINDOW + 3)
    live = DivergenceWatch(1000.0)
    for loss in losses:
        if live.observe(loss):
            live.restarted()
    replayed = DivergenceWatch(1000.0).replay(losses)
    assert replayed.run_length == live.run_length == 3


def test_the_command_line_prints_the_stop_and_takes_divergence_none(tmp_path, capsys):
    args = [
        "run",
        "--env",
        DIVERGING["env"],
        "--env-kwarg",
        "dim=15",
        "--env-kwarg",
        "context_dim=3",
        "--optimizer",
        "c-cma-es",
        "--samples",
        "50",
        "--iterations",
        "60",
        "--seed",
        "4",
        "--opt",
        "restarts=0",
        "--no-plot",
        "--no-progress",
    ]
    assert main([*args, "--out", str(tmp_path / "a")]) == EXIT_CODES["ok"]
    assert "iterations 14, episodes 700, regret " in capsys.readouterr().out  # the batched context stream
    assert json.loads((tmp_path / "a" / "config.json").read_text())["config"]["divergence"] == 1000.0
    assert main([*args, "--out", str(tmp_path / "b"), "--divergence", "none", "--iterations", "16"]) == 0
    assert "iterations 16, episodes 800" in capsys.readouterr().out
    with pytest.raises(SystemExit) as exit_info:  # argparse's own exit, code 2
        main([*args, "--out", str(tmp_path / "c"), "--divergence", "0"])
    assert exit_info.value.code == EXIT_CODES["usage"]
    error = capsys.readouterr().err
    assert "argument --divergence: expected a positive finite number or 'none', got '0'" in error


def test_the_factor_is_checked():
    base = {"env": "creps_gym/Sphere-v0", "optimizer": "creps", "iterations": 2, "samples": 12, "seed": 0}
    for bad in (0.0, -1.0, math.inf, "10"):
        with pytest.raises(ValueError, match="divergence: expected a positive finite number or None"):
            RunConfig(**base, divergence=bad)
    assert RunConfig(**base).divergence == 1000.0 and RunConfig(**base, divergence=None).divergence is None


@pytest.mark.slow
def test_no_committed_study_run_that_reached_its_target_or_budget_would_have_stopped():
    """Replayed on every committed study curve: the rule fires only on runs their optimiser stopped later
    (diverging CREPS-CMA at p = 64, C-CMA-ES with the former restart defaults on Different Powers at z = 3)
    and on the default C-CMA-ES runs of that cell (C3 and C3r alike), whose Huber restart recovers and which
    the rule restarts rather than stops (docs/optimizers.md, "Divergence"); the studies turn it off."""
    fired, documents = [], 0
    for path in sorted(ROOT.glob("benchmarks/*/runs/*.json")):
        document = json.loads(path.read_text())
        if "values" not in document:
            continue
        documents += 1
        watch = DivergenceWatch(1000.0)
        if any(watch.observe(float(v) if v is not None else math.nan) for v in document["values"]):
            fired.append((path.name, document["stop_reason"]))
    assert documents > 1000
    stopped_later = [name for name, reason in fired if reason.startswith("optimizer: ")]
    recovered = sorted(name for name, reason in fired if not reason.startswith("optimizer: "))
    assert len(stopped_later) == 20, fired
    # docs/optimizers.md: the default restarts' first search diverges, its Huber restart reaches the target
    # (6 study runs with the rule off, 6 of the portfolio table's runs with it on); c-cma-es restarts there
    assert all(name.startswith("DifferentPowers-p15-z3-c-cma-es-") for name in recovered), recovered
    # C3 (the default the study's runs were computed with, pinned: benchmarks/study_options.py) and, in the
    # same cell, C3r (the default since issue 45, its runs in docs/results/default_trial/), no other option
    c3 = [name for name in recovered if "-ridge_centre=zero-" in name]
    c3r = [name for name in recovered if "-ridge_centre=old-" in name]
    assert len(c3) == 12 and sum("-div1000-" in name for name in c3) == 6, c3
    assert len(c3r) == 7 and not any("-div1000-" in name for name in c3r), c3r
    assert all(name.count("=") == 1 for name in recovered), recovered


class _Crash(Exception):
    pass


def test_a_resumed_run_replays_its_history_and_stops_where_the_uninterrupted_one_does(tmp_path):
    from creps_gym.runner import resume

    options = {"env_kwargs": DIVERGING["env_kwargs"], "checkpoint_every": 1}
    options["optimizer_options"] = {"restarts": 0}
    args = ("c-cma-es", DIVERGING["env"], 60, DIVERGING["samples"], DIVERGING["seed"])
    uninterrupted = run(*args, **options)
    assert uninterrupted.stop_reason == "divergence" and len(uninterrupted) == 14

    def crash_at_nine(record, history):
        if record.iteration == 9:  # inside the window: 5 of its 10 diverged evaluations are behind
            raise _Crash

    with pytest.raises(_Crash):
        run(*args, run_dir=tmp_path / "run", callbacks=[crash_at_nine], **options)
    assert resume(tmp_path / "run").equals(uninterrupted)


@pytest.mark.slow
def test_a_run_resumed_after_the_rule_restarted_its_search_goes_on_as_the_uninterrupted_one(tmp_path):
    from creps_gym.runner import resume

    options = {"env_kwargs": DIVERGING["env_kwargs"], "checkpoint_every": 1}
    args = ("c-cma-es", DIVERGING["env"], 30, DIVERGING["samples"], DIVERGING["seed"])
    uninterrupted = run(*args, **options)
    assert uninterrupted.column("diag.restarts")[13] == 1.0 and len(uninterrupted) == 30

    def crash_at_twenty(record, history):
        if record.iteration == 20:  # after the restart at iteration 14
            raise _Crash

    with pytest.raises(_Crash):
        run(*args, run_dir=tmp_path / "run", callbacks=[crash_at_twenty], **options)
    assert resume(tmp_path / "run").equals(uninterrupted)


def test_a_run_stopped_by_divergence_reads_back_and_its_factor_is_part_of_the_run(tmp_path):
    """The checkpoint's stop reason ``divergence`` is one the loop can write (it reloads), and a factor
    other than the default is fingerprinted (a run folder edited to another factor is another run)."""
    from creps_gym.runner import resume
    from creps_gym.runner.rundir.checkpoint import config_fingerprint

    options = {"env_kwargs": DIVERGING["env_kwargs"], "checkpoint_every": 1}
    options["optimizer_options"] = {"restarts": 0}
    args = ("c-cma-es", DIVERGING["env"], 60, DIVERGING["samples"], DIVERGING["seed"])
    finished = run(*args, run_dir=tmp_path / "run", **options)
    assert finished.stop_reason == "divergence"
    assert resume(tmp_path / "run").equals(finished)
    import hashlib

    from creps_gym.runner.rundir.checkpoint import CHECKPOINT_FORMAT, FINGERPRINT_FIELDS

    settings = {"env": "creps_gym/Sphere-v0", "optimizer": "creps", "seed": 0, "samples": 10, "iterations": 3}
    default, changed = RunConfig(**settings), RunConfig(**settings, divergence=10.0)
    assert config_fingerprint(default) != config_fingerprint(changed)
    before = {"format": CHECKPOINT_FORMAT, **{k: default.to_dict()[k] for k in FINGERPRINT_FIELDS}}
    text = json.dumps(before, sort_keys=True, allow_nan=False).encode()
    assert config_fingerprint(default) == hashlib.sha256(text).hexdigest()  # old run folders still load
