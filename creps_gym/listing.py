"""What ``creps-gym list`` prints: aligned tables of the envs and optimisers, and "did you mean" hints.

Each env row shows the context space, the parameter space and the initial search distribution the runner
starts from by default (:func:`initial_hint`: the env-declared initial distribution).
"""

from __future__ import annotations

import difflib
import re
import warnings
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

__all__ = ["box_text", "did_you_mean", "env_rows", "initial_hint", "optimizer_rows", "plain", "table"]

_ROLE = re.compile(r":[a-z]+:`~?(?:[\w.]*\.)?([^`]+)`")  # :class:`~a.b.C` -> C


def plain(text: str) -> str:
    """A docstring line without reST markup: ``x`` -> x, :class:`~a.b.C` -> C."""
    return _ROLE.sub(r"\1", text).replace("``", "").replace("`", "")


def _number(value: float) -> str:
    return f"{value:.3g}"


def box_text(space: Any) -> str:
    """A Box as ``[low, high]^n`` (equal bounds) or ``n dims in [min low, max high]``; others as ``str``."""
    low = np.asarray(getattr(space, "low", np.nan), np.float64).ravel()
    high = np.asarray(getattr(space, "high", np.nan), np.float64).ravel()
    if low.size == 0 or np.isnan(low).any():
        return str(space)
    n = low.size
    if (low == low[0]).all() and (high == high[0]).all():
        interval = f"[{_number(low[0])}, {_number(high[0])}]"
        return interval if n == 1 else f"{interval}^{n}"
    return f"{n} dims in [{_number(low.min())}, {_number(high.max())}]"


def initial_hint(env: Any) -> str:
    """The runner's default initial search distribution for ``env`` (the env-declared one): N(mean, std²)."""
    from creps_gym.envs.base import box_initial_distribution, initial_distribution

    mean, std = initial_distribution(env)
    if (mean == mean[0]).all() and (std == std[0]).all():
        return f"N({_number(mean[0])}, {_number(std[0])}^2)"
    box_mean, box_std = box_initial_distribution(env.action_space)
    if np.array_equal(mean, box_mean) and np.array_equal(std, box_std):
        return "N(box centre, (width/4)^2)"
    scale = f"{_number(std[0])}^2" if (std == std[0]).all() else "per-parameter std^2"
    return f"N(env-declared mean, {scale})"


def _description(env: Any) -> str:
    summary = (type(env.unwrapped).__doc__ or "").strip().split("\n\n", 1)[0]  # the first paragraph
    return plain(" ".join(line.strip() for line in summary.splitlines()))


def env_rows(env_ids: Iterable[str]) -> list[list[str]]:
    """One row per env: id, context space, parameter space, initial distribution, description."""
    import gymnasium as gym

    rows = [["id", "context", "parameters θ", "initial (default)", "description"]]
    for env_id in env_ids:
        try:
            with warnings.catch_warnings():  # listing the older versions is not using them
                warnings.filterwarnings("ignore", message=r".*is out of date\. You should consider upgrading")
                env = gym.make(env_id)
        except Exception as exc:  # an env whose optional extra is missing is still listed
            rows.append([env_id, "?", "?", "?", plain(f"(not available: {type(exc).__name__}: {exc})")[:100]])
            continue
        spaces = [box_text(env.observation_space), box_text(env.action_space)]
        rows.append([env_id, *spaces, initial_hint(env), _description(env)])
        env.close()
    return rows


def optimizer_rows(descriptions: dict[str, str]) -> list[list[str]]:
    """One row per optimiser: name, description."""
    return [["name", "description"]] + [[name, plain(text)] for name, text in descriptions.items()]


def table(rows: Sequence[Sequence[str]], indent: str = "  ") -> str:
    """Rows as left-aligned columns (the last column is not padded)."""
    widths = [max(len(row[k]) for row in rows) for k in range(len(rows[0]) - 1)]
    lines = [
        "  ".join([*(cell.ljust(w) for cell, w in zip(row, widths, strict=False)), row[-1]]) for row in rows
    ]
    return "\n".join(indent + line.rstrip() for line in lines)


def did_you_mean(text: str, choices: Sequence[str]) -> str:
    """`` (did you mean 'x'?)`` for the closest choices (ids also match without their namespace), or ''."""
    by_key = {choice: choice for choice in choices}
    by_key.update({choice.split("/", 1)[1]: choice for choice in choices if "/" in choice})
    matches = difflib.get_close_matches(text, list(by_key), n=3, cutoff=0.6)
    if not matches and "/" in text:
        matches = difflib.get_close_matches(text.split("/", 1)[1], list(by_key), n=3, cutoff=0.6)
    suggestions = list(dict.fromkeys(by_key[m] for m in matches))
    if not suggestions:
        return ""
    return " (did you mean " + " or ".join(repr(s) for s in suggestions) + "?)"
