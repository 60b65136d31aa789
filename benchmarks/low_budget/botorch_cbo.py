"""c-bo built on BoTorch: the low-budget study's BoTorch column (issue 44, items 1 and 5).

The column ``c-bo-botorch``: the same contextual BO with BoTorch's model and optimisers in place of c-bo's
own, written as a BoTorch user would write it. Why the study measures it is in
:mod:`benchmarks.low_budget.library_gp`.

:class:`BoTorchCBO` subclasses :class:`~benchmarks.low_budget.library_gp.LibraryGPCBO` and keeps everything
that is not the model (the data, the scaling, the initial design, the transform, the refit schedule, the
kriging believer, Eqs. (R2) and (R3) and R1's trust region, the distilled policy and the checkpoints' data).
What BoTorch does:

- **The model**: ``SingleTaskGP`` with BoTorch's defaults (an RBF kernel with one lengthscale per input and
  BoTorch's dimension-scaled log-normal prior, a learned constant mean, the outcomes standardised), its
  hyperparameters fitted by ``fit_gpytorch_mll`` on a refit and kept in between (the model is rebuilt on
  all the data with them, so a tell costs no fit).
- **ask**: ``UpperConfidenceBound`` (μ + √β σ, c-bo's A1 with the same β) or ``qMaxValueEntropy`` (its
  max-value samples drawn over ``candidates`` random θ at the asked context), the context held fixed by
  ``FixedFeatureAcquisitionFunction``, maximised over θ's unit box by ``optimize_acqf`` (``raw_samples`` =
  ``candidates``, ``num_restarts`` = ``starts``).
- **recommend** (R1): ``PosteriorMean`` with the context fixed, maximised by ``optimize_acqf`` over R1's
  trust region B(s), and the best of G(s)'s θ kept if its posterior mean is larger; R2 and R3 are c-bo's
  own rules on BoTorch's posterior mean.

Randomness: every torch call runs inside ``torch.random.fork_rng`` seeded from the optimiser's numpy
Generator (asks) or from c-bo's fixed recommendation seed (``recommend``), so the same seed gives the same
run and torch's global generator is left as it was. Torch runs in float64 on ``threads`` threads (set
around each call, then restored). The options ``prior_mean``, ``trend`` and ``hyper_restarts`` belong to
c-bo's own GP and must keep their defaults; ``context_utility`` (the active selector's hook) is not
offered. Needs torch and BoTorch, which no extra of creps_gym installs (``pip install botorch`` with a CPU
build of torch).
"""

from __future__ import annotations

import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from benchmarks.low_budget.library_gp import SEEDS, LibraryGPCBO, LibraryGPConfig
from creps_gym.optimizers.cbo_config import CBOConfig, _bounded_int
from creps_gym.optimizers.cbo_recommend import RECOMMEND_SEED

__all__ = ["BoTorchCBO", "BoTorchConfig", "TorchGP"]

Array = NDArray[np.float64]
MAX_THREADS = 64


def _libraries() -> dict[str, Any]:
    """torch and the BoTorch/GPyTorch names this module uses (ImportError saying how to install them)."""
    try:
        import torch
        from botorch.acquisition import FixedFeatureAcquisitionFunction, PosteriorMean, UpperConfidenceBound
        from botorch.acquisition.max_value_entropy_search import qMaxValueEntropy
        from botorch.fit import fit_gpytorch_mll
        from botorch.models import SingleTaskGP
        from botorch.optim import optimize_acqf
        from gpytorch.mlls import ExactMarginalLogLikelihood
    except ImportError as error:
        raise ImportError(
            f"c-bo-botorch needs torch and BoTorch: `pip install botorch` with a CPU build of torch ({error})"
        ) from None
    return {
        "torch": torch,
        "FixedFeatureAcquisitionFunction": FixedFeatureAcquisitionFunction,
        "PosteriorMean": PosteriorMean,
        "UpperConfidenceBound": UpperConfidenceBound,
        "qMaxValueEntropy": qMaxValueEntropy,
        "fit_gpytorch_mll": fit_gpytorch_mll,
        "SingleTaskGP": SingleTaskGP,
        "optimize_acqf": optimize_acqf,
        "ExactMarginalLogLikelihood": ExactMarginalLogLikelihood,
    }


@contextmanager
def _torch_call(torch: Any, seed: int, threads: int) -> Iterator[None]:
    """Run torch with ``threads`` threads and its generator seeded with ``seed``, both restored after."""
    previous = torch.get_num_threads()
    torch.set_num_threads(threads)
    try:
        with torch.random.fork_rng(devices=[]), warnings.catch_warnings():
            warnings.simplefilter("ignore")  # BoTorch's input-scaling and optimisation notices
            torch.manual_seed(seed)
            yield
    finally:
        torch.set_num_threads(previous)


