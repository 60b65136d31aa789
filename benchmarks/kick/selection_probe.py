"""Does C-CMA-ES's selection pick kicks or targets? Selection rates per range of targets under a run's policy.

C-CMA-ES ranks the advantages a_k = R_k − V(s_k). If the context baseline V follows E[R | s], about half of
the samples in every range of targets are selected (ranked in the best N/2), and selection is about the kick θ
alone. If V cannot follow E[R | s], selection favours the targets where V is too low and starves the others.
This probe draws ``--batches`` batches of 20 kicks from a finished precision run's final policy at targets s ~
U[3, 12] m (the paper's draw; the study now trains on Beta(½, ½)), computes the advantages as the optimiser
does (each batch with the two batches before it, ``baseline_batches=3``) for several baseline degrees and
losses, and prints, per baseline, the fraction of samples selected in each range of targets, after a first
line with the median return in each range. Each line of output is a JSON object.

    python benchmarks/kick/selection_probe.py --run c-cma-es-trial1
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np

if __package__ in (None, ""):  # run as a script: make ``benchmarks`` importable
    sys.path[0] = str(Path(__file__).resolve().parents[2])

from benchmarks.kick.study import evaluate, load_run, make_env
from creps_gym.optimizers.contextual import context_advantages

FOLDER = Path(__file__).resolve().parent / "results" / "full" / "runs" / "precision"
BINS = ((3.0, 5.0), (5.0, 7.0), (7.0, 9.0), (9.0, 11.0), (11.0, 12.0))
BATCH = 20


def selection_rates(
    batches: list[tuple[np.ndarray, np.ndarray]], degree: int, loss: str, reuse: int = 2
) -> list[float]:
    """Per bin of ``BINS``: the fraction of samples ranked in their batch's best half by a_k = R_k − V(s_k).

    ``batches`` holds (contexts (n, 1), returns (n,)) in order; the baseline of batch b is fitted on it and on
    the ``reuse`` batches before it, so the first ``reuse`` batches only serve as history.
    """
    contexts, selected = [], []
    for index in range(reuse, len(batches)):
        history = batches[index - reuse : index]
        past_contexts = np.concatenate([c for c, _ in history]) if reuse else None
        past_returns = np.concatenate([r for _, r in history]) if reuse else None
        s, returns = batches[index]
        past = (past_contexts, past_returns)
        advantages, _ = context_advantages(s, returns, degree, 1e-10, *past, False, loss)
        rank = np.argsort(np.argsort(-advantages, kind="stable"), kind="stable")
        contexts.append(s[:, 0])
        selected.append(rank < s.shape[0] // 2)
    s, chosen = np.concatenate(contexts), np.concatenate(selected)
    return [float(chosen[(s >= low) & (s < high)].mean()) for low, high in BINS]


def probe(run: Path, n_batches: int, seed: int, degrees: Sequence[int]) -> list[dict[str, object]]:
    """The report lines: the median return per bin of targets, then one per (loss, degree) with the
    selection rate per bin."""
    env = make_env("precision", threads=1)
    learner = load_run(run)
    rng = np.random.default_rng(seed)
    batches = []
    for _ in range(n_batches):
        contexts = rng.uniform(3.0, 12.0, (BATCH, 1))
        returns, _ = evaluate(env, contexts, learner.ask(contexts))
        batches.append((contexts, returns))
    bins = [f"[{low:g}, {high:g})" for low, high in BINS]
    s = np.concatenate([c[:, 0] for c, _ in batches])
    returns = np.concatenate([r for _, r in batches])
    medians = [round(float(np.median(returns[(s >= low) & (s < high)])), 3) for low, high in BINS]
    lines: list[dict[str, object]] = [
        {"run": run.name, "median_return_per_bin": dict(zip(bins, medians, strict=True))}
    ]
    for loss in ("huber", "squared"):
        for degree in degrees:
            rates = np.round(selection_rates(batches, degree, loss), 2).tolist()
            lines.append({"run": run.name, "baseline_loss": loss, "baseline_degree": degree,
                          "selected_per_bin": dict(zip(bins, rates, strict=True))})  # fmt: skip
    return lines


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--run", required=True, help="a finished run's stem, e.g. c-cma-es-trial1")
    parser.add_argument("--folder", type=Path, default=FOLDER)
    parser.add_argument("--batches", type=int, default=12, help="batches of 20 drawn (the first 2: history)")
    parser.add_argument("--degrees", type=int, nargs="+", default=[2, 3, 4])
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    run = args.folder / args.run
    if not run.with_suffix(".npz").exists():
        parser.error(f"--run: expected a checkpoint {run.with_suffix('.npz')}, got none")
    if args.batches < 3:
        parser.error(f"--batches: expected an int >= 3, got {args.batches}")
    for line in probe(run, args.batches, args.seed, args.degrees):
        print(json.dumps(line), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
