"""What contextual Bayesian optimisation recommends at a context: the three rules of ``recommend_over``.

References: as :mod:`creps_gym.optimizers.cbo`. Everything here works in the scaled units of
:class:`~creps_gym.optimizers.cbo.ContextualBO`: θ in the unit box of the parameter box, s scaled by the
context scaling. With N(s) the k = max(1, ``candidates`` // 4) episodes whose scaled contexts are nearest
to s (the first on ties) and G(s) the best ⌈q k⌉ of them by return (q = ``trust_share``):

* ``"trust_region"`` (the default): the posterior mean's maximiser within the box the good neighbours span,

      θ̂(s) = argmax_{θ ∈ B(s)} μ(s, θ),   B(s) = [min_{i ∈ G(s)} θ_i, max_{i ∈ G(s)} θ_i]           (R1)

  (componentwise; ``trust_share=None``: the whole box). Over the whole box the mean extrapolates: after a
  refit with a long lengthscale and an interpolating fit it keeps rising past the good episodes, above every
  told return and with a small σ (so μ − κσ does not help), and its maximiser runs to a face of the box far
  from the data (issue 44's study: regrets of 10⁴–10⁷ after 500 episodes where 300 gave 10⁻³).
* ``"observed"``: the told θ with the largest posterior mean at s, over every episode,

      θ̂(s) = argmax_{i ≤ N} μ(s, θ_i)                                                             (R2)

  (the first on ties). It never recommends a θ that no episode has tried, so it cannot combine the
  good episodes' coordinates into one the data has never seen: on the kick flexibility, where a fall ends
  the return at zero, R1's maximiser moves onto the fall cliff as the data grow
  (``benchmarks/low_budget/recommenders.py`` measures the rules on the same runs). The price: between the
  told θ it cannot interpolate, so on smooth tasks R1 ends closer to the optimum.
* ``"neighbours"``: the told θ of the episodes N(s) with the largest posterior mean at s,

      θ̂(s) = θ_{i*},   i* = argmax_{i ∈ N(s)} μ(s, θ_i)                                            (R3)

  (the first in N(s)'s order on ties: the nearest context, or the first told while N(s) holds every
  episode, as in R2). R2 may pick a θ told at a distant context, which the GP rates at s
  only by extrapolating across the context; R3 picks one that was tried near s. On the v2 flexibility kick
  at 500 episodes it beats R1 on 8 of 10 seeds
  (``benchmarks/low_budget/results/recommenders_v2_defaults.md``), and with the refits of c-bo's former
  default, under which R1's kicks fell more often as the data grew, it held 6.04 m where R1 fell back to
  5.25 m (``recommenders_v2.md``).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from creps_gym.optimizers.acquisitions import AcquisitionMaximiser
from creps_gym.optimizers.gp_model import GPModel
from creps_gym.optimizers.gp_trend import with_trend_maximiser

__all__ = [
    "RECOMMEND_RULES",
    "RECOMMEND_SEED",
    "distillation_contexts",
    "least_squares_distillation",
    "observed_maximiser",
    "told_choice",
    "trust_region",
    "trust_region_maximiser",
]

Array = NDArray[np.float64]
RECOMMEND_RULES = ("trust_region", "observed", "neighbours")
#: Seed of ``recommend``'s fixed candidates and of a random distillation design (neither may draw from the
#: optimiser's Generator).
RECOMMEND_SEED = 20_150_901


def distillation_contexts(
    z: int, box: tuple[Array, Array] | None, told: Array, points: int, limit: int
) -> Array:
    """The contexts ``mean_policy`` distils ``recommend`` on, shape (g, z): ``points`` per dimension of the
    context ``box`` (low (z,), high (z,)), else of the ``told`` contexts' (n, z) range; where that grid
    would exceed ``limit`` contexts, ``limit // 10`` uniform ones from a fixed seed. One context (zeros)
    when z = 0 (the policy is a constant) or when there is neither a box nor a told context."""
    if z == 0 or (box is None and not told.shape[0]):
        return np.zeros((1, z))
    low, high = box if box is not None else (told.min(axis=0), told.max(axis=0))
    if points**z > limit:  # many context dimensions: a fixed random design
        unit = np.random.default_rng(RECOMMEND_SEED).uniform(size=(limit // 10, z))
        return low + unit * (high - low)
    axes = [np.linspace(a, b, points) for a, b in zip(low, high, strict=True)]
    return np.stack([g.ravel() for g in np.meshgrid(*axes, indexing="ij")], axis=1).reshape(-1, z)


def least_squares_distillation(features: Array, targets: Array) -> tuple[Array, dict[str, float]]:
    """The coefficients (k, p) of the features (g, k) that fit the targets (g, p) in least squares, and the
    fit's error on them in the targets' units: ``distillation_rmse`` (root mean square over the grid and
    the parameters) and ``distillation_max_error``."""
    coefficients = np.linalg.lstsq(features, targets, rcond=None)[0]
    residual = features @ coefficients - targets
    error = {"distillation_rmse": float(np.sqrt(np.mean(residual**2)))}
    return coefficients, error | {"distillation_max_error": float(np.abs(residual).max())}


def trust_region(
    units: Array, returns: Array, nearest: Array, share: float | None
) -> tuple[Array, tuple[Array, Array]]:
    """G(s) and B(s) of Eq. (R1).

    Parameters
    ----------
    units : (k, p)        the θ of the nearest episodes N(s), in the unit box.
    returns : (N,)        every told return (``nearest`` indexes it).
    nearest : (k,)        the indices of N(s).
    share : float or None q; None: B(s) is the whole unit box.

    Returns
    -------
    good : (g, p)         the θ of G(s) (all of N(s) for ``share=None``), best return first.
    bounds : ((p,), (p,)) B(s)'s low and high corners.
    """
    p = units.shape[1]
    if share is None:
        return units, (np.zeros(p), np.ones(p))
    count = max(1, math.ceil(share * nearest.shape[0]))
    good = units[np.argsort(-returns[nearest], kind="stable")[:count]]
    return good, (good.min(axis=0), good.max(axis=0))


def trust_region_maximiser(
    model: GPModel,
    context: Array,
    good: Array,
    bounds: tuple[Array, Array],
    fixed: Array,
    maximiser: AcquisitionMaximiser,
) -> Array:
    """Eq. (R1) at one scaled context (z,): the posterior mean's maximiser in B(s), shape (p,).

    ``fixed`` (m, p) are unit-box candidates from a fixed seed, mapped into B(s) and scored with the good
    θ (and the trend's own maximiser within B(s)); L-BFGS-B starts from the best of them."""
    low, high = bounds
    candidates = np.vstack([low + fixed * (high - low), good])
    candidates = with_trend_maximiser(candidates, model.beta, context, bounds)
    return maximiser.maximise(model, context, candidates, None, bounds)[0]


def observed_maximiser(model: GPModel, context: Array, units: Array) -> int:
    """Eq. (R2) at one scaled context (z,): the index of the told θ (rows of ``units``, (N, p), in the unit
    box) with the largest posterior mean at it (the first on ties)."""
    mean = model.predict(AcquisitionMaximiser.inputs(context, units))[0]  # R2
    return int(np.argmax(mean))


def told_choice(model: GPModel, context: Array, told: Array, among: Array) -> int:
    """Eq. (R3) at one scaled context (z,), or Eq. (R2) with ``among`` every index: the index of the chosen
    episode among the told θ ``told`` (N, p, in the unit box); ``among`` (k,) indexes the episodes to choose
    from (N(s), the nearest context first), the first of them on ties."""
    return int(among[observed_maximiser(model, context, told[among])])  # R2 / R3
