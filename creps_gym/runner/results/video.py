"""Record episodes of a rendering env to a video: the frames through each episode, streamed to the file.

``creps-gym evaluate RUN --video FILE`` records the test contexts it evaluates (one by default) with
:func:`write_video`. An env that has ``episode_frames()`` (the kick, the planar reacher, PointMaze and
Reacher: see their manuals) draws each frame only when it is written, so the progress on ``stderr`` counts
the frames as they are rendered; any other env gives its ``render()``: a list of frames
(``rgb_array_list``) or one frame (``rgb_array``). Needs the ``video`` extra (imageio and imageio-ffmpeg).
"""

from __future__ import annotations

import os
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any, TextIO

import numpy as np
from numpy.typing import NDArray

__all__ = ["EpisodeVideo", "write_video", "writer_options"]


class EpisodeVideo:
    """The frames of one episode per context of ``env`` (made with a render mode), drawn as they are read.

    Parameters
    ----------
    env : gymnasium.Env
        A creps_gym env made with ``render_mode="rgb_array_list"`` (or ``"rgb_array"``).
    policy : callable
        Contexts (n, z) -> parameters (n, p), e.g. a :class:`~creps_gym.optimizers.Policy`.
    contexts : ndarray, shape (n, z)
        One episode per row, in order.
    seeds : sequence of int, length n
        The reset seed of each episode.
    progress : text stream, optional
        Where to say what is being recorded (``sys.stderr`` in the CLI); None: silent.

    Attributes
    ----------
    returns : list of float
        The return of each episode recorded so far.
    """

    def __init__(
        self, env: Any, policy: Any, contexts: Any, seeds: Any, progress: TextIO | None = None
    ) -> None:
        self.env = env
        self.policy = policy
        self.contexts = np.asarray(contexts, dtype=np.float64)
        self.seeds = [int(seed) for seed in seeds]
        if self.contexts.ndim != 2 or self.contexts.shape[0] != len(self.seeds) or not self.seeds:
            raise ValueError(
                f"contexts, seeds: expected (n, z) contexts and n seeds, n >= 1, got {self.contexts.shape} "
                f"and {len(self.seeds)}"
            )
        self.progress = progress
        self.returns: list[float] = []
        self.frame_count = 0

    @property
    def fps(self) -> float:
        """Frames per second: the env's ``metadata["render_fps"]``."""
        return float(self.env.unwrapped.metadata.get("render_fps", self.env.metadata.get("render_fps", 4)))

    def _say(self, text: str, end: str = "\n") -> None:
        if self.progress is not None:
            self.progress.write(text + end)
            self.progress.flush()

    def _episode(self, index: int) -> Any:
        """Run episode ``index``; returns its frames (a lazy sequence where the env has one)."""
        context = self.contexts[index]
        self.env.reset(seed=self.seeds[index], options={"context": context})
        params = np.asarray(self.policy(context[None, :]), dtype=np.float64)[0]
        _, reward, *_ = self.env.step(params)
        self.returns.append(float(reward))
        lazy = getattr(self.env.unwrapped, "episode_frames", None)
        if callable(lazy):
            return lazy()
        frames = self.env.render()
        return frames if isinstance(frames, list) else [frames]

    def __iter__(self) -> Iterator[NDArray[np.uint8]]:
        total = len(self.seeds)
        tty = self.progress is not None and getattr(self.progress, "isatty", lambda: False)()
        for index in range(total):
            start = time.perf_counter()
            frames = self._episode(index)
            count = len(frames)
            context = ", ".join(f"{v:.4g}" for v in self.contexts[index])
            self._say(
                f"video: episode {index + 1}/{total}, context [{context}], return {self.returns[-1]:.6g}: "
                f"rendering {count} frame{'s' * (count != 1)} ({count / self.fps:.2f} s at {self.fps:g} fps)"
            )
            for number, frame in enumerate(frames, 1):
                if tty:
                    self._say(f"\rvideo: frame {number}/{count}", end="")
                self.frame_count += 1
                yield np.asarray(frame, dtype=np.uint8)
            if tty:
                self._say("")
            self._say(f"video: episode {index + 1}/{total} rendered in {time.perf_counter() - start:.1f} s")


def writer_options(path: str | os.PathLike[str], shape: tuple[int, ...], fps: float) -> dict[str, Any]:
    """imageio's writer options for ``path`` (.gif or .mp4) and frames of ``shape`` (height, width, 3)."""
    if str(path).lower().endswith(".gif"):
        return {"duration": 1000.0 / fps, "loop": 0}
    even = all(n % 2 == 0 for n in shape[:2])  # ffmpeg: even sizes suffice for yuv420p (no resizing)
    return {"fps": fps, **({"macro_block_size": 1} if even else {})}


def write_video(path: str | os.PathLike[str], video: EpisodeVideo) -> Path:
    """Stream the frames of ``video`` into ``path`` (.gif or .mp4; imageio picks the format by the
    name); returns the path. The env is closed at the end."""
    import imageio.v2 as imageio

    try:
        frames = iter(video)
        first = next(frames)
        with imageio.get_writer(path, mode="I", **writer_options(path, first.shape, video.fps)) as writer:
            writer.append_data(first)
            for frame in frames:
                writer.append_data(frame)
    finally:
        video.env.close()
    return Path(path)
