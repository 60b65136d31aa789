"""One :class:`FunctionSpec` per function of the paper's Table 1: kernel, formula, reference, optimum, target.

The specs drive everything else: the environment classes, their manuals, the registered ids and the tests.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import partial

import numpy as np
from numpy.typing import NDArray

from creps_gym.envs.functions import definitions as d

__all__ = ["REGRET_TARGET", "SPECS", "UNBOUNDED_TARGET", "FunctionSpec"]

#: The paper's stopping target for the bounded functions: a regret f(x) - f_opt of at most 1e-5.
REGRET_TARGET = 1e-5
#: The paper's stopping target for the functions that are unbounded below: f(x) <= -1e4.
UNBOUNDED_TARGET = -1e4


@dataclass(frozen=True)
class FunctionSpec:
    """Everything that defines one test function.

    Attributes
    ----------
    name : str
        The id's name, as in ``creps_gym/<name>-v0``.
    title : str
        Human-readable name, as in the paper.
    kernel : callable
        Batched kernel ``(n, p) -> (n,)`` in its canonical coordinates (see :mod:`.definitions`).
    formula : str
        The formula in the variable the kernel sees (``x``, or ``z = x - o`` / ``z = R (x - o)``).
    reference : str
        Where the definition comes from.
    panel : str
        The paper's figure panel showing the function.
    canonical_optimum : {"zeros", "ones"} or None
        The kernel's minimiser ``x*`` in canonical coordinates; ``None`` for a function unbounded below.
    shifted : bool
        The kernel sees ``x - o`` with a seeded shift ``o``.
    rotated : bool
        The kernel sees ``R (x - o)`` with a seeded orthogonal ``R`` (implies ``shifted``).
    note : str
        Extra remarks for the manual.
    """

    name: str
    title: str
    kernel: Callable[[NDArray[np.float64]], NDArray[np.float64]]
    formula: str
    reference: str
    panel: str
    canonical_optimum: str | None = "zeros"
    shifted: bool = False
    rotated: bool = False
    note: str = ""

    @property
    def bounded(self) -> bool:
        """Whether the function has a minimum (``f_opt``, ``x*``)."""
        return self.canonical_optimum is not None

    @property
    def f_opt(self) -> float | None:
        """The minimum value (0 for every bounded function of the suite), or None if unbounded below."""
        return 0.0 if self.bounded else None

    @property
    def target(self) -> float:
        """The paper's stopping target as a value of f: ``f_opt + 1e-5``, or ``-1e4`` if unbounded below."""
        return REGRET_TARGET if self.bounded else UNBOUNDED_TARGET

    def canonical_point(self, dim: int) -> NDArray[np.float64] | None:
        """``x*`` of the kernel (shape (dim,)), or None for an unbounded function."""
        if self.canonical_optimum is None:
            return None
        return np.ones(dim) if self.canonical_optimum == "ones" else np.zeros(dim)


_HANSEN = "Hansen's test-function suite (cmaes.m / pycma ff)"
_CEC = "Suganthan et al., CEC 2005 benchmark"
_RIDGE_NOTE = (
    "The search must walk along -x_1 until f(x) <= -1e4. Hansen's version has -x_1, the mirror image in x_1."
)

