"""What one more episode at a context would teach a GP about the optimal parameters everywhere (c-bo's
``context_utility``).

After J. H. Metzen, "Active Contextual Entropy Search" (2015), which extends BO-CPS (Metzen, Fabisch &
Hansen 2015): the context of the next trial is the one whose query most reduces the entropy of the
optimal parameters' distribution p(θ*(s)) summed over the whole context space. ACES estimates that
entropy reduction with one entropy search per representative context (a k-means summary of uniform
contexts in Metzen's implementation); here it is approximated in closed form, without sampling, by the
variance the query removes from the values of the *plausible maximisers*:

1. **Representers.** At each target context s_i (the selector draws them over the context box), the
   ``b`` parameter vectors of a shared candidate set with the largest upper confidence bound
   μ + √β σ: those that may still be the optimum θ*(s_i) (``plausible_maximisers``).
2. **Queries.** At a candidate context s_q, the ``b`` plausible maximisers there: the points the
   optimiser's own acquisition will choose among.
3. **Gain.** Observing y = f(x_q) + noise removes from the latent variance at a representer x_r the
   amount c(x_r, x_q)² / (σ²(x_q) + σ_n²), c the posterior covariance (Rasmussen & Williams 2006, Eq. 2.24
   with one more training point). The utility of s_q is the largest, over its queries, mean over the
   representers of that reduction, divided by σ_f² (a share of the prior variance, in [0, 1]):

       u(s_q) = max_{x_q} (1 / (σ_f² R)) Σ_r c(x_r, x_q)² / (σ²(x_q) + σ_n²).                  (C1)

A context far from the data has large posterior covariances with the plausible maximisers of its
neighbourhood and scores high; a context whose optimum is already pinned down scores low, however far
the optimum is from the others. Contexts already chosen for the same batch (``pending``) are added to the
model first at their best query with the posterior mean as the fantasised return (the kriging believer:
the covariances, all that (C1) uses, do not depend on the value), so a batch spreads out; the
representers and queries stay those of the model without them, so a pending episode can only lower the
variance (C1) counts, never swap in other points.

The variance of the maximisers' values stands in for the entropy of their location (the spread of the
plausible maximisers' values is what keeps p(θ*) wide); it is cheap (one triangular solve for all
candidates) and deterministic given the model and the candidate parameters.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray
from scipy import linalg

from creps_gym.optimizers.gp_model import GPModel, matern52

__all__ = ["context_information", "plausible_maximisers", "posterior_covariance", "utility_thetas"]

Array = NDArray[np.float64]
#: The parameter candidates of :func:`utility_thetas`: this many from a fixed seed (never the optimiser's
#: Generator), plus the θ of the best ``BEST_TOLD`` episodes told.
FIXED_THETAS, BEST_TOLD, THETA_SEED = 64, 16, 20_151_207
#: Largest (inputs x training points) block :func:`plausible_maximisers` predicts at once: many contexts
#: are scored in blocks, so the memory stays bounded whatever the selector asks.
BLOCK = 2**22


def utility_thetas(told: Array, returns: Array) -> Array:
    """The scaled θ among which plausible maximisers are chosen: :data:`FIXED_THETAS` uniform in the unit
    box from a fixed seed, then the told θ (n, q; scaled, clipped to the box) of the :data:`BEST_TOLD`
    best ``returns`` (n,) (ties: the earlier first): shape (≤ 80, q)."""
    fixed = np.random.default_rng(THETA_SEED).uniform(size=(FIXED_THETAS, told.shape[1]))
    return np.vstack([fixed, told[np.argsort(-returns, kind="stable")[:BEST_TOLD]]])


def _pairs(contexts: Array, thetas: Array) -> Array:
    """Every (context, θ) pair as model inputs: shape (r·M, c + q), context-major."""
    r, m = contexts.shape[0], thetas.shape[0]
    return np.hstack([np.repeat(contexts, m, axis=0), np.tile(thetas, (r, 1))])


def plausible_maximisers(model: GPModel, contexts: Array, thetas: Array, count: int, beta: float) -> Array:
    """The ``count`` inputs of largest μ + √β σ among ``thetas`` (M, q) at each scaled context (r, c).

    Returns
    -------
    ndarray, shape (r, count, c + q)
        Per context, its pairs in order of decreasing bound (ties: the earlier θ first).
    """
    r, m = contexts.shape[0], thetas.shape[0]
    rows = max(1, BLOCK // (m * max(1, model.inputs.shape[0])))  # contexts per block
    chosen = []
    for start in range(0, r, rows):
        block = contexts[start : start + rows]
        inputs = _pairs(block, thetas)
        mean, variance = model.predict(inputs)
        bound = (mean + math.sqrt(beta) * np.sqrt(variance)).reshape(block.shape[0], m)
        order = np.argsort(-bound, axis=1, kind="stable")[:, : min(count, m)]
        chosen.append(inputs.reshape(block.shape[0], m, -1)[np.arange(block.shape[0])[:, None], order])
    return np.concatenate(chosen)


def posterior_covariance(model: GPModel, a: Array, b: Array) -> Array:
    """The latent posterior covariance c(a_i, b_j) = k(a_i, b_j) − k(a_i, X) K⁻¹ k(X, b_j), (n_a, n_b)."""
    ls, signal = model.lengthscales, model.signal
    va = linalg.solve_triangular(
        model.chol, matern52(model.inputs, a, ls, signal), lower=True, check_finite=False
    )
    vb = linalg.solve_triangular(
        model.chol, matern52(model.inputs, b, ls, signal), lower=True, check_finite=False
    )
    return matern52(a, b, ls, signal) - va.T @ vb


def _gains(model: GPModel, queries: Array, representers: Array) -> Array:
    """(C1) before the maximum: the share of prior variance each query (m, d) removes, shape (m,)."""
    covariance = posterior_covariance(model, queries, representers)
    variance = model.latent_variance(queries)  # the units of the covariance (a trend's scale cancels)
    removed = np.einsum("mr,mr->m", covariance, covariance) / (variance + model.noise)
    return removed / (model.signal * representers.shape[0])


def context_information(
    model: GPModel,
    candidates: Array,
    targets: Array,
    thetas: Array,
    pending: Array | None = None,
    count: int = 8,
    beta: float = 4.0,
) -> Array:
    """Eq. (C1) at every candidate context: the utility of one more episode there, shape (m,).

    Parameters
    ----------
    model : GPModel
        The GP over scaled inputs (context, θ).
    candidates : ndarray, shape (m, c)
        Scaled candidate contexts.
    targets : ndarray, shape (r, c)
        Scaled contexts whose optimal parameters should be learnt (representative of the context box).
    thetas : ndarray, shape (M, q)
        Scaled parameter vectors among which the plausible maximisers are chosen.
    pending : ndarray, shape (k, c), optional
        Scaled contexts already chosen for this batch: added first, each at its best query.
    count : int
        b, plausible maximisers per context (representers and queries).
    beta : float
        β of the upper confidence bound that ranks them.
    """
    representers = plausible_maximisers(model, targets, thetas, count, beta)
    representers = representers.reshape(-1, representers.shape[2])
    conditioned = model
    for context in [] if pending is None else pending:
        options = plausible_maximisers(model, context[None, :], thetas, count, beta)[0]
        best = options[int(np.argmax(_gains(conditioned, options, representers)))]
        conditioned = conditioned.condition(best, float(conditioned.predict(best[None, :])[0][0]))
    queries = plausible_maximisers(model, candidates, thetas, count, beta)
    m, b, d = queries.shape
    return _gains(conditioned, queries.reshape(m * b, d), representers).reshape(m, b).max(axis=1)
