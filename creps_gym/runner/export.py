"""Export histories to the CSV layout IOHanalyzer reads (COCO-style comparisons).

One row per evaluation of the recommended policy, with the columns ``evaluations`` (training episodes so
far), ``value``, ``function_id`` (env id), ``algorithm_id`` (the optimiser, or the run's label: ``creps-gym
export`` labels each run by its setting group, see :mod:`creps_gym.runner.groups`), ``dimension``
(parameters p) and ``run_id`` (the master seed). ``value`` is the mean regret when every history has one
(minimised), else the mean evaluation return (maximised). Load the file in IOHanalyzer's R package with::

    read_pure_csv("iohanalyzer.csv", "evaluations", "value", "function_id", "algorithm_id",
                  "dimension", "run_id", maximization = FALSE)   # TRUE for returns

or upload it in the web interface ("use custom csv format") and map the columns of the same names. The
file follows IOHanalyzer's documented CSV conventions (tested in ``tests/test_plots_export.py``): one header
row, the function values as the only required column, one row per (function, algorithm, dimension, run,
evaluation count), evaluation counts increasing within each run, finite values.

Histories of different envs (env id, p or z differ) are refused unless ``mix_envs=True``: a regret and a
return cannot share one value column, and mixing is usually a mistake.
"""

from __future__ import annotations

import csv
import io
import math
import os
from collections.abc import Sequence
from pathlib import Path

from creps_gym.runner.history import History

__all__ = [
    "IOH_COLUMNS",
    "check_one_env",
    "env_key",
    "iohanalyzer_rows",
    "iohanalyzer_text",
    "write_iohanalyzer",
]

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


def write_iohanalyzer(
    histories: Sequence[History],
    path: str | os.PathLike[str],
    *,
    mix_envs: bool = False,
    labels: Sequence[str] | None = None,
) -> Path:
    """Write the rows of :func:`iohanalyzer_rows` to ``path`` (atomically); returns the file written.

    A link is followed (its target is replaced); a target that is not a regular file, or that is a run
    directory's own file, raises ``ValueError`` (:func:`creps_gym.runner.files.write_output`).
    """
    from creps_gym.runner.files import write_output
    from creps_gym.runner.rundir import RunDir

    text = iohanalyzer_text(histories, mix_envs, labels)
    return write_output(path, text.encode("utf-8"), protected=RunDir.owns)
