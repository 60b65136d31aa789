"""The surrogate's section of the C-CMA-ES target study (issue 33): ``c-cma-es-surrogate`` beside plain
``c-cma-es`` and pycma on one context, in the cells where issue 33 sets its targets.

Its runs are columns of the study like the others (:data:`SURROGATE_COLUMNS`), restricted to those cells, and
the table is computed from the cached runs only. A run's episodes are its true episodes: the runner counts the
episodes it evaluates, and the surrogate's model generations evaluate none.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

from benchmarks.ccmaes.columns import Column
from benchmarks.ccmaes.report import _batch_text, _episodes_text, median_episodes

__all__ = ["SURROGATE", "SURROGATE_CELLS", "SURROGATE_COLUMNS", "surrogate_table"]

SURROGATE = "c-cma-es-surrogate"
#: Issue 33's cells: (function, z, most surrogate / plain C-CMA-ES, most surrogate / pycma on one context).
SURROGATE_CELLS = (
    ("Sphere", 1, 0.7, 2.0),
    ("Sphere", 3, 0.7, None),
    ("Rosenbrock", 1, None, 2.0),
    ("ShiftedRotatedElliptic", 1, None, 2.0),
)
#: The surrogate at N = 50 and at the recommended N; a column is a product of functions and context
#: dimensions, so each batch size has two (the Sphere at z = 1 and 3, the others at z = 1), with one name.
SURROGATE_COLUMNS = tuple(
    Column(name, SURROGATE, batch, label, "tab:purple", functions=functions, context_dims=dims)
    for name, batch, label in (
        (SURROGATE, 50, "C-CMA-ES + surrogate, N = 50"),
        (f"{SURROGATE}-rec", "recommended", "C-CMA-ES + surrogate, recommended N"),
    )
    for functions, dims in ((("Sphere",), (1, 3)), (("Rosenbrock", "ShiftedRotatedElliptic"), (1,)))
)
#: (surrogate column, plain C-CMA-ES column) per batch size; pycma's column is ``cma-fixed``.
PAIRS = ((SURROGATE, "c-cma-es"), (f"{SURROGATE}-rec", "c-cma-es-rec"))

Cells = Mapping[tuple[str, int, str], Sequence[dict[str, Any]]]


def _ratio(numerator: float | None, denominator: float | None) -> float | None:
    if numerator is None or denominator is None or math.isinf(denominator) or denominator <= 0:
        return None
    return numerator / denominator


def _ratio_text(ratio: float | None, most: float | None) -> str:
    """``0.23 (≤ 0.7: met)``, ``0.9`` without a target, ``–`` without runs."""
    if ratio is None:
        return "–"
    text = "∞" if math.isinf(ratio) else f"{ratio:.2f}"
    if most is None:
        return text
    return f"{text} (≤ {most:g}: {'met' if ratio <= most else 'not met'})"


def surrogate_table(cells: Cells, budget: int) -> str:
    """One row per issue-33 cell and batch size: the surrogate's median true episodes, plain C-CMA-ES's at
    the same N, their ratio (target ≤ 0.7 on the Sphere), pycma's on one context at its default population
    and the surrogate's ratio to it (target ≤ 2 at z = 1). Medians count a missed seed as infinitely many."""
    lines = [
        "| function | z | N | C-CMA-ES + surrogate | C-CMA-ES | ratio (target) | pycma, 1 context, default N "
        "| ratio to pycma (target) |",
        "|---" * 8 + "|",
    ]
    for function, z, most_plain, most_pycma in SURROGATE_CELLS:
        pycma = cells.get((function, z, "cma-fixed"), [])
        for pair, (surrogate_name, plain_name) in enumerate(PAIRS):
            surrogate = cells.get((function, z, surrogate_name), [])
            plain = cells.get((function, z, plain_name), [])
            if not surrogate:
                continue
            ours = median_episodes(surrogate)
            batch = _batch_text(surrogate).removeprefix(", N = ") if pair else "50"
            texts = [
                batch,
                _episodes_text(surrogate, budget),
                _episodes_text(plain, budget),
                _ratio_text(_ratio(ours, median_episodes(plain)), most_plain),
                _episodes_text(pycma, budget),
                _ratio_text(_ratio(ours, median_episodes(pycma)), most_pycma),
            ]
            lines.append(f"| {function} | {z} | " + " | ".join(texts) + " |")
    return "\n".join(lines) + "\n"
