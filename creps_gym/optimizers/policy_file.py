"""The learned policy as an object and a file, independent of the optimiser, the run and the env.

A :class:`Policy` is the mean of a linear-Gaussian search distribution, θ(s) = Aᵀϕ(s): a feature map ϕ
(:mod:`creps_gym.optimizers.features`), the coefficients A (k, p), and what it was learned on (the env id
and keyword arguments, the context box and the parameter box, where the optimiser ran). Every optimiser of
this package gives one (``optimizer.mean_policy()``, equal to ``recommend`` bit for bit); the adapters of
non-contextual libraries give a constant one (ϕ(s) = [1]).

The file (:meth:`Policy.save`, :meth:`Policy.load`) is an ``.npz`` with the arrays and one JSON document,
never pickle; it needs numpy only (no MuJoCo, Ray or Gymnasium). Reading one is bounded and strict
(:mod:`creps_gym.optimizers.policy_io`): the file is untrusted input.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from creps_gym._validation import (
    as_float_array,
    check_bool,
    check_fits_in_memory,
    check_in_box,
    check_positive_int,
)
from creps_gym.optimizers.base import MAX_CONTEXT, overflowing_contexts
from creps_gym.optimizers.features import FeatureMap, make_features

__all__ = ["POLICY_FORMAT", "Policy"]

Array = NDArray[np.float64]
POLICY_FORMAT = "creps_gym.policy/1"
#: Largest context dimension a policy file may declare, and largest other int in a feature map's spec (a
#: polynomial's degree): the feature count of a hostile file stays cheap to compute.
MAX_CONTEXT_DIMS, MAX_SPEC_INT = 10_000, 1_000
_BOXES = ("context_low", "context_high", "param_low", "param_high")
_SCALARS = (str, int, float, bool, type(None))


def _box(value: Any, name: str, size: int) -> tuple[Array, Array] | None:
    """(low, high) of a box given as a pair of arrays (±inf allowed, low <= high), or None."""
    if value is None:
        return None
    if not isinstance(value, (tuple, list)) or len(value) != 2:
        raise TypeError(f"{name}: expected a pair (low, high) or None, got {type(value).__name__}")
    low, high = (as_float_array(v, name, (size,), finite=False).copy() for v in value)
    if np.isnan(low).any() or np.isnan(high).any() or (low > high).any():
        raise ValueError(f"{name}: expected low <= high without NaN, got low {low} and high {high}")
    for array in (low, high):
        array.flags.writeable = False
    return low, high


def _check_json_scalars(value: Any, name: str) -> dict[str, Any]:
    """A flat dict of JSON scalars (str keys), as ``source`` is."""
    if not isinstance(value, Mapping):
        raise TypeError(f"{name}: expected a dict of JSON scalars, got {type(value).__name__}")
    for key, item in value.items():
        if not isinstance(key, str) or not isinstance(item, _SCALARS):
            raise TypeError(f"{name}: expected str keys and str, number, bool or None values, got {key!r}")
        if isinstance(item, float) and not math.isfinite(item):
            raise ValueError(f"{name}[{key!r}]: expected a finite number or None, got {item}")
    return dict(value)


def _floats_only(values: list[Any]) -> bool:
    """Whether ``values`` holds only floats, or only lists of floats (checked in one pass, not walked)."""
    rows = all(type(item) is list and all(type(x) is float for x in item) for item in values)
    return rows or all(type(item) is float for item in values)


def _check_spec_ints(value: Any, name: str) -> None:
    """Refuse ints in a feature map's spec beyond :data:`MAX_SPEC_INT` (other than its context_dim)."""
    if isinstance(value, Mapping):
        for key, item in value.items():
            if key != "context_dim":
                _check_spec_ints(item, f"{name}[{key!r}]")
    elif isinstance(value, list):
        if _floats_only(value):  # a list of floats, or of rows of floats (RBF centres): no int to refuse
            return
        for index, item in enumerate(value):
            _check_spec_ints(item, f"{name}[{index}]")
    elif isinstance(value, int) and not isinstance(value, bool) and abs(value) > MAX_SPEC_INT:
        raise ValueError(f"{name}: expected an int of at most {MAX_SPEC_INT} in magnitude, got {value}")


