"""Helpers shared by several test modules (imported as ``from helpers import ...``)."""

from __future__ import annotations

import os
import re
import sys
from pathlib import Path
from typing import Any

import gymnasium as gym
import pytest
from gymnasium.error import DependencyNotInstalled

SPHERE = "creps_gym/Sphere-v0"


def make_or_skip(env_id: str, vector: bool = False, **kwargs: Any) -> Any:
    """``gym.make`` (or ``gym.make_vec``) an id, skipping the test when an optional extra is missing."""
    try:
        return gym.make_vec(env_id, **kwargs) if vector else gym.make(env_id, **kwargs)
    except (DependencyNotInstalled, ModuleNotFoundError) as exc:  # an optional extra (MuJoCo, robotics)
        pytest.skip(f"{env_id}: optional dependency not installed ({exc})")


def file_size_limited(n_bytes: int) -> dict[str, Any]:
    """``subprocess.run`` keywords for a child under ``ulimit -f`` of ``n_bytes`` (the CLI ignores SIGXFSZ,
    so a write past it fails with EFBIG). The child writes no bytecode: a ``.pyc`` it wrote would be cut at
    the limit, and Python keeps a short write, so every later process importing that module would die on the
    cut file (``marshal data too short``); it still reads the bytecode the others cached."""

    def limit() -> None:
        import resource

        resource.setrlimit(resource.RLIMIT_FSIZE, (n_bytes, n_bytes))

    return {"preexec_fn": limit, "env": {**os.environ, "PYTHONDONTWRITEBYTECODE": "1"}}


def python_blocks(path: Path) -> list[str]:
    """The ```python code blocks of a Markdown file, in order."""
    return re.findall(r"```python\n(.*?)```", Path(path).read_text(), flags=re.DOTALL)


def cli_command(*args: Any) -> list[str]:
    """The command line of ``creps-gym`` with ``args``, run through the current interpreter."""
    return [sys.executable, "-m", "creps_gym.cli", *map(str, args)]


def run_argv(
    out: Any,
    *extra: Any,
    env: str = SPHERE,
    env_kwargs: tuple[str, ...] = (),
    optimizer: str = "c-cma-es",
    iterations: int = 2,
    seed: int = 0,
) -> list[str]:
    """The arguments of ``creps-gym run`` for a short run into ``out``, then ``extra``."""
    kwargs = [item for pair in env_kwargs for item in ("--env-kwarg", pair)]
    return [
        "run",
        "--env",
        env,
        *kwargs,
        "--optimizer",
        optimizer,
        "--iterations",
        str(iterations),
        "--seed",
        str(seed),
        "--out",
        str(out),
        *map(str, extra),
    ]


def cli_in_process(*args: Any, cwd: Any = None, env: dict[str, str] | None = None, timeout: float = 0):
    """``creps-gym args`` run in this process through :func:`creps_gym.cli.main`, as a
    :class:`subprocess.CompletedProcess` (``returncode``, ``stdout``, ``stderr``), in ``cwd`` and with ``env``
    added to the environment, both restored afterwards, as are ``sys.path`` and the modules it imported from
    outside the interpreter's own paths (an ``--import`` module of a test folder).

    A test of library behaviour through the command line uses it: it costs no interpreter start. Tests of the
    process boundary (the console script, signals, start-up imports, ``-m`` and the working directory's
    path entry, environment variables read at import time) use :func:`cli_command` in a subprocess.
    ``timeout`` is accepted for the subprocess helpers' signature and ignored (pytest-timeout bounds a test).
    """
    import contextlib
    import io
    import os
    import subprocess

    from creps_gym.cli import main

    argv = [str(arg) for arg in args]
    stdout, stderr = io.StringIO(), io.StringIO()
    saved_path, saved_modules, saved_cwd = list(sys.path), set(sys.modules), os.getcwd()
    saved_env = {key: os.environ.get(key) for key in (env or {})}
    try:
        os.environ.update(env or {})
        if cwd is not None:
            os.chdir(cwd)
        with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
            try:
                code = main(argv)
            except SystemExit as exc:  # argparse: --help (0) and usage errors (2)
                code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
    finally:
        os.chdir(saved_cwd)
        sys.path[:] = saved_path
        for name in set(sys.modules) - saved_modules:  # a test folder's module must not outlive its test
            if _in_a_test_folder(getattr(sys.modules[name], "__file__", None)):
                del sys.modules[name]
        for key, value in saved_env.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value
    return subprocess.CompletedProcess(["creps-gym", *argv], code, stdout.getvalue(), stderr.getvalue())


_TEMPORARY = str(Path(__import__("tempfile").gettempdir()).resolve())
#: This checkout: its modules (the package, ``benchmarks``) stay imported even when it lies in the temporary
#: folder, as a clean CI clone may (deleting them would leave two copies of the package in one process).
_REPOSITORY = str(Path(__file__).resolve().parents[1])


def _in_a_test_folder(file: str | None) -> bool:
    """Whether a module's ``__file__`` is in a temporary test folder (an ``--import`` module of a test)."""
    path = str(file or "")
    return path.startswith(_TEMPORARY) and not path.startswith(_REPOSITORY + os.sep)


def study_in_process(study: str, *args: Any) -> str:
    """``python -m benchmarks.<study>.run ARGS`` run in this process through its ``main``, which must return
    0; its standard output. The studies' tests start a process once per study and mode (by path, ``-m``), and
    check the rest of a script's behaviour with this."""
    import contextlib
    import importlib
    import io

    stdout = io.StringIO()
    with contextlib.redirect_stdout(stdout):
        code = importlib.import_module(f"benchmarks.{study}.run").main([str(arg) for arg in args])
    assert code == 0, stdout.getvalue()[-2000:]
    return stdout.getvalue()


