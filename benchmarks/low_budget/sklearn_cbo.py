"""c-bo built on scikit-learn: the low-budget study's scikit-learn column (issue 44, items 1 and 5).

The column ``c-bo-sklearn``: the same contextual BO with scikit-learn's ``GaussianProcessRegressor`` in place
of c-bo's own GP, written as a scikit-learn user would write it. Why the study measures it is in
:mod:`benchmarks.low_budget.library_gp`; :class:`SklearnCBO` subclasses its
:class:`~benchmarks.low_budget.library_gp.LibraryGPCBO` and keeps everything that is not the model.

- **The model**: ``GaussianProcessRegressor`` with the kernel of scikit-learn's documentation for noisy data,
  ``ConstantKernel() * RBF(length_scale=ones(d)) + WhiteKernel()`` (one lengthscale per input, every
  hyperparameter within scikit-learn's default bounds, (1e-5, 1e5)), ``normalize_y=True`` and the library's
  default fit: L-BFGS-B on the log marginal likelihood from the kernel's start, no restarts. The
  hyperparameters are fitted on a refit and kept in between (the model is rebuilt on all the data with
  ``optimizer=None``, so a tell costs no fit).
- **ask and recommend**: c-bo's own acquisitions, candidates and L-BFGS-B over θ's unit box, on
  scikit-learn's posterior. ``GaussianProcessRegressor`` predicts a mean and a standard deviation but no
  gradient with respect to the inputs, so the gradient is a central difference (Eq. L1 below), from one
  prediction of 2d + 1 points. The posterior is the latent function's: scikit-learn's predictive variance
  less the ``WhiteKernel``'s noise (Eq. L2).
- **The kriging believer** within a batch refits the model on one more point with the same kernel
  (scikit-learn has no rank-one update).

Equations::

    (L1)  ∂f/∂x_i ≈ (f(x + h e_i) − f(x − h e_i)) / 2h,  h = 1e-6 (the unit box's units), for f = μ and σ²
    (L2)  σ²_latent(x) = max(σ²_sklearn(x) − σ²_noise · sd(y)², 0)

with sd(y) scikit-learn's scale of the targets under ``normalize_y`` (their standard deviation, 1 where it
is 0). Randomness: the fit's ``random_state`` is drawn from the optimiser's Generator, so the same seed gives
the same run. The options ``prior_mean``, ``trend`` and ``hyper_restarts`` belong to c-bo's own GP and must
keep their defaults (:class:`~benchmarks.low_budget.library_gp.LibraryGPConfig`). Needs scikit-learn, which
no extra of creps_gym installs (``pip install scikit-learn``).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from benchmarks.low_budget.library_gp import LibraryGPCBO, LibraryGPConfig
from creps_gym.optimizers.cbo_config import CBOConfig

__all__ = ["SklearnCBO", "SklearnConfig", "SklearnGP"]

Array = NDArray[np.float64]
STEP = 1e-6  #: h of Eq. (L1)


def _gpr() -> Any:
    """scikit-learn's ``GaussianProcessRegressor`` and kernels (ImportError saying how to install them)."""
    try:
        from sklearn.gaussian_process import GaussianProcessRegressor, kernels
    except ImportError as error:
        raise ImportError(f"c-bo-sklearn needs scikit-learn: `pip install scikit-learn` ({error})") from None
    return GaussianProcessRegressor, kernels


def _kernel(d: int) -> Any:
    """The kernel's structure and start: ``ConstantKernel() * RBF(ones(d)) + WhiteKernel()``."""
    kernels = _gpr()[1]
    return kernels.ConstantKernel() * kernels.RBF(length_scale=np.ones(d)) + kernels.WhiteKernel()


def _regressor(kernel: Any, fit: bool, seed: int = 0) -> Any:
    """A ``GaussianProcessRegressor`` on ``kernel``: fitting its hyperparameters by the library's default
    (``fit``, from ``random_state`` ``seed``) or keeping them (``optimizer=None``)."""
    regressor = _gpr()[0]
    if fit:
        return regressor(kernel, normalize_y=True, random_state=seed)
    return regressor(kernel, normalize_y=True, optimizer=None)


