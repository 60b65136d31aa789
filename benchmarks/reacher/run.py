"""Reproduce Fig. 4a of Abdolmaleki et al. (2019): CREPS against CREPS-CMA-old on the planar reacher.

Each algorithm learns ``creps_gym/PlanarReacher-v0`` for several seeds with 100 samples per iteration
(contexts drawn uniformly from the via-point box). After every iteration the mean policy ``recommend(s)``
is evaluated on a fixed, seeded set of test via-points; the figure shows the median over seeds of that
mean-policy return against iterations, with the 25-75 % band and the min-max range. The script writes

* ``fig4a[_quick].png``: the learning curves (cost ``−R`` on a log axis, so both plateaus are visible);
* ``fig4b[_quick].png``: the motion of the median CREPS-CMA-old policy for ``v50 = (1, 1)`` (Fig. 4b);
* ``results[_quick].md``: the table, also copied between the markers in ``README.md``;
* ``results[_quick].json``: what the three above are drawn from (every seed's mean-policy return curve, its
  final via, goal and acceleration figures, Fig. 4b's policy parameters) and the ``provenance`` of the
  computation (:mod:`benchmarks.provenance`); ``--render-only`` redraws everything from it;
* ``runs[_quick]/``: one checkpoint per run (optimiser state and curve so far, ``.npz`` + JSON, no pickle).
  A full run that is interrupted resumes from its last checkpoint; finished runs are reused, unless the
  source of the optimisers, the env or the DMP changed since (a fingerprint is stored). ``--fresh`` starts
  over, and so does every ``--quick`` invocation (a reproduction).

The optimisers are driven directly with ``ask``/``tell``; the seeds make every number reproducible.

Usage::

    python benchmarks/reacher/run.py --quick     # 5 seeds x 200 iterations, computed again: about 15 s
    python benchmarks/reacher/run.py             # 20 seeds x 400 iterations (the paper's x axis), ~3 min
    python benchmarks/reacher/run.py --quick --render-only   # redraw from results_quick.json
"""

from __future__ import annotations

import argparse
import hashlib
import inspect
import json
import re
import shutil
import sys
import time
from pathlib import Path

import numpy as np

# Run by path: the repository root first on sys.path, as `python -m` puts it (see benchmarks/__init__.py).
if not __package__:
    sys.path[0] = str(Path(__file__).resolve().parents[2])

import creps_gym.envs.reacher.planar as planar_module
import creps_gym.movement.dmp as dmp_module
import creps_gym.optimizers.creps as creps_module
import creps_gym.optimizers.creps_cma as creps_cma_module
import creps_gym.optimizers.features as features_module
from benchmarks.provenance import provenance, provenance_text
from creps_gym.envs.reacher import PlanarReacherEnv
from creps_gym.optimizers import CREPS, CREPSCMA, ContextualOptimizer, load_state, save_state

HERE = Path(__file__).resolve().parent
ALGORITHMS = {
    "creps": ("CREPS", lambda seed: CREPS(25, 2, epsilon=0.5, initial_mean=0.0, initial_cov=1.0, seed=seed)),
    "creps-cma-old": (
        "CREPS-CMA-old",
        lambda seed: CREPSCMA(
            25, 2, variant="old", epsilon=0.5, initial_mean=0.0, initial_cov=1.0, seed=seed
        ),
    ),
    "creps-cma-current": (
        "CREPS-CMA-current",
        lambda seed: CREPSCMA(
            25, 2, variant="current", epsilon=0.5, initial_mean=0.0, initial_cov=1.0, seed=seed
        ),
    ),
}
MODES = {"quick": {"seeds": 5, "iterations": 200}, "full": {"seeds": 20, "iterations": 400}}
TEST_SEED, N_TEST, SAMPLES, CHECKPOINT_EVERY = 20190101, 100, 100, 50
SOLVED = -0.05  # a mean-policy return above this: via-point misses of a few cm and a smooth motion


def test_contexts() -> np.ndarray:
    """The fixed test via-points, shape (100, 2)."""
    return np.random.default_rng(TEST_SEED).uniform(0.0, 2.0, size=(N_TEST, 2))


