"""The history of a run directory, rebuilt from its append-only log.

A checkpoint holds no history: the records are in ``log.jsonl``, and a checkpoint keeps the checksum
:func:`~creps_gym.runner.rundir.log_chain.history_crc` of records 1..k, so the history at a checkpoint is
rebuilt from the log and checked (:func:`checkpoint_history`). A checkpoint of an older format holds its
history itself (upgraded on load: :mod:`creps_gym.runner.rundir.checkpoint`). :func:`read_history` serves
plots and exports, also of unfinished or damaged runs.
"""

from __future__ import annotations

import warnings
from typing import TYPE_CHECKING, Any

from creps_gym.errors import RunDirWarning
from creps_gym.runner.history import History, IterationRecord
from creps_gym.runner.rundir import files
from creps_gym.runner.rundir.log_chain import chain_crc, history_crc, record_chain

if TYPE_CHECKING:  # for annotations only: rundir imports this module
    from creps_gym.runner.rundir import RunDir

__all__ = ["REBUILD", "RESTART", "checkpoint_history", "read_history"]

RESTART = "delete it to restart the run from its first iteration, or restore it from a backup"
REBUILD = (
    "the history up to the checkpoint cannot be rebuilt: restore it from a backup, or delete "
    "checkpoint.npz to restart the run from its first iteration"
)


def _is_final(run_dir: RunDir, final: History, state: dict[str, Any]) -> bool:
    """Whether ``final`` is the history the final checkpoint ``state`` closed."""
    held = state.get("held_history")
    if held is not None:  # a checkpoint of an older format: the history it holds
        return final.equals(held, include_time=True) and final.meta == held.meta
    meta = run_dir.document().get("meta", {})
    same = len(final) == state["iteration"] and final.stop_reason == state["stop_reason"]
    return same and final.meta == meta and history_crc(final.records) == state["log_crc"]


def checkpoint_history(
    run_dir: RunDir,
    state: dict[str, Any],
    records: list[IterationRecord],
    meta: dict[str, Any] | None = None,
) -> History | None:
    """The history at the checkpoint ``state``: the first ``state["iteration"]`` ``records`` of the log.

    Its metadata is ``meta``, else the one in ``config.json``.

    None if the log lacks one of them (damaged or truncated); :class:`RunDirError` if they are all there
    but differ from those the checkpoint was written after (an edited log or another run's).
    """
    count = state["iteration"]
    kept = records[:count]
    if len(kept) < count or any(r.iteration != i for i, r in enumerate(kept, 1)):
        return None
    if history_crc(kept) != state["log_crc"]:
        raise run_dir.damaged(run_dir.LOG, f"iterations 1 to {count} differ from those checkpointed", REBUILD)
    meta = dict(run_dir.document().get("meta", {}) if meta is None else meta)
    return History(list(kept), meta, state["stop_reason"])


def read_history(run_dir: RunDir) -> History:
    """``history.json`` if the run finished, else the iterations of the checkpoint and those after it.

    Nothing is skipped silently: a damaged ``history.json`` (or one that the final checkpoint did not
    close) is rebuilt from the checkpoint and the log, and damaged log lines are named, with a
    :class:`RunDirWarning`; the history then stops before the first missing iteration. A damaged
    checkpoint raises :class:`RunDirError`.
    """
    loaded = run_dir.load_checkpoint()
    state = None if loaded is None else loaded[0]
    path = run_dir.file(run_dir.HISTORY_JSON)
    if files.check_regular(path):
        try:
            final = History.from_dict(files.json_document(files.read_run_file(path), run_dir.HISTORY_JSON))
            if state is not None and _is_final(run_dir, final, state):
                return final
            problem = f"differs from the final history of {run_dir.CHECKPOINT}"
            if state is None:  # a run ends with a checkpoint: nothing vouches for this one
                problem = f"no {run_dir.CHECKPOINT} closes it"
        except (OSError, ValueError, KeyError, TypeError, AttributeError) as exc:
            problem = f"damaged ({type(exc).__name__}: {exc})"
        message = f"{path}: {problem}; rebuilt from {run_dir.CHECKPOINT} and {run_dir.LOG}"
        warnings.warn(message + " (`creps-gym resume` rewrites it)", RunDirWarning, stacklevel=3)
    damaged: list[int] = []
    chains: dict[int, int | None] = {}
    records, _ = run_dir.read_log(damaged, chains)
    history = History(meta=dict(run_dir.document().get("meta", {})))
    held = None if state is None else state.get("held_history")
    legacy = held is not None  # the history is the checkpoint's own, the log adds nothing to it
    if held is not None:
        history = held
    elif state is not None:
        history = checkpoint_history(run_dir, state, records) or history
    from_checkpoint = len(history)
    foreign = _append_own_records(run_dir, history, records, chains)
    checkpointed = 0 if state is None or legacy else state["iteration"]
    legacy_part = from_checkpoint if legacy else None
    _warn_log_problems(run_dir, records, damaged, (len(history), checkpointed), legacy_part)
    if foreign is not None:
        warnings.warn(
            f"{run_dir.file(run_dir.LOG)}: logged iteration {foreign} is not this run's (its line has no "
            f"chain or another run's; copied or written by hand?), so the history ends at iteration "
            f"{len(history)}; `creps-gym resume` redoes the rest",
            RunDirWarning,
            stacklevel=3,
        )
    return history


def _append_own_records(
    run_dir: RunDir, history: History, records: list[IterationRecord], chains: dict[int, int | None]
) -> int | None:
    """Append the logged records that follow ``history`` and are provably this run's.

    Each must carry the ``"chain"`` (:func:`~creps_gym.runner.rundir.log_chain.record_chain`) of this run's
    fingerprint and of the history before it. Returns the first iteration that does not (None if none).
    """
    following = [r for r in records if r.iteration > len(history)]
    if history.stop_reason is not None or not following or following[0].iteration != len(history) + 1:
        return None
    fingerprint, crc = run_dir.fingerprint(), history_crc(history.records)
    for record in following:
        if record.iteration != len(history) + 1:
            break
        entry = record.to_dict()
        if chains.get(record.iteration) != record_chain(fingerprint, crc, entry):
            return record.iteration
        history.append(record)
        crc = chain_crc(crc, entry)
    return None


def _warn_log_problems(
    run_dir: RunDir,
    records: list[IterationRecord],
    damaged: list[int],
    lengths: tuple[int, int],
    legacy: int | None,
) -> None:
    """Warn about damaged lines, missing and left-out iterations of the log read into a history.

    ``lengths``: the history's and the (log-based) checkpoint's numbers of iterations.
    """
    length = lengths[0]
    lost = [record.iteration for record in records if record.iteration > length]
    kept = {record.iteration for record in records}
    missing = [i for i in range(1, max(lengths) + 1) if i not in kept]
    problems = [f"damaged lines {damaged}"] if damaged else []
    if missing and not damaged:
        problems.append(f"iterations {missing[0]} to {missing[-1]} are missing (a truncated log?)")
    if lost:
        problems.append(f"logged iterations {lost[0]} to {lost[-1]} follow a gap and are left out")
    if problems:
        where = "" if legacy is None else f" ({legacy} from {run_dir.CHECKPOINT}, the rest from the log)"
        warnings.warn(
            f"{run_dir.file(run_dir.LOG)}: {'; '.join(problems)}; the history has iterations 1 to "
            f"{length}{where}",
            RunDirWarning,
            stacklevel=4,
        )
