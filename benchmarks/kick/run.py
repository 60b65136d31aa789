"""Reproduce the paper's humanoid kick experiments (section 5.3) through the generic path: Fig. 5c and Fig. 7.

* precision (Fig. 5c): C-CMA-ES, CREPS-CMA (old mean) and CREPS on ``creps_gym/KickPrecision-v1`` (falls
  graded by severity), 20 samples per iteration, training targets drawn from Beta(½, ½) on [3, 12] m (the
  ends more often than uniform draws); the mean policy's distance to the target, averaged over 10 targets
  in [3, 12] m.
  Paper: 0.34 ± 0.11 m after 1,000 iterations.
* flexibility (Fig. 7): CREPS, CREPS-CMA (old mean) and C-CMA-ES on ``creps_gym/KickFlexibility-v2``
  (forward distance only; a miss scores its foot-ball distance), 100 samples per iteration; the mean
  policy's forward kick distance averaged over the 4 × 7 grid of ball positions. Paper after 700
  iterations: 6.50 ± 2.95 m (CREPS-CMA) against 2.67 ± 2.69 m (CREPS).
* oracles: pycma learning each target (precision) and each of the 28 ball positions (flexibility) alone,
  with a generous budget: the yardstick of what this robot reaches (``--only oracle`` runs only them).

Every optimiser is a registry name started from the env-declared initial distribution through
:class:`~creps_gym.wrappers.OffsetParams` (see :mod:`benchmarks.kick.study`). Runs checkpoint as they go and
rerunning a command resumes them; ``results.json`` and the rendering (``summary.md``, figures) are rebuilt
from the finished runs after every invocation (:mod:`benchmarks.kick.report`). Two invocations with
different ``--only`` can run side by side.

    python benchmarks/kick/run.py --quick                      # computes every run again: minutes on 2 cores
    python benchmarks/kick/run.py --quick --render-only        # re-renders the committed quick runs
    python benchmarks/kick/run.py --full --only precision      # hours; resumable
    python benchmarks/kick/run.py --full --render-only         # results.json, summary.md, figures

``--contexts NAME`` trains every selected method on other training contexts: ``uniform``, ``arcsine`` or a
learning selector of :mod:`creps_gym.selectors` (``bandit``, ``progress``); its runs go to
``results/<mode>-<NAME>`` unless ``--out`` says otherwise, e.g.
``python benchmarks/kick/run.py --full --only precision --methods creps-cma-old --contexts bandit``.

``--features NAME`` gives every selected method other mean features (``affine``, ``quadratic`` or ``rbf``,
:meth:`~benchmarks.kick.study.RunSpec.mean_features`); its runs go to ``results/<mode>-features-<NAME>``
(``results/<mode>-<contexts>-features-<NAME>`` with ``--contexts``), e.g.
``python benchmarks/kick/run.py --full --only flexibility --methods c-cma-es --features quadratic``.

``--opt KEY=VALUE`` (repeatable; VALUE is JSON or a plain string) gives every selected method these optimiser
options on top of ``METHODS``' own, checked by the optimiser's config before anything runs; its runs go to
``results/<mode>[-<contexts>][-features-<NAME>]-opt-<slug>`` (:func:`~benchmarks.kick.study.options_slug`) and
their run files record the merged options. A trial draws the study's seeds and contexts, so its run differs
from the study's run of the same trial in the options only, e.g.
``python benchmarks/kick/run.py --full --only precision --methods creps-cma-old --opt epsilon=1.0``.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from functools import partial
from pathlib import Path
from typing import Any

# Run by path: the repository root first on sys.path, as `python -m` puts it (see benchmarks/__init__.py).
if not __package__:
    sys.path[0] = str(Path(__file__).resolve().parents[2])

import numpy as np

from benchmarks.kick.oracle import oracle_point
from benchmarks.kick.report import render
from benchmarks.kick.study import (
    FEATURES,
    SELECTED_CONTEXTS,
    TRAINING,
    TRAINING_CONTEXTS,
    RunSpec,
    evaluation_contexts,
    make_env,
    results_folder,
    train_run,
)
from benchmarks.study_options import C3_PIN
from benchmarks.study_tools import NO_STAGNATION
from creps_gym.cli.types import key_value
from creps_gym.optimizers.registry import make_optimizer
from creps_gym.runner.protocol import check_batch_size

RESULTS = Path(__file__).resolve().parent / "results"
#: Budgets per mode: (iterations, trials) per experiment, and the oracle's episodes per position.
MODES = {
    "quick": {"precision": (40, 1), "flexibility": (8, 1), "oracle": 130},
    "full": {"precision": (1000, 3), "flexibility": (700, 3), "oracle": 3000},
}
SAMPLES = {"precision": 20, "flexibility": 100}
#: Every method runs the paper's whole budget: the stagnation criterion (meant for noise-free problems) is
#: off, the optimisers' other stop criteria (a degenerate covariance, ...) still end a run.
FULL_BUDGET = {"tolstagnation": NO_STAGNATION}
RBF = {"ridge": 1e-2, **FULL_BUDGET}
#: C-CMA-ES on the precision task (``KickPrecision-v1``) ranks each sample against a local baseline, the
#: kernel-weighted median of the recent returns at nearby targets (bandwidth 0.3 context standard
#: deviations, about 0.8 m): near 12 m nearly every sample falls, and a polynomial baseline, least squares or
#: Huber's, ranks all those falls last whatever their severity, so the mean there has no direction back to a
#: kick that stands (docs/algorithms.md, C1''). Its mean moves half way to each new fit (c_m = 0.5): the
#: regression on μ_eff ≈ 6 samples moves the mean at the targets' ends by about 0.8 σ per iteration under
#: blind selection, enough to step into a fall. README, "Where the precision error came from", has the
#: settings this replaced (Huber's baseline on v0; mean_repulsion).
LOCAL = {"baseline_bandwidth": 0.3, "c_m": 0.5, **FULL_BUDGET}
#: The methods of each experiment: registry name, mean features, options. C-CMA-ES keeps C3 (the mean fit's
#: ridge towards 0, its default before issue 45), with which its committed runs were computed. The CREPS
#: methods use the paper's RBF features; C-CMA-ES keeps its default affine features, because its mean is a
#: regression on the μ = N/2 selected samples only (μ_eff ≈ 6 at N = 20), too few for 5 RBF coefficients per
#: parameter without a strong ridge, which would then pull the mean back towards the reference kick at every
#: update.
METHODS = {
    "precision": (
        ("c-cma-es", "affine", {**LOCAL, **dict(C3_PIN)}),
        ("creps-cma-old", "rbf", RBF),
        ("creps", "rbf", RBF),
    ),
    "flexibility": (
        ("creps", "rbf", RBF),
        ("creps-cma-old", "rbf", RBF),
        ("c-cma-es", "affine", {**FULL_BUDGET, **dict(C3_PIN)}),
    ),
}


def _parser() -> argparse.ArgumentParser:
    """The command line's options (:func:`parse_args` resolves and checks them)."""
    parser = argparse.ArgumentParser(description="Reproduce the paper's kick experiments (Fig. 5c, Fig. 7).")
    mode = parser.add_mutually_exclusive_group()
    mode.add_argument("--quick", action="store_true", help="small budgets (default)")
    mode.add_argument("--full", action="store_true", help="the paper's budgets")
    parser.add_argument("--only", choices=("precision", "flexibility", "oracle"), default=None)
    parser.add_argument("--methods", nargs="+", default=None, help="registry names to run (default: all)")
    parser.add_argument("--trials", type=int, default=None, help="override the mode's number of trials")
    parser.add_argument(
        "--iterations",
        type=int,
        default=None,
        help="override the mode's iterations (a screening budget; rerun without it to resume to the mode's)",
    )
    parser.add_argument(
        "--trial-indices",
        type=int,
        nargs="+",
        default=None,
        help="run only these trials (0-based; e.g. one trial per process on another core)",
    )
    parser.add_argument("--render-only", action="store_true", help="compute nothing; render finished runs")
    parser.add_argument("--out", type=Path, default=None, help="default: benchmarks/kick/results/<mode>")
    parser.add_argument("--threads", type=int, default=0, help="simulation threads (0: all CPUs)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--checkpoint-every", type=int, default=10)
    parser.add_argument(
        "--contexts",
        choices=[*TRAINING_CONTEXTS, *SELECTED_CONTEXTS],
        default=None,
        help="training contexts of every experiment (default: TRAINING's); runs go to results/<mode>-<NAME>",
    )
    parser.add_argument(
        "--features",
        choices=FEATURES,
        default=None,
        help="mean features of every method (default: METHODS'); runs go to results/<mode>-features-<NAME>",
    )
    parser.add_argument(
        "--opt",
        action="append",
        type=key_value,
        default=[],
        metavar="KEY=VALUE",
        help="optimiser option of every selected method, VALUE in JSON or a string (repeatable); "
        "runs go to results/<mode>-opt-<slug>",
    )
    return parser


