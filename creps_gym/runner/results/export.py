"""Export histories to the CSV layout IOHanalyzer reads (COCO-style comparisons).

One row per evaluation of the recommended policy, with the columns ``evaluations`` (training episodes so
far), ``value``, ``function_id`` (env id), ``algorithm_id`` (the optimiser, or the run's label: ``creps-gym
export`` labels each run by its setting group, see :mod:`creps_gym.runner.results.groups`), ``dimension``
(parameters p) and ``run_id`` (the master seed). ``value`` is the mean regret when every history has one
(minimised), else the mean evaluation return (maximised). Load the file in IOHanalyzer's R package with::

    read_pure_csv("iohanalyzer.csv", "evaluations", "value", "function_id", "algorithm_id",
                  "dimension", "run_id", maximization = FALSE)   # TRUE for returns

or upload it in the web interface ("use custom csv format") and map the columns of the same names. The
file follows IOHanalyzer's documented CSV conventions (tested in
``tests/runner/results/test_plots_export.py``): one header row, the function values as the only required
column, one row per (function, algorithm, dimension, run, evaluation count), evaluation counts increasing
within each run, finite values.

Histories of different envs (env id, p or z differ) are refused unless ``mix_envs=True``: a regret and a
return cannot share one value column, and mixing is usually a mistake.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

from creps_gym.runner.history import History
from creps_gym.runner.ioh import (
    IOH_COLUMNS,
    check_one_env,
    env_key,
    iohanalyzer_rows,
    iohanalyzer_text,
)
from creps_gym.runner.rundir import RunDir
from creps_gym.runner.rundir.files import write_output

__all__ = [
    "IOH_COLUMNS",
    "check_one_env",
    "env_key",
    "iohanalyzer_rows",
    "iohanalyzer_text",
    "write_iohanalyzer",
]


def write_iohanalyzer(
    histories: Sequence[History],
    path: str | os.PathLike[str],
    *,
    mix_envs: bool = False,
    labels: Sequence[str] | None = None,
) -> Path:
    """Write the rows of :func:`iohanalyzer_rows` to ``path`` (atomically); returns the file written.

    A link is followed (its target is replaced); a target that is not a regular file, or that is a run
    directory's own file, raises ``ValueError`` (:func:`creps_gym.runner.rundir.files.write_output`).
    """
    text = iohanalyzer_text(histories, mix_envs, labels)
    return write_output(path, text.encode("utf-8"), protected=RunDir.owns)
