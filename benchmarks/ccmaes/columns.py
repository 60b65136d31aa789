"""The columns of the C-CMA-ES target study: a *column* is a method at a batch size, with its options and the
cells it runs in; the tables of :mod:`benchmarks.ccmaes.report` and the runs of :mod:`benchmarks.ccmaes.run`
are made of them."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

__all__ = [
    "BATCH_SWEEP",
    "BOUND_CELLS",
    "BOUND_COLUMNS",
    "BOUND_ROWS",
    "COLUMNS",
    "HEADLINE",
    "REMEDIES",
    "REMEDY_FUNCTION",
    "SIGNAL_COLUMNS",
    "SIGNAL_PAIRS",
    "SWEEP_FUNCTION",
    "YARDSTICK",
    "Column",
]


@dataclass(frozen=True)
class Column:
    """A method at a batch size: ``batch`` is N, ``"recommended"`` (the optimiser's
    ``recommended_batch_size(p, z)``) or ``"default"`` (pycma's own population, 4 + floor(3 ln p));
    ``options`` are further options of the optimiser (see :attr:`benchmarks.study_tools.RunSpec.options`).
    ``functions`` and ``context_dims`` restrict the column to those cells (empty: every cell); a restricted
    column runs with the headline seeds. ``dim_factor`` multiplies p (the recommended N stays p's)."""

    name: str
    method: str
    batch: int | str
    label: str
    colour: str
    options: tuple[tuple[str, Any], ...] = ()
    functions: tuple[str, ...] = ()
    context_dims: tuple[int, ...] = ()
    dim_factor: int = 1


COLUMNS = (
    Column("creps-cma-old", "creps-cma-old", 50, "CREPS-CMA-old, N = 50", "tab:blue"),
    Column("c-cma-es", "c-cma-es", 50, "C-CMA-ES, N = 50", "tab:red"),
    Column("c-cma-es-rec", "c-cma-es", "recommended", "C-CMA-ES, recommended N", "tab:orange"),
    Column("creps-cma-csa", "creps-cma-csa", 50, "CREPS-CMA-CSA, N = 50", "tab:green"),
    Column("cma-fixed-batch", "cma-fixed-batch", 50, "pycma, 1 context, N = 50", "0.55"),
    Column("cma-fixed", "cma-fixed", "default", "pycma, 1 context, default N", "0.25"),
)
#: The function of the remedies table.
REMEDY_FUNCTION = "Rosenbrock"


def _remedy(name: str, label: str, options: tuple[tuple[str, Any], ...]) -> Column:
    return Column(name, "c-cma-es", 50, label, "0.4", options, functions=(REMEDY_FUNCTION,))


#: Issue 12's remedies for Rosenbrock at z = 3, as variants of C-CMA-ES at N = 50: the columns of the
#: remedies table, in its order (``c-cma-es``, the default, has both remedies: its runs are the COLUMNS').
REMEDIES = (
    _remedy("c-cma-es-bare", "neither", (("baseline_batches", 1), ("restarts", 0))),
    _remedy("c-cma-es-reuse", "sample reuse only", (("restarts", 0),)),
    _remedy("c-cma-es-restarts", "restarts only", (("baseline_batches", 1),)),
    Column("c-cma-es", "c-cma-es", 50, "both (the default)", "tab:red"),
    _remedy("c-cma-es-std", "default, standardised advantages", (("standardise_advantages", True),)),
    _remedy("c-cma-es-passive", "default, active = False", (("active", False),)),
    _remedy("c-cma-es-cubic", "default, cubic baseline", (("baseline_degree", 3),)),
)
SWEEP_FUNCTION = "Sphere"
#: C-CMA-ES at fixed batch sizes around its recommended one (24 at p = 15, z = 1), on :data:`SWEEP_FUNCTION`
#: at z = 1 with the headline seeds: whether any N meets the recommended-N target there.
BATCH_SWEEP = tuple(
    Column(f"c-cma-es-n{n}", "c-cma-es", n, f"N = {n}", "0.4", functions=(SWEEP_FUNCTION,), context_dims=(1,))
    for n in (12, 16, 20, 24, 32, 40)
)
#: C-CMA-ES with the coefficients' step-size signal (C4') instead of the default (C4), at N = 50 and at the
#: recommended N, in every cell with the headline seeds; the default's runs are those of :data:`COLUMNS`.
COEFFICIENTS = (("step_size_signal", "coefficients"),)
SIGNAL_COLUMNS = (
    Column("c-cma-es-coef", "c-cma-es", 50, "coefficients, N = 50", "0.4", COEFFICIENTS),
    Column(
        "c-cma-es-rec-coef", "c-cma-es", "recommended", "coefficients, recommended N", "0.4", COEFFICIENTS
    ),
)
#: (default column, coefficients column) of :func:`signal_table`, per batch size.
SIGNAL_PAIRS = (("c-cma-es", "c-cma-es-coef"), ("c-cma-es-rec", "c-cma-es-rec-coef"))
#: The two cells whose targets pull C-CMA-ES's step-size control apart: the Sphere at z = 1 at the
#: recommended N (the bound of twice pycma's episodes) and Rosenbrock at z = 3 at N = 50 (≥ 95 % of the
#: seeds). Each row is a variant with its column in each cell; columns that other tables run reuse their runs.
BOUND_CELLS = (("Sphere", 1, "recommended"), ("Rosenbrock", 3, 50))
NO_REUSE = (("baseline_batches", 1),)
FAST_DAMPING = (("d_sigma", 0.8),)
BOUND_ROWS = (
    ("default", (), ("c-cma-es-rec", "c-cma-es")),
    ("no sample reuse", NO_REUSE, ("c-cma-es-rec-bb1", "c-cma-es-restarts")),
    ("coefficients", COEFFICIENTS, ("c-cma-es-rec-coef", "c-cma-es-coef")),
    ("coefficients, no reuse", NO_REUSE + COEFFICIENTS, ("c-cma-es-rec-coef-bb1", "c-cma-es-coef-bb1")),
    ("d_σ = 0.8", FAST_DAMPING, ("c-cma-es-rec-d08", "c-cma-es-d08")),
    (
        "coefficients, no reuse, d_σ = 0.8",
        NO_REUSE + FAST_DAMPING + COEFFICIENTS,
        ("c-cma-es-rec-coef-bb1-d08", "c-cma-es-coef-bb1-d08"),
    ),
)
#: pycma on one context of a Sphere with 2p parameters, as many as C-CMA-ES's affine mean has coefficients
#: at z = 1, at its default population and at C-CMA-ES's recommended N: what learning 2p numbers costs CMA-ES.
YARDSTICK = tuple(
    Column(name, method, batch, label, "0.5", functions=("Sphere",), context_dims=(1,), dim_factor=2)
    for name, method, batch, label in (
        ("cma-fixed-2p", "cma-fixed", "default", "pycma, 2p, default N"),
        ("cma-fixed-batch-2p", "cma-fixed-batch", "recommended", "pycma, 2p, recommended N"),
    )
)


def _bound_columns() -> tuple[Column, ...]:
    """The columns of :data:`BOUND_ROWS` that no other table runs, each restricted to its cell."""
    elsewhere = {c.name for c in COLUMNS + REMEDIES + SIGNAL_COLUMNS}
    columns = []
    for label, options, names in BOUND_ROWS:
        for (function, z, batch), name in zip(BOUND_CELLS, names, strict=True):
            if name not in elsewhere:
                columns.append(Column(name, "c-cma-es", batch, label, "0.4", options, (function,), (z,)))
    return tuple(columns)


BOUND_COLUMNS = _bound_columns()
#: The columns of the headline table (run with the headline seeds).
HEADLINE = ("creps-cma-old", "c-cma-es", "c-cma-es-rec", "cma-fixed")
