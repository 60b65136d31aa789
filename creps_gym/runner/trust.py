"""A run directory is untrusted input: what it may name, and how big a run may be.

**No imports from a run directory.** Gymnasium imports ``module`` for an env id ``"module:Env-v0"``, and
envs that wrap another env (e.g. ``creps_gym/PointMazeGoal-v0``'s ``env`` keyword) pass such ids on. So
the configuration read back from ``config.json`` may only name

* a registered env id, or ``"module:Env-v0"`` whose ``module`` is already imported;
* strings of the form ``"module:..."`` (in the env keywords and optimiser options) whose module is already
  imported;
* a registered optimiser name (the registry never imports a ``"module:Class"`` read from a file).

Anything else raises :class:`~creps_gym.errors.RunDirError`. The user imports the module
(``creps-gym resume --import MODULE``, the same for every command, or ``import MODULE`` before
:func:`creps_gym.runner.resume`).

**Checkpoints.** A checkpoint records the :func:`config_fingerprint` of its run; :func:`check_checkpoint`
refuses one written under another configuration, and runner state that no run can have written.

**Sizes.** :func:`check_run_memory` refuses, before the optimiser or the batch is allocated, a run whose
arrays would not fit in memory (:func:`creps_gym._validation.check_fits_in_memory`).
"""

from __future__ import annotations

import hashlib
import importlib
import json
import sys
from collections.abc import Iterator, Sequence
from typing import Any

import gymnasium as gym

from creps_gym._validation import check_fits_in_memory, config_field
from creps_gym.errors import RunDirError
from creps_gym.optimizers.registry import optimizer_names
from creps_gym.runner.checks import CRITERION
from creps_gym.runner.config import RunConfig
from creps_gym.selectors.registry import selector_names

__all__ = [
    "CHECKPOINT_FORMAT",
    "FINGERPRINT_FIELDS_IF_SET",
    "IMPORT_ADVICE",
    "check_checkpoint",
    "check_run_memory",
    "check_trusted",
    "config_fingerprint",
    "escape_text",
    "import_modules",
    "module_reference",
    "possible_stop_reason",
    "registered_env_id",
]

CHECKPOINT_FORMAT = "creps_gym.run/3"
#: Formats still read: ``/2`` holds the whole history (and drew contexts by seeded resets), ``/1`` also has
#: no fingerprint (matched on the history's seed, samples and env).
LEGACY_FORMATS = ("creps_gym.run/2", "creps_gym.run/1")
#: The configuration fields that define a run's results (the others only say where and how it runs).
FINGERPRINT_FIELDS = ("env", "env_kwargs", "optimizer", "optimizer_options", "seed", "samples", "iterations",
                      "eval_every", "eval_contexts", "context_draws", "initial_mean", "initial_std",
                      "max_episodes", "target_regret", "max_time")  # fmt: skip
#: Fields fingerprinted only when set (``context_selector`` not None): runs without a selector keep the
#: fingerprint they had before the fields existed, so their checkpoints still load.
FINGERPRINT_FIELDS_IF_SET = ("context_selector", "context_selector_options")
#: ``divergence`` is fingerprinted only when it is not the default, for the same reason.
DEFAULT_DIVERGENCE = RunConfig.divergence
#: The fields format ``creps_gym.run/2`` fingerprinted (it had no ``context_draws``: always ``"reset"``).
FINGERPRINT_FIELDS_2 = tuple(name for name in FINGERPRINT_FIELDS if name != "context_draws")


#: What to do about a module a run directory names; the CLI puts its command in place of ``COMMAND``.
IMPORT_ADVICE = (
    "import the module yourself if you trust it (`creps-gym COMMAND --import MODULE`, or `import MODULE` "
    "in Python first)"
)


def module_reference(text: str) -> str | None:
    """The module a ``"module:name"`` string makes Gymnasium (or a registry) import, or None.

    Gymnasium imports *any* text before the first ``:`` of an env id (``"1evil:X-v0"``, ``"my-evil:X"``,
    ``"évil:X"``, ``" os :X"``), whether or not it is a Python identifier, so every such text counts as
    a module reference, unchanged (no stripping: ``" os"`` is not the module ``os``).
    """
    module, colon, _ = text.partition(":")
    return module if colon else None


def import_modules(modules: Sequence[str]) -> None:
    """Import the modules a user names (``--import``): the only code imported on a user's word."""
    for module in modules:
        try:
            importlib.import_module(module)
        except ImportError as exc:
            raise ValueError(f"expected an importable module, got {module!r} ({exc})") from None