def parse_args(argv: Sequence[str] | None = None) -> argparse.Namespace:
    """The options, with the mode, the checked ``--opt`` options and the results folder resolved."""
    parser = _parser()
    args = parser.parse_args(argv)
    args.mode = "full" if args.full else "quick"
    args.options = _options(parser, args)
    if args.out is None:
        try:
            args.out = RESULTS / results_folder(args.mode, args.contexts, args.features, args.options)
        except ValueError as exc:
            parser.error(f"argument --opt: {exc}")
    if args.iterations is not None and args.iterations < 1:
        parser.error(f"--iterations: expected an int >= 1, got {args.iterations}")
    if args.trials is not None and args.trials < 1:
        parser.error(f"--trials: expected an int >= 1, got {args.trials}")
    if args.trial_indices is not None and min(args.trial_indices) < 0:
        parser.error(f"--trial-indices: expected ints >= 0, got {args.trial_indices}")
    return args


def _options(parser: argparse.ArgumentParser, args: argparse.Namespace) -> dict[str, Any]:
    """The ``--opt`` options as a dict, each checked by one ask/tell of every selected method with them on a
    synthetic batch of the experiment's size (:func:`creps_gym.runner.protocol.check_batch_size`); a repeated
    KEY, or an option a method refuses, is a usage error naming it."""
    keys = [key for key, _ in args.opt]
    if repeated := sorted({key for key in keys if keys.count(key) > 1}):
        parser.error(f"argument --opt: expected each KEY once, got {repeated} more than once")
    options = dict(args.opt)
    for spec, _ in run_specs(args, options) if options else []:
        points = evaluation_contexts(spec.experiment)
        contexts = points[np.arange(spec.samples) % len(points)]
        try:
            check_batch_size(partial(_synthetic_optimizer, spec), contexts, spec.options, spec.name)
        except (TypeError, ValueError) as exc:
            parser.error(f"argument --opt: {spec.name}: {exc}")
    return options


