"""Learning-curve plots (``pip install creps-gym[plot]``; matplotlib is imported only when plotting).

:func:`plot_histories` draws, for each group of runs (one optimiser over several seeds), the median and a
quantile band over the runs of (left) the mean sample return on a symlog axis and (right) the evaluated
regret of the recommended policy on a log axis with the target regret as a dashed line, or its evaluation
return when the env has no regret. The x axis is the number of training episodes; the legend gives each
group's stop reasons and the title names the env and its dimensions. :func:`plot_run_dirs` does the same
from run directories, grouping them by optimiser. Runs of different envs are refused unless
``mix_envs=True`` (then grouped by optimiser and env).
"""

from __future__ import annotations

import io
import os
from collections import Counter
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from creps_gym.optimizers.adapters.base import import_optional
from creps_gym.runner.export import check_one_env, env_key
from creps_gym.runner.files import output_target, write_output
from creps_gym.runner.history import History
from creps_gym.runner.rundir import RunDir
from creps_gym.runner.trust import escape_text

__all__ = ["figure_bytes", "load_history", "plot_histories", "plot_run_dirs", "save_figure"]


def _stack(runs: Sequence[History], name: str) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """x (episodes of the longest run) and a (runs, iterations) matrix padded with NaN."""
    longest = max(runs, key=len)
    values = np.full((len(runs), len(longest)), np.nan)
    for i, run in enumerate(runs):
        values[i, : len(run)] = run.column(name)
    return longest.column("episodes"), values


def _plain(text: str) -> str:
    """Text from a run folder as matplotlib shows it literally: escaped controls, no mathtext (``$``)."""
    return escape_text(text).replace("$", r"\$")


def _stop_text(runs: Sequence[History]) -> str:
    counts = Counter(str(run.stop_reason or "unfinished") for run in runs)
    return ", ".join(reason if n == 1 else f"{reason} ×{n}" for reason, n in counts.most_common())


def _draw(axis: Any, x: NDArray[np.float64], values: NDArray[np.float64], label: str, band: tuple) -> None:
    keep = np.isfinite(values).any(axis=0)
    if not keep.any():
        return
    x, values = x[keep], values[:, keep]
    (line,) = axis.plot(x, np.nanmedian(values, axis=0), label=label)
    if values.shape[0] > 1:
        low, high = np.nanquantile(values, band, axis=0)
        axis.fill_between(x, low, high, color=line.get_color(), alpha=0.25, linewidth=0)


def _symlog(axis: Any, values: NDArray[np.float64]) -> None:
    """A symlog y axis whose linear part is the decade of the smallest non-zero |value| (returns < 0 too)."""
    magnitudes = np.abs(values[np.isfinite(values) & (values != 0)])
    if magnitudes.size:
        axis.set_yscale("symlog", linthresh=10.0 ** np.floor(np.log10(magnitudes.min())))


