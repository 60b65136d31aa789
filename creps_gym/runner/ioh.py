"""The IOHanalyzer CSV text of histories (:mod:`creps_gym.runner.results.export` writes it to a file).

A module of its own so that the run directory (:mod:`creps_gym.runner.rundir`), which writes its own
``iohanalyzer.csv``, and the export, which refuses to write into a run directory, do not import each other.
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Sequence

from creps_gym.runner.history import History

__all__ = ["IOH_COLUMNS", "check_one_env", "env_key", "iohanalyzer_rows", "iohanalyzer_text"]

IOH_COLUMNS = ("evaluations", "value", "function_id", "algorithm_id", "dimension", "run_id")


def env_key(history: History) -> str:
    """The env of a run as text: id, parameters p and context dimensions z (from its metadata)."""
    meta = history.meta
    return f"{meta.get('env', '?')} (p = {meta.get('n_params', '?')}, z = {meta.get('n_context_dims', '?')})"


def check_one_env(histories: Sequence[History], mix_envs: bool = False) -> list[str]:
    """The sorted env keys of ``histories``; ``ValueError`` if there are several and ``mix_envs`` is False."""
    envs = sorted({env_key(h) for h in histories})
    if len(envs) > 1 and not mix_envs:
        raise ValueError(
            f"runs: expected runs of one env (pass mix_envs=True, or --mix-envs, to combine them), got {envs}"
        )
    return envs


def iohanalyzer_rows(
    histories: Sequence[History], mix_envs: bool = False, labels: Sequence[str] | None = None
) -> tuple[list[tuple], str]:
    """Rows (in :data:`IOH_COLUMNS` order) and the metric (``"regret"`` or ``"return"``).

    ``labels``: each history's ``algorithm_id`` (default its optimiser).
    """
    if not histories:
        raise ValueError("histories: expected at least one History, got none")
    if labels is not None and len(labels) != len(histories):
        raise ValueError(f"labels: expected one per history ({len(histories)}), got {len(labels)}")
    check_one_env(histories, mix_envs)
    use_regret = all(h.meta.get("metric") == "regret" for h in histories)
    rows = []
    for k, history in enumerate(histories):
        meta = history.meta
        algorithm = meta.get("optimizer", "unknown") if labels is None else labels[k]
        ids = (meta.get("env", "unknown"), algorithm, meta.get("n_params", 0))
        for record in history:
            value = record.eval_regret if use_regret else record.eval_return
            if not math.isnan(value):
                rows.append((record.episodes, repr(float(value)), *ids, meta.get("seed", 0)))
    return rows, "regret" if use_regret else "return"


def iohanalyzer_text(
    histories: Sequence[History], mix_envs: bool = False, labels: Sequence[str] | None = None
) -> str:
    """The CSV text of :func:`write_iohanalyzer`."""
    rows, _ = iohanalyzer_rows(histories, mix_envs, labels)
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(IOH_COLUMNS)
    writer.writerows(rows)
    return buffer.getvalue()