def iteration_contexts(seed: int, iteration: int) -> np.ndarray:
    """Training contexts of one iteration, shape (100, 2); a pure function of (seed, iteration)."""
    return np.random.default_rng([seed, iteration]).uniform(0.0, 2.0, size=(SAMPLES, 2))


def evaluate_mean_policy(env: PlanarReacherEnv, opt: ContextualOptimizer, contexts: np.ndarray) -> np.ndarray:
    """[mean return, median via distance, median goal distance, mean acceleration cost] of the mean policy."""
    returns, info = env.evaluate(contexts, opt.recommend(contexts))
    return np.array(
        [
            returns.mean(),
            np.median(info["via_distance"]),
            np.median(info["goal_distance"]),
            info["acceleration_cost"].mean(),
        ]
    )


def code_fingerprint() -> str:
    """SHA-256 of the optimisers', the env's and the DMP's source: checkpoints of other code are redone."""
    digest = hashlib.sha256()
    for module in (creps_module, creps_cma_module, features_module, planar_module, dmp_module):
        digest.update(Path(inspect.getfile(module)).read_bytes())
    return digest.hexdigest()[:16]


def run_one(algorithm: str, seed: int, iterations: int, folder: Path) -> np.ndarray:
    """Learn one run (resuming from its checkpoint); the curve, shape (iterations + 1, 4)."""
    env, tests = PlanarReacherEnv(), test_contexts()
    path = folder / f"{algorithm}-seed{seed}.npz"
    cls = CREPS if algorithm == "creps" else CREPSCMA
    state = load_state(path) if path.exists() else {}
    if state and state.pop("bench_fingerprint", None) != code_fingerprint():
        print(f"{path.name}: made by other code, starting over")
        state = {}
    if state:
        curve, start = np.asarray(state.pop("bench_curve")), int(state.pop("bench_next_iteration"))
        if start >= iterations:
            return curve[: iterations + 1]
        opt = cls.from_state_dict(state)
        curve = np.concatenate([curve, np.full((iterations + 1 - curve.shape[0], 4), np.nan)])
    else:
        opt = ALGORITHMS[algorithm][1](seed)
        curve, start = np.full((iterations + 1, 4), np.nan), 0
        curve[0] = evaluate_mean_policy(env, opt, tests)
    for it in range(start, iterations):
        contexts = iteration_contexts(seed, it)
        params = opt.ask(contexts)
        opt.tell(contexts, params, env.evaluate(contexts, params)[0])
        curve[it + 1] = evaluate_mean_policy(env, opt, tests)
        if (it + 1) % CHECKPOINT_EVERY == 0 or it + 1 == iterations:
            state = {**opt.state_dict(), "bench_curve": curve[: it + 2], "bench_next_iteration": it + 1}
            save_state({**state, "bench_fingerprint": code_fingerprint()}, path)
    return curve


def final_policy(algorithm: str, seed: int, folder: Path) -> ContextualOptimizer:
    """The optimiser of a finished run, from its checkpoint."""
    state = load_state(folder / f"{algorithm}-seed{seed}.npz")
    for key in ("bench_curve", "bench_next_iteration", "bench_fingerprint"):
        state.pop(key)
    return (CREPS if algorithm == "creps" else CREPSCMA).from_state_dict(state)


