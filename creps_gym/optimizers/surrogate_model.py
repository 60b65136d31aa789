"""The surrogate of ``c-cma-es-surrogate`` as pure functions: a weighted least-squares model of the return
over (s, θ) in the search distribution's coordinates, and the rank agreement that decides whether to trust it.

The model is lq-CMA-ES's (Hansen 2019) with the context as extra inputs; the equation tags (S1)–(S6) are those
of ``docs/algorithms.md``, "Surrogate-assisted contextual CMA-ES", which cites the sources.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import linalg

from creps_gym._validation import as_float_array
from creps_gym.optimizers.features import FeatureMap

__all__ = [
    "KINDS",
    "MAX_COEFFICIENTS",
    "SurrogateModel",
    "choose_kind",
    "fit_model",
    "kendall_tau",
    "model_coefficients",
    "richest_kind",
]

Array = NDArray[np.float64]
#: Model kinds from the poorest to the richest; the diagnostic ``model_kind`` is the index (0: no model).
KINDS = ("none", "linear", "diagonal", "full")
#: The most coefficients a model may have (S2): a richer kind is never used. A fit costs O(n m²) for m
#: coefficients on n ≈ 2m episodes, so this bounds a fit's time and memory (a full quadratic up to d = 33
#: inputs, the diagonal one up to p = 199 at z = 1, then the linear one up to p + z = 599).
MAX_COEFFICIENTS = 600


def model_coefficients(kind: str, n_params: int, n_context_dims: int) -> int:
    """The number of coefficients of a model ``kind`` over u = (s, θ) with d = z + p inputs (S2).

    linear: 1 + d; diagonal: the linear terms, θ_i², s⊗θ and every s_i s_j (i ≤ j); full: every monomial of
    u of degree ≤ 2, 1 + d + d(d + 1)/2.
    """
    p, z = n_params, n_context_dims
    d = p + z
    if kind == "linear":
        return 1 + d
    if kind == "diagonal":
        return 1 + d + p + z * p + z * (z + 1) // 2
    return 1 + d + d * (d + 1) // 2


def richest_kind(n_params: int, n_context_dims: int) -> str:
    """The richest kind with at most :data:`MAX_COEFFICIENTS` coefficients (``"none"`` if not even the
    linear model has)."""
    for kind in reversed(KINDS[1:]):
        if model_coefficients(kind, n_params, n_context_dims) <= MAX_COEFFICIENTS:
            return kind
    return "none"


def choose_kind(n_data: int, n_params: int, n_context_dims: int, margin: float) -> str:
    """The richest kind up to :func:`richest_kind` whose coefficients times ``margin`` fit in ``n_data``
    archived episodes (S2), or ``"none"`` when not even the linear model does."""
    allowed = KINDS.index(richest_kind(n_params, n_context_dims))
    for kind in reversed(KINDS[1 : allowed + 1]):
        if n_data >= margin * model_coefficients(kind, n_params, n_context_dims):
            return kind
    return "none"


def _design(kind: str, contexts: Array, whitened: Array) -> Array:
    """The regressors of a model ``kind`` (S2) at standardised contexts (n, z) and whitened θ (n, p)."""
    n, z = contexts.shape
    u = np.concatenate([contexts, whitened], axis=1)
    columns = [np.ones((n, 1)), u]
    if kind == "diagonal":
        upper = np.triu_indices(z)
        columns += [whitened**2, (contexts[:, :, None] * whitened[:, None, :]).reshape(n, -1)]
        columns.append((contexts[:, :, None] * contexts[:, None, :])[:, upper[0], upper[1]])
    elif kind == "full":
        upper = np.triu_indices(u.shape[1])
        columns.append((u[:, :, None] * u[:, None, :])[:, upper[0], upper[1]])
    return np.concatenate(columns, axis=1)


@dataclass(frozen=True, eq=False)
class SurrogateModel:
    """R̂(s, θ) fitted in the coordinates of the search distribution it was fitted under (S1), (S2).

    Parameters
    ----------
    kind : str                        one of :data:`KINDS` but ``"none"``.
    mean_coefficients : (k, p)        A of that distribution: its mean Aᵀϕ(s).
    step_size : float                 its σ.
    whitening : (p, p)                its C^(−1/2).
    context_centre, context_scale : (z,)   the archive's context mean and standard deviation.
    return_centre, return_scale : float    R is fitted as (R − centre)/scale.
    coefficients : (m,)               the model's coefficients on :func:`_design`'s regressors.
    """

    kind: str
    mean_coefficients: Array
    step_size: float
    whitening: Array
    context_centre: Array
    context_scale: Array
    return_centre: float
    return_scale: float
    coefficients: Array

    def inputs(self, mean_map: FeatureMap, contexts: Array, params: Array) -> tuple[Array, Array]:
        """(standardised s, whitened θ) = ((s − c)/d, C^(−1/2)(θ − Aᵀϕ(s))/σ), Eq. (S1)."""
        deviations = (params - mean_map(contexts) @ self.mean_coefficients) / self.step_size
        return (contexts - self.context_centre) / self.context_scale, deviations @ self.whitening  # Eq. (S1)

    def predict(self, mean_map: FeatureMap, contexts: Array, params: Array) -> Array:
        """R̂ at contexts (n, z) and parameters (n, p): shape (n,), Eq. (S2)."""
        design = _design(self.kind, *self.inputs(mean_map, contexts, params))
        return self.return_centre + self.return_scale * (design @ self.coefficients)  # Eq. (S2)

    def state(self, prefix: str) -> dict[str, Any]:
        """The model as arrays and JSON scalars, keys starting with ``prefix``."""
        arrays = {name: getattr(self, name).copy() for name in self._ARRAYS}
        scalars = {
            "kind": self.kind,
            "step_size": self.step_size,
            "return_centre": self.return_centre,
            "return_scale": self.return_scale,
        }
        return {f"{prefix}{name}": value for name, value in {**arrays, **scalars}.items()}

    @classmethod
    def from_state(
        cls, state: Mapping[str, Any], prefix: str, n_params: int, n_context_dims: int, n_features: int
    ) -> SurrogateModel:
        """Rebuild a model from :meth:`state`, checking each entry's shape and finiteness."""
        kind = state[f"{prefix}kind"]
        if kind not in KINDS[1:]:
            raise ValueError(f"state['{prefix}kind']: expected one of {KINDS[1:]}, got {kind!r}")
        p, z = n_params, n_context_dims
        shapes = {
            "mean_coefficients": (n_features, p),
            "whitening": (p, p),
            "context_centre": (z,),
            "context_scale": (z,),
            "coefficients": (model_coefficients(kind, p, z),),
        }
        arrays = {
            name: as_float_array(state[f"{prefix}{name}"], f"state['{prefix}{name}']", shape).copy()
            for name, shape in shapes.items()
        }
        scalars = {
            name: float(as_float_array(state[f"{prefix}{name}"], f"state['{prefix}{name}']", ()))
            for name in ("step_size", "return_centre", "return_scale")
        }
        return cls(kind=kind, **arrays, **scalars)

    _ARRAYS = ("mean_coefficients", "whitening", "context_centre", "context_scale", "coefficients")


