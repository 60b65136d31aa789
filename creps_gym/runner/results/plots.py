"""Learning-curve plots (``pip install creps-gym[plot]``; matplotlib is imported only when plotting).

:func:`plot_histories` draws, for each group of runs (one optimiser over several seeds), the median and a
quantile band over the runs of (left) the mean sample return on a symlog axis and (right) the evaluated
regret of the recommended policy on a log axis with the target regret as a dashed line, or its evaluation
return (symlog axis) when the env has no regret. The x axis is the number of training episodes; the legend,
below both panels (it never covers a curve: the figure grows with it), gives each group's size and stop
reasons, and the title names the env and its dimensions. :func:`plot_run_dirs` does the same from run
directories, one group per setting (:mod:`creps_gym.runner.results.groups`: everything fingerprinted but the
seed), or as ``labels`` say. Runs of different envs are refused unless ``mix_envs=True``.
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
from creps_gym.runner.history import History
from creps_gym.runner.results.export import check_one_env
from creps_gym.runner.rundir import RunDir
from creps_gym.runner.rundir.files import output_target, write_output
from creps_gym.runner.rundir.references import escape_text

__all__ = ["check_title", "figure_bytes", "load_history", "plot_histories", "plot_run_dirs", "save_figure"]


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


def check_title(title: Any) -> str:
    """``title`` if matplotlib can draw it; ``ValueError`` naming ``title`` for bad mathtext (``$...$``)."""
    from matplotlib import cbook
    from matplotlib.mathtext import MathTextParser

    if not isinstance(title, str):
        raise TypeError(f"title: expected a str or None, got {type(title).__name__}")
    if cbook.is_math_text(title):
        try:
            MathTextParser("path").parse(title)
        except ValueError as exc:
            reason = " ".join(str(exc).split())
            raise ValueError(
                f"title: expected text matplotlib can draw ($...$ is mathtext; write \\$ for a dollar sign), "
                f"got {escape_text(title)!r} ({reason})"
            ) from None
    return title


def _stop_text(runs: Sequence[History]) -> str:
    counts = Counter(str(run.stop_reason or "unfinished") for run in runs)
    return ", ".join(reason if n == 1 else f"{reason} ×{n}" for reason, n in counts.most_common())


def _draw(axis: Any, x: NDArray[np.float64], values: NDArray[np.float64], style: dict, band: tuple) -> Any:
    """The median line (or None when no value is finite) and the quantile band of a group."""
    keep = np.isfinite(values).any(axis=0)
    if not keep.any():
        return None
    x, values = x[keep], values[:, keep]
    (line,) = axis.plot(x, np.nanmedian(values, axis=0), **style)
    if values.shape[0] > 1:
        low, high = np.nanquantile(values, band, axis=0)
        axis.fill_between(x, low, high, color=line.get_color(), alpha=0.25, linewidth=0)
    return line


def _draw_groups(axes: tuple, groups: Mapping[str, Sequence[History]], regret: bool, band: tuple) -> list:
    """Draw each group (legend text -> runs) on both panels in its own colour; (line, text) legend entries."""
    metric = "eval_regret" if regret else "eval_return"
    entries = []
    for k, (text, runs) in enumerate(groups.items()):
        style = {"color": f"C{k % 10}", "linestyle": ("-", "--", ":", "-.")[k // 10 % 4], "label": text}
        lines = [
            _draw(axes[0], *_stack(runs, "mean_return"), style, band),
            _draw(axes[1], *_stack(runs, metric), style, band),
        ]
        drawn = [line for line in lines if line is not None]
        entries += [(drawn[0], text)] if drawn else []
    return entries


def _figure(texts: Sequence[str]) -> tuple[Any, Any, Any, Any, int]:
    """The figure, its two panels and the strip below them, sized for a legend of ``texts``; its columns."""
    longest = max(len(text) for text in texts)
    columns = 2 if len(texts) > 3 and longest <= 55 else 1
    width = max(11.0, 0.075 * longest * columns + 1.0)  # about 0.075 inch per character at "small" size
    strip = 0.22 * -(-len(texts) // columns) + 0.3  # 0.22 inch per legend row
    figure = import_optional("matplotlib.figure", "plot").Figure(
        figsize=(width, 4.2 + strip), layout="constrained"
    )
    panels, below = figure.subfigures(2, 1, height_ratios=[4.2, strip])
    return figure, *panels.subplots(1, 2), below, columns


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
    if title is not None:
        check_title(title)
    envs = check_one_env([run for runs in groups.values() for run in runs], mix_envs)
    regret = all(run.meta.get("metric") == "regret" for runs in groups.values() for run in runs)
    texts = [_plain(f"{label} (n={len(runs)}; stop: {_stop_text(runs)})") for label, runs in groups.items()]
    target = regret and target_regret is not None
    figure, left, right, below, columns = _figure(texts + (["target regret"] if target else []))
    entries = _draw_groups((left, right), dict(zip(texts, groups.values(), strict=True)), regret, band)
    _symlog(left, np.concatenate([run.column("mean_return") for runs in groups.values() for run in runs]))
    left.set(xlabel="episodes", ylabel="mean sample return (symlog)", title="samples")
    right.set(xlabel="episodes", title="recommended (mean) policy on the test contexts")
    if regret:
        right.set_yscale("log")
        right.set_ylabel("mean regret (log)")
        if target:
            line = right.axhline(target_regret, color="black", linestyle="--", linewidth=1)
            entries.append((line, f"target regret {target_regret:g}"))
    else:  # returns that span decades (a cost falling from 10 to 0.01) need a log-like axis, as on the left
        _symlog(
            right, np.concatenate([run.column("eval_return") for runs in groups.values() for run in runs])
        )
        right.set_ylabel("mean evaluation return (symlog)")
    for axis in (left, right):
        axis.grid(True, alpha=0.3)
    if entries:
        handles, labels = zip(*entries, strict=True)
        below.legend(handles, labels, loc="center", ncols=columns, fontsize="small", frameon=False)
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
    directory's own file, raises ``ValueError`` (:func:`creps_gym.runner.rundir.files.write_output`), and so
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
    labels: Sequence[str] | None = None,
    **kwargs: Any,
) -> Any:
    """Plot run directories, one group per setting (see :mod:`creps_gym.runner.results.groups`).

    ``labels``: one per run directory (same label, same group) or one per setting group. The target
    regret line is drawn when every run has the same ``target_regret``.
    """
    from creps_gym.runner.results.groups import group_runs, load_runs

    runs = load_runs(paths)
    check_one_env([history for _, history in runs], mix_envs)
    groups, _ = group_runs(runs, labels)
    targets = {config.target_regret for config, _ in runs}
    if len(targets) == 1 and "target_regret" not in kwargs:
        kwargs["target_regret"] = targets.pop()
    return plot_histories(groups, out, mix_envs=mix_envs, **kwargs)