def registered_env_id(env_id: str, *, import_module: bool = False) -> str:
    """``env_id`` if registered (a ``module:Env-v0``'s module imported first with ``import_module``)."""
    import creps_gym

    module = module_reference(env_id)
    if module is not None and import_module:
        import_modules([module])
    if env_id.split(":", 1)[-1] not in gym.registry:
        raise ValueError(f"expected one of {creps_gym.registered_ids()}, got {env_id!r}")
    return env_id


def _strings(value: Any, where: str) -> Iterator[tuple[str, str]]:
    """Every string in a JSON value (keys included), with where it is."""
    if isinstance(value, str):
        yield where, value
    elif isinstance(value, dict):
        for key, item in value.items():
            yield f"{where}.{key}", str(key)
            yield from _strings(item, f"{where}.{key}")
    elif isinstance(value, (list, tuple)):
        for index, item in enumerate(value):
            yield from _strings(item, f"{where}[{index}]")


def check_trusted(config: RunConfig, source: str) -> None:
    """Refuse a configuration read from ``source`` that would import code (see the module docstring)."""

    def refuse(field: str, value: str, why: str) -> RunDirError:
        return RunDirError(
            f"{source}: {field}: expected {why}, got {value!r}; a run directory never makes the runner "
            f"import code: {IMPORT_ADVICE}"
        )

    if config.optimizer is not None and config.optimizer not in optimizer_names():
        raise refuse("optimizer", config.optimizer, f"a registered optimiser name {optimizer_names()}")
    if config.context_selector is not None and config.context_selector not in selector_names():
        raise refuse("context_selector", config.context_selector, f"a registered selector {selector_names()}")
    found = [("env", config.env)] if config.env is not None else []
    found += _strings(config.env_kwargs, "env_kwargs")
    found += _strings(config.optimizer_options, "optimizer_options")
    found += _strings(config.context_selector_options, "context_selector_options")
    for field, text in found:
        module = module_reference(text)
        if module is not None and module not in sys.modules:
            raise refuse(field, text, f"no reference to a module that is not imported (here {module!r})")
    if config.env is not None and config.env.split(":", 1)[-1] not in gym.registry:  # module imported above
        raise refuse("env", config.env, "a registered env id")
    _check_options_are_data(config, source)


def _check_options_are_data(config: RunConfig, source: str) -> None:
    """Refuse ``cma`` options that pycma would evaluate as code (``{"tolfun": "9**9**9"}``)."""
    if config.optimizer != "cma":  # nevergrad and optuna accept only names from their allow-lists
        return
    from creps_gym.optimizers.adapters.pycma import check_option_value

    options = dict(config.optimizer_options)
    nested = options.pop("cma_options", {})
    for key, value in {**(nested if isinstance(nested, dict) else {}), **options}.items():
        try:
            check_option_value(str(key), value)
        except ValueError as exc:
            raise RunDirError(
                f"{source}: optimizer_options: {exc}; a run directory holds data only"
            ) from None


def check_run_memory(config: RunConfig, n_params: int, n_context_dims: int, *, covariance: bool) -> None:
    """Refuse a run whose optimiser and batch arrays would not fit in memory, before they are allocated.

    The estimate counts 8-byte floats: about ``6 p²`` for a covariance and its factors (when
    ``covariance``), ``4 N p`` for the batch of parameters and its copies, ``4 N z`` for the contexts and
    features, and ``2 E p`` for the evaluation (N samples, E test contexts).
    """
    p, z, n, e = n_params, n_context_dims, config.samples, config.eval_contexts
    square = 6.0 * p * p if covariance else 0.0
    batch, evaluation = 4.0 * n * p + 4.0 * n * (z + 1), 2.0 * e * p
    if max(batch, evaluation) > square:  # name the largest term's argument
        name, value = ("samples", n) if batch >= evaluation else ("eval_contexts", e)
    elif config.env_kwargs:
        name, value = "env_kwargs", config.env_kwargs
    else:
        name, value = "env", config.env
    what = f"the covariance (p x p, p = {p}), the batch (samples x p) and the evaluation (eval_contexts x p)"
    with config_field(name):
        check_fits_in_memory(8.0 * (square + batch + evaluation), name, value, what)


def config_fingerprint(config: RunConfig, checkpoint_format: str = CHECKPOINT_FORMAT) -> str:
    """SHA-256 (hex) of a checkpoint format and the fields it fingerprints of ``config``."""
    data = config.to_dict()
    names = FINGERPRINT_FIELDS if checkpoint_format == CHECKPOINT_FORMAT else FINGERPRINT_FIELDS_2
    document = {"format": checkpoint_format, **{name: data[name] for name in names}}
    if data.get("context_selector") is not None:
        document.update({name: data[name] for name in FINGERPRINT_FIELDS_IF_SET})
    if data.get("divergence", DEFAULT_DIVERGENCE) != DEFAULT_DIVERGENCE:  # the default: as before it existed
        document["divergence"] = data["divergence"]
    return hashlib.sha256(json.dumps(document, sort_keys=True, allow_nan=False).encode()).hexdigest()