def fit_model(
    kind: str,
    mean_map: FeatureMap,
    coefficients: Array,
    step_size: float,
    whitening: Array,
    archive: tuple[Array, Array, Array],
) -> SurrogateModel | None:
    """Weighted least squares of the archived returns on the regressors of ``kind`` (S1)–(S3).

    Parameters
    ----------
    kind : str
        ``"linear"``, ``"diagonal"`` or ``"full"``.
    mean_map, coefficients, step_size, whitening
        ϕ, A (k, p), σ and C^(−1/2) (p, p) of the current search distribution.
    archive : (contexts (n, z), params (n, p), returns (n,))
        The archived true episodes.

    Returns
    -------
    SurrogateModel or None
        None when the normal equations are singular or the fit is not finite.
    """
    contexts, params, returns = archive
    spread = contexts.std(axis=0)
    centre, spread = contexts.mean(axis=0), np.where(spread > 0, spread, 1.0)
    r_centre = float(returns.mean())
    r_scale = float(np.abs(returns - r_centre).max()) or 1.0
    model = SurrogateModel(
        kind,
        coefficients.copy(),
        float(step_size),
        whitening.copy(),
        centre,
        spread,
        r_centre,
        r_scale,
        np.zeros(0),
    )
    s, u = model.inputs(mean_map, contexts, params)
    design = _design(kind, s, u)
    distance = np.einsum("ij,ij->i", u, u)  # Mahalanobis distance² to the current mean at s_k
    ranks = np.empty(distance.size)
    ranks[np.argsort(distance, kind="stable")] = np.arange(distance.size)
    weights = 1.0 - 0.9 * ranks / max(distance.size - 1, 1)  # Eq. (S3): 1 (nearest) down to 0.1 (farthest)
    root = np.sqrt(weights)
    try:  # Eq. (S3): a QR least-squares solve of √w·X c = √w·y (the normal equations square cond X)
        fit = linalg.lstsq(
            design * root[:, None],
            root * (returns - r_centre) / r_scale,
            check_finite=False,
            lapack_driver="gelsy",
        )[0]
    except (linalg.LinAlgError, ValueError):
        return None
    if not np.isfinite(fit).all():
        return None
    return SurrogateModel(
        kind,
        model.mean_coefficients,
        model.step_size,
        model.whitening,
        centre,
        spread,
        r_centre,
        r_scale,
        fit,
    )


def kendall_tau(first: Array, second: Array) -> float:
    """Kendall's τ-b between two score vectors (n,), Eq. (S4); 0 when either is constant."""
    a = np.sign(first[:, None] - first[None, :])
    b = np.sign(second[:, None] - second[None, :])
    concordance = float((a * b).sum())
    norm = float(np.sqrt(np.abs(a).sum() * np.abs(b).sum()))
    return concordance / norm if norm > 0 else 0.0
