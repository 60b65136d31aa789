"""The kick study's figures, drawn from its ``results.json`` document (:mod:`benchmarks.kick.report`):
Fig. 5c (error per target), Fig. 7 (mean distance per ball position) and the learning curves."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.kick.study import GRID_X, GRID_Y, TARGETS

__all__ = ["mean_curve", "plot"]


def mean_curve(curves: list[Any]) -> dict[int, float]:
    """Iteration → mean over the trials' curves ``[[iteration, value], ...]`` where every trial has one."""
    by_iteration = [dict((int(i), v) for i, v in curve) for curve in curves]
    common = set.intersection(*(set(c) for c in by_iteration)) if by_iteration else set()
    return {i: float(np.mean([c[i] for c in by_iteration])) for i in sorted(common)}


def plot(document: dict[str, Any], out: Path) -> None:
    """Fig. 5c (error per target), Fig. 7 (mean distance per ball position) and learning curves as PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6))
    colours = {
        name: f"C{k}" for k, name in enumerate(sorted({*document["precision"], *document["flexibility"]}))
    }
    for name, entry in document["precision"].items():
        if name == "oracle" and len(entry["target_errors"]) != len(TARGETS):
            continue
        errors = np.asarray(entry["target_errors"]).reshape(-1, len(TARGETS))
        axes[0].errorbar(
            TARGETS, errors.mean(0), errors.std(0), marker="o", capsize=3, label=name, color=colours[name]
        )
    axes[0].set(xlabel="target distance s [m]", ylabel="distance to target [m]", title="Kick precision")
    twin = axes[1].twinx()
    twin.set_ylabel("flexibility: forward distance [m] (dashed)")
    for experiment, ax in zip(("precision", "flexibility"), (axes[1], twin), strict=True):
        style = "-" if experiment == "precision" else "--"
        for name, entry in document[experiment].items():
            curves = [curve for curve in entry.get("curves", []) if curve]
            for curve in curves:  # each trial thin, the mean over the trials (where all ran) bold
                ax.plot(*np.asarray(curve).T, ls=style, color=colours[name], alpha=0.25, lw=0.8)
            if mean := mean_curve(curves):
                ax.plot(
                    list(mean),
                    list(mean.values()),
                    ls=style,
                    color=colours[name],
                    lw=2,
                    label=f"{experiment[:4]} {name}",
                )
    axes[1].set(
        xlabel="iteration",
        ylabel="precision error [m] (solid)",
        title="Mean policy while learning (bold: mean over trials)",
    )
    fig.legend(fontsize=7, loc="lower center", ncol=4)
    fig.tight_layout(rect=(0, 0.12, 1, 1))
    fig.savefig(out / "precision.png", dpi=110)
    plt.close(fig)
    _plot_heatmaps(plt, document, out)


def _plot_heatmaps(plt: Any, document: dict[str, Any], out: Path) -> None:
    flexibility = document["flexibility"]
    maps = {n: np.mean(e["position_distances"], axis=0) for n, e in flexibility.items() if n != "oracle"}
    oracle = flexibility.get("oracle", {}).get("position_distances", [])
    if len(oracle) == len(GRID_X) * len(GRID_Y):
        maps["oracle"] = np.asarray(oracle)
    if not maps:
        return
    dx, dy = (GRID_X[1] - GRID_X[0]) / 2, (GRID_Y[1] - GRID_Y[0]) / 2
    extent = [GRID_X[0] - dx, GRID_X[-1] + dx, GRID_Y[0] - dy, GRID_Y[-1] + dy]
    fig, axes = plt.subplots(1, len(maps), figsize=(3.6 * len(maps), 3.2), squeeze=False)
    for ax, (name, values) in zip(axes[0], maps.items(), strict=True):
        grid = np.asarray(values).reshape(len(GRID_X), len(GRID_Y))
        image = ax.imshow(grid.T, origin="lower", aspect="auto", cmap="jet", vmin=0, vmax=14, extent=extent)
        ax.set(xlabel="x_B [m]", ylabel="y_B [m]", title=f"{name}: forward distance")
        fig.colorbar(image, ax=ax, label="m")
    fig.tight_layout()
    fig.savefig(out / "flexibility.png", dpi=110)
    plt.close(fig)
