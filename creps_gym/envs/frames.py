"""The frames of a rendered episode, drawn one at a time as they are read.

A rendering env's ``episode_frames()`` returns an :class:`EpisodeFrames`: its length is known at once, and
each frame is drawn only when it is read, so a video writer can stream them and report progress while the
expensive part (MuJoCo's software rendering, matplotlib's drawing) runs. ``render()`` in the
``rgb_array_list`` mode is ``list(env.episode_frames())``.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from typing import overload

import numpy as np
from numpy.typing import NDArray

__all__ = ["EpisodeFrames"]

Frame = NDArray[np.uint8]


class EpisodeFrames(Sequence[Frame]):
    """``count`` frames; frame ``i`` is ``draw(i)``, a (height, width, 3) uint8 image, drawn when read.

    Parameters
    ----------
    count : int
        Number of frames (>= 1).
    draw : callable
        ``draw(i) -> ndarray (height, width, 3) uint8`` for ``0 <= i < count``.
    """

    def __init__(self, count: int, draw: Callable[[int], Frame]) -> None:
        if not isinstance(count, int) or isinstance(count, bool) or count < 1:
            raise ValueError(f"count: expected an int >= 1, got {count!r}")
        self._count = count
        self._draw = draw

    def __len__(self) -> int:
        return self._count

    @overload
    def __getitem__(self, index: int) -> Frame: ...

    @overload
    def __getitem__(self, index: slice) -> list[Frame]: ...

    def __getitem__(self, index: int | slice) -> Frame | list[Frame]:
        if isinstance(index, slice):
            return [self[i] for i in range(*index.indices(self._count))]
        if not -self._count <= index < self._count:
            raise IndexError(f"index: expected one in [{-self._count}, {self._count}), got {index}")
        return self._draw(index % self._count)

    def __iter__(self) -> Iterator[Frame]:
        return (self._draw(i) for i in range(self._count))