class Policy:
    """A learned mean policy θ(s) = Aᵀϕ(s); call it on contexts to get parameters.

    Parameters
    ----------
    features : FeatureMap, str or dict
        ϕ (a map, a registered name or a spec, see :func:`~creps_gym.optimizers.features.make_features`).
    coefficients : array_like, shape (k, p)
        A, finite.
    context_dim : int, optional
        z (default: the feature map's).
    context_box, param_box : pair of array_like, optional
        (low, high) of the contexts, shape (z,), and of the parameters, shape (p,), where known (±inf
        allowed). Contexts outside ``context_box`` are refused like the env refuses them; parameters are
        never clipped to ``param_box`` (``recommend`` does not clip, and the envs evaluate parameters outside
        their box as given unless their manual says otherwise): it is information.
    env : str, optional
        The Gymnasium id the policy was learned on; ``env_kwargs`` its keyword arguments (JSON).
    source : dict, optional
        Where the policy comes from: JSON scalars such as ``optimizer``, ``iteration``, ``which``,
        ``eval_return``, ``eval_regret``.
    """

    def __init__(
        self,
        features: FeatureMap | str | Mapping[str, Any],
        coefficients: Any,
        *,
        context_dim: int | None = None,
        context_box: Any = None,
        param_box: Any = None,
        env: str | None = None,
        env_kwargs: Mapping[str, Any] | None = None,
        source: Mapping[str, Any] | None = None,
    ) -> None:
        if context_dim is None:
            if not isinstance(features, FeatureMap):
                raise TypeError("context_dim: expected an int >= 0 with a feature map name or spec, got None")
            context_dim = features.context_dim
        z = check_positive_int(context_dim, "context_dim", minimum=0)
        if isinstance(features, Mapping):
            _check_spec_ints(dict(features), "features")
        self.features = make_features(dict(features) if isinstance(features, Mapping) else features, z)
        coefficients = as_float_array(coefficients, "coefficients", (self.features.n_features, None)).copy()
        if coefficients.shape[1] < 1:
            raise ValueError(f"coefficients: expected at least one column (p >= 1), got {coefficients.shape}")
        coefficients.flags.writeable = False
        self.coefficients = coefficients
        self.context_box = _box(context_box, "context_box", z)
        self.param_box = _box(param_box, "param_box", self.n_params)
        if env is not None and not isinstance(env, str):
            raise TypeError(f"env: expected a Gymnasium id (str) or None, got {type(env).__name__}")
        if env_kwargs is not None and not isinstance(env_kwargs, Mapping):
            raise TypeError(f"env_kwargs: expected a dict or None, got {type(env_kwargs).__name__}")
        self.env, self.env_kwargs = env, dict(env_kwargs or {})
        self.source = _check_json_scalars(source or {}, "source")

    @classmethod
    def constant(cls, params: Any, context_dim: int, **kwargs: Any) -> Policy:
        """The policy that gives ``params`` (p,) for every context (ϕ(s) = [1], the adapters' policy)."""
        z = check_positive_int(context_dim, "context_dim", minimum=0)
        row = as_float_array(params, "params", (None,))
        return cls({"name": "polynomial", "degree": 0}, row[None, :], context_dim=z, **kwargs)

    # -- the policy ----------------------------------------------------------------------------------------
    @property
    def context_dim(self) -> int:
        """z, the context dimension."""
        return int(self.features.context_dim)

    @property
    def n_params(self) -> int:
        """p, the parameter dimension."""
        return int(self.coefficients.shape[1])

    def check_batch(self, n: int, name: str = "contexts") -> None:
        """Refuse, before allocating, ``n`` contexts whose features and parameters would not fit in memory.

        The estimate counts 8-byte floats: ``n k (z + 2)`` for the features (a radial basis map holds an
        (n, k, z) array of differences) and ``2 n (z + p)`` for the contexts and the parameters; ``name``
        is the argument named in the ``ValueError`` (a command-line flag, ``"contexts"``).
        """
        k, z, p = self.features.n_features, self.context_dim, self.n_params
        what = f"the policy's features and parameters (n x k x z floats, k = {k}, z = {z}, p = {p})"
        check_fits_in_memory(8.0 * n * (k * (z + 2) + 2 * (z + p)), name, n, what)

    def __call__(self, contexts: Any, *, extrapolate: bool = False) -> Array:
        """The mean parameters for contexts.

        Parameters
        ----------
        contexts : array_like, shape (n, z) or (z,)
            Finite contexts; one context of shape (z,) gives parameters of shape (p,), like the env's
            ``reset(options={"context": s})`` takes one context of shape (z,).
        extrapolate : bool
            Accept contexts outside the context box (refused by default, as the env refuses them).

        Returns
        -------
        ndarray, shape (n, p) or (p,)
        """
        extrapolate = check_bool(extrapolate, "extrapolate")
        z = self.context_dim
        array = as_float_array(contexts, "contexts")
        single = array.shape == (z,)
        if not single and (array.ndim != 2 or array.shape[1] != z or array.shape[0] < 1):
            raise ValueError(f"contexts: expected shape (n, {z}) with n >= 1, or ({z},), got {array.shape}")
        rows = array[None, :] if single else array
        self.check_batch(rows.shape[0])
        largest = float(np.abs(rows).max()) if rows.size else 0.0
        if largest > MAX_CONTEXT:
            raise ValueError(f"contexts: expected |s| <= {MAX_CONTEXT:g}, got max |s| = {largest:g}")
        if self.context_box is not None and not extrapolate:
            low, high = self.context_box
            check_in_box(rows, low, high, "contexts", " (pass extrapolate=True to go outside it)")
        with np.errstate(over="ignore", invalid="ignore"):
            mean = self.features(rows) @ self.coefficients
        if not np.isfinite(mean).all():
            raise overflowing_contexts(rows, "the policy's parameters")
        return mean[0] if single else mean

    def __repr__(self) -> str:
        where = f", env={self.env!r}" if self.env else ""
        return f"Policy(features={self.features.name!r}, z={self.context_dim}, p={self.n_params}{where})"

    def equals(self, other: Any) -> bool:
        """Same features, coefficients (bit for bit), boxes, env and source."""
        if not isinstance(other, Policy):
            return False
        boxes = all(
            (a is None and b is None) or (a is not None and b is not None and all(map(np.array_equal, a, b)))
            for a, b in ((self.context_box, other.context_box), (self.param_box, other.param_box))
        )
        same = self.to_dict(arrays=False) == other.to_dict(arrays=False)
        return boxes and same and self.coefficients.tobytes() == other.coefficients.tobytes()

    # -- documents and files --------------------------------------------------------------------------------
    def arrays(self) -> dict[str, Array]:
        """The arrays of the file: ``coefficients`` and the boxes that are known."""
        arrays = {"coefficients": self.coefficients}
        for prefix, box in (("context", self.context_box), ("param", self.param_box)):
            if box is not None:
                arrays[f"{prefix}_low"], arrays[f"{prefix}_high"] = box
        return arrays

    def to_dict(self, arrays: bool = True) -> dict[str, Any]:
        """A JSON-serialisable document (arrays as lists, ±inf as ``"inf"``/``"-inf"``) that
        :meth:`from_dict` reads back bit for bit; without ``arrays``, the file's JSON document."""
        document = {
            "format": POLICY_FORMAT,
            "features": self.features.spec(),
            "context_dim": self.context_dim,
            "n_params": self.n_params,
            "env": self.env,
            "env_kwargs": self.env_kwargs,
            "source": self.source,
        }
        if arrays:
            document["arrays"] = {
                key: [v if math.isfinite(v) else str(v) for v in value.ravel().tolist()]
                for key, value in self.arrays().items()
            }
        return document

    @classmethod
    def from_dict(cls, document: Mapping[str, Any], arrays: Mapping[str, Any] | None = None) -> Policy:
        """Rebuild a policy from :meth:`to_dict`'s document (or the file's document and its arrays),
        checking every field; ``ValueError`` or ``TypeError`` naming the field otherwise."""
        if not isinstance(document, Mapping):
            raise TypeError(f"document: expected a JSON object, got {type(document).__name__}")
        expected = {"format", "features", "context_dim", "n_params", "env", "env_kwargs", "source"}
        expected |= {"arrays"} if arrays is None else set()
        if set(document) != expected:
            raise ValueError(f"document: expected the keys {sorted(expected)}, got {sorted(document)}")
        if document["format"] != POLICY_FORMAT:
            raise ValueError(f"document['format']: expected {POLICY_FORMAT!r}, got {document['format']!r}")
        z = check_positive_int(document["context_dim"], "document['context_dim']", minimum=0)
        p = check_positive_int(document["n_params"], "document['n_params']")
        if z > MAX_CONTEXT_DIMS:
            raise ValueError(f"document['context_dim']: expected at most {MAX_CONTEXT_DIMS}, got {z}")
        if not isinstance(document["features"], Mapping):
            raise TypeError("document['features']: expected a feature map's spec (a JSON object)")
        found = _arrays(document.get("arrays")) if arrays is None else dict(arrays)
        if "coefficients" not in found or set(found) - {"coefficients", *_BOXES}:
            raise ValueError(f"arrays: expected 'coefficients' and boxes among {_BOXES}, got {sorted(found)}")
        coefficients = np.asarray(found["coefficients"], dtype=np.float64)
        if arrays is None and coefficients.ndim == 1 and coefficients.size % p == 0:  # to_dict: flat
            coefficients = coefficients.reshape(-1, p)
        boxes = {}
        for prefix in ("context", "param"):
            pair = [found.get(f"{prefix}_low"), found.get(f"{prefix}_high")]
            if (pair[0] is None) != (pair[1] is None):
                raise ValueError(f"arrays: expected both {prefix}_low and {prefix}_high or neither")
            boxes[f"{prefix}_box"] = None if pair[0] is None else pair
        policy = cls(
            document["features"],
            coefficients,
            context_dim=z,
            env=document["env"],
            env_kwargs=document["env_kwargs"],
            source=document["source"],
            **boxes,
        )
        if policy.n_params != p:
            got = policy.n_params
            raise ValueError(f"arrays['coefficients']: expected {p} columns (n_params), got {got}")
        return policy

    def save(self, path: str | os.PathLike[str]) -> Path:
        """Write the policy file (``.npz``: the arrays and one JSON document, never pickle) atomically;
        returns the file written. ``path`` is followed if it is a symbolic link (its target is replaced);
        a FIFO, a device or a folder there is a ``ValueError``, a failed write an ``OSError`` naming it."""
        from creps_gym.optimizers.policy_io import write_policy_file

        return write_policy_file(self.to_dict(arrays=False), self.arrays(), path)

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> Policy:
        """Read a policy file written by :meth:`save` (bounded, no pickle, no symbolic link followed).

        Raises
        ------
        ValueError
            Not a policy file: a folder (a run folder's policies load with
            :func:`creps_gym.load_policy`), unknown, missing or oversized entries, wrong dtypes or shapes,
            a bad field.
        FileNotFoundError
            No such file.
        """
        from creps_gym.optimizers.policy_io import read_policy_file

        if os.path.isdir(path):
            raise ValueError(
                f"path: expected a policy file, got the folder {path}; the policies of a run folder load "
                f"with creps_gym.load_policy({os.fspath(path)!r}) (which='best' or 'final')"
            )
        document, arrays = read_policy_file(path)
        try:
            return cls.from_dict(document, arrays)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"path: expected a creps_gym policy file, got {path} ({exc})") from None


def _arrays(value: Any) -> dict[str, Array]:
    """The ``arrays`` of :meth:`Policy.to_dict`: lists of numbers or ``"inf"``/``"-inf"``."""
    if not isinstance(value, Mapping):
        raise TypeError(f"document['arrays']: expected a JSON object, got {type(value).__name__}")
    out = {}
    for key, items in value.items():
        if not isinstance(items, list) or not all(
            (isinstance(v, (int, float)) and not isinstance(v, bool)) or v in ("inf", "-inf") for v in items
        ):
            raise TypeError(f"document['arrays'][{key!r}]: expected a list of numbers, 'inf' or '-inf'")
        out[str(key)] = np.array([float(v) for v in items], dtype=np.float64)
    return out
