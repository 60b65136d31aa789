"""What ``creps-gym list`` prints: aligned tables of the envs and optimisers.

Each env row shows the context space, the parameter space and the initial search distribution the runner
starts from by default (:func:`initial_hint`: the env-declared initial distribution).

``creps-gym list`` and ``creps-gym --help`` must start fast, so they print a static table,
:mod:`creps_gym._table`, instead of importing numpy, Gymnasium and every env. That module is generated
from the live registry by ``python -m creps_gym.listing --write`` (:func:`live_table`), and
``python -m creps_gym.listing --check`` (run by ``tests/cli/test_cli_startup.py``) fails when they disagree.
"""

from __future__ import annotations

import importlib.util
import re
import sys
import warnings
from collections.abc import Iterable, Sequence
from typing import Any

__all__ = [
    "LIST_WIDTH",
    "OPTIONAL_MODULES",
    "available_env_rows",
    "box_text",
    "deprecated_ids",
    "env_listing",
    "env_rows",
    "initial_hint",
    "live_table",
    "optimizer_rows",
    "plain",
    "table",
]

_ROLE = re.compile(r":[a-z]+:`~?(?:[\w.]*\.)?([^`]+)`")  # :class:`~a.b.C` -> C
#: Optional modules an env may need, and the extra that installs them.
OPTIONAL_MODULES = {"mujoco": "mujoco", "gymnasium_robotics": "mujoco"}
ENV_HEADER = ["id", "context", "parameters θ", "initial (default)", "description"]
#: The width ``creps-gym list`` keeps to (a longer cell wraps).
LIST_WIDTH = 100
OPTIMIZER_HEADER = ["name", "description"]


def plain(text: str) -> str:
    """A docstring line without reST markup: ``x`` -> x, :class:`~a.b.C` -> C."""
    return _ROLE.sub(r"\1", text).replace("``", "").replace("`", "")


def _number(value: float, digits: int = 3) -> str:
    return f"{value:.{digits}g}"


def box_text(space: Any) -> str:
    """A Box exactly, per dimension: ``[low, high]^n`` when every dimension has the same bounds, else the
    product of each run of equal intervals, e.g. ``[0.15, 0.3]×[-0.15, 0.15]`` or ``[-5, 5]^12×[-5.99059,
    5]×[-5, 5]^2`` (bounds to 6 significant digits); other spaces as ``str``."""
    import numpy as np

    low = np.asarray(getattr(space, "low", np.nan), np.float64).ravel()
    high = np.asarray(getattr(space, "high", np.nan), np.float64).ravel()
    if low.size == 0 or np.isnan(low).any():
        return str(space)
    runs: list[list[Any]] = []  # [interval text, count]
    for lo, hi in zip(low, high, strict=True):
        interval = f"[{_number(lo, 6)}, {_number(hi, 6)}]"
        if runs and runs[-1][0] == interval:
            runs[-1][1] += 1
        else:
            runs.append([interval, 1])
    return "×".join(text if count == 1 else f"{text}^{count}" for text, count in runs)


def initial_hint(env: Any) -> str:
    """The runner's default initial search distribution for ``env`` (the env-declared one): N(mean, std²)."""
    import numpy as np

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

    rows = [list(ENV_HEADER)]
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
    return [list(OPTIMIZER_HEADER)] + [[name, plain(text)] for name, text in descriptions.items()]


def table(rows: Sequence[Sequence[str]], indent: str = "  ") -> str:
    """Rows as left-aligned columns (the last column is not padded)."""
    widths = [max(len(row[k]) for row in rows) for k in range(len(rows[0]) - 1)]
    lines = [
        "  ".join([*(cell.ljust(w) for cell, w in zip(row, widths, strict=False)), row[-1]]) for row in rows
    ]
    return "\n".join(indent + line.rstrip() for line in lines)


def table_wrapped(rows: Sequence[Sequence[str]], width: int = LIST_WIDTH, indent: str = "  ") -> str:
    """:func:`table` whose last column wraps at ``width``, continued under its own start."""
    import textwrap

    widths = [max(len(row[k]) for row in rows) for k in range(len(rows[0]) - 1)]
    start = len(indent) + sum(w + 2 for w in widths)
    lines = []
    for row in rows:
        head = indent + "".join(cell.ljust(w + 2) for cell, w in zip(row, widths, strict=False))
        wrapped = textwrap.wrap(row[-1], max(width - start, 20)) or [""]
        lines += [(head if k == 0 else " " * start) + text for k, text in enumerate(wrapped)]
    return "\n".join(line.rstrip() for line in lines)


def deprecated_ids(env_ids: Iterable[str]) -> dict[str, str]:
    """Each id with a newer version among ``env_ids`` (Gymnasium warns that it is out of date): its newest."""
    newest: dict[str, tuple[int, str]] = {}
    versions = {}
    for env_id in env_ids:
        match = re.fullmatch(r"(.+)-v(\d+)", env_id)
        if match is not None:
            versions[env_id] = (match.group(1), int(match.group(2)))
            name, version = versions[env_id]
            newest[name] = max(newest.get(name, (version, env_id)), (version, env_id))
    return {
        env_id: newest[name][1] for env_id, (name, version) in versions.items() if newest[name][0] > version
    }