def _fitted(gp: Any, inputs: Array, targets: Array) -> Any:
    """``gp.fit(inputs (n, d), targets (n,))`` without the library's notices."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # bounds reached and L-BFGS-B's convergence notices
        return gp.fit(inputs, targets)


@dataclass(frozen=True, eq=False)
class SklearnConfig(LibraryGPConfig):
    """:class:`~benchmarks.low_budget.library_gp.LibraryGPConfig` for :class:`SklearnCBO`."""

    column: ClassVar[str] = "c-bo-sklearn"
    library: ClassVar[str] = "scikit-learn"


class SklearnGP:
    """A fitted ``GaussianProcessRegressor`` behind the calls c-bo's shared code makes of a model.

    ``predict(x (m, d)) -> (mean (m,), variance (m,))``: the latent function's posterior, Eq. (L2);
    ``predict_with_gradient(x (1, d))``: that and the gradients (1, d) of Eq. (L1); ``condition(x (d,), y)``:
    the model with one more observation. ``beta`` is None: no quadratic trend.
    """

    beta = None

    def __init__(self, gp: Any, inputs: Array, targets: Array) -> None:
        self.gp, self._inputs, self._targets = gp, inputs, targets
        scale = float(np.std(targets)) if targets.shape[0] else 1.0
        scale = scale if scale > 0.0 else 1.0  # scikit-learn's normalize_y leaves a constant target unscaled
        self._noise = float(gp.kernel_.k2.noise_level) * scale**2

    @property
    def inputs(self) -> Array:
        """The inputs (n, d) the model holds: the told episodes' and the kriging believer's fantasies."""
        return self._inputs

    @property
    def observation_noise(self) -> float:
        """The ``WhiteKernel``'s noise variance in the units of :meth:`predict` (MES's floor, Eq. A4)."""
        return self._noise

    def predict(self, x: Array) -> tuple[Array, Array]:
        mean, std = self.gp.predict(np.asarray(x, dtype=np.float64), return_std=True)
        return mean.astype(np.float64), np.maximum(std.astype(np.float64) ** 2 - self._noise, 0.0)  # Eq. (L2)

    def predict_with_gradient(self, x: Array) -> tuple[Array, Array, Array, Array]:
        point = np.asarray(x, dtype=np.float64).reshape(-1)
        steps = STEP * np.eye(point.shape[0])
        mean, variance = self.predict(np.vstack([point, point + steps, point - steps]))
        d = point.shape[0]
        dmean = (mean[1 : d + 1] - mean[d + 1 :]) / (2.0 * STEP)  # Eq. (L1)
        dvariance = (variance[1 : d + 1] - variance[d + 1 :]) / (2.0 * STEP)
        return mean[:1], variance[:1], dmean[None, :], dvariance[None, :]

    def condition(self, x: Array, y: float) -> SklearnGP:
        inputs = np.vstack([self._inputs, np.asarray(x, dtype=np.float64)[None, :]])
        targets = np.append(self._targets, float(y))
        return SklearnGP(_fitted(_regressor(self.gp.kernel_, fit=False), inputs, targets), inputs, targets)


class SklearnCBO(LibraryGPCBO):
    """c-bo with scikit-learn's GP (see the module docstring).

    Parameters
    ----------
    n_params, n_context_dims : int
        p and z.
    **options
        The fields of :class:`SklearnConfig`: c-bo's options.
    """

    kind: ClassVar[str] = "c-bo-sklearn"
    config_class: ClassVar[type] = SklearnConfig

    def _init_from_config(self, config: CBOConfig) -> None:
        _gpr()  # fail at construction, not at the first tell, where scikit-learn is missing
        super()._init_from_config(config)

    def _fit(self, inputs: Array, targets: Array, seed: int) -> tuple[list[str], Array]:
        """scikit-learn's fit on (inputs (n, d), targets (n,)): the kernel's hyperparameter names and its
        ``theta`` (the log of their values)."""
        gp = _fitted(_regressor(_kernel(inputs.shape[1]), fit=True, seed=seed), inputs, targets)
        names = [parameter.name for parameter in gp.kernel_.hyperparameters]
        return names, np.asarray(gp.kernel_.theta, dtype=np.float64).copy()

    def _model(self, inputs: Array, targets: Array, names: list[str], hyper: Array) -> SklearnGP:
        """A ``GaussianProcessRegressor`` on every episode with the kept hyperparameters (no fit)."""
        kernel = _kernel(inputs.shape[1])
        expected = [parameter.name for parameter in kernel.hyperparameters]
        if names != expected or hyper.shape[0] != kernel.theta.shape[0]:
            raise ValueError(
                f"hyper_names: expected scikit-learn's hyperparameters {expected} ({kernel.theta.shape[0]} "
                f"values), got {names} ({hyper.shape[0]})"
            )
        gp = _fitted(_regressor(kernel.clone_with_theta(hyper), fit=False), inputs, targets)
        return SklearnGP(gp, inputs, targets)

    def _log_hyper(self, model: SklearnGP) -> Array:
        """c-bo's layout of the hyperparameters, in the normalised targets' units: log lengthscales, log
        signal variance (the ``ConstantKernel``'s value) and log noise variance (the ``WhiteKernel``'s)."""
        kernel = model.gp.kernel_
        lengthscales = np.atleast_1d(kernel.k1.k2.length_scale).astype(np.float64)
        signal, noise = float(kernel.k1.k1.constant_value), float(kernel.k2.noise_level)
        return np.concatenate([np.log(lengthscales), [np.log(signal), np.log(noise)]])
