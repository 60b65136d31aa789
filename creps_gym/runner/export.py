"""Export histories to the CSV layout IOHanalyzer reads (COCO-style comparisons).

One row per evaluation of the recommended policy, with the columns ``evaluations`` (training episodes so
far), ``value``, ``function_id`` (env id), ``algorithm_id`` (optimiser), ``dimension`` (parameters p)
and ``run_id`` (the master seed). ``value`` is the mean regret when every history has one (minimised), else
the mean evaluation return (maximised). Load the file in IOHanalyzer's R package with::

    read_pure_csv("iohanalyzer.csv", "evaluations", "value", "function_id", "algorithm_id",
                  "dimension", "run_id", maximization = FALSE)   # TRUE for returns

or upload it in the web interface and map the columns of the same names.
"""

from __future__ import annotations

import csv
import io
import math
import os
from collections.abc import Sequence
from pathlib import Path

from creps_gym.runner.history import History, atomic_write_text

__all__ = ["IOH_COLUMNS", "iohanalyzer_rows", "iohanalyzer_text", "write_iohanalyzer"]

IOH_COLUMNS = ("evaluations", "value", "function_id", "algorithm_id", "dimension", "run_id")


def iohanalyzer_rows(histories: Sequence[History]) -> tuple[list[tuple], str]:
    """Rows (in :data:`IOH_COLUMNS` order) and the metric (``"regret"`` or ``"return"``)."""
    if not histories:
        raise ValueError("histories: expected at least one History, got none")
    use_regret = all(h.meta.get("metric") == "regret" for h in histories)
    rows = []
    for history in histories:
        meta = history.meta
        ids = (meta.get("env", "unknown"), meta.get("optimizer", "unknown"), meta.get("n_params", 0))
        for record in history:
            value = record.eval_regret if use_regret else record.eval_return
            if not math.isnan(value):
                rows.append((record.episodes, repr(float(value)), *ids, meta.get("seed", 0)))
    return rows, "regret" if use_regret else "return"


def iohanalyzer_text(histories: Sequence[History]) -> str:
    """The CSV text of :func:`write_iohanalyzer`."""
    rows, _ = iohanalyzer_rows(histories)
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(IOH_COLUMNS)
    writer.writerows(rows)
    return buffer.getvalue()


def write_iohanalyzer(histories: Sequence[History], path: str | os.PathLike[str]) -> Path:
    """Write the rows of :func:`iohanalyzer_rows` to ``path`` (atomically); returns the path."""
    return atomic_write_text(path, iohanalyzer_text(histories))
