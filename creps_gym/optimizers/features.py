"""Context feature maps for contextual policy search.

Two kinds of features appear in CREPS (Abdolmaleki et al., 2019, section 3):

* the *mean features* ϕ(s) of the linear-Gaussian policy π(θ|s) = N(Aᵀϕ(s), Σ), affine ``[1, s]`` by
  default (:class:`AffineFeatures`), with quadratic (:class:`QuadraticFeatures`) and normalised radial basis
  functions (:class:`RBFFeatures`) also available;
* the *baseline features* φ(s) = [s, s²] of the dual (:class:`BaselineFeatures`), element-wise squares and
  no constant, because the dual depends on φ only through φ − φ̂.

Every feature map is a small frozen object with ``__call__(contexts (n, z)) -> (n, k)``, ``n_features`` and a
JSON-serialisable ``spec()``; :func:`make_features` rebuilds one from its spec, so optimiser checkpoints stay
free of pickle. Users add their own map with :func:`register_feature_map`.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from creps_gym._validation import check_fits_in_memory

__all__ = [
    "MAX_FEATURES",
    "AffineFeatures",
    "BaselineFeatures",
    "FeatureMap",
    "PolynomialFeatures",
    "QuadraticFeatures",
    "RBFFeatures",
    "count_monomials",
    "make_features",
    "register_feature_map",
]

Array = NDArray[np.float64]
#: Most features a map may have: beyond it, even the features of one context would not fit in memory.
MAX_FEATURES = 2**32


def count_monomials(context_dim: int, degree: int, limit: int = MAX_FEATURES) -> int:
    """The number C(z + d, d) of monomials of ``context_dim`` variables up to ``degree``, by formula.

    Computed as a product of min(z, d) factors that stops at the first partial product above ``limit``
    (then the returned count exceeds ``limit``), so it is fast for any size and never enumerates.
    """
    n, r = context_dim + degree, min(context_dim, degree)
    count = 1
    for i in range(1, r + 1):
        count = count * (n - r + i) // i  # C(n - r + i, i), an integer at every step
        if count > limit:
            break
    return count


@dataclass(frozen=True)
class FeatureMap:
    """Base class: a deterministic map from contexts (n, z) to features (n, k)."""

    context_dim: int
    name: ClassVar[str] = "base"
    constant_column: ClassVar[int | None] = None  # index of a feature that is always 1, if any

    def __post_init__(self) -> None:
        if isinstance(self.context_dim, bool) or not isinstance(self.context_dim, (int, np.integer)):
            raise TypeError(f"context_dim: expected an int >= 0, got {type(self.context_dim).__name__}")
        if self.context_dim < 0:
            raise ValueError(f"context_dim: expected an int >= 0, got {self.context_dim}")

    @property
    def n_features(self) -> int:
        """Number of features k."""
        raise NotImplementedError

    def __call__(self, contexts: Array) -> Array:
        raise NotImplementedError

    def constant_coefficients(self, mean: Array) -> Array:
        """Coefficients A (k, p) whose policy mean Aᵀϕ(s) equals ``mean`` (p,) for every context.

        Raises ``ValueError`` for maps that cannot represent a constant (no constant feature).
        """
        if self.constant_column is None:
            raise ValueError(
                f"initial_mean: expected full coefficients of shape ({self.n_features}, p) for the "
                f"{self.name!r} feature map, which has no constant feature; got a constant mean"
            )
        coefficients = np.zeros((self.n_features, mean.shape[0]))
        coefficients[self.constant_column] = mean
        return coefficients

    def spec(self) -> dict[str, Any]:
        """JSON-serialisable description, inverse of :func:`make_features`: the name and every constructor
        field (arrays as nested lists), so a registered subclass with fields of its own is rebuilt."""
        data: dict[str, Any] = {"name": self.name}
        for item in fields(self):
            if item.init:
                value = getattr(self, item.name)
                data[item.name] = value.tolist() if isinstance(value, (np.ndarray, np.generic)) else value
        return data


@dataclass(frozen=True)
class AffineFeatures(FeatureMap):
    """ϕ(s) = [1, s]: a policy mean linear in the context (the paper's default)."""

    name: ClassVar[str] = "affine"
    constant_column: ClassVar[int | None] = 0

    @property
    def n_features(self) -> int:
        return 1 + self.context_dim

    def __call__(self, contexts: Array) -> Array:
        return np.concatenate([np.ones((contexts.shape[0], 1)), contexts], axis=1)


@dataclass(frozen=True)
class QuadraticFeatures(FeatureMap):
    """ϕ(s) = [1, s, s²] with element-wise squares (no cross terms)."""

    name: ClassVar[str] = "quadratic"
    constant_column: ClassVar[int | None] = 0

    @property
    def n_features(self) -> int:
        return 1 + 2 * self.context_dim

    def __call__(self, contexts: Array) -> Array:
        return np.concatenate([np.ones((contexts.shape[0], 1)), contexts, contexts**2], axis=1)


@dataclass(frozen=True)
class PolynomialFeatures(FeatureMap):
    """ϕ(s) = every monomial of s up to ``degree``, cross terms included: [1, s_i, s_i s_j (i ≤ j), ...].

    Contextual CMA-ES fits its context baseline V(s) on these (a full quadratic by default).

    Parameters
    ----------
    context_dim : int
    degree : int
        Highest total degree, ≥ 0 (0 is the constant alone).
    """

    degree: int = 2
    name: ClassVar[str] = "polynomial"
    constant_column: ClassVar[int | None] = 0

    def __post_init__(self) -> None:
        super().__post_init__()
        if isinstance(self.degree, bool) or not isinstance(self.degree, (int, np.integer)) or self.degree < 0:
            raise ValueError(f"degree: expected an int >= 0, got {self.degree!r}")
        object.__setattr__(self, "degree", int(self.degree))
        count = count_monomials(self.context_dim, self.degree)
        if count > MAX_FEATURES:
            raise ValueError(
                f"degree: expected a degree whose monomials of {self.context_dim} context dimensions number "
                f"at most {MAX_FEATURES}, got {self.degree} (over {MAX_FEATURES} features)"
            )
        # The monomials' index tuples (56 + 8 d bytes each) and the k x k Gram matrix of a weighted fit.
        what = f"the {count} monomials of degree <= {self.degree} and their k x k Gram matrix (k = {count})"
        check_fits_in_memory(count * (8.0 * count + 56.0 + 8.0 * self.degree), "degree", self.degree, what)

    @property
    def monomials(self) -> list[tuple[int, ...]]:
        """The context indices multiplied in each feature, constant first."""
        return [
            combination
            for order in range(self.degree + 1)
            for combination in itertools.combinations_with_replacement(range(self.context_dim), order)
        ]

    @property
    def n_features(self) -> int:
        return math.comb(self.context_dim + self.degree, self.degree)

    def __call__(self, contexts: Array) -> Array:
        columns = [np.prod(contexts[:, list(term)], axis=1) for term in self.monomials]
        return np.stack(columns, axis=1)


@dataclass(frozen=True)
class BaselineFeatures(FeatureMap):
    """φ(s) = [s, s²] for the dual's context baseline V(s) = φ(s)ᵀw (paper footnote 2; no constant)."""

    name: ClassVar[str] = "baseline"

    @property
    def n_features(self) -> int:
        return 2 * self.context_dim

    def __call__(self, contexts: Array) -> Array:
        return np.concatenate([contexts, contexts**2], axis=1)


@dataclass(frozen=True, eq=False)
class RBFFeatures(FeatureMap):
    """Normalised Gaussian radial basis functions: ϕ_i(s) = exp(−|s − c_i|²/(2h²)) / Σ_j exp(·).

    Parameters
    ----------
    context_dim : int
    centres : array_like, shape (k, z)
        Centres c_i, for example a grid over the context box (see :meth:`grid`).
    bandwidth : float
        Width h > 0, in context units.
    """

    centres: Any = field(default=None)
    bandwidth: float = 1.0
    name: ClassVar[str] = "rbf"

    def __post_init__(self) -> None:
        super().__post_init__()
        centres = np.asarray(self.centres, dtype=np.float64)
        if centres.ndim != 2 or centres.shape[1] != self.context_dim or centres.shape[0] < 1:
            raise ValueError(
                f"centres: expected shape (k, {self.context_dim}) with k >= 1, got {np.shape(self.centres)}"
            )
        if not np.isfinite(centres).all():
            raise ValueError("centres: expected finite values, got NaN or inf")
        bandwidth = self.bandwidth
        if isinstance(bandwidth, (bool, np.bool_)) or not isinstance(bandwidth, (int, float, np.number)):
            raise TypeError(f"bandwidth: expected a finite number > 0, got {type(bandwidth).__name__}")
        try:
            width = np.float64(bandwidth)
        except OverflowError:  # a Python int beyond the float range
            width = np.float64(np.inf)
        with np.errstate(over="ignore", under="ignore"):
            usable = bool(np.isfinite(width) and 0.0 < 2.0 * width**2 < np.inf)
        if not usable:  # the logits divide by 2 h², which must be a positive finite number
            raise ValueError(f"bandwidth: expected a finite number > 0 whose 2 h² is too, got {bandwidth!r}")
        centres.setflags(write=False)
        object.__setattr__(self, "centres", centres)
        object.__setattr__(self, "bandwidth", float(bandwidth))

    @classmethod
    def grid(cls, low: Any, high: Any, per_dim: int, bandwidth: float | None = None) -> RBFFeatures:
        """Centres on a regular grid of ``per_dim`` points per context dimension over [low, high]."""
        low, high = np.atleast_1d(np.asarray(low, float)), np.atleast_1d(np.asarray(high, float))
        axes = [np.linspace(lo, hi, per_dim) for lo, hi in zip(low, high, strict=True)]
        centres = np.stack([a.ravel() for a in np.meshgrid(*axes, indexing="ij")], axis=1)
        if bandwidth is None:
            bandwidth = float(np.max(high - low)) / max(per_dim - 1, 1)
        return cls(context_dim=low.shape[0], centres=centres, bandwidth=bandwidth)

    @property
    def n_features(self) -> int:
        return int(self.centres.shape[0])

    def __call__(self, contexts: Array) -> Array:
        sq_dist = ((contexts[:, None, :] - self.centres[None, :, :]) ** 2).sum(axis=2)
        logits = -sq_dist / (2.0 * self.bandwidth**2)
        logits -= logits.max(axis=1, keepdims=True)  # safe normalisation far from every centre
        activations = np.exp(logits)
        return activations / activations.sum(axis=1, keepdims=True)

    def constant_coefficients(self, mean: Array) -> Array:
        # Normalised RBFs sum to one, so equal rows give a constant mean.
        return np.tile(mean, (self.n_features, 1))

    def __eq__(
        self, other: object
    ) -> bool:  # by value: centres are an array, which dataclass eq cannot compare
        return type(other) is type(self) and self.spec() == other.spec()  # type: ignore[attr-defined]

    def __hash__(self) -> int:
        return hash((self.context_dim, self.centres.tobytes(), self.bandwidth))


_REGISTRY: dict[str, type[FeatureMap]] = {
    cls.name: cls
    for cls in (AffineFeatures, QuadraticFeatures, PolynomialFeatures, BaselineFeatures, RBFFeatures)
}


def register_feature_map(cls: type[FeatureMap]) -> type[FeatureMap]:
    """Register a user :class:`FeatureMap` subclass (by its ``name``) so checkpoints can rebuild it.

    A name already taken by another class (a built-in such as ``"affine"`` included) raises ``ValueError``;
    registering the same class again (a reloaded module) is allowed.
    """
    if not (isinstance(cls, type) and issubclass(cls, FeatureMap)):
        raise TypeError(f"cls: expected a FeatureMap subclass, got {cls!r}")
    taken = _REGISTRY.get(cls.name)
    if taken is not None and (taken.__module__, taken.__qualname__) != (cls.__module__, cls.__qualname__):
        raise ValueError(f"cls: expected a feature map name not yet registered, got {cls.name!r} ({taken})")
    _REGISTRY[cls.name] = cls
    return cls


def make_features(
    spec: str | dict[str, Any] | FeatureMap, context_dim: int, option: str = "features"
) -> FeatureMap:
    """Build a feature map from a name (``"affine"``, ``"quadratic"``, ``"baseline"``), a spec dict or a map.

    Errors name ``option`` (the optimiser option the spec was given as, e.g. ``"mean_features"``).

    Raises
    ------
    ValueError
        Unknown name, or a map whose ``context_dim`` differs from ``context_dim``.
    """
    if isinstance(spec, FeatureMap):
        feature_map = spec
    elif not isinstance(spec, (str, Mapping)):
        raise TypeError(f"{option}: expected a name, a spec dict or a FeatureMap, got {type(spec).__name__}")
    else:
        kwargs = {"name": spec} if isinstance(spec, str) else dict(spec)
        name = kwargs.pop("name", None)
        if name not in _REGISTRY:
            raise ValueError(f"{option}: expected one of {sorted(_REGISTRY)}, got {name!r}")
        kwargs.setdefault("context_dim", context_dim)
        try:
            feature_map = _REGISTRY[name](**kwargs)
        except (TypeError, ValueError) as exc:  # name the option: "mean_features: degree: expected ..."
            raise type(exc)(f"{option}: {exc}") from None
    if feature_map.context_dim != context_dim:
        raise ValueError(
            f"{option}: expected a map for context_dim={context_dim}, got one for {feature_map.context_dim}"
        )
    return feature_map