@dataclass(frozen=True, eq=False)
class BoTorchConfig(LibraryGPConfig):
    """:class:`~benchmarks.low_budget.library_gp.LibraryGPConfig` for :class:`BoTorchCBO`, and ``threads``.

    threads : int    torch's thread count during the optimiser's calls (default 1: one core, as
        ``OPENBLAS_NUM_THREADS=1`` gives the other methods of the study).
    """

    column: ClassVar[str] = "c-bo-botorch"
    library: ClassVar[str] = "BoTorch"
    threads: int = 1

    def __post_init__(self) -> None:
        super().__post_init__()
        object.__setattr__(self, "threads", _bounded_int(self.threads, "threads", 1, MAX_THREADS))


class TorchGP:
    """A fitted ``SingleTaskGP`` behind the two calls c-bo's shared code makes of a model.

    ``predict(x (m, d)) -> (mean (m,), variance (m,))``: the posterior of the latent function in the
    targets' units; ``condition(x (d,), y)``: the model with one more observation (BoTorch's
    ``condition_on_observations``). ``beta`` is None: no quadratic trend.
    """

    beta = None

    def __init__(self, gp: Any, torch: Any) -> None:
        self.gp, self._torch = gp, torch

    def predict(self, x: Array) -> tuple[Array, Array]:
        with self._torch.no_grad(), warnings.catch_warnings():
            warnings.simplefilter("ignore")  # a context outside the told range is outside the unit cube
            posterior = self.gp.posterior(self._torch.from_numpy(np.ascontiguousarray(x, dtype=np.float64)))
            mean, variance = posterior.mean.squeeze(-1), posterior.variance.squeeze(-1)
        return mean.numpy().astype(np.float64), variance.numpy().astype(np.float64)

    def condition(self, x: Array, y: float) -> TorchGP:
        torch = self._torch
        point, value = torch.from_numpy(np.asarray(x, np.float64)[None, :]), torch.tensor([[float(y)]])
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # as in predict
            return TorchGP(self.gp.condition_on_observations(point, value.double()), torch)


