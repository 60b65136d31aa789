"""The generic runner: any ask/tell optimiser on any contextual episodic env.

``run(optimizer, env, iterations, samples_per_iteration, seed, ...) -> History`` runs the loop (contexts,
ask, evaluate, tell), evaluates the recommended policy on fixed test contexts, and optionally writes a run
directory (config, JSONL log, versions, atomic ``.npz`` checkpoints) that :func:`resume` continues. See
``docs/runner.md``.

The loop's core is flat: :mod:`.api` (run, resume), :mod:`.config` (RunConfig), :mod:`.build` (what a
new run builds), :mod:`.loop` (the Runner), :mod:`.seeds` (the seed plan), :mod:`.contexts` (how contexts
are drawn), :mod:`.selection` (the context selector), :mod:`.protocol` (an optimiser checked against the
ask/tell protocol), :mod:`.env_model` (the model behind an env's wrappers), :mod:`.divergence`,
:mod:`.callbacks` (callbacks, progress bar), :mod:`.history` (History), :mod:`.ioh` (its IOHanalyzer CSV
text). Three wings:

* :mod:`.backends`: where episodes run (failure policy, serial; :mod:`.backends.episodes` what every
  backend shares, :mod:`.backends.vector`, :mod:`.backends.ray`, :mod:`.backends.watchdog`);
* :mod:`.rundir`: the run directory (:class:`RunDir`; :mod:`.rundir.files` its files, :mod:`.rundir.session`
  the lock file and Ctrl-C, :mod:`.rundir.log_chain` the log's lines, :mod:`.rundir.recovery` the history
  from the log, :mod:`.rundir.checkpoint` what a checkpoint may hold and its formats,
  :mod:`.rundir.references` what a run directory may name, :mod:`.rundir.policies` the policies a run
  keeps, ``load_policy``);
* :mod:`.results`: what is made of finished runs (:mod:`.results.plots`, :mod:`.results.export` (IOHanalyzer
  CSV files), :mod:`.results.groups` seeds of one setting, :mod:`.results.video`,
  :mod:`.results.outputs` the output paths a user names).
"""

from creps_gym.runner.api import resume, run
from creps_gym.runner.backends import EnvSource, make_backend
from creps_gym.runner.build import default_initial_distribution
from creps_gym.runner.callbacks import Callback, ProgressBar
from creps_gym.runner.config import BACKENDS, CONTEXT_DRAWS, VECTOR_MODES, RunConfig
from creps_gym.runner.history import History, IterationRecord
from creps_gym.runner.loop import Runner
from creps_gym.runner.results.export import write_iohanalyzer
from creps_gym.runner.results.plots import load_history, plot_histories, plot_run_dirs
from creps_gym.runner.rundir import RunDir, package_versions
from creps_gym.runner.seeds import split_seed

__all__ = [
    "BACKENDS",
    "CONTEXT_DRAWS",
    "VECTOR_MODES",
    "Callback",
    "EnvSource",
    "History",
    "IterationRecord",
    "ProgressBar",
    "RunConfig",
    "RunDir",
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
