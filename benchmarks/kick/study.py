"""One run of the kick study: a registry optimiser trained through the generic path, resumable.

Every run searches the kick through :class:`~creps_gym.wrappers.OffsetParams` with its defaults: the agent's
θ is the offset from the env's declared initial mean (the reference kick) in units of its declared standard
deviation (0.02 of the normalised range), so every optimiser starts from the env-declared distribution N(0, I)
exactly as ``creps-gym run`` does. The ridge of a contextual mean fit then pulls the policy towards the
reference kick (see ``docs/wrappers.md``).

A run is (experiment, optimiser, trial). Its training contexts at iteration ``t`` are drawn from
``default_rng([seed, key, trial, t])``, uniformly in the env's context box (the env's own draw) or from
Beta(½, ½) scaled into it (``contexts="arcsine"``, :class:`~creps_gym.wrappers.BetaContexts`), or by a
learning context selector (``contexts="bandit"`` or ``"progress"``, :mod:`creps_gym.selectors`, told every
iteration's returns and checkpointed in ``<name>-trial<k>.selector.json``), and its
optimiser's seed comes from ``SeedSequence([seed, key, trial])``, where ``key`` is a CRC-32 of
``"<experiment>/<name>"``, so adding a method never changes another one's numbers. The optimiser's
checkpoint (``.npz``) holds its own generator, and the history (``.history.json``) is written with it, so a
resumed run is bit-identical to an uninterrupted one.
"""

from __future__ import annotations

import json
import os
import re
import time
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

import creps_gym  # noqa: F401  (registers the ids)
from benchmarks.provenance import provenance
from creps_gym.envs.base import initial_distribution
from creps_gym.optimizers.features import RBFFeatures
from creps_gym.optimizers.registry import make_optimizer, optimizer_class
from creps_gym.runner.rundir.files import json_document, read_run_file
from creps_gym.selectors import make_selector
from creps_gym.wrappers import BetaContexts, OffsetParams

__all__ = [
    "ENV_IDS",
    "FEATURES",
    "GRID_X",
    "GRID_Y",
    "LEGACY_ENV_IDS",
    "SELECTED_CONTEXTS",
    "TARGETS",
    "TRAINING",
    "TRAINING_CONTEXTS",
    "RunSpec",
    "context_sampler",
    "context_selector",
    "episode_metric",
    "evaluate",
    "evaluation_contexts",
    "grid_contexts",
    "make_env",
    "mean_policy_metric",
    "options_slug",
    "read_json",
    "results_folder",
    "stored_setting",
    "train_run",
    "write_json",
]

TARGETS = np.linspace(3.0, 12.0, 10)  # precision: the 10 evaluation targets (m)
GRID_X, GRID_Y = np.linspace(0.15, 0.30, 4), np.linspace(-0.15, 0.15, 7)  # flexibility: the ball grid (m)
ENV_IDS = {"precision": "creps_gym/KickPrecision-v1", "flexibility": "creps_gym/KickFlexibility-v2"}
#: The env of each experiment in run and oracle files that do not name theirs (written before they did).
LEGACY_ENV_IDS = {"precision": "creps_gym/KickPrecision-v0", "flexibility": "creps_gym/KickFlexibility-v1"}
#: Largest study file read (bytes): a full run's document or history is well under 1 MiB.
MAX_JSON_BYTES = 64 * 2**20
#: The packages a kick run's provenance names besides numpy, scipy and gymnasium.
PACKAGES = ("mujoco", "cma")
EVAL_EVERY = 50  # iterations between evaluations of the mean policy (the learning curves)
#: How a run draws its training contexts: the shape parameter a = b of a Beta(a, b) scaled into the env's
#: context box, or None for the env's own (uniform) draw. Run files that name none drew "uniform".
TRAINING_CONTEXTS = {"uniform": None, "arcsine": 0.5}
#: Training contexts chosen by a learning selector (registry names of :mod:`creps_gym.selectors`).
SELECTED_CONTEXTS = ("bandit", "progress")
#: The study's training contexts per experiment (``results/<mode>``; ``--contexts`` trains on others).
#: Precision: the arcsine law Beta(½, ½) on [3, 12] m trains each outer quarter of the range on a third of
#: the draws; uniform draws put 1 in 18 in the last half metre, too few to fix the far end of an affine
#: policy that the targets in between pin (README, "Where the precision error came from"). Every precision
#: method draws the same way.
TRAINING = {"precision": "arcsine", "flexibility": "uniform"}


#: The mean features a run can use (``RunSpec.features``, ``run.py --features``).
FEATURES = ("affine", "quadratic", "rbf")