class BoTorchCBO(LibraryGPCBO):
    """c-bo with BoTorch's model, acquisitions and optimiser (see the module docstring).

    Parameters
    ----------
    n_params, n_context_dims : int
        p and z.
    **options
        The fields of :class:`BoTorchConfig`: c-bo's options and ``threads``.
    """

    kind: ClassVar[str] = "c-bo-botorch"
    config_class: ClassVar[type] = BoTorchConfig

    def _init_from_config(self, config: CBOConfig) -> None:
        self._lib = _libraries()
        super()._init_from_config(config)

    def _call(self, seed: int) -> Any:
        return _torch_call(self._lib["torch"], seed, self.config.threads)

    def _tensor(self, array: Array) -> Any:
        return self._lib["torch"].from_numpy(np.ascontiguousarray(array, dtype=np.float64))

    # -- the model -----------------------------------------------------------------------------------------
    def _fit(self, inputs: Array, targets: Array, seed: int) -> tuple[list[str], Array]:
        """BoTorch's maximum a posteriori fit on (inputs (n, d), targets (n,)): the raw hyperparameters'
        names and values, in the order of ``named_parameters``."""
        lib = self._lib
        with self._call(seed):
            gp = lib["SingleTaskGP"](self._tensor(inputs), self._tensor(targets[:, None]))
            lib["fit_gpytorch_mll"](lib["ExactMarginalLogLikelihood"](gp.likelihood, gp))
        named = list(gp.named_parameters())
        values = [parameter.detach().numpy().astype(np.float64).ravel() for _, parameter in named]
        return [name for name, _ in named], np.concatenate(values)

    def _model(self, inputs: Array, targets: Array, names: list[str], hyper: Array) -> TorchGP:
        """A ``SingleTaskGP`` on every episode with the kept hyperparameters (no fit)."""
        torch = self._lib["torch"]
        gp = self._lib["SingleTaskGP"](self._tensor(inputs), self._tensor(targets[:, None]))
        parameters = dict(gp.named_parameters())
        sizes = [parameters[name].numel() if name in parameters else -1 for name in names]
        if list(parameters) != names or sum(sizes) != hyper.shape[0]:
            raise ValueError(
                f"hyper_names: expected BoTorch's parameters {list(parameters)} "
                f"({sum(p.numel() for p in parameters.values())} values), got {names} ({hyper.shape[0]})"
            )
        with torch.no_grad():
            offset = 0
            for name, size in zip(names, sizes, strict=True):
                parameter = parameters[name]
                parameter.copy_(self._tensor(hyper[offset : offset + size]).reshape(parameter.shape))
                offset += size
        gp.eval()
        return TorchGP(gp, torch)

    def _log_hyper(self, model: TorchGP) -> Array:
        """c-bo's layout of the hyperparameters, for its diagnostics and ``stop``: log lengthscales, log
        signal variance and log noise variance, in the standardised outcomes' units. The signal variance is
        the kernel's ``outputscale`` where it has one (BoTorch before 0.12 scaled a Matérn kernel), else 1:
        since 0.12 the default kernel is an unscaled RBF on standardised outcomes."""
        covariance = model.gp.covar_module
        kernel = getattr(covariance, "base_kernel", covariance)
        lengthscales = kernel.lengthscale.detach().numpy().ravel()
        scale = getattr(covariance, "outputscale", None)
        signal = 0.0 if scale is None else float(np.log(scale.detach().numpy().ravel()[0]))
        noise = float(model.gp.likelihood.noise.detach().numpy().ravel()[0])
        return np.concatenate([np.log(lengthscales), [signal, np.log(noise)]]).astype(np.float64)

    # -- ask -----------------------------------------------------------------------------------------------
    def _propose(self, model: Any, context: Array) -> Array:
        """The acquisition's maximiser over θ's unit box at a scaled context (z,), by ``optimize_acqf``
        (``mes_floor`` plays no part: BoTorch's MES samples its maxima over its own candidate set)."""
        lib, p, z = self._lib, self.n_params, self.n_context_dims
        seed = int(self.rng.integers(SEEDS))
        torch, fixed = lib["torch"], self._tensor(context[None, :])
        with self._call(seed):
            if self.config.acquisition == "ucb":
                acquisition = lib["UpperConfidenceBound"](model.gp, beta=self.config.beta)
            else:
                thetas = torch.rand(self.config.candidates, p, dtype=torch.float64)
                candidate_set = torch.cat([fixed.expand(self.config.candidates, z), thetas], dim=1)
                acquisition = lib["qMaxValueEntropy"](
                    model.gp, candidate_set, num_mv_samples=self.config.mes_samples
                )
            unit = self._maximise(acquisition, fixed, np.zeros(p), np.ones(p), seed)
        return unit

    def _maximise(self, acquisition: Any, fixed: Any, low: Array, high: Array, seed: int) -> Array:
        """``optimize_acqf`` of ``acquisition`` over θ in [low, high] with the context columns fixed."""
        lib, z = self._lib, self.n_context_dims
        function = lib["FixedFeatureAcquisitionFunction"](
            acquisition, d=z + self.n_params, columns=list(range(z)), values=fixed
        )
        bounds = self._tensor(np.stack([low, high]))
        x, _ = lib["optimize_acqf"](
            function,
            bounds,
            q=1,
            num_restarts=self.config.starts,
            raw_samples=self.config.candidates,
            options={"seed": seed},
        )
        return np.clip(x.detach().numpy().astype(np.float64).reshape(self.n_params), low, high)

    # -- recommend -----------------------------------------------------------------------------------------
    def recommend(self, contexts: Any) -> Array:
        """Eq. (R1) with BoTorch's posterior mean and optimiser (see the module docstring), or c-bo's Eq.
        (R2) or (R3) on it: shape (n, p). Deterministic (a fixed seed): a context gives the same θ alone or
        in any batch."""
        if self.model is None or self.config.recommend_over != "trust_region":
            return super().recommend(contexts)
        contexts = self._check_contexts(contexts, "contexts")
        scaled = self._scaled_contexts(contexts)
        return self._unscaled_params(np.array([self._mean_maximiser(row) for row in scaled]))

    def _mean_maximiser(self, context: Array) -> Array:
        """R1 at one scaled context (z,): the posterior mean's maximiser over B(s), or G(s)'s best θ."""
        good, (low, high) = self.trust_region(context)
        model = self.model
        with self._call(RECOMMEND_SEED):
            mean = self._lib["PosteriorMean"](model.gp)  # type: ignore[union-attr]
            unit = self._maximise(mean, self._tensor(context[None, :]), low, high, RECOMMEND_SEED)
        options = np.vstack([unit, good])
        inputs = np.hstack([np.tile(context, (options.shape[0], 1)), options])
        return options[int(np.argmax(model.predict(inputs)[0]))]  # type: ignore[union-attr]