def _synthetic_optimizer(spec: RunSpec) -> Any:
    """``spec``'s optimiser with its options on a two-parameter problem of the experiment's contexts."""
    z = evaluation_contexts(spec.experiment).shape[1]
    return make_optimizer(spec.name, 2, z, 0, mean_features=spec.mean_features(), **spec.options)


def run_specs(args: argparse.Namespace, options: dict[str, Any] | None = None) -> list[tuple[RunSpec, int]]:
    """(spec, trials) of every training run the arguments select, with the ``--opt`` ``options`` (default:
    ``args.options``) on top of ``METHODS``' own."""
    extra = getattr(args, "options", {}) if options is None else options
    runs = []
    for experiment, methods in METHODS.items():
        if args.only not in (None, experiment):
            continue
        iterations, trials = MODES[args.mode][experiment]
        iterations = getattr(args, "iterations", None) or iterations
        for name, features, method_options in methods:
            if args.methods is None or name in args.methods:
                options = {**method_options, **extra}
                spec = RunSpec(
                    experiment,
                    name,
                    SAMPLES[experiment],
                    iterations,
                    args.features or features,
                    options,
                    args.contexts or TRAINING[experiment],
                )
                runs.append((spec, args.trials or trials))
    return runs


def trial_numbers(args: argparse.Namespace, trials: int) -> list[int]:
    """The trials to run: ``--trial-indices`` if given, else 0 .. trials - 1."""
    return list(args.trial_indices) if args.trial_indices is not None else list(range(trials))


def compute(args: argparse.Namespace) -> None:
    """Per selected experiment: the per-context oracle (unless ``--methods`` picks methods), then every
    method's trials. ``--full``: finished runs are read back and unfinished ones resume; ``--quick`` is a
    reproduction: it computes every selected run and oracle again."""
    envs: dict[str, Any] = {}
    experiments = [e for e in METHODS if args.only in (None, "oracle", e)]
    if args.methods is None:
        for experiment in experiments:
            env = envs.setdefault(experiment, make_env(experiment, args.threads))
            for index in range(len(evaluation_contexts(experiment))):
                result = oracle_point(
                    env,
                    experiment,
                    index,
                    MODES[args.mode]["oracle"],
                    args.seed,
                    args.out / "runs" / experiment,
                    fresh=args.mode == "quick",
                )
                print(f"{experiment} oracle at {result['context']}: {result['value']:.2f} m", flush=True)
    if args.only == "oracle":
        return
    for spec, trials in run_specs(args):
        env = envs.setdefault(spec.experiment, make_env(spec.experiment, args.threads))
        for trial in trial_numbers(args, trials):
            result = train_run(
                spec,
                env,
                trial,
                args.seed,
                args.out / "runs" / spec.experiment,
                args.checkpoint_every,
                fresh=args.mode == "quick",
            )
            metric = sum(result["values"]) / len(result["values"])
            print(
                f"{spec.experiment} {spec.name} trial {trial}: {metric:.2f} m "
                f"after {result['iterations']} iterations",
                flush=True,
            )


def main(argv: Sequence[str] | None = None) -> int:
    args = parse_args(argv)
    if not args.render_only:
        compute(args)
    print(render(args.out, args.mode, MODES[args.mode]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