def env_listing(rows: Sequence[Sequence[str]], width: int = LIST_WIDTH) -> str:
    """Table rows of :func:`available_env_rows` (header first) as one block per env, within ``width``.

    The first line has the id, the context space, the parameter space and the default initial distribution
    (each wrapped to a line of its own where they do not fit); the description follows, indented, after
    ``(deprecated: use NEWER)`` for an id with a newer version.
    """
    import textwrap

    deprecated = deprecated_ids(row[0] for row in rows[1:])
    lines = []
    for env_id, context, params, initial, description in rows[1:]:
        parts = [f"context {context}", f"θ {params}", f"initial {initial}"] if context != "?" else []
        line = "  " + env_id
        for part in parts:
            if len(line) + 2 + len(part) > width:
                lines.append(line)
                line = "      " + part
            else:
                line += "  " + part
        lines.append(line)
        if env_id in deprecated:
            description = f"(deprecated: use {deprecated[env_id]}) {description}"
        lines += textwrap.wrap(description, width, initial_indent=" " * 6, subsequent_indent=" " * 6)
    return "\n".join(lines)


# -- the static table of the fast commands --------------------------------------------------------------
def _needed_modules(env_ids: Sequence[str]) -> dict[str, list[str]]:
    """For each id, the :data:`OPTIONAL_MODULES` without which ``gymnasium.make`` fails.

    Each module is blocked in turn (``sys.modules[name] = None``) while every env is made, so this must
    run before any of them is imported (a fresh process: ``python -m creps_gym.listing``).
    """
    import gymnasium as gym

    loaded = sorted(set(OPTIONAL_MODULES) & set(sys.modules))
    if loaded:
        raise RuntimeError(
            f"expected a process that has not imported {loaded} (run python -m creps_gym.listing)"
        )
    needs: dict[str, list[str]] = {env_id: [] for env_id in env_ids}
    for module in OPTIONAL_MODULES:
        sys.modules[module] = None  # type: ignore[assignment]  # `import module` raises ImportError
        try:
            for env_id in env_ids:
                try:
                    with warnings.catch_warnings():
                        warnings.simplefilter("ignore")
                        gym.make(env_id).close()
                except Exception:  # any failure: the env cannot be made without the module
                    needs[env_id].append(module)
        finally:
            del sys.modules[module]
    return needs


def live_table() -> dict[str, Any]:
    """What :mod:`creps_gym._table` holds, computed from the registries and ``RunConfig``."""
    from dataclasses import MISSING, fields

    import creps_gym
    from creps_gym.envs.registration import all_registrations
    from creps_gym.optimizers.registry import describe_optimizers
    from creps_gym.runner.config import BACKENDS, VECTOR_MODES, RunConfig

    ids = creps_gym.registered_ids()
    needs = _needed_modules(ids)
    envs = [[*row, needs[row[0]]] for row in env_rows(ids)[1:]]
    return {
        "ENVS": envs,
        "OPTIMIZERS": optimizer_rows(describe_optimizers())[1:],
        "BACKENDS": list(BACKENDS),
        "VECTOR_MODES": list(VECTOR_MODES),
        "RUN_DEFAULTS": {f.name: f.default for f in fields(RunConfig) if f.default is not MISSING},
        "REGISTRATIONS": all_registrations(),
    }


def table_source(data: dict[str, Any]) -> str:
    """The Python source of :mod:`creps_gym._table` holding ``data``."""
    import pprint

    lines = [
        "# ruff: noqa: E501",
        '"""What `creps-gym list` and `--help` print, without importing numpy, Gymnasium or any env.',
        "",
        "Generated from the registries and RunConfig by `python -m creps_gym.listing --write`: do not edit.",
        "ENVS rows: id, context, parameters, initial distribution, description, optional modules it needs.",
        "REGISTRATIONS: the gymnasium.register keywords of every id (entry points are strings), which",
        "`import creps_gym` registers as soon as Gymnasium is imported, without importing any env module.",
        '"""',
        "",
        "__all__ = [" + ", ".join(f'"{name}"' for name in sorted(data)) + "]",
        "",
        "# fmt: off",
    ]
    for name, value in data.items():
        lines.append(f"{name} = {pprint.pformat(value, width=400, sort_dicts=False)}")
    return "\n".join(lines) + "\n# fmt: on\n"


def available_env_rows(envs: Sequence[Sequence[Any]]) -> list[list[str]]:
    """Table rows (with the header) of static env rows; envs whose optional modules are not installed
    are marked ``(not available: pip install creps-gym[extra])``."""
    rows = [list(ENV_HEADER)]
    for *cells, needs in envs:
        missing = [module for module in needs if importlib.util.find_spec(module) is None]
        if missing:
            extras = sorted({OPTIONAL_MODULES[module] for module in missing})
            cells = [cells[0], "?", "?", "?", f"(not available: pip install creps-gym[{','.join(extras)}])"]
        rows.append(list(cells))
    return rows


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m creps_gym.listing --write | --check``: regenerate or check :mod:`creps_gym._table`."""
    from pathlib import Path

    args = list(sys.argv[1:] if argv is None else argv)
    if args not in (["--write"], ["--check"]):
        print("usage: python -m creps_gym.listing --write | --check", file=sys.stderr)
        return 2
    path = Path(__file__).with_name("_table.py")
    source = table_source(live_table())
    if args == ["--write"]:
        path.write_text(source, encoding="utf-8")
        print(f"wrote {path}")
        return 0
    if path.read_text(encoding="utf-8") != source:
        print(f"{path} is out of date: run python -m creps_gym.listing --write", file=sys.stderr)
        return 1
    print(f"{path} agrees with the registries")
    return 0


if __name__ == "__main__":
    sys.exit(main())
