"""The records of an ask/tell run (:mod:`creps_gym.runner.manual`): its spaces and its episodes.

Both are read back from an untrusted run folder (``config.json``'s ``meta``, the checkpoint's JSON
document): :meth:`Spaces.from_dict` and :meth:`Episode.from_dict` check every value and raise
``ValueError`` naming what is wrong, which the caller words as damage of the file it read.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from creps_gym.errors import ConfigError
from creps_gym.optimizers.base import ContextualOptimizer
from creps_gym.optimizers.registry import optimizer_class
from creps_gym.runner.config import RunConfig
from creps_gym.runner.history import decode_float, encode_float

__all__ = [
    "ASK_TELL",
    "BOX_OPTIONS",
    "Episode",
    "Sizes",
    "Spaces",
    "check_optimizer",
    "is_ask_tell",
    "refuse_resume",
    "with_box_options",
]

Array = NDArray[np.float64]

#: The key of an ask/tell run's spaces in ``config.json``'s ``meta`` and of its state in the checkpoint.
ASK_TELL = "ask_tell"
#: Where a box's options go for an optimiser whose configuration takes them (c-bo: its search box).
BOX_OPTIONS = ("param_low", "param_high", "context_low", "context_high")


@dataclass(frozen=True)
class Spaces:
    """The parameter box (p,) and the context box (z,) of an ask/tell run (infinite bounds allowed)."""

    param_low: Array
    param_high: Array
    context_low: Array
    context_high: Array

    @classmethod
    def of(cls, **boxes: Any) -> Spaces:
        """Checked boxes: 1-D, non-empty, no NaN, low < high (``ValueError`` naming the box)."""
        arrays = {}
        for name in BOX_OPTIONS:
            value = np.asarray(boxes[name], dtype=np.float64)
            if value.ndim != 1 or value.size == 0 or np.isnan(value).any():
                raise ValueError(f"{name}: expected a non-empty list of numbers, got {boxes[name]!r}")
            arrays[name] = value
        for kind in ("param", "context"):
            low, high = arrays[f"{kind}_low"], arrays[f"{kind}_high"]
            if low.shape != high.shape or not (low < high).all():
                raise ValueError(
                    f"{kind}_high: expected {low.size} numbers above {kind}_low {low.tolist()}, got "
                    f"{high.tolist()}"
                )
        return cls(**arrays)

    @classmethod
    def from_dict(cls, data: Any) -> Spaces:
        if not isinstance(data, dict) or sorted(data) != sorted(BOX_OPTIONS):
            raise ValueError(f"expected the boxes {list(BOX_OPTIONS)}, got {str(data)[:200]}")
        if not all(isinstance(v, list) for v in data.values()):
            raise ValueError("expected each box as a list of numbers")
        return cls.of(**{k: [decode_float(x) for x in v] for k, v in data.items()})

    def to_dict(self) -> dict[str, list[Any]]:
        return {name: [encode_float(x) for x in getattr(self, name)] for name in BOX_OPTIONS}

    def env(self) -> gym.Env:
        """A stand-in env holding the boxes: what the optimiser's start and the policy files read."""
        return _SpacesEnv(self)

    def equals(self, other: Spaces) -> bool:
        return all(np.array_equal(getattr(self, n), getattr(other, n)) for n in BOX_OPTIONS)


class _SpacesEnv(gym.Env):  # type: ignore[type-arg]
    """The spaces of an ask/tell run; its episodes run outside creps_gym."""

    def __init__(self, spaces: Spaces) -> None:
        self.action_space = gym.spaces.Box(spaces.param_low, spaces.param_high, dtype=np.float64)
        self.observation_space = gym.spaces.Box(spaces.context_low, spaces.context_high, dtype=np.float64)

    def step(self, action: Any) -> Any:
        raise RuntimeError("an ask/tell run's episodes run outside creps_gym: `creps-gym tell` their returns")


EPISODE_KEYS = ["asked", "context", "episode", "failed", "params", "value"]