def plot_histories(
    groups: Mapping[str, Sequence[History]],
    path: str | os.PathLike[str] | None = None,
    *,
    band: tuple[float, float] = (0.25, 0.75),
    title: str | None = None,
    target_regret: float | None = None,
    mix_envs: bool = False,
) -> Any:
    """Plot learning curves: median and quantile band over the runs of each group.

    Parameters
    ----------
    groups : mapping of str to sequence of History
        Label -> runs (e.g. one optimiser over several seeds).
    path : path-like, optional
        Where to save the figure (see :func:`save_figure`).
    band : (float, float)
        Quantiles of the shaded band (default the inter-quartile range).
    title : str, optional
        Default: the env and its dimensions, e.g. ``creps_gym/Sphere-v0 (p = 15, z = 1)``.
    target_regret : float, optional
        Drawn as a dashed line on the regret panel.
    mix_envs : bool
        Allow runs of different envs (``ValueError`` otherwise).

    Returns
    -------
    matplotlib.figure.Figure
    """
    if not groups or any(len(runs) == 0 for runs in groups.values()):
        raise ValueError("groups: expected at least one group, each with at least one History")
    if not 0.0 <= band[0] < band[1] <= 1.0:
        raise ValueError(f"band: expected quantiles 0 <= low < high <= 1, got {band}")
    envs = check_one_env([run for runs in groups.values() for run in runs], mix_envs)
    figure_module = import_optional("matplotlib.figure", "plot")
    figure = figure_module.Figure(figsize=(11, 4.2), layout="constrained")
    left, right = figure.subplots(1, 2)
    regret = all(run.meta.get("metric") == "regret" for runs in groups.values() for run in runs)
    metric = "eval_regret" if regret else "eval_return"
    for label, runs in groups.items():
        text = _plain(f"{label} (n={len(runs)}; stop: {_stop_text(runs)})")
        _draw(left, *_stack(runs, "mean_return"), text, band)
        _draw(right, *_stack(runs, metric), text, band)
    _symlog(left, np.concatenate([run.column("mean_return") for runs in groups.values() for run in runs]))
    left.set(xlabel="episodes", ylabel="mean sample return (symlog)", title="samples")
    right.set(xlabel="episodes", title="recommended (mean) policy on the test contexts")
    if regret:
        right.set_yscale("log")
        right.set_ylabel("mean regret (log)")
        if target_regret is not None:
            right.axhline(target_regret, color="black", linestyle="--", linewidth=1,
                          label=f"target regret {target_regret:g}")  # fmt: skip
    else:
        right.set_ylabel("mean evaluation return")
    for axis in (left, right):
        axis.grid(True, alpha=0.3)
        axis.legend(fontsize="small")
    figure.suptitle(title if title is not None else _plain(" / ".join(envs)))
    if path is not None:
        save_figure(figure, path)
    return figure


def figure_bytes(figure: Any, image_format: str = "png") -> bytes:
    """The figure as an image file's content (``"png"``, ``"pdf"``, ``"svg"``, ...)."""
    buffer = io.BytesIO()
    figure.savefig(buffer, format=image_format, dpi=120)
    return buffer.getvalue()


def save_figure(figure: Any, path: str | os.PathLike[str]) -> Path:
    """Write ``figure`` to exactly ``path``, in the format of its extension (PNG without one).

    A link is followed (its target is replaced); a target that is not a regular file, or that is a run
    directory's own file, raises ``ValueError`` (:func:`creps_gym.runner.files.write_output`), and so
    does an extension matplotlib cannot write. Returns the file written.
    """
    output_target(path, protected=RunDir.owns)  # refused before drawing
    suffix = Path(path).suffix.lstrip(".").lower()
    return write_output(path, figure_bytes(figure, suffix or "png"), protected=RunDir.owns)


def load_history(path: str | os.PathLike[str]) -> History:
    """The history of a run directory: ``history.json`` if finished, else the last checkpoint and the log.

    Damage is never skipped silently (see :meth:`RunDir.read_history`).
    """
    return RunDir.open(path).read_history()


def plot_run_dirs(
    paths: Sequence[str | os.PathLike[str]],
    out: str | os.PathLike[str] | None = None,
    *,
    mix_envs: bool = False,
    **kwargs: Any,
) -> Any:
    """Plot run directories, one group per optimiser (per optimiser and env with ``mix_envs``).

    The target regret line is drawn when every run has the same ``target_regret``.
    """
    histories = [load_history(p) for p in paths]
    several_envs = len(check_one_env(histories, mix_envs)) > 1
    groups: dict[str, list[History]] = {}
    for history in histories:
        label = str(history.meta.get("optimizer", "?"))
        if several_envs:
            label += f" on {env_key(history)}"
        groups.setdefault(label, []).append(history)
    targets = {RunDir.open(p).config().target_regret for p in paths}
    if len(targets) == 1 and "target_regret" not in kwargs:
        kwargs["target_regret"] = targets.pop()
    return plot_histories(groups, out, mix_envs=mix_envs, **kwargs)
