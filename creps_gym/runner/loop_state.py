"""The loop's state in a checkpoint: what a run keeps (:func:`loop_state`), how it resumes (:func:`restore`).

A checkpoint holds the optimiser's ``state_dict()`` and the loop's state: the env stream's generator, the
counts, the wall time so far, the stop reason, the checksum ``log_crc`` of the history's records (the
records are in the log, which :func:`restore` reads back and checks), the best evaluated policy
(:mod:`creps_gym.runner.rundir.policies`) and the context selector's state. A checkpoint of an older format
reaches this module upgraded (:mod:`creps_gym.runner.rundir.checkpoint`): it holds its history itself.
"""

from __future__ import annotations

from typing import Any

from creps_gym.errors import RunDirError
from creps_gym.optimizers.registry import restore_optimizer
from creps_gym.runner import protocol
from creps_gym.runner.history import History
from creps_gym.runner.rundir import RESTART, RunDir
from creps_gym.runner.rundir.recovery import REBUILD, checkpoint_history

__all__ = ["loop_state", "restore"]


def loop_state(runner: Any, run_dir: RunDir) -> dict[str, Any]:
    """The loop's state of ``runner`` (a :class:`~creps_gym.runner.loop.Runner`) as its checkpoint in
    ``run_dir`` keeps it (O(1) in the run)."""
    return {
        "env_rng": runner.env_rng.bit_generator.state,
        "iteration": runner.iteration,
        "episodes": runner.episodes,
        "elapsed": runner.elapsed,
        "stop_reason": runner.history.stop_reason,
        "log_crc": runner._log_crc,
        "best_policy": runner.policies.checkpoint_state(run_dir),
        **runner.draws.selection.state(),
    }


def restore(runner: Any, run_dir: RunDir, optimizer: Any, optimizer_class: Any, seed: int) -> None:
    """Restore ``runner`` (a :class:`~creps_gym.runner.loop.Runner`, which calls this while it is built)
    from the checkpoint of ``run_dir`` (read once), or start it afresh if it has none.

    ``optimizer`` (an object) or ``optimizer_class`` restores an object optimiser's state; ``seed`` seeds
    a new one. A damaged checkpoint, or one that does not fit the run, raises :class:`RunDirError`.
    """
    loaded = run_dir.load_checkpoint(runner.config)
    if loaded is None:
        if runner.config.optimizer is None and optimizer is None:
            raise ValueError(f"run_dir: expected a checkpoint in {run_dir.path}, got none")
        runner.optimizer = runner._new_optimizer(optimizer, seed, check=False)
        runner.history = History(meta=runner._meta())
        return
    state, optimizer_state = loaded
    try:
        if runner.config.optimizer is not None:
            runner.optimizer = restore_optimizer(runner.config.optimizer, optimizer_state)
        else:
            runner.optimizer = (optimizer_class or type(optimizer)).from_state_dict(optimizer_state)
        protocol.check_optimizer_sizes(runner.optimizer, "optimizer state", runner)
        runner.env_rng.bit_generator.state = protocol.generator_state(state["env_rng"])
        runner.draws.selection.load(state)
        runner.history = _history_at_checkpoint(run_dir, state, runner._meta())
        runner._log_crc = int(state["log_crc"])
        runner.policies.restore(state["best_policy"], runner.history)
        runner.iteration, runner.episodes = int(state["iteration"]), int(state["episodes"])
        runner._elapsed_before = float(state["elapsed"])
    except RunDirError:
        raise
    except (KeyError, TypeError, ValueError, IndexError, AttributeError, OverflowError) as exc:
        raise run_dir.damaged(RunDir.CHECKPOINT, exc, RESTART) from None


def _history_at_checkpoint(run_dir: RunDir, state: dict[str, Any], meta: dict[str, Any]) -> History:
    """The history up to the checkpoint: rebuilt from the log (an older format's checkpoint holds it)."""
    held = state.get("held_history")
    if held is not None:
        return held
    damaged: list[int] = []
    records, _ = run_dir.read_log(damaged)
    history = checkpoint_history(run_dir, state, records, meta)
    if history is None:
        found = f"damaged lines {damaged}" if damaged else "a truncated log"
        count = state["iteration"]
        raise run_dir.damaged(RunDir.LOG, f"iterations 1 to {count} are not all intact ({found})", REBUILD)
    return history
