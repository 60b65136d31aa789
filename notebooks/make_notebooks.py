"""Generate the tutorial notebooks (``01_quickstart``, ``02_compare_optimisers``, ``03_robot_tasks``).

The notebooks are written from the cell sources below with nbformat, so their source is reviewable here,
then executed (nbclient, in a temporary folder) so that they are committed with their outputs and the
figures show on the repository page. Each notebook reads ``CREPS_GYM_QUICK=1`` in its first cell and then
runs a small configuration (how CI runs them, see ``tests/docs/test_notebooks.py``); the committed outputs come
from the full configuration.

    python notebooks/make_notebooks.py            # write and execute every notebook (a few minutes)
    python notebooks/make_notebooks.py --no-execute  # sources only, no outputs
"""

from __future__ import annotations

import argparse
import os
import tempfile
from pathlib import Path

import nbformat
from nbformat.v4 import new_code_cell, new_markdown_cell, new_notebook

HERE = Path(__file__).resolve().parent

SETUP = """\
import os

# CREPS_GYM_QUICK=1 runs a small configuration (CI executes the notebooks this way).
QUICK = os.environ.get("CREPS_GYM_QUICK", "0") == "1"
os.environ.setdefault("MUJOCO_GL", "egl")  # headless rendering for the MuJoCo kick (notebook 3)

import matplotlib.pyplot as plt
import numpy as np
import gymnasium as gym

import creps_gym  # registers the creps_gym/... environment ids
print("creps_gym", creps_gym.__version__, "| quick mode:", QUICK)"""

QUICKSTART = [
    new_markdown_cell(
        "# Quickstart: a contextual function, CREPS-CMA and the ask/tell loop\n\n"
        "A *contextual* episodic task: each episode draws a context `s` (here uniform in [0, 3]), the agent "
        "answers with one parameter vector `θ`, and the episode returns one number. CREPS-CMA learns a "
        "policy `θ = Aᵀ[1, s]` plus Gaussian exploration that solves *every* context at once."
    ),
    new_code_cell(SETUP),
    new_markdown_cell("## 1. Make an environment\nThe observation is the context; the action is `θ`."),
    new_code_cell(
        """DIM = 5 if QUICK else 15
env = gym.make("creps_gym/Sphere-v0", dim=DIM, context_dim=1)
print("context space:", env.observation_space)
print("parameter space:", env.action_space.shape)

context, info = env.reset(seed=0, options={"context": np.array([1.5])})
_, reward, terminated, truncated, info = env.step(np.zeros(DIM))
print("context", context, "-> return", reward, "| regret", info["regret"], "| one step:", terminated)"""
    ),
    new_markdown_cell(
        "## 2. The ask/tell loop by hand\n"
        "The native vector env evaluates a whole batch of episodes at once. After each step it draws fresh "
        "contexts for the next batch (Gymnasium's same-step autoreset)."
    ),
    new_code_cell(
        """from creps_gym.envs.evaluation import evaluate_policy, test_contexts
from creps_gym.optimizers import CREPSCMA

SAMPLES, ITERATIONS = 50, (150 if QUICK else 600)
venv = gym.make_vec("creps_gym/Sphere-v0", num_envs=SAMPLES, dim=DIM, context_dim=1)
optimizer = CREPSCMA(DIM, 1, variant="old", seed=0, initial_cov=4.0)
tests = test_contexts(venv, 16, seed=123)  # fixed test contexts for the learning curve

contexts, _ = venv.reset(seed=0)
episodes, regrets = [], []
for iteration in range(ITERATIONS):
    params = optimizer.ask(contexts)                      # θ_k ~ π(θ | s_k)
    next_contexts, returns, _, _, _ = venv.step(params)   # one episode per row
    optimizer.tell(contexts, params, returns)             # weights, mean and covariance update
    contexts = next_contexts
    episodes.append((iteration + 1) * SAMPLES)
    regrets.append(evaluate_policy(venv, optimizer.recommend, tests).mean_regret)
print(f"mean regret of the mean policy after {episodes[-1]} episodes: {regrets[-1]:.2e}")"""
    ),
    new_markdown_cell("## 3. Plot learning"),
    new_code_cell(
        """fig, ax = plt.subplots(figsize=(6, 3.5))
ax.semilogy(episodes, regrets)
ax.set(xlabel="episodes", ylabel="mean regret on the test contexts", title="CREPS-CMA-old on Sphere")
ax.grid(True, alpha=0.3)
plt.show()"""
    ),
    new_markdown_cell(
        "The learned policy gives a different `θ` for every context. Compare it with the known optimum:"
    ),
    new_code_cell(
        """s = np.array([[0.0], [1.5], [3.0]])
print("recommended θ_1:", optimizer.recommend(s)[:, 0])
print("optimal θ*_1:  ", venv.model.optimal_params(s)[:, 0])
venv.close()
env.close()"""
    ),
]