@dataclass(frozen=True)
class RunSpec:
    """One optimiser on one experiment: registry name, mean features, options, budget, training contexts
    (a key of ``TRAINING_CONTEXTS``)."""

    experiment: str
    name: str
    samples: int
    iterations: int
    features: str = "rbf"
    options: dict[str, Any] = field(default_factory=dict)
    contexts: str = "uniform"

    def __post_init__(self) -> None:
        if self.contexts not in (*TRAINING_CONTEXTS, *SELECTED_CONTEXTS):
            expected = [*sorted(TRAINING_CONTEXTS), *SELECTED_CONTEXTS]
            raise ValueError(f"contexts: expected one of {expected}, got {self.contexts!r}")
        if self.features not in FEATURES:
            raise ValueError(f"features: expected one of {list(FEATURES)}, got {self.features!r}")

    @property
    def key(self) -> int:
        """Stable seed component of this (experiment, name) pair."""
        return zlib.crc32(f"{self.experiment}/{self.name}".encode())

    def mean_features(self) -> Any:
        """Affine [1, s], quadratic [1, s, s²] (element-wise squares), or normalised RBFs: 5 centres over
        [3, 12] m (precision), 3 × 3 over the grid (flexibility)."""
        if self.features in ("affine", "quadratic"):
            return self.features
        if self.experiment == "precision":
            return RBFFeatures.grid([3.0], [12.0], 5)
        return RBFFeatures.grid([GRID_X[0], GRID_Y[0]], [GRID_X[-1], GRID_Y[-1]], 3)


def results_folder(
    mode: str, contexts: str | None, features: str | None, options: dict[str, Any] | None = None
) -> str:
    """The name of a results folder: ``<mode>``, then ``-<contexts>``, ``-features-<features>`` and
    ``-opt-<slug>`` for training contexts, mean features and optimiser options other than the study's
    (``run.py --contexts``, ``--features``, ``--opt``; the slug is :func:`options_slug`)."""
    name = mode if contexts is None else f"{mode}-{contexts}"
    name = name if features is None else f"{name}-features-{features}"
    return name if not options else f"{name}-opt-{options_slug(options)}"


#: Longest options slug of a results folder's name (``run.py --opt``).
MAX_SLUG = 100


def options_slug(options: dict[str, Any]) -> str:
    """The options as part of a folder name: ``KEY-VALUE`` per option in key order, joined by ``+``, each
    value its JSON text with every character other than letters, digits, ``.`` and ``-`` turned into ``_``
    (``{"epsilon": 1.0, "step_size": "csa"}`` -> ``epsilon-1.0+step_size-csa``). A slug over
    :data:`MAX_SLUG` characters raises ``ValueError``."""
    parts = []
    for key in sorted(options):
        value = re.sub(r"[^A-Za-z0-9.-]+", "_", json.dumps(options[key])).strip("_") or "_"
        parts.append(f"{re.sub(r'[^A-Za-z0-9_]+', '_', key)}-{value}")
    slug = "+".join(parts)
    if len(slug) > MAX_SLUG:
        raise ValueError(f"options: expected a folder slug of at most {MAX_SLUG} characters, got {slug!r}")
    return slug


def make_env(experiment: str, threads: int) -> OffsetParams:
    """The experiment's env behind :class:`OffsetParams` (centre and scale: the env-declared distribution)."""
    return OffsetParams(gym.make(ENV_IDS[experiment], num_threads=threads))


def context_sampler(spec: RunSpec, env: OffsetParams) -> Any:
    """``sampler(rng, n) -> (n, z)``: the training contexts of ``spec`` in the env's context box."""
    shape = TRAINING_CONTEXTS[spec.contexts]
    if shape is None:
        return env.unwrapped.sample_contexts
    box = env.unwrapped.observation_space
    return BetaContexts(box.low, box.high, shape)


def context_selector(spec: RunSpec, env: OffsetParams) -> Any:
    """The learning selector of ``spec`` bound to the env's context box, or None (a fixed law)."""
    if spec.contexts not in SELECTED_CONTEXTS:
        return None
    selector, box = make_selector(spec.contexts), env.unwrapped.observation_space
    selector.bind(box.low.astype(np.float64), box.high.astype(np.float64), env.unwrapped.sample_contexts)
    return selector


def _selector_states(path: Path, selector: Any, iteration: int, states: dict[str, Any]) -> dict[str, Any]:
    """Write the selector's state at ``iteration`` beside the previous checkpoint's (a kill before the
    optimiser's checkpoint is saved leaves that one the one to resume from); returns the states kept."""
    kept = {**{k: v for k, v in states.items() if int(k) < iteration}, str(iteration): selector.state_dict()}
    kept = dict(sorted(kept.items(), key=lambda item: int(item[0]))[-2:])
    write_json(path, kept)
    return kept


