"""Fig. 4b-style drawing of a planar-arm motion with matplotlib's Agg backend (the optional ``plot`` extra).

:func:`draw_motion` draws a whole motion in one image (overlaid postures), :func:`motion_frames` one frame
per time step for a video. matplotlib is imported only when an image is drawn, so the envs work without it.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from creps_gym.envs.frames import EpisodeFrames

__all__ = ["draw_motion", "motion_frames", "posture_shades"]

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
    canvas, ax = _axes(postures)
    indices, grey = posture_shades(postures.shape[0], via_step)
    order = np.argsort(-grey)  # light postures first, the darkest on top
    for index, level in zip(indices[order], grey[order], strict=True):
        xy = postures[index]
        ax.plot(xy[:, 0], xy[:, 1], "-o", color=str(level), lw=1.5, ms=2.5)
    ax.plot(postures[:, -1, 0], postures[:, -1, 1], "-", color="tab:green", lw=1.0, label="hand path")
    _markers(ax, via_point, goal)
    return _image(canvas)


def motion_frames(
    postures: Array, via_point: Array, goal: Array, via_step: int, dt: float, stride: int = 2
) -> EpisodeFrames:
    """One frame per ``stride`` samples of a motion, each drawn when read: the arm at that time, the hand's
    path so far, the via-point, the goal and the time.

    Parameters
    ----------
    postures : ndarray, shape (T, joints + 1, 2)
        Joint positions over time (base first).
    via_point, goal : ndarray, shape (2,)
    via_step : int
        Sample index of the via-point time (the title says when it is reached).
    dt : float
        Seconds between samples.
    stride : int
        Samples per frame (the last sample always has a frame).

    Returns
    -------
    EpisodeFrames
        ``ceil((T - 1) / stride) + 1`` frames, each an ndarray of uint8, shape (480, 480, 3).
    """
    samples = np.unique(np.append(np.arange(0, postures.shape[0], stride), postures.shape[0] - 1))
    canvas, ax = _axes(postures)
    (path,) = ax.plot([], [], "-", color="tab:green", lw=1.0, label="hand path")
    (arm,) = ax.plot([], [], "-o", color="black", lw=2.0, ms=3.5, label="arm")
    # What changes from frame to frame, and what lies over it, is drawn over a copy of the rest (axes, ticks,
    # grid), which is drawn once: the same pixels as the whole figure, in a third of the time.
    moving = [path, arm, *_markers(ax, via_point, goal), ax.set_title(" ", fontsize=10)]
    for artist in moving:
        artist.set_animated(True)
    canvas.draw()
    background = canvas.copy_from_bbox(ax.figure.bbox)

    def draw(index: int) -> NDArray[np.uint8]:
        k = int(samples[index])
        arm.set_data(postures[k, :, 0], postures[k, :, 1])
        path.set_data(postures[: k + 1, -1, 0], postures[: k + 1, -1, 1])
        note = " (via-point time)" if k == via_step else ""
        moving[-1].set_text(f"t = {k * dt:.2f} s, step {k} of {postures.shape[0] - 1}{note}")
        canvas.restore_region(background)
        for artist in moving:
            ax.draw_artist(artist)
        return _image(canvas, redraw=False)

    return EpisodeFrames(len(samples), draw)


def _axes(postures: Array) -> tuple[Any, Any]:
    """The Agg canvas of a 480x480 figure and square axes that hold every posture of the motion."""
    figure_class, canvas_class = _matplotlib()
    fig = figure_class(figsize=(SIZE_PIXELS / DPI, SIZE_PIXELS / DPI), dpi=DPI)
    canvas = canvas_class(fig)
    ax = fig.add_axes((0.13, 0.1, 0.84, 0.84))
    low = min(-1.5, float(postures.min()) - 0.2)
    high = max(5.5, float(postures.max()) + 0.2)
    ax.set_xlim(low, high)
    ax.set_ylim(low, high)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.grid(True, lw=0.3)
    return canvas, ax


def _markers(ax: Any, via_point: Array, goal: Array) -> list[Any]:
    """The via-point (red cross), the goal (blue star) and the legend; the artists, in drawing order."""
    (via,) = ax.plot(
        [via_point[0]], [via_point[1]], "x", color="red", ms=12, mew=3, label="via-point (context)"
    )
    (star,) = ax.plot([goal[0]], [goal[1]], "*", color="tab:blue", ms=14, label="goal")
    return [via, star, ax.legend(loc="upper right", fontsize="small", framealpha=0.9)]


def _image(canvas: Any, redraw: bool = True) -> NDArray[np.uint8]:
    """The canvas's RGB pixels, after drawing the whole figure unless ``redraw`` is False."""
    if redraw:
        canvas.draw()
    return np.asarray(canvas.buffer_rgba())[:, :, :3].copy()
