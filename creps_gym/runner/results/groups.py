"""Which run directories are seeds of one setting: the groups that ``plot`` and ``export`` compare.

A run's *setting* is everything in its fingerprinted configuration (:data:`FINGERPRINT_FIELDS`: the
optimiser and its options, the batch, the env and its keyword arguments, the initial distribution, the
budget ...) except its seed. Runs of the same setting are pooled as seeds; runs of different settings are
never pooled unless the user labels them alike.

A group's default label is its optimiser, followed by the settings that differ between the groups
(``c-cma-es, samples=16`` and ``c-cma-es, samples=32``; an option or env keyword argument by its own
name, ``epsilon=0.8``), and `` on <env>`` when the groups' envs differ. User labels
(:func:`group_runs` ``labels``, ``--label``) are given either one per run directory (runs with the same
label are pooled, whatever their settings) or one per group, in the order of the groups' first run.
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from typing import Any

from creps_gym.runner.config import RunConfig
from creps_gym.runner.history import History
from creps_gym.runner.results.export import env_key
from creps_gym.runner.rundir import RunDir
from creps_gym.runner.rundir.checkpoint import FINGERPRINT_FIELDS

__all__ = ["SETTING_FIELDS", "group_runs", "load_runs", "setting"]

#: The configuration fields of a setting: the fingerprinted ones except the seed.
SETTING_FIELDS = tuple(name for name in FINGERPRINT_FIELDS if name != "seed")
_SHOWN_BY_NAME = ("optimizer_options", "env_kwargs")  # their keys are shown as ``key=value``


def load_runs(paths: Sequence[str | os.PathLike[str]]) -> list[tuple[RunConfig, History]]:
    """The configuration and history of each run directory (each read as untrusted input)."""
    runs = []
    for path in paths:
        directory = RunDir.open(path)
        runs.append((directory.config(), directory.read_history()))
    return runs


def setting(config: RunConfig) -> dict[str, Any]:
    """A run's setting, flat: ``{"samples": 16, "optimizer_options.epsilon": 0.8, ...}`` (no seed)."""
    data = config.to_dict()
    flat: dict[str, Any] = {}
    for name in SETTING_FIELDS:
        value = data[name]
        if name in _SHOWN_BY_NAME and isinstance(value, dict):
            flat.update({f"{name}.{key}": item for key, item in value.items()})
        else:
            flat[name] = value
    return flat


def _text(value: Any) -> str:
    if value is None:
        return "none"
    return value if isinstance(value, str) else json.dumps(value, sort_keys=True)


def _default_labels(settings: list[dict[str, Any]], histories: list[History]) -> list[str]:
    """Each group's optimiser and the settings that differ between the groups (see the module)."""
    keys = sorted({key for flat in settings for key in flat})
    differ = [key for key in keys if len({json.dumps(flat.get(key, None)) for flat in settings}) > 1]
    several_envs = len({env_key(history) for history in histories}) > 1
    labels = []
    for flat, history in zip(settings, histories, strict=True):
        parts = [str(flat["optimizer"])]
        for key in differ:
            if key in ("optimizer", "env"):
                continue
            name = key.split(".", 1)[1] if key.startswith(_SHOWN_BY_NAME) else key
            parts.append(f"{name}={_text(flat.get(key, 'default'))}")
        labels.append(", ".join(parts) + (f" on {env_key(history)}" if several_envs else ""))
    if len(set(labels)) < len(labels):  # settings that print alike (1 and "1"): numbered, never pooled
        labels = [f"{label} #{k}" for k, label in enumerate(labels, 1)]
    return labels


def group_runs(
    runs: Sequence[tuple[RunConfig, History]], labels: Sequence[str] | None = None
) -> tuple[dict[str, list[History]], list[str]]:
    """Group runs by setting (see the module) and label the groups.

    Parameters
    ----------
    runs : sequence of (RunConfig, History)
        E.g. from :func:`load_runs`.
    labels : sequence of str, optional
        One per run (runs with the same label form one group) or one per setting group (in the order of
        each group's first run). Default: :func:`_default_labels`.

    Returns
    -------
    groups : dict of str to list of History
        Label -> the runs of the group, in the groups' order.
    run_labels : list of str
        Each run's label, in the order of ``runs``.
    """
    keys = [json.dumps(setting(config), sort_keys=True) for config, _ in runs]
    order = list(dict.fromkeys(keys))
    if labels is None:
        firsts = [next(i for i, key in enumerate(keys) if key == group) for group in order]
        names = _default_labels([setting(runs[i][0]) for i in firsts], [runs[i][1] for i in firsts])
        run_labels = [names[order.index(key)] for key in keys]
    elif len(labels) == len(runs):
        run_labels = list(labels)
    elif len(labels) == len(order):
        run_labels = [labels[order.index(key)] for key in keys]
    else:
        raise ValueError(
            f"labels: expected one per run directory ({len(runs)}) or one per setting group ({len(order)}), "
            f"got {len(labels)}"
        )
    groups: dict[str, list[History]] = {}
    for label, (_, history) in zip(run_labels, runs, strict=True):
        groups.setdefault(label, []).append(history)
    return groups, run_labels
