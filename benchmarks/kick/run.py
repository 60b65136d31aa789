"""Reproduce the paper's humanoid kick experiments (section 5.3): Fig. 5c and Fig. 7.

* precision (Fig. 5c): CREPS-CMA (old mean) on ``creps_gym/KickPrecision-v0``, 20 samples per iteration,
  with linear (affine) and RBF mean features; the mean policy's error to the target, against the target
  distance. Paper: 0.34 ± 0.11 m after 1,000 iterations.
* flexibility (Fig. 7): CREPS against CREPS-CMA (old mean) on ``creps_gym/KickFlexibility-v0``, 100 samples
  per iteration, RBF features; a heatmap of the mean policy's kick distance over ball positions (median over
  trials). Paper after 700 iterations: 6.50 ± 2.95 m (CREPS-CMA) against 2.67 ± 2.69 m (CREPS).

The optimisers search the offset θ − θ_ref from the env's reference kick through the
:class:`~creps_gym.wrappers.OffsetParams` wrapper (centre: the reference kick, unit scale), starting at 0
with a small isotropic covariance. The ridge of the weighted maximum-likelihood mean fit of the RBF policies
(``--ridge``) then shrinks them towards the reference kick instead of towards the mid-range pose, which
falls; without it they drifted into falls (63 % of the samples after 60 iterations, against 14 % with it).
Linear (affine) policies keep the optimisers' default ridge, 1e-8.

Every run writes a checkpoint every ``--checkpoint-every`` iterations and its final result as JSON under
``--out``; rerunning the same command resumes where it stopped (contexts are drawn from
``default_rng([seed, trial, iteration])`` and the optimiser's checkpoint holds its own generator).

Usage::

    python benchmarks/kick/run.py --quick          # minutes on 2 cores
    python benchmarks/kick/run.py --full           # the paper's budgets (many hours)
    python benchmarks/kick/run.py --quick --only precision
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

import creps_gym  # noqa: F401  (registers the ids)
from creps_gym.optimizers import CREPS, CREPSCMA
from creps_gym.optimizers.features import RBFFeatures
from creps_gym.wrappers import OffsetParams

MODES: dict[str, dict[str, Any]] = {
    "quick": {"precision": (150, 1), "flexibility": (30, 2)},  # (iterations, trials)
    "full": {"precision": (1000, 3), "flexibility": (700, 10)},
}
PRECISION_SAMPLES, FLEXIBILITY_SAMPLES = 20, 100
TARGETS = np.linspace(3.0, 12.0, 10)
GRID_X, GRID_Y = np.linspace(0.15, 0.30, 4), np.linspace(-0.15, 0.15, 7)
PAPER = {
    "precision": "0.34 ± 0.11 m error (CREPS-CMA-old, RBF, 1000 iterations × 20 samples)",
    "flexibility": "CREPS-CMA-old 6.50 ± 2.95 m, CREPS 2.67 ± 2.69 m (700 iterations × 100 samples)",
}


def make_env(env_id: str, threads: int) -> OffsetParams:
    """The env under :class:`OffsetParams` centred on the reference kick with unit scale (offsets in
    normalised units; the search's σ is ``--sigma``). Batches go through ``evaluate_offsets``."""
    return OffsetParams(gym.make(env_id, num_threads=threads), scale=1.0)


def evaluate_offsets(env: OffsetParams, contexts: np.ndarray, offsets: np.ndarray) -> tuple[Any, Any]:
    """The unwrapped env's batched ``evaluate`` at ``reference + offsets`` (exactly, with unit scale)."""
    return env.unwrapped.evaluate(contexts, env.to_env(offsets))


def make_optimizer(spec: dict[str, Any], env: Any, args: argparse.Namespace, seed: int) -> Any:
    """CREPS or CREPS-CMA (old mean) over offsets from the reference kick, starting at 0."""
    features = spec["features"]
    # The relative ridge regularises RBF policies; on affine features (1, s) it would shrink the bias.
    ridge = args.ridge if isinstance(features, RBFFeatures) else 1e-8
    common = {
        "epsilon": 0.5,
        "initial_mean": np.zeros(25),
        "initial_cov": args.sigma**2,
        "mean_features": features,
        "ridge": ridge,
        "seed": seed,
    }
    if spec["algorithm"] == "CREPS":
        return CREPS(25, env.unwrapped.context_dim, **common)
    return CREPSCMA(25, env.unwrapped.context_dim, variant="old", **common)


def train(
    env: Any, opt: Any, samples: int, iterations: int, trial_seed: list[int], ckpt: Path, every: int
) -> Any:
    """Ask/tell loop from the optimiser's current iteration up to ``iterations``, with checkpoints."""
    history_path = ckpt.with_suffix(".history.json")
    history = json.loads(history_path.read_text()) if history_path.exists() else []
    history = history[: opt.iteration]
    while opt.iteration < iterations:
        rng = np.random.default_rng([*trial_seed, opt.iteration])
        contexts = env.unwrapped.sample_contexts(rng, samples)
        offsets = opt.ask(contexts)
        returns, info = evaluate_offsets(env, contexts, offsets)
        opt.tell(contexts, offsets, returns)
        history.append([float(returns.mean()), float(info["fell"].mean())])
        if opt.iteration % every == 0 or opt.iteration == iterations:
            opt.save(ckpt)
            history_path.write_text(json.dumps(history))
    return opt


def precision_errors(env: Any, opt: Any) -> np.ndarray:
    """Distance (m) of the ball's rest point to the target, for the mean policy at each of TARGETS."""
    contexts = TARGETS[:, None]
    _, info = evaluate_offsets(env, contexts, opt.recommend(contexts))
    x, y = info["ball_displacement"].T
    return np.hypot(x - TARGETS, y)


def flexibility_distances(env: Any, opt: Any) -> np.ndarray:
    """Forward kick distance (m) of the mean policy on the GRID_X × GRID_Y grid, shape (4, 7); falls = 0."""
    xs, ys = np.meshgrid(GRID_X, GRID_Y, indexing="ij")
    contexts = np.stack([xs.ravel(), ys.ravel()], axis=1)
    _, info = evaluate_offsets(env, contexts, opt.recommend(contexts))
    distance = np.where(info["fell"], 0.0, info["ball_displacement"][:, 0])
    return distance.reshape(xs.shape)


def run_one(spec: dict[str, Any], args: argparse.Namespace, env: Any, trial: int) -> dict[str, Any]:
    """Train (or resume) one run and evaluate its mean policy; cached as JSON."""
    out = args.out / spec["experiment"]
    out.mkdir(parents=True, exist_ok=True)
    stem = f"{spec['name']}_trial{trial}"
    result_path, ckpt = out / f"{stem}.json", out / f"{stem}.npz"
    if result_path.exists():
        done = json.loads(result_path.read_text())
        if done["iterations"] == spec["iterations"]:
            return done
    seed = [args.seed, spec["index"], trial]
    cls = CREPS if spec["algorithm"] == "CREPS" else CREPSCMA
    if ckpt.exists():
        opt = cls.load(ckpt)
    else:
        opt = make_optimizer(spec, env, args, int(np.random.SeedSequence(seed).generate_state(1)[0]))
    start = time.perf_counter()
    train(env, opt, spec["samples"], spec["iterations"], seed, ckpt, args.checkpoint_every)
    evaluate = precision_errors if spec["experiment"] == "precision" else flexibility_distances
    values = evaluate(env, opt)
    result = {
        "name": spec["name"],
        "trial": trial,
        "iterations": spec["iterations"],
        "samples": spec["samples"],
        "episodes": spec["iterations"] * spec["samples"],
        "seconds_this_session": time.perf_counter() - start,
        "values": values.tolist(),
    }
    result_path.write_text(json.dumps(result))
    return result


def specs(args: argparse.Namespace) -> list[dict[str, Any]]:
    """The runs of the selected experiments."""
    budgets = dict(MODES["full" if args.full else "quick"])
    for experiment, (iterations, trials) in budgets.items():
        budgets[experiment] = (args.iterations or iterations, args.trials or trials)
    runs = []
    if args.only in (None, "precision"):
        iterations, trials = budgets["precision"]
        rbf = RBFFeatures.grid([3.0], [12.0], 5)
        for index, (name, features) in enumerate((("linear", "affine"), ("rbf", rbf))):
            runs.append(
                {
                    "experiment": "precision",
                    "name": name,
                    "algorithm": "CREPS-CMA-old",
                    "features": features,
                    "samples": PRECISION_SAMPLES,
                    "iterations": iterations,
                    "trials": trials,
                    "index": index,
                }
            )
    if args.only in (None, "flexibility"):
        iterations, trials = budgets["flexibility"]
        rbf = RBFFeatures.grid([0.15, -0.15], [0.30, 0.15], 3)
        for index, name in enumerate(("CREPS", "CREPS-CMA-old"), start=2):
            runs.append(
                {
                    "experiment": "flexibility",
                    "name": name,
                    "algorithm": name,
                    "features": rbf,
                    "samples": FLEXIBILITY_SAMPLES,
                    "iterations": iterations,
                    "trials": trials,
                    "index": index,
                }
            )
    return runs


def summarise(experiment: str, results: dict[str, list[dict[str, Any]]], out: Path) -> list[str]:
    """Print and plot the results of one experiment; returns the summary lines."""
    lines = [f"## {experiment} (paper: {PAPER[experiment]})"]
    for name, trials in results.items():
        values = np.array([t["values"] for t in trials])
        minutes = sum(t["seconds_this_session"] for t in trials) / 60
        if experiment == "flexibility":
            values = np.median(values, axis=0)  # the paper's heatmap: median over trials
        lines.append(
            f"{name}: {values.mean():.2f} ± {values.std():.2f} m over {values.size} "
            f"{'targets × trials' if experiment == 'precision' else 'ball positions (median of trials)'}; "
            f"{trials[0]['iterations']} iterations × {trials[0]['samples']} samples, {len(trials)} trial(s), "
            f"{minutes:.1f} min"
        )
    try:
        plot(experiment, results, out)
    except ImportError:
        lines.append("(matplotlib missing: no figure)")
    return lines


def _cell_edges() -> list[float]:
    """imshow extent that centres each heatmap cell on its grid point."""
    dx, dy = (GRID_X[1] - GRID_X[0]) / 2, (GRID_Y[1] - GRID_Y[0]) / 2
    return [GRID_X[0] - dx, GRID_X[-1] + dx, GRID_Y[0] - dy, GRID_Y[-1] + dy]


def plot(experiment: str, results: dict[str, list[dict[str, Any]]], out: Path) -> None:
    """Fig. 5c (error against target) or Fig. 7 (heatmaps) as PNG under ``out``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if experiment == "precision":
        fig, ax = plt.subplots(figsize=(5, 3.5))
        for name, trials in results.items():
            values = np.array([t["values"] for t in trials])
            ax.errorbar(TARGETS, values.mean(0), values.std(0), marker="o", capsize=3, label=name)
        ax.set(
            xlabel="target distance s [m]", ylabel="distance to target [m]", title="Kick precision (Fig. 5c)"
        )
        ax.legend()
        fig.tight_layout()
        fig.savefig(out / "fig5c_precision.png", dpi=120)
    else:
        fig, axes = plt.subplots(1, len(results), figsize=(4.5 * len(results), 3.5), squeeze=False)
        for ax, (name, trials) in zip(axes[0], results.items(), strict=True):
            median = np.median(np.array([t["values"] for t in trials]), axis=0)
            image = ax.imshow(
                median.T,
                origin="lower",
                aspect="auto",
                cmap="jet",
                vmin=0,
                vmax=14,
                extent=_cell_edges(),
            )
            ax.set(xlabel="x_B [m]", ylabel="y_B [m]", title=f"{name}: median kick distance")
            fig.colorbar(image, ax=ax, label="m")
        fig.tight_layout()
        fig.savefig(out / "fig7_flexibility.png", dpi=120)
    plt.close(fig)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description="Reproduce the paper's kick experiments (Fig. 5c, Fig. 7).")
    mode = parser.add_mutually_exclusive_group()
    mode.add_argument("--quick", action="store_true", help="small budgets (default)")
    mode.add_argument("--full", action="store_true", help="the paper's budgets")
    parser.add_argument("--only", choices=("precision", "flexibility"), default=None)
    parser.add_argument("--out", type=Path, default=Path("benchmarks/kick/results"))
    parser.add_argument("--threads", type=int, default=0, help="simulation threads (0: all CPUs)")
    parser.add_argument("--sigma", type=float, default=0.02, help="initial standard deviation (normalised)")
    parser.add_argument("--ridge", type=float, default=1e-2, help="ridge of the mean fit (relative)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--checkpoint-every", type=int, default=10)
    parser.add_argument("--iterations", type=int, default=None, help="override the mode's iterations")
    parser.add_argument("--trials", type=int, default=None, help="override the mode's trials")
    args = parser.parse_args(argv)
    name = "full" if args.full else "quick"
    if args.iterations or args.trials:
        name = f"custom_i{args.iterations or 'mode'}_t{args.trials or 'mode'}"
    args.out = args.out / name
    envs = {
        "precision": make_env("creps_gym/KickPrecision-v0", args.threads),
        "flexibility": make_env("creps_gym/KickFlexibility-v0", args.threads),
    }
    collected: dict[str, dict[str, list[dict[str, Any]]]] = {}
    for spec in specs(args):
        for trial in range(spec["trials"]):
            result = run_one(spec, args, envs[spec["experiment"]], trial)
            collected.setdefault(spec["experiment"], {}).setdefault(spec["name"], []).append(result)
            print(
                f"{spec['experiment']} {spec['name']} trial {trial}: mean {np.mean(result['values']):.2f} m",
                flush=True,
            )
    lines = []
    for experiment, results in collected.items():
        lines += summarise(experiment, results, args.out)
    (args.out / "summary.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