def evaluate(env: OffsetParams, contexts: np.ndarray, offsets: np.ndarray) -> tuple[Any, Any]:
    """The unwrapped env's batched ``evaluate`` at the env parameters of the agent's ``offsets``."""
    return env.unwrapped.evaluate(contexts, env.to_env(offsets))


def grid_contexts() -> np.ndarray:
    """The 4 × 7 ball positions (x_B, y_B), shape (28, 2), x-major."""
    xs, ys = np.meshgrid(GRID_X, GRID_Y, indexing="ij")
    return np.stack([xs.ravel(), ys.ravel()], axis=1)


def episode_metric(experiment: str, contexts: np.ndarray, info: dict[str, Any]) -> np.ndarray:
    """Per episode (n,): the distance (m) from the ball's rest point to the target ``s`` straight ahead
    (precision), or the ball's forward distance (m), 0 when the robot falls (flexibility)."""
    x, y = info["ball_displacement"].T
    if experiment == "precision":
        return np.hypot(x - contexts[:, 0], y)
    return np.where(info["fell"], 0.0, x)


def evaluation_contexts(experiment: str) -> np.ndarray:
    """The precision task's 10 targets (10, 1), or the flexibility task's 28 ball positions (28, 2)."""
    return TARGETS[:, None] if experiment == "precision" else grid_contexts()


def mean_policy_metric(env: OffsetParams, experiment: str, opt: Any) -> list[float]:
    """The mean policy's per-target errors (precision) or per-position distances (flexibility)."""
    contexts = evaluation_contexts(experiment)
    _, info = evaluate(env, contexts, opt.recommend(contexts))
    return episode_metric(experiment, contexts, info).tolist()


def read_json(path: Path) -> Any:
    """The JSON document of a study file, read as a run folder's file is: a symbolic link or another
    non-regular file is refused, and so is a file over :data:`MAX_JSON_BYTES` (``RunDirError``, a
    ``ValueError`` naming it)."""
    return json_document(read_run_file(path, MAX_JSON_BYTES), str(path))


def load_run(stem: Path) -> Any:
    """The optimiser of the run ``<folder>/<name>-trial<k>``, restored from its checkpoint ``<stem>.npz``."""
    return optimizer_class(stem.name.rsplit("-trial", 1)[0]).load(stem.with_suffix(".npz"))


def _new_optimizer(spec: RunSpec, env: OffsetParams, seed: int) -> Any:
    mean, std = initial_distribution(env)  # N(0, I) through OffsetParams' defaults
    z = env.unwrapped.context_dim
    return make_optimizer(
        spec.name,
        env.action_space.shape[0],
        z,
        seed,
        initial_mean=mean,
        initial_cov=std**2,
        mean_features=spec.mean_features(),
        **spec.options,
    )


def write_json(path: Path, document: Any) -> None:
    """Atomic JSON write (a kill never leaves half a file)."""
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(document))
    os.replace(tmp, path)


def stored_setting(document: dict[str, Any], experiment: str) -> dict[str, Any]:
    """The ``setting`` of a run file, with the env it ran on (``LEGACY_ENV_IDS`` if the file does not say)
    and its training contexts ("uniform" if it does not say)."""
    return {"env": LEGACY_ENV_IDS[experiment], "contexts": "uniform", **document.get("setting", {})}


