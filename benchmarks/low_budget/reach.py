"""What the low-dimensional kicks can reach at all (issue 44's kick targets).

A policy of ``creps_gym/KickPrecisionLowDim-vN`` or ``KickFlexibilityLowDim-vN`` answers each context with
k metaparameters u in the id's box [−1, 1]^k (v0: 6; v1: 7 and 8; v2: 3 and 4), so its mean
metric over the study's test contexts can be no better than the best u of each context on its own. This
script searches that best u context by context with pycma (from the id's declared start, u = 0 and
σ = 0.3, in the box, ``--evaluations`` episodes per context, seed 1) and records, per context, the best
metric it found (the kick precision's error in m, the flexibility's distance in m) and its u; for the
precision task also the farthest kick it finds that does not fall (any target: the distance does not
depend on it). Its values are reachable (they were reached); they bound what the search can find, not the
truth, so a larger ``--evaluations`` can only find better values.
Writes one JSON document with provenance and a Markdown table next to it (``--render-only`` redraws it).
The committed v2 results were computed with :func:`benchmarks.numeric_stack.pinned_environment`'s
variables set (their provenance records the stack).

    OPENBLAS_NUM_THREADS=1 python -m benchmarks.low_budget.reach \\
        --out benchmarks/low_budget/results/reach.json            # the v0 ids
    OPENBLAS_NUM_THREADS=1 python -m benchmarks.low_budget.reach \\
        --tasks KickPrecisionLowDim-v1 KickFlexibilityLowDim-v1 \\
        --out benchmarks/low_budget/results/reach_v1.json
    OPENBLAS_NUM_THREADS=1 python -m benchmarks.low_budget.reach \\
        --tasks KickPrecisionLowDim-v2 KickFlexibilityLowDim-v2 \\
        --out benchmarks/low_budget/results/reach_v2.json
"""

from __future__ import annotations

import sys
from pathlib import Path

if not __package__:  # run by path: the repository root first on sys.path, as `python -m` puts it
    sys.path[0] = str(Path(__file__).resolve().parents[2])

import argparse
import json
from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np

import creps_gym  # noqa: F401  (registers the ids)
from benchmarks.kick.study import episode_metric
from benchmarks.low_budget import add_output_arguments, replay_command
from benchmarks.low_budget.study import evaluation_contexts, task_by_name
from benchmarks.provenance import provenance

TASKS = (
    "KickPrecisionLowDim",
    "KickFlexibilityLowDim",
    "KickPrecisionLowDim-v1",
    "KickFlexibilityLowDim-v1",
    "KickPrecisionLowDim-v2",
    "KickFlexibilityLowDim-v2",
)
#: The paper's figures (the issue's targets for the low-dimensional kicks): mean error ≤ 0.34 m, ≥ 6.5 m.
PAPER = {"error": 0.34, "distance": 6.5}
SEED = 1


def search(
    score: Callable[[np.ndarray], np.ndarray], start: Any, sigma: float, evaluations: int
) -> tuple[float, list[float] | None]:
    """pycma's best (lowest) ``score`` in the box [−1, 1]^k from ``start``: (best score, its u as a list).

    ``score`` maps a batch of u (n, k) to scores (n,); every asked u is scored once, in pycma's batches.
    """
    import cma

    options = {"bounds": [-1.0, 1.0], "seed": SEED, "verbose": -9, "maxfevals": evaluations}
    strategy = cma.CMAEvolutionStrategy(np.asarray(start, dtype=np.float64), sigma, options)
    best, best_u = np.inf, None
    while not strategy.stop():
        batch = np.asarray(strategy.ask())
        scores = score(batch)
        strategy.tell(list(batch), [float(value) for value in scores])
        row = int(np.argmin(scores))
        if scores[row] < best:
            best, best_u = float(scores[row]), batch[row].tolist()
    return best, best_u