SPECS: tuple[FunctionSpec, ...] = (
    FunctionSpec(
        "Rosenbrock",
        "Rosenbrock",
        d.rosenbrock,
        "f(x) = sum_{i=1}^{p-1} [100 (x_{i+1} - x_i^2)^2 + (1 - x_i)^2]",
        "Rosenbrock (1960); " + _HANSEN,
        "Fig. 1a",
        canonical_optimum="ones",
        note="For p >= 4 there is also a local minimum near x_1 = -1.",
    ),
    FunctionSpec("Sphere", "Sphere", d.sphere, "f(x) = sum_i x_i^2", "De Jong (1975); " + _HANSEN, "Fig. 1b"),
    FunctionSpec(
        "ShiftedSphere",
        "Shifted Sphere",
        d.sphere,
        "f(x) = sum_i z_i^2,  z = x - o",
        _CEC + ", F1 (without its bias)",
        "Fig. 1c",
        shifted=True,
    ),
    FunctionSpec(
        "ShiftedSchwefel",
        "Shifted Schwefel's problem 1.2",
        d.schwefel_1_2,
        "f(x) = sum_{i=1}^{p} (sum_{j=1}^{i} z_j)^2,  z = x - o",
        "Schwefel (1995), problem 1.2; " + _CEC + ", F2 (without its bias)",
        "Fig. 1d",
        shifted=True,
    ),
    FunctionSpec(
        "CigTab",
        "CigTab",
        d.cigtab,
        "f(x) = x_1^2 + 1e8 x_p^2 + 1e4 sum_{i=2}^{p-1} x_i^2",
        _HANSEN + ", fcigtab",
        "Fig. 1e",
    ),
    FunctionSpec(
        "Tablet",
        "Tablet",
        d.tablet,
        "f(x) = 1e6 x_1^2 + sum_{i=2}^{p} x_i^2",
        _HANSEN + ", ftablet",
        "Fig. 1f",
    ),
    FunctionSpec(
        "ShiftedRotatedElliptic",
        "Shifted Rotated High-Conditioned Elliptic (condition 1e6)",
        d.elliptic,
        "f(x) = sum_{i=1}^{p} (1e6)^((i-1)/(p-1)) z_i^2,  z = R (x - o)",
        _CEC + ", F3 (without its bias); " + _HANSEN + ", felli",
        "Fig. 1g",
        shifted=True,
        rotated=True,
    ),
    FunctionSpec(
        "ShiftedRotatedElliptic1e4",
        "Shifted Rotated High-Conditioned Elliptic, variant with condition 1e4",
        partial(d.elliptic, condition=1e4),
        "f(x) = sum_{i=1}^{p} (1e4)^((i-1)/(p-1)) z_i^2,  z = R (x - o)",
        _CEC + ", F3 with condition 1e4",
        "Fig. 1h",
        shifted=True,
        rotated=True,
    ),
    FunctionSpec(
        "DifferentPowers",
        "Different Powers",
        d.different_powers,
        "f(x) = sum_{i=1}^{p} |x_i|^(2 + 10 (i-1)/(p-1))",
        _HANSEN + ", fdiffpow",
        "Fig. 2a",
    ),
    FunctionSpec(
        "Plane",
        "Plane",
        d.plane,
        "f(x) = x_1",
        _HANSEN + ", fplane",
        "Fig. 2b",
        canonical_optimum=None,
        note="The search must walk along -x_1 until f(x) <= -1e4.",
    ),
    FunctionSpec(
        "TwoAxes",
        "Two Axes",
        d.two_axes,
        "f(x) = 1e6 sum_{i=1}^{floor(p/2)} x_i^2 + sum_{i=floor(p/2)+1}^{p} x_i^2",
        _HANSEN + ", ftwoaxes",
        "Fig. 2c",
        note="Hansen's ftwoaxes puts the weight 1e6 on the second half: the same function up to an axis "
        "permutation; this one follows docs/algorithms.md.",
    ),
    FunctionSpec(
        "Cigar", "Cigar", d.cigar, "f(x) = x_1^2 + 1e6 sum_{i=2}^{p} x_i^2", _HANSEN + ", fcigar", "Fig. 2d"
    ),
    FunctionSpec(
        "Rastrigin",
        "Rastrigin",
        d.rastrigin,
        "f(x) = 10 p + sum_{i=1}^{p} [x_i^2 - 10 cos(2 pi x_i)]",
        "Rastrigin (1974); " + _HANSEN,
        "Fig. 2e",
        note="Multimodal: a Gaussian search distribution with 50 samples per iteration is not expected to "
        "reach the global optimum (the paper's Fig. 2e does not reach the target either).",
    ),
    FunctionSpec(
        "ParabolicRidge",
        "Parabolic Ridge",
        d.parabolic_ridge,
        "f(x) = x_1 + 100 sum_{i=2}^{p} x_i^2",
        _HANSEN + ", fparabR",
        "Fig. 2f",
        canonical_optimum=None,
        note=_RIDGE_NOTE,
    ),
    FunctionSpec(
        "SharpRidge",
        "Sharp Ridge",
        d.sharp_ridge,
        "f(x) = x_1 + 100 sqrt(sum_{i=2}^{p} x_i^2)",
        _HANSEN + ", fsharpR",
        "Fig. 2g",
        canonical_optimum=None,
        note=_RIDGE_NOTE,
    ),
)