COMPARE = [
    new_markdown_cell(
        "# Compare optimisers through the runner\n\n"
        "`creps_gym.runner.run` plugs any registered ask/tell optimiser into any contextual env and "
        "evaluates the recommended (mean) policy on fixed test contexts. pycma and nevergrad are "
        "*non-contextual*: they return one `θ` for every context, so their regret over the contexts has a "
        "floor, while contextual CMA-ES (`c-cma-es`, the recommended optimiser) and CREPS-CMA learn the "
        "context dependence."
    ),
    new_code_cell(SETUP),
    new_code_cell(
        """from creps_gym.optimizers import describe_optimizers
from creps_gym.runner import plot_histories, run

for name, description in describe_optimizers().items():
    print(f"{name:18s} {description}")"""
    ),
    new_code_cell(
        """ENV = "creps_gym/ShiftedSphere-v0"
ENV_KWARGS = {"dim": 5 if QUICK else 10, "context_dim": 1}
ITERATIONS, SAMPLES = (60 if QUICK else 400), 30
SEEDS = [0] if QUICK else [0, 1, 2]
OPTIMISERS = ["c-cma-es", "creps-cma-old", "cma", "nevergrad"]

histories = {
    name: [
        run(name, ENV, ITERATIONS, SAMPLES, seed, env_kwargs=ENV_KWARGS, target_regret=1e-5)
        for seed in SEEDS
    ]
    for name in OPTIMISERS
}
for name, runs in histories.items():
    finals = [h.records[-1].eval_regret for h in runs]
    episodes = runs[0].records[-1].episodes
    print(f"{name:15s} final mean regret {np.median(finals):.2e} after {episodes} episodes")"""
    ),
    new_code_cell(
        """import io
from IPython.display import Image

figure = plot_histories(histories, title="ShiftedSphere, 1-D context")  # a matplotlib Figure
buffer = io.BytesIO()
figure.savefig(buffer, format="png", dpi=90)
Image(buffer.getvalue())"""
    ),
    new_markdown_cell(
        "On a *single* fixed context CMA-ES needs fewer episodes than a contextual method (see "
        "`docs/results/functions/`); the contextual method's advantage is that one run solves all contexts."
    ),
]

