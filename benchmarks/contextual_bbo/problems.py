"""The contextual benchmark of IJCAI 2017 / GECCO 2019: f_s(θ) = f(θ + G s), its six functions, a run's draw.

The protocol (Abdolmaleki et al., "Contextual Covariance Matrix Adaptation Evolutionary Strategies", IJCAI
2017, section 6.1; reused by A. Fabisch, GECCO 2019, arXiv:1810.11491): θ ∈ R^20, a context s ~ U[1, 2)^{n_s}
per episode, G ~ N(0, 1)^{20 × n_s} drawn once per run, the return −f_s(θ) = −f(θ + G s), an initial mean
~ N(0, I) (the same for every context) and covariance I, N = 50 episodes per generation, 20 runs.

The functions, implemented here from their definitions (the COCO/BBOB ones where the function is a BBOB
function, N. Hansen et al., "Real-parameter black-box optimization benchmarking 2009: noiseless functions
definitions", INRIA RR-6829). What differs from COCO, for every BBOB function below: no rotation R, no
oscillation T_osz, no random x_opt and f_opt: the optimum x* is the function's canonical one (0, or 1 for
Rosenbrock), moved per context by the protocol's shift, θ*(s) = x* − G s, and f_opt = 0.

- Sphere (BBOB f1): Σ x_i².
- Rosenbrock (the original, not BBOB f8's scaled, shifted form): Σ_{i<p} 100 (x_{i+1} − x_i²)² + (1 − x_i)².
- Ellipsoidal (BBOB f2 without T_osz): Σ 10^{6 (i−1)/(p−1)} x_i².
- Discus (BBOB f11 without rotation and T_osz): 10^6 x_1² + Σ_{i≥2} x_i².
- Different Powers (BBOB f14 without rotation): √(Σ |x_i|^{2 + 4 (i−1)/(p−1)}).
- Ackley (not a BBOB function; Ackley 1987 in its usual form with a = 20, b = 0.2, c = 2π):
  −20 exp(−0.2 √(mean x_i²)) − exp(mean cos 2π x_i) + 20 + e. The protocol's bounds ±32.5 apply to θ: θ is
  clipped to [−32.5, 32.5]^p before it is evaluated (our reading; the optimiser is not told).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from creps_gym.envs.functions.definitions import elliptic, rosenbrock, sphere

__all__ = ["PROBLEMS", "Problem", "RunDraw", "ackley", "different_powers_bbob", "discus", "draw_run"]

Array = NDArray[np.float64]
#: p of the protocol.
N_PARAMS = 20
#: Episodes per generation of the protocol.
GENERATION = 50


def discus(x: Array) -> Array:
    """Discus: ``10^6 x_1² + Σ_{i≥2} x_i²`` (BBOB f11 without rotation and T_osz); x* = 0, f* = 0."""
    return 1e6 * np.square(x[:, 0]) + np.square(x[:, 1:]).sum(axis=1)


def different_powers_bbob(x: Array) -> Array:
    """Different powers as BBOB f14 without rotation: ``√(Σ |x_i|^{2 + 4 (i−1)/(p−1)})``; x* = 0, f* = 0.

    Not the project's ``different_powers`` (Hansen's ``fdiffpow``: exponents 2 to 12, no square root)."""
    p = x.shape[1]
    exponents = 2.0 + 4.0 * np.arange(p) / (p - 1)
    return np.sqrt(np.power(np.abs(x), exponents).sum(axis=1))


def ackley(x: Array) -> Array:
    """Ackley: ``−20 exp(−0.2 √(mean x_i²)) − exp(mean cos 2π x_i) + 20 + e``; x* = 0, f* = 0 (up to
    round-off: about 4e-16 at 0)."""
    root = np.sqrt(np.square(x).mean(axis=1))
    waves = np.cos(2.0 * math.pi * x).mean(axis=1)
    return -20.0 * np.exp(-0.2 * root) - np.exp(waves) + 20.0 + math.e


@dataclass(frozen=True)
class Problem:
    """One function of the protocol: its kernel, context dimension, generations and start."""

    name: str
    context_dim: int
    generations: int
    sigma0: float = 1.0
    bound: float | None = None  # θ is clipped to [−bound, bound]^p before evaluation
    optimum: float = 0.0  # x* = optimum · 1

    def kernel(self, x: Array) -> Array:
        """f(x) for points x (n, p)."""
        return KERNELS[self.name](x)

    @property
    def episodes(self) -> int:
        """The protocol's budget: generations × N."""
        return self.generations * GENERATION


KERNELS = {
    "Sphere": sphere,
    "Rosenbrock": rosenbrock,
    "Ellipsoidal": elliptic,
    "Discus": discus,
    "DifferentPowers": different_powers_bbob,
    "Ackley": ackley,
}

#: The six problems with the protocol's context dimensions, generations and starts.
PROBLEMS = {
    problem.name: problem
    for problem in (
        Problem("Sphere", 2, 200),
        Problem("Rosenbrock", 1, 850, optimum=1.0),
        Problem("Ellipsoidal", 1, 800),
        Problem("Discus", 1, 850),
        Problem("DifferentPowers", 1, 600),
        Problem("Ackley", 1, 1100, sigma0=14.5, bound=32.5),
    )
}


@dataclass(frozen=True)
class RunDraw:
    """Everything a run of the protocol draws from its seed: G, the initial mean, the test contexts and the
    streams of the training contexts and of the optimiser."""

    problem: Problem
    shift: Array  # G, shape (p, n_s)
    initial_mean: Array  # (p,)
    test_contexts: Array  # (n_test, n_s)
    context_rng: np.random.Generator
    optimizer_seed: int

    def evaluate(self, contexts: Array, params: Array) -> Array:
        """f_s(θ) = f(clip(θ) + G s) for rows of contexts (n, n_s) and params (n, p)."""
        if self.problem.bound is not None:
            params = np.clip(params, -self.problem.bound, self.problem.bound)
        return self.problem.kernel(params + contexts @ self.shift.T)

    def regret(self, contexts: Array, params: Array) -> Array:
        """f_s(θ) − f_s(θ*(s)) = f_s(θ), since f* = 0 at θ*(s) = x* − G s."""
        return self.evaluate(contexts, params)

    def contexts(self, n: int) -> Array:
        """n training contexts from U[1, 2)^{n_s}."""
        return 1.0 + self.context_rng.random((n, self.problem.context_dim))


def draw_run(problem: Problem, seed: int, n_test: int = 100) -> RunDraw:
    """The run ``seed`` of ``problem``: independent children of ``SeedSequence(seed)`` for G, the initial
    mean, the test contexts, the training contexts and the optimiser's seed."""
    streams = [np.random.default_rng(child) for child in np.random.SeedSequence(seed).spawn(5)]
    return RunDraw(
        problem=problem,
        shift=streams[0].standard_normal((N_PARAMS, problem.context_dim)),
        initial_mean=streams[1].standard_normal(N_PARAMS),
        test_contexts=1.0 + streams[2].random((n_test, problem.context_dim)),
        context_rng=streams[3],
        optimizer_seed=int(streams[4].integers(2**31)),
    )