def no_figure(*args: Any) -> Path:
    """A stand-in for a study's ``plot_*`` function where a test checks no figure: draws nothing and returns
    the figure's path (its first ``Path`` argument), as the plotting functions do."""
    return next(arg for arg in args if isinstance(arg, Path))


# -- forged checkpoints and crashes: the run-folder attack and recovery tests
_CHECKPOINT_KEYS = ("format", "fingerprint", "state_crc")


def forge(path: Path, **changes: Any) -> None:
    """Change fields of the loop state in the checkpoint ``path`` (``optimizer.KEY`` for the optimiser's)
    and recompute its checksum, as a forger who knows the format would."""
    import json
    import zlib

    from creps_gym.optimizers import load_state, save_state

    flat = load_state(path)
    flat.update(changes)
    state = {k: v for k, v in flat.items() if not k.startswith("optimizer.") and k not in _CHECKPOINT_KEYS}
    flat["state_crc"] = zlib.crc32(json.dumps(state, allow_nan=False, sort_keys=True).encode())
    save_state(flat, path)


def crash_at(iteration: int) -> Any:
    """A runner callback that raises ``RuntimeError("crash")`` after ``iteration``'s record (with
    ``checkpoint_every=1`` the run's last checkpoint is the iteration before)."""
    from creps_gym.runner import Callback

    class CrashAt(Callback):
        def on_iteration(self, record: Any, history: Any) -> bool:
            if record.iteration == iteration:
                raise RuntimeError("crash")
            return False

    return CrashAt()


def skip_unless_stack_of(record: dict[str, Any]) -> None:
    """Skip the calling test, naming what differs, unless this process computes on the numeric stack of
    a committed provenance ``record`` (its ``packages``' numpy and scipy, its ``blas`` kernels and its
    ``simd``, numpy's dispatch; the committed stack's where absent; see :mod:`benchmarks.numeric_stack`):
    a committed run is bit for bit the code's only there. The suite's processes compute on the committed
    runs' stack on any x86-64 CPU with AVX2 and FMA (``conftest.py``)."""
    from benchmarks.numeric_stack import differences

    found = differences(record["packages"], record.get("blas"), record.get("simd"))
    if found:
        pytest.skip("bit for bit only on the stack that computed the committed run: " + "; ".join(found))


# -- the `extras` marker: tests that need an optional extra; CI's lowest-versions environment runs the others
EXTRAS = pytest.mark.extras
_EXTRA_ENV_MODULES = ("creps_gym.envs.kick", "creps_gym.wrappers")  # MuJoCo, Gymnasium(-Robotics) MuJoCo envs


def needs_extra(env_or_optimizer: str) -> bool:
    """Whether a registered env id or optimiser name needs an optional extra (MuJoCo, a library)."""
    from creps_gym.optimizers.adapters import MinimizerAdapter
    from creps_gym.optimizers.registry import optimizer_class, optimizer_names

    if env_or_optimizer in optimizer_names():  # the bundled adapters wrap pycma, nevergrad and optuna
        return issubclass(optimizer_class(env_or_optimizer), MinimizerAdapter)
    entry_point = gym.spec(env_or_optimizer).entry_point
    return isinstance(entry_point, str) and entry_point.startswith(_EXTRA_ENV_MODULES)


def marked(names: Any) -> list[Any]:
    """Parameters for ``pytest.mark.parametrize``, the ones that need an optional extra marked ``extras``."""
    return [pytest.param(name, marks=EXTRAS) if needs_extra(name) else name for name in names]


# -- a GP's posterior gradients against central differences (c-bo's model, with or without a trend)
def check_posterior_gradients(model: Any, x: Any, step: float = 1e-6, variance_atol: float = 1e-7) -> None:
    """``model.predict_with_gradient(x)``'s mean and variance gradients (m, d) are the central differences
    of ``model.predict`` with ``step`` in each input dimension."""
    import numpy as np

    _, _, dmean, dvariance = model.predict_with_gradient(x)
    for j in range(x.shape[1]):
        shift = np.zeros(x.shape[1])
        shift[j] = step
        up, down = model.predict(x + shift), model.predict(x - shift)
        np.testing.assert_allclose(dmean[:, j], (up[0] - down[0]) / (2 * step), rtol=1e-5, atol=1e-7)
        np.testing.assert_allclose(
            dvariance[:, j], (up[1] - down[1]) / (2 * step), rtol=1e-5, atol=variance_atol
        )


# -- a c-bo with a GP: p = 2, z = 1, batches of 4 on a contextual sphere whose optimum is θ = (s, s)
def driven_cbo(seed: int = 0, batches: int = 4, **options: Any) -> Any:
    """``c-bo`` (with ``options``) after ``batches`` seeded asks and tells of 4 episodes (contexts uniform on
    [0, 1), returns −|θ − s|²)."""
    import numpy as np

    from creps_gym.optimizers import make_optimizer

    optimizer = make_optimizer("c-bo", 2, 1, seed, **options)
    rng = np.random.default_rng(0)
    for _ in range(batches):
        contexts = rng.uniform(size=(4, 1))
        params = optimizer.ask(contexts)
        optimizer.tell(contexts, params, -((params - contexts) ** 2).sum(axis=1))
    return optimizer