ROBOTS = [
    new_markdown_cell(
        "# Robot tasks: the planar reacher and the humanoid kick\n\n"
        "The reacher (paper section 5.2) is pure numpy. The kick (section 5.3) needs MuJoCo, and rendering "
        "needs an OpenGL backend (headless: `MUJOCO_GL=egl` or `osmesa`); the kick cells print why they "
        "are skipped when either is missing."
    ),
    new_code_cell(SETUP),
    new_markdown_cell("## Planar reacher: a 5-link arm through a via-point (the context)"),
    new_code_cell(
        """from creps_gym.optimizers import CREPSCMA
from creps_gym.runner import run

# An optimiser object (rather than a registry name) stays in our hands, trained, after the run.
optimizer = CREPSCMA(25, 2, variant="old", seed=0, initial_cov=1.0)
history = run(
    optimizer, "creps_gym/PlanarReacher-v1", iterations=(15 if QUICK else 300),
    samples_per_iteration=(40 if QUICK else 100), seed=0, eval_every=5,
)
returns = history.column("eval_return")
keep = np.isfinite(returns)
plt.semilogy(history.column("episodes")[keep], -returns[keep])  # the cost spans three decades
plt.xlabel("episodes"); plt.ylabel("cost −R on the test via-points (log scale)"); plt.show()"""
    ),
    new_markdown_cell("Render the initial (zero) DMP and the learned motion for one via-point."),
    new_code_cell(
        """env = gym.make("creps_gym/PlanarReacher-v1", render_mode="rgb_array")
via = np.array([1.0, 1.0])
frames = []
for label, theta in [("zero DMP", np.zeros(25)), ("learned", optimizer.recommend(via[None])[0])]:
    env.reset(seed=0, options={"context": via})
    _, reward, *_ = env.step(theta)
    frames.append((label, reward, env.render()))
fig, axes = plt.subplots(1, 2, figsize=(8, 4))
for ax, (label, reward, frame) in zip(axes, frames):
    ax.imshow(frame); ax.set_title(f"{label}: return {reward:.2f}"); ax.axis("off")
plt.show()
env.close()"""
    ),
    new_markdown_cell("## Humanoid kick (MuJoCo): the shipped reference kick, rendered"),
    new_code_cell(
        """try:
    import mujoco  # noqa: F401
    kick = gym.make("creps_gym/KickPrecision-v1", render_mode="rgb_array")
except ImportError as exc:
    kick = None
    print("MuJoCo is not installed (pip install creps-gym[mujoco]); skipping the kick:", exc)

if kick is not None:
    kick.reset(seed=0, options={"context": np.array([6.0])})
    _, reward, _, _, info = kick.step(kick.unwrapped.reference_params())
    print(f"target 6 m: the ball travelled {info['kick_distance']:.2f} m, return {reward:.2f}")
    try:
        frame = kick.render()
    except RuntimeError as exc:  # no OpenGL context on this machine
        frame = None
        print("rendering is unavailable here:", exc)
    if frame is not None:
        plt.imshow(frame); plt.axis("off"); plt.title("end of the swing"); plt.show()
    kick.close()"""
    ),
]


def execute(notebook: nbformat.NotebookNode, quick: bool = False, timeout: int = 1800) -> None:
    """Run every cell in place (fresh kernel, a temporary working folder), in full or quick mode."""
    import nbclient

    previous = os.environ.get("CREPS_GYM_QUICK")
    os.environ["CREPS_GYM_QUICK"] = "1" if quick else "0"
    try:
        with tempfile.TemporaryDirectory() as folder:
            client = nbclient.NotebookClient(
                notebook,
                timeout=timeout,
                kernel_name="python3",
                record_timing=False,
                resources={"metadata": {"path": folder}},
            )
            client.execute()
    finally:
        if previous is None:
            os.environ.pop("CREPS_GYM_QUICK")
        else:
            os.environ["CREPS_GYM_QUICK"] = previous


def build(cells: list) -> nbformat.NotebookNode:
    """A notebook of ``cells`` with the kernel metadata, validated (no outputs yet)."""
    notebook = new_notebook(cells=[nbformat.from_dict(cell) for cell in cells])
    notebook.metadata["kernelspec"] = {"name": "python3", "display_name": "Python 3", "language": "python"}
    notebook.metadata["language_info"] = {"name": "python"}
    nbformat.validate(notebook)
    return notebook


def write(name: str, cells: list, run: bool = True) -> Path:
    """Write one notebook, executed in full mode unless ``run`` is False; returns its path."""
    notebook = build(cells)
    if run:
        execute(notebook)
        notebook.metadata.pop("widgets", None)
    path = HERE / f"{name}.ipynb"
    nbformat.write(notebook, path)
    return path


NOTEBOOKS = {"01_quickstart": QUICKSTART, "02_compare_optimisers": COMPARE, "03_robot_tasks": ROBOTS}


def main(argv: list[str] | None = None) -> None:
    """Write (and execute) every notebook, or the ones named."""
    parser = argparse.ArgumentParser(description="Write the tutorial notebooks with their outputs.")
    parser.add_argument("names", nargs="*", choices=[*NOTEBOOKS, []], help="default: all")
    parser.add_argument("--no-execute", action="store_true", help="write the sources without outputs")
    args = parser.parse_args(argv)
    for name in args.names or NOTEBOOKS:
        print("wrote", write(name, NOTEBOOKS[name], run=not args.no_execute), flush=True)


if __name__ == "__main__":
    main()
