"""The generic runner: any ask/tell optimiser on any contextual episodic env.

``run(optimizer, env, iterations, samples_per_iteration, seed, ...) -> History`` runs the loop (contexts,
ask, evaluate, tell), evaluates the recommended policy on fixed test contexts, and optionally writes a run
directory (config, JSONL log, versions, atomic ``.npz`` checkpoints) that :func:`resume` continues. See
``docs/runner.md``.

Modules: :mod:`.config` (RunConfig), :mod:`.loop` (the Runner), :mod:`.build` (what a new run builds),
:mod:`.contexts` (how contexts are drawn), :mod:`.api` (run, resume), :mod:`.history` (History),
:mod:`.backends` (failure policy, serial; :mod:`.vector_backend`, :mod:`.ray_backend`), :mod:`.callbacks`
(callbacks, progress bar), :mod:`.rundir` (run directory), :mod:`.recovery` (the history from the log),
:mod:`.session` (lock file, Ctrl-C), :mod:`.trust` (what a run directory may name, memory limits),
:mod:`.policy_store` (the best and final policies a run keeps, ``load_policy``),
:mod:`.export` (IOHanalyzer CSV), :mod:`.plots` (matplotlib).
"""

from creps_gym.errors import EpisodeError, RunDirError, RunDirWarning
from creps_gym.runner.api import resume, run
from creps_gym.runner.backends import EnvSource, make_backend
from creps_gym.runner.callbacks import Callback, ProgressBar
from creps_gym.runner.config import BACKENDS, CONTEXT_DRAWS, VECTOR_MODES, RunConfig
from creps_gym.runner.export import write_iohanalyzer
from creps_gym.runner.history import History, IterationRecord
from creps_gym.runner.loop import Runner, default_initial_distribution, split_seed
from creps_gym.runner.plots import load_history, plot_histories, plot_run_dirs
from creps_gym.runner.rundir import RunDir, package_versions

__all__ = [
    "BACKENDS",
    "CONTEXT_DRAWS",
    "VECTOR_MODES",
    "Callback",
    "EnvSource",
    "EpisodeError",
    "History",
    "IterationRecord",
    "ProgressBar",
    "RunConfig",
    "RunDir",
    "RunDirError",
    "RunDirWarning",
    "Runner",
    "default_initial_distribution",
    "load_history",
    "make_backend",
    "package_versions",
    "plot_histories",
    "plot_run_dirs",
    "resume",
    "run",
    "split_seed",
    "write_iohanalyzer",
]
