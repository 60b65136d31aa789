"""Which GP for c-bo: scikit-learn's GaussianProcessRegressor and BoTorch's SingleTaskGP against the
numpy/scipy GP of ``creps_gym.optimizers.gp_model``, on the data an ask sees at 200 and 500 episodes
(p = 4, z = 1).

Measured per data size n (the Sphere's returns at random (s, θ) in the unit box, same kernel: ARD Matérn-5/2
plus a noise term):

* ``fit``: a hyperparameter fit (maximum likelihood, one random restart: sklearn's ``n_restarts_optimizer=1``,
  ours ``fit_hyperparameters(..., restarts=1)``; BoTorch: ``fit_gpytorch_mll`` from its default start, which
  retries only on failure);
* ``predict``: mean and standard deviation at the 320 candidates an ask scores per context;
* ``gradient_eval``: one evaluation of the acquisition's value and gradient in θ for L-BFGS-B. scikit-learn
  gives no gradient with respect to the inputs, so its figure is q + 1 = 5 single-point predictions (central
  differences would need 2q + 1); BoTorch's is UCB (β = 4) and its autograd backward pass at one point;
* ``ask_per_episode``: c-bo's own time per asked episode, a batch of 4 after n episodes; for BoTorch, its
  ``optimize_acqf`` of UCB over θ with s fixed (``FixedFeatureAcquisitionFunction``, 320 raw samples, 3
  L-BFGS-B restarts, the fitted model kept), per context of the same 4.

BoTorch runs in float64 on one torch thread (``torch.set_num_threads(1)``, as ``OPENBLAS_NUM_THREADS=1``
gives the others one BLAS thread). It needs torch, which the default install leaves out (PyPI's Linux
wheels pull several GB of CUDA libraries): with a CPU build of torch, ``pip install botorch``; without it the
BoTorch rows are left out.

    OPENBLAS_NUM_THREADS=1 python -m benchmarks.low_budget.gp_backends --out gp_backends.json
"""

from __future__ import annotations

import sys
from pathlib import Path

if not __package__:  # run by path: the repository root first on sys.path, as `python -m` puts it
    sys.path[0] = str(Path(__file__).resolve().parents[2])

import argparse
import json
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from benchmarks.low_budget import add_output_arguments, replay_command
from benchmarks.provenance import provenance
from creps_gym.optimizers import make_optimizer
from creps_gym.optimizers.gp_model import default_start, fit_gp, fit_hyperparameters

P, Z, CANDIDATES = 4, 1, 320


def _seconds(function: Callable[[], Any], repeats: int) -> float:
    """The median wall time of ``repeats`` calls."""
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        function()
        times.append(time.perf_counter() - start)
    return float(np.median(times))


