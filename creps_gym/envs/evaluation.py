"""Policy evaluation on a fixed, seeded set of test contexts: the paper's error metric.

The paper's learning curves (Figs. 1-3) plot, per iteration, the error of the *mean* policy: the mean over a
set of contexts of the regret ``f(x) - f_opt`` of the parameters the mean policy gives for each context.
:func:`evaluate_policy` computes that for any env that knows its optimum (``SupportsRegret``), and the mean
return for any other :class:`~creps_gym.envs.base.ContextualEpisodicEnv` (the reacher, the kick, the
episodic wrappers). It uses only the env's public model methods (``sample_contexts``, ``evaluate``,
``regret``), so the same code serves every env, and it never touches the env's own random state or episode.

Functions
---------
test_contexts
    A fixed, seeded set of test contexts drawn from the env's own context distribution.
evaluate_policy
    Mean regret (where defined) and mean return of a policy on given contexts.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from gymnasium.vector import VectorEnv
from numpy.typing import NDArray

from creps_gym._validation import as_float_array, check_positive_int
from creps_gym.envs.base import ContextualEpisodicEnv, ContextualEpisodicVectorEnv, SupportsRegret

__all__ = [
    "MODEL_KINDS",
    "PolicyEvaluation",
    "contextual_model",
    "evaluate_policy",
    "finite_mean",
    "test_contexts",
]

Array = NDArray[np.float64]
Policy = Callable[[Array], Any]


def finite_mean(values: Any) -> float:
    """The mean of finite values, without overflow: finite whenever every value is.

    ``np.mean`` sums first, so values near the float limit (returns of -1.4e308) give -inf; then the
    mean is taken of the values scaled by their largest magnitude and scaled back (the plain mean is kept
    whenever it is finite, so ordinary results keep their bits). Non-finite values give a non-finite mean.
    """
    values = np.asarray(values, dtype=np.float64)
    with np.errstate(over="ignore", invalid="ignore"):
        mean = float(values.mean())
        if not np.isfinite(mean) and np.isfinite(values).all() and values.size:
            scale = float(np.abs(values).max())
            mean = float((values / scale).mean()) * scale
    return mean


@dataclass(frozen=True)
class PolicyEvaluation:
    """The result of :func:`evaluate_policy`.

    Attributes
    ----------
    contexts : ndarray, shape (n, z)
        The contexts evaluated.
    params : ndarray, shape (n, p)
        The parameters the policy gave for them.
    returns : ndarray, shape (n,)
        The episodic returns.
    regrets : ndarray, shape (n,), or None
        The regrets, when the env knows its optimum (``SupportsRegret``); else None.
    """

    contexts: Array
    params: Array
    returns: Array
    regrets: Array | None

    @property
    def mean_return(self) -> float:
        """Mean return over the contexts."""
        return finite_mean(self.returns)

    @property
    def mean_regret(self) -> float | None:
        """Mean regret over the contexts (the paper's error), or None if the env has no regret."""
        return None if self.regrets is None else finite_mean(self.regrets)

    @property
    def metric(self) -> str:
        """``"regret"`` (lower is better) where the env knows its optimum, else ``"return"``."""
        return "return" if self.regrets is None else "regret"

    @property
    def value(self) -> float:
        """The headline number: the mean regret where defined, else the mean return."""
        return self.mean_return if self.mean_regret is None else self.mean_regret


MODEL_KINDS = ("env", "vector")
_KIND_TEXT = {
    "env": "a creps_gym ContextualEpisodicEnv (possibly wrapped)",
    "vector": "a native creps_gym ContextualEpisodicVectorEnv (possibly wrapped)",
}


def contextual_model(
    env: Any, accept: tuple[str, ...] = MODEL_KINDS, *, user: str | None = None
) -> ContextualEpisodicEnv:
    """The :class:`ContextualEpisodicEnv` model behind ``env``: the one lookup every module uses.

    Parameters
    ----------
    env : gymnasium.Env or gymnasium.vector.VectorEnv
        A creps_gym env under any Gymnasium wrappers (``accept`` holds ``"env"``), or a native vector env
        under any vector wrappers, whose ``model`` is returned (``accept`` holds ``"vector"``).
    accept : tuple of {"env", "vector"}
        The kinds of env accepted.
    user : str, optional
        Who asks (e.g. a wrapper's name), named in the error.

    Raises
    ------
    TypeError
        ``env`` is not of an accepted kind; the message names the kinds and what was given.
    """
    if not accept or any(kind not in MODEL_KINDS for kind in accept):
        raise ValueError(f"accept: expected a non-empty tuple of {MODEL_KINDS}, got {accept!r}")
    base = getattr(env, "unwrapped", env)
    if "vector" in accept and isinstance(base, ContextualEpisodicVectorEnv):
        return base.model
    if "env" in accept and isinstance(base, ContextualEpisodicEnv):
        return base
    expected = " or ".join(_KIND_TEXT[kind] for kind in accept)
    hint = ""
    if accept == ("vector",) and isinstance(base, VectorEnv):
        hint = "; for Sync/AsyncVectorEnv wrap each sub-env with the scalar wrapper"
    who = f"{user} " if user else ""
    raise TypeError(f"env: {who}expected {expected}, got {type(base).__name__}{hint}")


def test_contexts(env: Any, n: int, seed: int) -> Array:
    """A fixed set of ``n`` test contexts, shape (n, z), drawn from the env's context distribution.

    The contexts come from ``env.sample_contexts`` with a fresh ``numpy.random.default_rng(seed)``: the same
    ``(env, n, seed)`` gives bit-identical contexts, and the env's own ``np_random`` is left untouched.

    Parameters
    ----------
    env : ContextualEpisodicEnv, possibly wrapped, or a native vector env
    n : int
        Number of contexts (>= 1).
    seed : int
        Seed (>= 0) of the test set; use a seed different from the training one.

    Returns
    -------
    ndarray, shape (n, z)
    """
    model = contextual_model(env)
    n = check_positive_int(n, "n")
    seed = check_positive_int(seed, "seed", minimum=0)
    contexts = model.sample_contexts(np.random.default_rng(seed), n)
    return as_float_array(contexts, "sample_contexts output", (n, model.context_dim))


test_contexts.__test__ = False  # type: ignore[attr-defined]  # not a pytest test despite its name


def _policy_params(policy: Policy | Any, contexts: Array, param_dim: int) -> Array:
    n = contexts.shape[0]
    if callable(policy):
        params = as_float_array(policy(contexts.copy()), "policy(contexts)")
        if params.shape != (n, param_dim):
            raise ValueError(f"policy(contexts): expected shape ({n}, {param_dim}), got {params.shape}")
        return params
    params = as_float_array(policy, "policy")
    if params.shape == (param_dim,):
        return np.broadcast_to(params, (n, param_dim)).copy()
    if params.shape != (n, param_dim):
        raise ValueError(
            f"policy: expected a callable, parameters of shape ({param_dim},) or ({n}, {param_dim}), "
            f"got shape {params.shape}"
        )
    return params


def evaluate_policy(env: Any, policy: Policy | Any, contexts: Any) -> PolicyEvaluation:
    """Evaluate a policy on fixed contexts: the paper's error metric where the env defines a regret.

    Parameters
    ----------
    env : ContextualEpisodicEnv, possibly wrapped, or a native vector env
        Only the model's public methods are used (``evaluate``, and ``regret`` for ``SupportsRegret`` envs);
        the env's episode and random state are untouched. Gymnasium wrappers around the model are bypassed:
        contexts and parameters are in the model's own spaces.
    policy : callable or array_like
        The (mean) policy: a callable mapping contexts (n, z) to parameters (n, p), e.g.
        ``optimizer.recommend``; or fixed parameters of shape (p,) (the same for every context) or (n, p).
    contexts : array_like, shape (n, z)
        The test contexts, e.g. from :func:`test_contexts`.

    Returns
    -------
    PolicyEvaluation
        ``.value`` is the mean regret (``.metric == "regret"``) where the env knows its optimum, else the
        mean return (``.metric == "return"``); the per-context arrays are kept.
    """
    model = contextual_model(env)
    contexts = model.check_contexts(contexts, "contexts")
    if contexts.shape[0] == 0:
        raise ValueError("contexts: expected at least one context, got shape " + str(contexts.shape))
    params = _policy_params(policy, contexts, model.param_dim)
    returns, _ = model.evaluate(contexts, params)
    returns = model.check_returns(returns, params, "policy")
    regrets = None
    if isinstance(model, SupportsRegret):
        regrets = as_float_array(model.regret(contexts, params), "env.regret output", (contexts.shape[0],))
    return PolicyEvaluation(contexts.copy(), params, returns, regrets)