def _scorer(env: Any, kind: str, context: np.ndarray, sign: float) -> Callable[[np.ndarray], np.ndarray]:
    """The scores of a batch of u (n, k) at ``context``: ``sign`` times the episodes' metric."""

    def score(u: np.ndarray) -> np.ndarray:
        batch = np.repeat(context[None, :], u.shape[0], axis=0)
        info = env.evaluate(batch, u)[1]
        return sign * np.asarray(episode_metric(kind, batch, info), dtype=np.float64)

    return score


def reach(task_name: str, evaluations: int, contexts: Any = None) -> dict[str, Any]:
    """The task's best metric per test context (or per row of ``contexts``) and, for the precision task,
    the farthest kick without a fall."""
    task = task_by_name(task_name)
    kind = task.kick_experiment
    env = gym.make(task.env_id).unwrapped
    contexts = evaluation_contexts(task, env) if contexts is None else np.asarray(contexts, np.float64)
    start, std = env.initial_distribution()
    sign = 1.0 if kind == "precision" else -1.0  # pycma minimises: the error, or minus the distance
    rows = []
    for context in contexts:
        best, u = search(_scorer(env, kind, context, sign), start, float(np.mean(std)), evaluations)
        rows.append({"context": context.tolist(), "best": sign * best, "u": u})
    document = {"task": task_name, "metric": task.metric, "evaluations": evaluations, "contexts": rows}
    if kind == "precision":

        def shorter(u: np.ndarray) -> np.ndarray:
            info = env.evaluate(np.repeat(contexts[:1], u.shape[0], axis=0), u)[1]
            return np.where(info["fell"], np.inf, -info["ball_displacement"][:, 0])

        farthest, u = search(shorter, start, float(np.mean(std)), evaluations)
        document["farthest"] = {"distance": -farthest, "u": u}
    env.close()
    return document


def summary(document: dict[str, Any]) -> str:
    """A Markdown table per task: the best metric per context and its mean against the paper's figure."""
    lines = []
    for result in document["results"]:
        name, metric = result["task"], result["metric"]
        values = np.array([row["best"] for row in result["contexts"]])
        contexts = [", ".join(f"{v:g}" for v in row["context"]) for row in result["contexts"]]
        lines += [f"### {name}", "", f"| context | best {metric} found (m) |", "|---|---|"]
        lines += [f"| {c} | {v:.3g} |" for c, v in zip(contexts, values, strict=True)]
        better = "≤" if metric == "error" else "≥"
        lines += [
            "",
            f"Mean over the {values.size} test contexts: **{values.mean():.3g} m** (the paper's figure, the "
            f"issue's target: {better} {PAPER[metric]} m; {result['evaluations']} episodes per context).",
        ]
        if "farthest" in result:
            lines.append(f"The farthest kick found without a fall: {result['farthest']['distance']:.3g} m.")
        lines.append("")
    return "\n".join(lines)


def render(path: Path) -> str:
    """Write the table of the results at ``path`` (JSON) to the same name with ``.md``; returns it."""
    document = json.loads(path.read_text(encoding="utf-8"))
    command = replay_command("reach", document)
    text = f"{summary(document)}\nCommand: `OPENBLAS_NUM_THREADS=1 {command}`.\n"
    path.with_suffix(".md").write_text(text, encoding="utf-8")
    return text


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tasks", nargs="+", choices=TASKS, default=list(TASKS[:2]))
    parser.add_argument("--evaluations", type=int, default=300, help="episodes per context (pycma's budget)")
    add_output_arguments(parser)
    args = parser.parse_args(argv)
    if args.render_only:
        print(render(args.out))
        return
    if args.evaluations < 1:
        parser.error(f"--evaluations: expected a positive integer, got {args.evaluations}")
    results = []
    for name in args.tasks:
        results.append(reach(name, args.evaluations))
        print(json.dumps(results[-1]), flush=True)
    document = {"command": sys.argv, "results": results, "provenance": provenance(["cma", "mujoco"])}
    args.out.write_text(json.dumps(document, indent=1) + "\n", encoding="utf-8")
    print(render(args.out))


if __name__ == "__main__":
    main()
