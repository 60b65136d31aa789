"""Fig. 4b-style drawing of a planar-arm motion with matplotlib's Agg backend (the optional ``plot`` extra).

matplotlib is imported only when an image is drawn, so the envs work without it.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["draw_motion", "posture_shades"]

Array = NDArray[np.float64]
SIZE_PIXELS = 480
DPI = 100
POSTURE_STRIDE = 5


def _matplotlib() -> tuple[Any, Any]:
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError as exc:
        raise ImportError(
            "render_mode='rgb_array' needs matplotlib: install the plot extra (pip install 'creps-gym[plot]')"
        ) from exc
    return Figure, FigureCanvasAgg


def posture_shades(n_samples: int, via_step: int, stride: int = POSTURE_STRIDE) -> tuple[Array, Array]:
    """Indices of the drawn postures and their grey levels (0 black, 1 white), darker near ``via_step``.

    Parameters
    ----------
    n_samples : int
        Number of postures in the motion.
    via_step : int
        Index of the via-point time.
    stride : int
        Draw every ``stride``-th posture (the last one always).

    Returns
    -------
    indices : ndarray of int, shape (m,)
    grey : ndarray, shape (m,)
        ``0.85 (1 − exp(−|k − via_step| / 15))``: black at the via-point time, light grey far from it.
    """
    indices = np.unique(np.append(np.arange(0, n_samples, stride), n_samples - 1))
    grey = 0.85 * (1.0 - np.exp(-np.abs(indices - via_step) / 15.0))
    return indices, grey


def draw_motion(postures: Array, via_point: Array, goal: Array, via_step: int) -> NDArray[np.uint8]:
    """Draw overlaid arm postures, the hand's path, the via-point and the goal.

    Parameters
    ----------
    postures : ndarray, shape (T, joints + 1, 2)
        Joint positions over time (base first), e.g. from ``forward_kinematics``.
    via_point, goal : ndarray, shape (2,)
        Marked with a red cross and a blue star.
    via_step : int
        Sample index of the via-point time (the darkest posture).

    Returns
    -------
    ndarray of uint8, shape (480, 480, 3)
        The RGB image.
    """
    figure_class, canvas_class = _matplotlib()
    fig = figure_class(figsize=(SIZE_PIXELS / DPI, SIZE_PIXELS / DPI), dpi=DPI)
    canvas = canvas_class(fig)
    ax = fig.add_axes((0.13, 0.1, 0.84, 0.86))
    indices, grey = posture_shades(postures.shape[0], via_step)
    order = np.argsort(-grey)  # light postures first, the darkest on top
    for index, level in zip(indices[order], grey[order], strict=True):
        xy = postures[index]
        ax.plot(xy[:, 0], xy[:, 1], "-o", color=str(level), lw=1.5, ms=2.5)
    ax.plot(postures[:, -1, 0], postures[:, -1, 1], "-", color="tab:green", lw=1.0)
    ax.plot([via_point[0]], [via_point[1]], "x", color="red", ms=12, mew=3)
    ax.plot([goal[0]], [goal[1]], "*", color="tab:blue", ms=14)
    low = min(-1.5, float(postures.min()) - 0.2)
    high = max(5.5, float(postures.max()) + 0.2)
    ax.set_xlim(low, high)
    ax.set_ylim(low, high)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.grid(True, lw=0.3)
    canvas.draw()
    image = np.asarray(canvas.buffer_rgba())[:, :, :3].copy()
    return image