def _data(n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    inputs = rng.uniform(size=(n, P + Z))
    returns = -(((inputs[:, Z:] - 0.5) * 12.0 + inputs[:, :Z]) ** 2).sum(axis=1)
    return inputs, (returns - returns.mean()) / returns.std()


def sklearn_times(n: int, repeats: int) -> dict[str, float]:
    """scikit-learn's fit, predict and gradient-evaluation times (see the module docstring)."""
    from sklearn.gaussian_process import GaussianProcessRegressor
    from sklearn.gaussian_process.kernels import ConstantKernel, Matern, WhiteKernel

    inputs, targets = _data(n, np.random.default_rng(0))
    kernel = ConstantKernel(1.0) * Matern(np.full(P + Z, 0.5), nu=2.5) + WhiteKernel(1e-3)
    model = GaussianProcessRegressor(kernel, n_restarts_optimizer=1, random_state=0)
    fit = _seconds(lambda: model.fit(inputs, targets), repeats)
    candidates = np.random.default_rng(1).uniform(size=(CANDIDATES, P + Z))
    predict = _seconds(lambda: model.predict(candidates, return_std=True), repeats)
    one = candidates[:1]
    gradient = _seconds(lambda: [model.predict(one, return_std=True) for _ in range(P + 1)], repeats)
    return {"fit": fit, "predict": predict, "gradient_eval": gradient}


def numpy_times(n: int, repeats: int) -> dict[str, float]:
    """Our GP's fit, predict and gradient-evaluation times, and c-bo's ask time per episode."""
    inputs, targets = _data(n, np.random.default_rng(0))
    start = default_start(P + Z)
    fit = _seconds(lambda: fit_hyperparameters(inputs, targets, start, np.random.default_rng(0), 1), repeats)
    model = fit_gp(inputs, targets, fit_hyperparameters(inputs, targets, start, np.random.default_rng(0), 1))
    candidates = np.random.default_rng(1).uniform(size=(CANDIDATES, P + Z))
    predict = _seconds(lambda: model.predict(candidates), repeats)
    gradient = _seconds(lambda: model.predict_with_gradient(candidates[:1]), repeats)
    optimizer = make_optimizer("c-bo", P, Z, 0, initial_cov=4.0)
    rng = np.random.default_rng(2)
    contexts = rng.uniform(0, 1, (n, Z))
    params = rng.uniform(-6, 6, (n, P))
    optimizer.tell(contexts, params, -((params + contexts) ** 2).sum(axis=1), allow_external=True)
    asked = rng.uniform(0, 1, (4, Z))
    ask = _seconds(lambda: optimizer.ask(asked), repeats) / 4
    return {"fit": fit, "predict": predict, "gradient_eval": gradient, "ask_per_episode": ask}


def botorch_times(n: int, repeats: int) -> dict[str, float] | None:
    """BoTorch's fit, predict, gradient-evaluation and acquisition-optimisation times (see the module
    docstring); None when BoTorch is not installed."""
    try:
        import torch
        from botorch.acquisition import FixedFeatureAcquisitionFunction, UpperConfidenceBound
        from botorch.fit import fit_gpytorch_mll
        from botorch.models import SingleTaskGP
        from botorch.optim import optimize_acqf
        from gpytorch.kernels import MaternKernel, ScaleKernel
        from gpytorch.mlls import ExactMarginalLogLikelihood
    except ImportError:
        return None
    torch.set_num_threads(1)
    torch.manual_seed(0)
    inputs, targets = (torch.from_numpy(a) for a in _data(n, np.random.default_rng(0)))

    def fitted() -> Any:  # a new model each time: every fit starts from BoTorch's default hyperparameters
        kernel = ScaleKernel(MaternKernel(nu=2.5, ard_num_dims=P + Z))
        model = SingleTaskGP(inputs, targets[:, None], covar_module=kernel)
        fit_gpytorch_mll(ExactMarginalLogLikelihood(model.likelihood, model))
        return model

    fit = _seconds(fitted, repeats)
    model = fitted()
    candidates = torch.from_numpy(np.random.default_rng(1).uniform(size=(CANDIDATES, P + Z)))
    model.eval()

    def predict() -> tuple[Any, Any]:
        with torch.no_grad():
            posterior = model.posterior(candidates)
            return posterior.mean, posterior.variance

    acquisition = UpperConfidenceBound(model, beta=4.0)

    def gradient() -> None:
        point = candidates[:1, None, :].clone().requires_grad_(True)
        acquisition(point).sum().backward()

    bounds = torch.stack([torch.zeros(P), torch.ones(P)]).double()
    asked = torch.from_numpy(np.random.default_rng(2).uniform(0, 1, (4, Z)))

    def ask() -> None:
        for context in asked:
            fixed = FixedFeatureAcquisitionFunction(acquisition, P + Z, list(range(Z)), context[None, :])
            optimize_acqf(fixed, bounds, q=1, num_restarts=3, raw_samples=CANDIDATES)

    times = {"fit": fit, "predict": _seconds(predict, repeats), "gradient_eval": _seconds(gradient, repeats)}
    return {**times, "ask_per_episode": _seconds(ask, repeats) / 4}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", nargs="+", type=int, default=[200, 500])
    parser.add_argument("--repeats", type=int, default=3)
    add_output_arguments(parser)
    args = parser.parse_args(argv)
    if args.render_only:
        render(args.out)
        return
    results = {}
    for n in args.sizes:
        results[str(n)] = {"sklearn": sklearn_times(n, args.repeats), "numpy": numpy_times(n, args.repeats)}
        botorch = botorch_times(n, args.repeats)
        if botorch is not None:
            results[str(n)]["botorch"] = botorch
        print(n, json.dumps(results[str(n)]), flush=True)
    document = {
        "command": sys.argv,
        "results": results,
        "provenance": provenance(["scikit-learn", "torch", "botorch", "gpytorch"]),
    }
    args.out.write_text(json.dumps(document, indent=1) + "\n")
    print(render(args.out))


def render(path: Path) -> str:
    """Write the table of the results at ``path`` (JSON) to the same name with ``.md``; returns it."""
    document = json.loads(path.read_text())
    lines = [
        "| episodes n | GP | fit (s) | predict, 320 candidates (s) | value + gradient in θ (s) | "
        "ask per episode (s) |",
        "|---|---|---|---|---|---|",
    ]
    for n, row in document["results"].items():
        for name, times in row.items():
            ask = f"{times['ask_per_episode']:.3g}" if "ask_per_episode" in times else "–"
            lines.append(
                f"| {n} | {name} | {times['fit']:.3g} | {times['predict']:.3g} | "
                f"{times['gradient_eval']:.3g} | {ask} |"
            )
    command = replay_command("gp_backends", document)
    text = "\n".join(lines) + f"\n\nMedians of the repeats. Command: `OPENBLAS_NUM_THREADS=1 {command}`.\n"
    path.with_suffix(".md").write_text(text)
    return text


if __name__ == "__main__":
    main()