def plot_curves(curves: dict[str, np.ndarray], path: Path, title: str) -> None:
    """Median cost curve with the 25-75 % band and the min-max range, per algorithm."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.5), dpi=110)
    for (algorithm, curve), colour in zip(curves.items(), ("tab:red", "tab:blue", "tab:green"), strict=False):
        cost = -curve[:, :, 0]  # (seeds, iterations + 1)
        x = np.arange(cost.shape[1])
        q = np.percentile(cost, [0, 25, 50, 75, 100], axis=0)
        ax.fill_between(x, q[0], q[4], color=colour, alpha=0.1, lw=0)
        ax.fill_between(x, q[1], q[3], color=colour, alpha=0.3, lw=0)
        ax.plot(x, q[2], color=colour, lw=2, label=f"{ALGORITHMS[algorithm][0]} (median of {cost.shape[0]})")
    ax.set_yscale("log")
    ax.set_xlabel("iterations (100 samples each)")
    ax.set_ylabel("cost of the mean policy, −R (log)")
    ax.set_title(title)
    ax.grid(True, which="both", lw=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def table(curves: dict[str, np.ndarray], iterations: int, header: str) -> str:
    """Markdown table: median [25 %, 75 %] mean-policy return at marks, the worst seed, final medians."""
    marks = sorted({0, iterations // 10, iterations // 4, iterations // 2, iterations})
    lines = [header, "", "| algorithm | " + " | ".join(f"R @ {m}" for m in marks)]
    lines[-1] += (
        f" | worst seed R @ end | seeds with R > {SOLVED} @ end | via miss @ end (m) | goal miss @ end (m)"
        " | accel. cost @ end |"
    )
    lines.append("|" + "---|" * (len(marks) + 6))
    for algorithm, curve in curves.items():
        cells = []
        for m in marks:
            q = np.percentile(curve[:, m, 0], [25, 50, 75])
            cells.append(f"{q[1]:.3g} [{q[0]:.3g}, {q[2]:.3g}]")
        final = np.median(curve[:, -1, 1:], axis=0)
        solved = f"{int((curve[:, -1, 0] > SOLVED).sum())}/{curve.shape[0]}"
        cells += [
            f"{curve[:, -1, 0].min():.3g}",
            solved,
            f"{final[0]:.3f}",
            f"{final[1]:.3f}",
            f"{final[2]:.4f}",
        ]
        lines.append(f"| {ALGORITHMS[algorithm][0]} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def update_readme(mode: str, text: str) -> None:
    """Replace the block between ``<!-- results:{mode} -->`` markers in README.md (if the markers exist)."""
    readme = HERE / "README.md"
    if not readme.exists():
        return
    start, end = f"<!-- results:{mode} -->", f"<!-- /results:{mode} -->"
    content = readme.read_text(encoding="utf-8")
    pattern = re.compile(re.escape(start) + r".*?" + re.escape(end), re.S)
    if pattern.search(content):
        readme.write_text(pattern.sub(lambda _: f"{start}\n{text}{end}", content), encoding="utf-8")


def fig4b_policy(curves: dict[str, np.ndarray], folder: Path) -> dict | None:
    """The median-seed CREPS-CMA-old run's mean policy at the via-point (1, 1): its seed and parameters."""
    if "creps-cma-old" not in curves:
        return None
    finals = curves["creps-cma-old"][:, -1, 0]
    seed = int(np.argsort(finals)[len(finals) // 2])
    params = final_policy("creps-cma-old", seed, folder).recommend(np.array([[1.0, 1.0]]))[0]
    return {"seed": seed, "params": params.tolist()}


def draw_fig4b(policy: dict | None, path: Path) -> None:
    """Render Fig. 4b's policy (see :func:`fig4b_policy`) for the via-point (1, 1), like the paper's."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if policy is None:
        return
    env = PlanarReacherEnv(render_mode="rgb_array")
    env.reset(options={"context": [1.0, 1.0]})
    env.step(np.asarray(policy["params"]))
    plt.imsave(path, env.render())


def results_document(mode: str, curves: dict[str, np.ndarray], policy: dict | None) -> dict:
    """What the table and figures are drawn from, with this computation's provenance."""
    return {
        "mode": mode,
        "provenance": provenance(),
        "returns": {name: curve[:, :, 0].tolist() for name, curve in curves.items()},
        "finals": {name: curve[:, -1, 1:].tolist() for name, curve in curves.items()},
        "fig4b": policy,
    }


def stored_curves(document: dict) -> dict[str, np.ndarray]:
    """The curves (seeds, iterations + 1, 4) of a results document: returns in column 0, the final via,
    goal and acceleration figures in the last row (the rest NaN: nothing drawn uses them)."""
    curves = {}
    for name, returns in document["returns"].items():
        curve = np.full((*np.shape(returns), 4), np.nan)
        curve[:, :, 0] = returns
        curve[:, -1, 1:] = document["finals"][name]
        curves[name] = curve
    return curves


def report_text(document: dict) -> str:
    """The table of ``results[_quick].md`` and its provenance, from a results document."""
    curves = stored_curves(document)
    seeds, iterations = next(iter(curves.values())).shape[:2]
    header = (
        f"Planar reacher, {document['mode']} mode: {seeds} seeds x {iterations - 1} iterations x {SAMPLES} "
        f"samples; mean-policy return R on {N_TEST} fixed test via-points, median [25 %, 75 %] over seeds."
    )
    runs = seeds * len(curves)  # one record for all of them
    where = provenance_text([document["provenance"]] * runs)
    return f"{table(curves, iterations - 1, header)}\n{where}\n"


def render(document: dict, suffix: str) -> str:
    """Write ``results[suffix].md`` (and README's block), ``fig4a``, ``fig4b``; returns the table."""
    curves = stored_curves(document)
    text = report_text(document)
    (HERE / f"results{suffix}.md").write_text(text, encoding="utf-8")
    update_readme(document["mode"], text)
    seeds = next(iter(curves.values())).shape[0]
    plot_curves(curves, HERE / f"fig4a{suffix}.png", f"Planar reacher (Fig. 4a), {seeds} seeds")
    draw_fig4b(document["fig4b"], HERE / f"fig4b{suffix}.png")
    return text


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description="Reproduce Fig. 4a (planar reacher): CREPS vs CREPS-CMA-old")
    parser.add_argument(
        "--quick", action="store_true", help="5 seeds x 200 iterations, computed again (default 20 x 400)"
    )
    parser.add_argument("--seeds", type=int, help="number of seeds (overrides the mode)")
    parser.add_argument("--iterations", type=int, help="iterations per run (overrides the mode)")
    parser.add_argument(
        "--algorithms", nargs="+", default=["creps", "creps-cma-old"], choices=list(ALGORITHMS)
    )
    parser.add_argument("--fresh", action="store_true", help="delete this mode's checkpoints first")
    parser.add_argument(
        "--render-only", action="store_true", help="compute nothing: redraw from results[_quick].json"
    )
    args = parser.parse_args(argv)
    mode = "quick" if args.quick else "full"
    seeds = args.seeds or MODES[mode]["seeds"]
    iterations = args.iterations or MODES[mode]["iterations"]
    suffix = "_quick" if args.quick else ""
    if args.render_only:
        path = HERE / f"results{suffix}.json"
        if not path.exists():  # the full results were computed before results.json existed
            parser.error(
                f"--render-only: {path.name} not found; compute it: python benchmarks/reacher/run.py"
                + (" --quick" if args.quick else "")
            )
        print(render(json.loads(path.read_text(encoding="utf-8")), suffix))
        return
    folder = HERE / f"runs{suffix}"
    if (args.fresh or args.quick) and folder.exists():  # --quick is a reproduction: it computes again
        shutil.rmtree(folder)
    folder.mkdir(exist_ok=True)
    curves, started = {}, time.perf_counter()
    for algorithm in args.algorithms:
        curves[algorithm] = np.stack([run_one(algorithm, seed, iterations, folder) for seed in range(seeds)])
        print(f"{ALGORITHMS[algorithm][0]}: {seeds} runs done ({time.perf_counter() - started:.1f} s so far)")
    document = results_document(mode, curves, fig4b_policy(curves, folder))
    (HERE / f"results{suffix}.json").write_text(json.dumps(document) + "\n", encoding="utf-8")
    text = render(json.loads((HERE / f"results{suffix}.json").read_text(encoding="utf-8")), suffix)
    print(text)
    elapsed = time.perf_counter() - started
    print(f"total {elapsed:.1f} s; wrote fig4a{suffix}.png, fig4b{suffix}.png and results{suffix}.md")


if __name__ == "__main__":
    main()
