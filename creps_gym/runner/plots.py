"""Learning-curve plots (``pip install creps-gym[plot]``; matplotlib is imported only when plotting).

:func:`plot_histories` draws, for each group of runs (one optimiser over several seeds), the median and a
quantile band over the runs of (left) the mean sample return and (right) the evaluated regret of the
recommended policy on a log axis, or its evaluation return when the env has no regret. The x axis is the
number of training episodes. :func:`plot_run_dirs` does the same from run directories, grouping them by
optimiser (and env, when several envs are plotted).
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from creps_gym.optimizers.adapters.base import import_optional
from creps_gym.runner.history import History
from creps_gym.runner.rundir import RunDir

__all__ = ["load_history", "plot_histories", "plot_run_dirs"]


def _stack(runs: Sequence[History], name: str) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """x (episodes of the longest run) and a (runs, iterations) matrix padded with NaN."""
    longest = max(runs, key=len)
    values = np.full((len(runs), len(longest)), np.nan)
    for i, run in enumerate(runs):
        values[i, : len(run)] = run.column(name)
    return longest.column("episodes"), values


def _draw(axis: Any, x: NDArray[np.float64], values: NDArray[np.float64], label: str, band: tuple) -> None:
    keep = np.isfinite(values).any(axis=0)
    if not keep.any():
        return
    x, values = x[keep], values[:, keep]
    (line,) = axis.plot(x, np.nanmedian(values, axis=0), label=f"{label} (n={values.shape[0]})")
    if values.shape[0] > 1:
        low, high = np.nanquantile(values, band, axis=0)
        axis.fill_between(x, low, high, color=line.get_color(), alpha=0.25, linewidth=0)


def plot_histories(
    groups: Mapping[str, Sequence[History]],
    path: str | os.PathLike[str] | None = None,
    *,
    band: tuple[float, float] = (0.25, 0.75),
    title: str | None = None,
) -> Any:
    """Plot learning curves: median and quantile band over the runs of each group.

    Parameters
    ----------
    groups : mapping of str to sequence of History
        Label -> runs (e.g. one optimiser over several seeds).
    path : path-like, optional
        Where to save the figure (PNG, PDF, ... by extension).
    band : (float, float)
        Quantiles of the shaded band (default the inter-quartile range).
    title : str, optional

    Returns
    -------
    matplotlib.figure.Figure
    """
    if not groups or any(len(runs) == 0 for runs in groups.values()):
        raise ValueError("groups: expected at least one group, each with at least one History")
    if not 0.0 <= band[0] < band[1] <= 1.0:
        raise ValueError(f"band: expected quantiles 0 <= low < high <= 1, got {band}")
    figure_module = import_optional("matplotlib.figure", "plot")
    figure = figure_module.Figure(figsize=(11, 4.2), layout="constrained")
    left, right = figure.subplots(1, 2)
    regret = all(run.meta.get("metric") == "regret" for runs in groups.values() for run in runs)
    metric = "eval_regret" if regret else "eval_return"
    for label, runs in groups.items():
        _draw(left, *_stack(runs, "mean_return"), label, band)
        _draw(right, *_stack(runs, metric), label, band)
    left.set(xlabel="episodes", ylabel="mean sample return", title="samples")
    right.set(xlabel="episodes", title="recommended (mean) policy on the test contexts")
    if regret:
        right.set_yscale("log")
        right.set_ylabel("mean regret (log)")
    else:
        right.set_ylabel("mean evaluation return")
    for axis in (left, right):
        axis.grid(True, alpha=0.3)
        axis.legend(fontsize="small")
    if title:
        figure.suptitle(title)
    if path is not None:
        figure.savefig(Path(path), dpi=120)
    return figure


def load_history(path: str | os.PathLike[str]) -> History:
    """The history of a run directory: ``history.json`` if finished, else the last checkpoint and the log.

    Damage is never skipped silently (see :meth:`RunDir.read_history`).
    """
    return RunDir.open(path).read_history()


def plot_run_dirs(
    paths: Sequence[str | os.PathLike[str]], out: str | os.PathLike[str] | None = None, **kwargs: Any
) -> Any:
    """Plot run directories, one group per optimiser (per optimiser and env if the envs differ)."""
    histories = [load_history(p) for p in paths]
    several_envs = len({h.meta.get("env") for h in histories}) > 1
    groups: dict[str, list[History]] = {}
    for history in histories:
        label = str(history.meta.get("optimizer", "?"))
        if several_envs:
            label += f" on {history.meta.get('env', '?')}"
        groups.setdefault(label, []).append(history)
    return plot_histories(groups, out, **kwargs)