def train_run(
    spec: RunSpec,
    env: OffsetParams,
    trial: int,
    seed: int,
    folder: Path,
    checkpoint_every: int = 10,
    fresh: bool = False,
) -> dict[str, Any]:
    """Train (or resume, or read back) one run and evaluate its mean policy; returns its result document.

    Files under ``folder``: ``<name>-trial<k>.npz`` (optimiser), ``.history.json`` (the setting; per
    iteration, mean return and fall rate of the batch; every ``EVAL_EVERY`` iterations the mean policy's
    metric) and, when finished, ``.json`` (the result). A result or checkpoint of another setting (env,
    training contexts, features, options, batch size) is computed again, and so is every run with ``fresh``
    (a reproduction: nothing is read back). The run ends at ``spec.iterations`` or when the optimiser's own
    stop criteria are met. The result holds the ``provenance`` of the session that finished it
    (:func:`benchmarks.provenance.provenance`).
    """
    folder.mkdir(parents=True, exist_ok=True)
    stem = folder / f"{spec.name}-trial{trial}"
    result_path, ckpt, history_path, selector_path = _run_files(stem)
    selector = context_selector(spec, env)
    setting = {
        "env": ENV_IDS[spec.experiment],
        "contexts": spec.contexts,
        "features": spec.features,
        "options": spec.options,
        "samples": spec.samples,
    }
    if result_path.exists() and not fresh:
        done = read_json(result_path)
        if done["budget_iterations"] == spec.iterations and stored_setting(done, spec.experiment) == setting:
            return done
    base_seed = [seed, spec.key, trial]
    opt, history, states = _resume(spec, env, stem, setting, base_seed, selector, fresh)
    draw_contexts = context_sampler(spec, env) if selector is None else selector.select
    start = time.perf_counter()
    while opt.iteration < spec.iterations and not opt.stop():
        rng = np.random.default_rng([*base_seed, opt.iteration])
        contexts = draw_contexts(rng, spec.samples)
        offsets = opt.ask(contexts)
        returns, info = evaluate(env, contexts, offsets)
        opt.tell(contexts, offsets, returns)
        if selector is not None:
            selector.tell(contexts, returns, {k: float(v) for k, v in dict(opt.diagnostics).items()})
        history["batch"].append([float(returns.mean()), float(info["fell"].mean())])
        if opt.iteration % EVAL_EVERY == 0:
            history["evaluations"].append([opt.iteration, mean_policy_metric(env, spec.experiment, opt)])
        if opt.iteration % checkpoint_every == 0 or opt.iteration == spec.iterations or opt.stop():
            write_json(history_path, history)
            if selector is not None:
                states = _selector_states(selector_path, selector, opt.iteration, states)
            opt.save(ckpt)
    result = _result_document(spec, trial, setting, opt, env, history, start)
    write_json(result_path, result)
    return result


def _result_document(
    spec: RunSpec,
    trial: int,
    setting: dict[str, Any],
    opt: Any,
    env: OffsetParams,
    history: dict[str, Any],
    start: float,
) -> dict[str, Any]:
    """:func:`train_run`'s result document of a finished run: its setting, budget and progress, the mean
    policy's metric, the history, the seconds of its last session (since ``time.perf_counter()`` was
    ``start``) and this session's provenance."""
    return {
        "experiment": spec.experiment,
        "name": spec.name,
        "setting": setting,
        "features": spec.features,
        "options": spec.options,
        "trial": trial,
        "samples": spec.samples,
        "budget_iterations": spec.iterations,
        "iterations": opt.iteration,
        "episodes": opt.iteration * spec.samples,
        "stopped": sorted(opt.stop()),
        "values": mean_policy_metric(env, spec.experiment, opt),
        "history": history,
        "seconds_last_session": time.perf_counter() - start,
        "provenance": provenance(PACKAGES),
    }


def _run_files(stem: Path) -> tuple[Path, ...]:
    """The files of the run ``stem``: its result ``.json``, checkpoint ``.npz``, ``.history.json`` and
    ``.selector.json``."""
    return tuple(stem.with_suffix(suffix) for suffix in (".json", ".npz", ".history.json", ".selector.json"))


def _resume(
    spec: RunSpec,
    env: OffsetParams,
    stem: Path,
    setting: dict[str, Any],
    base_seed: list[Any],
    selector: Any,
    fresh: bool,
) -> tuple[Any, dict[str, Any], dict[str, Any]]:
    """:func:`train_run`'s optimiser, history and selector states (by iteration): restored from the run's
    checkpoint ``<stem>.npz`` when its history is of ``setting`` (and, with a selector, the selector has a
    state at that iteration), else new (``fresh``: always). The history is written before the checkpoint,
    so after a kill it may run ahead of it: it is cut back to the checkpoint's iteration."""
    _, ckpt, history_path, selector_path = _run_files(stem)
    history = read_json(history_path) if ckpt.exists() and not fresh else {}
    states = read_json(selector_path) if selector and selector_path.exists() else {}
    opt = load_run(stem) if stored_setting(history, spec.experiment) == setting else None
    if opt is not None and selector is not None and str(opt.iteration) not in states:
        opt = None  # no selector state at the checkpoint: start over
    if opt is not None and selector is not None:
        selector.load_state_dict(states[str(opt.iteration)])
    if opt is None:  # a checkpoint of another setting starts over
        opt = _new_optimizer(spec, env, int(np.random.SeedSequence(base_seed).generate_state(1)[0]))
        history = {"setting": setting, "batch": [], "evaluations": []}
    history["batch"] = history["batch"][: opt.iteration]
    history["evaluations"] = [e for e in history["evaluations"] if e[0] <= opt.iteration]
    return opt, history, states