def _same_run(flat: dict[str, Any], config: RunConfig) -> bool:
    if flat["format"] in LEGACY_FORMATS and config.context_draws != "reset":
        return False  # an old checkpoint with a new config.json (the old stream is "reset")
    if flat["format"] != LEGACY_FORMATS[-1]:
        return flat.get("fingerprint") == config_fingerprint(config, flat["format"])
    meta = flat["history"]["meta"]  # a legacy checkpoint: its history's metadata
    expected = {"seed": config.seed, "samples": config.samples, "env": config.env or meta.get("env")}
    return all(meta.get(key) == value for key, value in expected.items())


def possible_stop_reason(stop: Any, config: RunConfig, iteration: int) -> bool:
    """Whether the loop can have stopped a run of ``config`` after ``iteration`` iterations with ``stop``.

    ``stop`` None means not stopped. The loop (:mod:`creps_gym.runner.loop`) checks its reasons in order:
    at ``config.iterations`` the reason is ``"iterations"``, and only there; where the next iteration would
    exceed ``max_episodes`` it is ``"max_episodes"``; the others need their option (``target_regret``,
    ``max_time``, ``divergence``) or are ``"callback"`` or ``"optimizer: "`` with plain sorted criterion
    names.
    """
    if stop is not None and not isinstance(stop, str):
        return False
    budget = config.max_episodes
    over_budget = budget is not None and (iteration + 1) * config.samples > budget
    if iteration >= config.iterations or (over_budget and iteration > 0):
        return stop == ("iterations" if iteration >= config.iterations else "max_episodes")
    if stop is None:
        return True
    needs = {
        "target_regret": config.target_regret,
        "max_time": config.max_time,
        "divergence": config.divergence,
        "callback": True,
    }
    if stop in needs:
        return iteration > 0 and needs[stop] is not None
    criteria = stop.removeprefix("optimizer: ").split(", ")
    named = stop.startswith("optimizer: ") and all(CRITERION.fullmatch(name) for name in criteria)
    return iteration > 0 and named and criteria == sorted(set(criteria))


def escape_text(text: Any) -> str:
    """``str(text)`` safe to print: control characters (ANSI escapes, newlines) as Python escapes."""
    text = str(text)
    if text.isprintable():
        return text
    return "".join(c if c.isprintable() else c.encode("unicode_escape").decode("ascii") for c in text)


def _consistent(flat: dict[str, Any], config: RunConfig) -> bool:
    """Counts, types and records that a run of ``config`` can have written."""
    iteration, episodes, elapsed = flat["iteration"], flat["episodes"], flat["elapsed"]
    ok = all(type(v) is int for v in (iteration, episodes)) and 0 <= iteration <= config.iterations
    ok = ok and episodes == iteration * config.samples and isinstance(flat["env_rng"], dict)
    ok = ok and type(elapsed) in (int, float) and 0 <= elapsed < float("inf")
    if flat["format"] == CHECKPOINT_FORMAT:  # the history is in the log: its checksum and stop reason
        stop = flat["stop_reason"]
        return ok and type(flat["log_crc"]) is int and possible_stop_reason(stop, config, iteration)
    records = flat["history"]["records"]
    ok = (
        ok
        and len(records) == iteration
        and possible_stop_reason(flat["history"].get("stop_reason"), config, iteration)
    )
    for number, record in enumerate(records, 1):
        counts = record["iteration"], record["episodes"]
        ok = ok and all(type(v) is int for v in counts) and counts == (number, number * config.samples)
    return ok


def check_checkpoint(flat: dict[str, Any], config: RunConfig, path: str, advice: str) -> None:
    """Refuse a checkpoint (``load_state`` content) of another run, or with runner state no run wrote."""
    try:
        same, consistent = _same_run(flat, config), _consistent(flat, config)
    except (KeyError, TypeError, ValueError, AttributeError, IndexError) as exc:
        raise RunDirError(
            f"{path}: damaged or not written by creps_gym ({type(exc).__name__}: {exc}); {advice}"
        ) from None
    if not same:
        raise RunDirError(
            f"{path}: expected the checkpoint of the run configured in config.json (env {config.env}, seed "
            f"{config.seed}, ...), got one written by a run with another configuration (copied from another "
            f"run?); {advice}"
        )
    if not consistent:
        found = {key: flat[key] for key in ("iteration", "episodes", "elapsed")}
        raise RunDirError(
            f"{path}: damaged or not written by creps_gym (inconsistent runner state {found}); {advice}"
        )