@dataclass
class Episode:
    """One episode of the current batch: its id, context (z,), asked and clipped params (p,), return."""

    episode: int
    context: Array
    asked: Array
    params: Array
    value: float | None = None  # the told return (None: pending)
    failed: bool = False

    @property
    def pending(self) -> bool:
        return self.value is None and not self.failed

    def to_dict(self) -> dict[str, Any]:
        data = {"episode": self.episode, "failed": self.failed, "value": self.value}
        data.update({k: getattr(self, k).tolist() for k in ("context", "asked", "params")})
        return data

    @classmethod
    def from_dict(cls, data: Any, p: int, z: int) -> Episode:
        """An episode of the checkpoint, checked (``ValueError`` naming what is wrong)."""
        if not isinstance(data, dict) or sorted(data) != EPISODE_KEYS:
            raise ValueError(f"expected an episode record, got {str(data)[:200]}")
        episode, value, failed = data["episode"], data["value"], data["failed"]
        if type(episode) is not int or episode < 1 or type(failed) is not bool:
            raise ValueError(f"expected an episode id >= 1 and a failed flag, got {episode!r}, {failed!r}")
        if value is not None and (type(value) is not float or not math.isfinite(value) or failed):
            raise ValueError(f"episode {episode}: expected a finite return or none, got {value!r}")
        arrays = {}
        for key, size in (("context", z), ("asked", p), ("params", p)):
            row = data[key]
            if not isinstance(row, list) or len(row) != size or not all(type(x) is float for x in row):
                raise ValueError(f"episode {episode}: expected {key} of {size} numbers, got {str(row)[:200]}")
            arrays[key] = np.array(row, dtype=np.float64)
            if not np.isfinite(arrays[key]).all():
                raise ValueError(f"episode {episode}: expected finite {key}, got {row}")
        return cls(episode, value=value, failed=failed, **arrays)


def is_ask_tell(run_dir: Any) -> bool:
    """Whether ``run_dir`` is an ask/tell run (its ``config.json``'s ``meta`` holds its spaces)."""
    return ASK_TELL in run_dir.document().get("meta", {})


def refuse_resume(run_dir: Any) -> None:
    """``ValueError`` for an ask/tell run: its episodes run outside creps_gym, ``resume`` cannot run them."""
    if is_ask_tell(run_dir):
        raise ValueError(
            f"run_dir: expected a run that creps_gym runs, got {run_dir.path}, an ask/tell run (its episodes "
            "run outside creps_gym): continue it with `creps-gym ask` and `creps-gym tell`"
        )


def check_optimizer(name: str | None) -> None:
    """``ConfigError`` naming ``optimizer`` unless it is one of creps_gym's own (not an adapter)."""
    from creps_gym.optimizers.adapters import MinimizerAdapter

    cls = None if name is None else optimizer_class(name)
    if cls is None or not issubclass(cls, ContextualOptimizer) or issubclass(cls, MinimizerAdapter):
        raise ConfigError(
            "optimizer",
            "expected one of creps_gym's own optimisers (an adapter asks and tells whole populations, not "
            f"one episode at a time), got {name!r}",
        )


def with_box_options(config: RunConfig, spaces: Spaces) -> RunConfig:
    """``config`` with the boxes as options of an optimiser that takes them (c-bo) and was not given them:
    the parameter box the user typed is the robot's, so the search stays inside it."""
    fields = getattr(optimizer_class(config.optimizer), "config_class", None)
    names = getattr(fields, "__dataclass_fields__", {})
    options = dict(config.optimizer_options)
    for name in BOX_OPTIONS:
        value = getattr(spaces, name)
        if name in names and name not in options and np.isfinite(value).all():
            options[name] = value.tolist()
    return replace(config, optimizer_options=options)


@dataclass
class Sizes:
    """What the runner's checks read of a run: its config and sizes."""

    config: RunConfig
    n_params: int
    n_context_dims: int
    env_name: str = "the run's spaces"
