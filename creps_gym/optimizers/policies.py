"""The linear-Gaussian search distribution shared by every creps_gym optimiser.

π(θ|s) = N(Aᵀϕ(s), σ²C): a mean linear in the context features ϕ(s) (affine ``[1, s]`` by default, see
:mod:`creps_gym.optimizers.features`), a covariance matrix C with its lower Cholesky factor, and a global step
size σ. CREPS and CREPS-CMA keep σ = 1, so C is their Σ; contextual CMA-ES adapts σ and C separately.

The module holds the pure maths the update rules share about the distribution: the SPD repair of a
covariance (:func:`spd_factor`) and the validation of an initial or restored distribution; the weighted
ridge fit of the mean coefficients lives in :mod:`creps_gym.optimizers.mean_fit` (re-exported here).
:class:`LinearGaussianPolicy` is the thin state holder: sampling, the mean, and a state dict that is checked
on restore like a constructor argument.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import fields
from typing import Any

import numpy as np
from numpy.typing import NDArray

from creps_gym._validation import as_float_array, check_positive_int, check_real
from creps_gym.optimizers.base import overflowing_contexts
from creps_gym.optimizers.cma_rules import record_mean_return, stagnated, stagnation_window
from creps_gym.optimizers.features import FeatureMap
from creps_gym.optimizers.mean_fit import weighted_ml_fit
from creps_gym.optimizers.policy_file import Policy

__all__ = [
    "LinearGaussianPolicy",
    "PolicyAccess",
    "check_option_names",
    "check_usable_covariance",
    "initial_coefficients",
    "initial_covariance",
    "spd_factor",
    "split_step_size",
    "weighted_ml_fit",
]

Array = NDArray[np.float64]


def check_option_names(config_class: type, options: Mapping[str, Any]) -> None:
    """Raise ``TypeError`` naming the valid options when ``options`` has a name that is not an init field of
    the dataclass ``config_class`` (other than ``n_params`` and ``n_context_dims``)."""
    valid = {f.name for f in fields(config_class) if f.init} - {"n_params", "n_context_dims"}
    unknown = set(options) - valid
    if unknown:
        raise TypeError(f"options: expected names in {sorted(valid)}, got unknown {sorted(unknown)}")


def spd_factor(cov: Array, floor: float = 1e-12) -> tuple[Array, Array, bool]:
    """Symmetrise ``cov`` and return (Σ, lower Cholesky factor, repaired).

    If the Cholesky factorisation fails (Σ lost positive-definiteness to round-off, or a sample covariance
    from fewer samples than dimensions is singular), eigenvalues are clipped to ``floor · max eigenvalue``
    (and to at least 1e-300) and Σ is rebuilt; ``repaired`` is then True.
    """
    cov = 0.5 * (cov + cov.T)
    try:
        return cov, np.linalg.cholesky(cov), False
    except np.linalg.LinAlgError:
        values, vectors = np.linalg.eigh(cov)
        values = np.maximum(values, max(floor * values.max(), 1e-300))
        cov = (vectors * values) @ vectors.T
        cov = 0.5 * (cov + cov.T)
        return cov, np.linalg.cholesky(cov), True


def initial_coefficients(
    value: Any, features: FeatureMap, n_params: int, name: str = "initial_mean"
) -> Array:
    """Coefficients A (k, p) from a scalar, a constant mean (p,) or full coefficients (k, p)."""
    array = as_float_array(value, name)
    if array.ndim == 0:
        return features.constant_coefficients(np.full(n_params, float(array)))
    if array.shape == (n_params,):
        return features.constant_coefficients(array)
    if array.shape == (features.n_features, n_params):
        return array.copy()
    raise ValueError(
        f"{name}: expected a scalar, shape ({n_params},) or ({features.n_features}, {n_params}), "
        f"got shape {array.shape}"
    )


def initial_covariance(value: Any, n_params: int, name: str = "initial_cov") -> Array:
    """An SPD matrix (p, p) from a variance, variances (p,) or a matrix; raises on anything else."""
    array = as_float_array(value, name)
    if array.ndim == 0:
        array = np.full(n_params, float(array))
    if array.shape == (n_params,):
        if (array <= 0).any():
            raise ValueError(f"{name}: expected variances > 0, got min {array.min()}")
        array = np.diag(array)
        check_usable_covariance(array, name)
        return array
    if array.shape != (n_params, n_params):
        raise ValueError(
            f"{name}: expected a scalar, shape ({n_params},) or ({n_params}, {n_params}), got {array.shape}"
        )
    if not np.allclose(array, array.T, rtol=1e-10, atol=0.0):
        raise ValueError(f"{name}: expected a symmetric matrix, got an asymmetric one")
    try:
        np.linalg.cholesky(array)
    except np.linalg.LinAlgError:
        raise ValueError(
            f"{name}: expected a symmetric positive-definite matrix, got one that is not"
        ) from None
    check_usable_covariance(array, name)
    return array.copy()


def check_usable_covariance(cov: Array, name: str, step_size: float = 1.0) -> None:
    """``ValueError`` naming ``name`` unless the SPD ``cov`` can be sampled and updated without overflow.

    Its doubled entries (the symmetrisation Σ + Σᵀ) and its eigenvalues times ``step_size²`` must be finite:
    a covariance of 1e308 passes Cholesky but makes every sample non-finite.
    """
    with np.errstate(over="ignore", invalid="ignore"):
        largest = float(np.abs(cov).max()) if cov.size else 0.0
        eigenvalues = np.linalg.eigvalsh(cov) if np.isfinite(2.0 * largest) else np.full(1, np.inf)
        scaled = float(step_size) ** 2 * eigenvalues
    if not np.isfinite(scaled).all():
        raise ValueError(
            f"{name}: expected a covariance whose doubled entries and eigenvalues (times the step size²) are "
            f"finite, got entries up to {largest:.4g} (step size {step_size:.4g})"
        )


def split_step_size(cov: Array) -> tuple[float, Array]:
    """σ0 = det(Σ0)^(1/2p) and C0 = Σ0/σ0², so that det C0 = 1."""
    _, logdet = np.linalg.slogdet(cov)
    sigma = float(np.exp(logdet / (2 * cov.shape[0])))
    return sigma, cov / sigma**2


class LinearGaussianPolicy:
    """π(θ|s) = N(Aᵀϕ(s), σ²C), the search distribution of every creps_gym optimiser.

    Parameters
    ----------
    mean_map : FeatureMap
        ϕ(s), k features.
    coefficients : ndarray, shape (k, p)
        A.
    cov : ndarray, shape (p, p)
        C, symmetric positive definite.
    step_size : float
        σ > 0 (1 for CREPS and CREPS-CMA, whose Σ is C).
    """

    def __init__(self, mean_map: FeatureMap, coefficients: Array, cov: Array, step_size: float = 1.0) -> None:
        self.mean_map = mean_map
        self.coefficients = coefficients
        self.cov, self.chol, _ = spd_factor(cov)
        self.step_size = float(step_size)

    @property
    def n_params(self) -> int:
        """p, the dimension of θ."""
        return int(self.coefficients.shape[1])

    @property
    def covariance(self) -> Array:
        """The full covariance σ²C, shape (p, p)."""
        return self.step_size**2 * self.cov

    def mean(self, contexts: Array) -> Array:
        """Policy mean Aᵀϕ(s) for contexts (n, z): shape (n, p)."""
        return self.mean_map(contexts) @ self.coefficients

    def sample(self, contexts: Array, rng: np.random.Generator) -> Array:
        """θ ~ N(Aᵀϕ(s), σ²C) for each context row: shape (n, p)."""
        noise = rng.standard_normal((contexts.shape[0], self.n_params))
        return self.mean(contexts) + (noise @ self.chol.T) * self.step_size

    def set_cov(self, cov: Array) -> bool:
        """Replace C by the SPD repair of ``cov``; returns whether a repair was needed."""
        self.cov, self.chol, repaired = spd_factor(cov)
        return repaired

    def copy(self) -> LinearGaussianPolicy:
        """An independent copy (a ``tell`` updates a copy and commits it only when everything is finite)."""
        twin = LinearGaussianPolicy.__new__(LinearGaussianPolicy)
        twin.mean_map, twin.step_size = self.mean_map, self.step_size
        twin.coefficients, twin.cov, twin.chol = self.coefficients.copy(), self.cov.copy(), self.chol.copy()
        return twin

    def is_finite(self) -> bool:
        """True when A, the factor of C and σ are all finite (and σ > 0)."""
        return bool(
            np.isfinite(self.coefficients).all()
            and np.isfinite(self.chol).all()
            and np.isfinite(self.step_size)
            and self.step_size > 0.0
        )

    # -- state ---------------------------------------------------------------------------------------------
    def state(self) -> dict[str, Any]:
        """Arrays and scalars that restore the policy exactly (see :meth:`from_state`)."""
        return {"coefficients": self.coefficients.copy(), "cov": self.cov.copy(), "step_size": self.step_size}

    @classmethod
    def from_state(
        cls, mean_map: FeatureMap, n_params: int, state: Mapping[str, Any]
    ) -> LinearGaussianPolicy:
        """Rebuild a policy from :meth:`state`, checking it like a constructor argument.

        Raises
        ------
        ValueError, TypeError
            Missing entries, wrong shapes or dtypes, non-finite values, an asymmetric or not positive-definite
            C, or σ ≤ 0. The messages name the state entry.
        """
        for key in ("coefficients", "cov"):
            if key not in state:
                raise ValueError(f"state: expected an entry {key!r}, got keys {sorted(state)}")
        k = mean_map.n_features
        coefficients = as_float_array(state["coefficients"], "state['coefficients']", (k, n_params)).copy()
        cov = as_float_array(state["cov"], "state['cov']", (n_params, n_params)).copy()
        if not np.array_equal(cov, cov.T):
            raise ValueError("state['cov']: expected a symmetric matrix, got an asymmetric one")
        try:
            np.linalg.cholesky(cov)
        except np.linalg.LinAlgError:
            raise ValueError(
                "state['cov']: expected a positive-definite matrix, got one that is not"
            ) from None
        step_size = state.get("step_size", 1.0)
        step_size = check_real(step_size, "state['step_size']", strict=True)
        if step_size**2 < np.finfo(np.float64).tiny:  # σ² would underflow: a NaN condition number
            raise ValueError(
                f"state['step_size']: expected a value >= 1.5e-154 (σ² a normal float), got {step_size}"
            )
        check_usable_covariance(cov, "state['cov']", step_size)
        return cls(mean_map, coefficients, cov, step_size)


class PolicyAccess:
    """Mixin for optimisers that keep a :class:`LinearGaussianPolicy` in ``self.policy`` and a Generator in
    ``self.rng``: the read-only views, ``recommend`` and sampling."""

    policy: LinearGaussianPolicy
    rng: np.random.Generator

    @staticmethod
    def recommended_batch_size(n_params: int, n_context_dims: int) -> int:
        """CMA-ES's population 4 + ⌊3 ln p⌋ per mean feature of ϕ(s) = [1, s], so (4 + ⌊3 ln p⌋)·(1 + z),
        and at least 2k + 2 for the k features of a full quadratic in s (the baselines are regressions)."""
        n_params = check_positive_int(n_params, "n_params")
        n_context_dims = check_positive_int(n_context_dims, "n_context_dims", minimum=0)
        population = 4 + int(3 * math.log(n_params))
        quadratic = 1 + n_context_dims + n_context_dims * (n_context_dims + 1) // 2
        return max(population * (1 + n_context_dims), 2 * quadratic + 2)

    @staticmethod
    def minimum_batch_size(n_params: int, n_context_dims: int) -> int:
        """The smallest batch N the runner accepts: max(4 + ⌊3 ln p⌋, 5 (1 + z), k + 1).

        CMA-ES's population 4 + ⌊3 ln p⌋, at least 2.5 selected samples (N/2) per coefficient of the
        affine mean features [1, s], and more samples than the k = 1 + z + z(z + 1)/2 features of a full
        quadratic in s (the baselines are regressions). Measured in ``docs/optimizers.md`` (*Batch size*):
        below it c-cma-es and CREPS-CMA diverged on the Sphere on every seed tried. ``tell`` itself accepts
        any batch of at least two.
        """
        n_params = check_positive_int(n_params, "n_params")
        n_context_dims = check_positive_int(n_context_dims, "n_context_dims", minimum=0)
        quadratic = 1 + n_context_dims + n_context_dims * (n_context_dims + 1) // 2
        return max(4 + int(3 * math.log(n_params)), 5 * (1 + n_context_dims), quadratic + 1)

    @property
    def coefficients(self) -> Array:
        """The mean coefficients A, shape (k, p), as a read-only view."""
        view = self.policy.coefficients.view()
        view.flags.writeable = False
        return view

    @property
    def cov(self) -> Array:
        """The search covariance σ²C (Σ for CREPS and CREPS-CMA), shape (p, p)."""
        return self.policy.covariance

    @property
    def step_size(self) -> float:
        """σ (1 unless the optimiser adapts it)."""
        return self.policy.step_size

    def recommended_coefficients(self) -> Array:
        """The coefficients A, shape (k, p), of the mean policy that ``recommend`` and ``mean_policy`` both
        give: the running search's here; an optimiser that recommends another policy (C-CMA-ES's kept best,
        Eq. (C10)) overrides this one method, so the two can never disagree."""
        return self.policy.coefficients

    def recommend(self, contexts: Any) -> Array:
        """The mean policy Aᵀϕ(s) for contexts (n, z): shape (n, p); ``ValueError`` where it is not finite."""
        checked = self._check_contexts(contexts, "contexts")  # type: ignore[attr-defined]
        with np.errstate(over="ignore", invalid="ignore"):
            mean = self.policy.mean_map(checked) @ self.recommended_coefficients()
        if not np.isfinite(mean).all():
            raise overflowing_contexts(checked, "the mean policy")
        return mean

    def mean_policy(self) -> Policy:
        """The mean policy Aᵀϕ(s) that ``recommend`` gives, as a
        :class:`~creps_gym.optimizers.policy_file.Policy`: a copy, independent of the optimiser, that gives
        ``recommend``'s parameters bit for bit (the kept best of a restarted C-CMA-ES included)."""
        source = {"optimizer": self.kind, "iteration": self.iteration}  # type: ignore[attr-defined]
        return Policy(self.policy.mean_map, self.recommended_coefficients(), source=source)

    def _sample(self, contexts: Array) -> Array:
        return self.policy.sample(contexts, self.rng)

    def _record_returns(self, returns: Array) -> None:
        """What ``tolflatfitness`` and ``tolstagnation`` watch: runs of flat batches (all returns equal, as
        pycma's) and the last ``stagnation_window`` mean returns."""
        spread = float(returns.max() - returns.min())
        flat = spread <= 1e-12 * max(float(np.abs(returns).max()), 1e-300)
        self.flat_iterations = self.flat_iterations + 1 if flat else 0  # type: ignore[attr-defined]
        tolstagnation = self.config.tolstagnation  # type: ignore[attr-defined]
        self.stagnation_window = stagnation_window(self.n_params, returns.shape[0], tolstagnation)
        self.mean_returns = record_mean_return(self.mean_returns, returns, self.stagnation_window)

    def _no_signal_stops(self) -> dict[str, Any]:
        """``tolflatfitness`` and ``tolstagnation``, if met: the returns carry no signal any more."""
        met: dict[str, Any] = {}
        if self.flat_iterations >= self.config.tolflatfitness:  # type: ignore[attr-defined]
            met["tolflatfitness"] = self.flat_iterations  # type: ignore[attr-defined]
        if stagnated(self.mean_returns, self.stagnation_window):  # type: ignore[attr-defined]
            met["tolstagnation"] = self.stagnation_window  # type: ignore[attr-defined]
        return met

    def _policy_state(self) -> dict[str, Any]:
        """The config, the Generator, the initial distribution and the policy: what every checkpoint holds."""
        config = self.config  # type: ignore[attr-defined]
        state = {
            "config": config.to_json(),
            "rng": self.rng.bit_generator.state,
            "initial_mean": config.initial_mean.copy(),
            "initial_cov": config.initial_cov.copy(),
            "flat_iterations": self.flat_iterations,  # type: ignore[attr-defined]
        }
        state.update(self.policy.state())
        return state
