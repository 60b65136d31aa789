"""A checkpoint is untrusted input: its formats, the run it belongs to, the state a run can have written.

**Formats.** A checkpoint is written in the current format, :data:`CHECKPOINT_FORMAT` (``creps_gym.run/3``:
the loop's state with the checksum ``log_crc`` of the history's records, which are in the log). Two older
formats are still read (:data:`LEGACY_FORMATS`): ``/2`` holds the whole history (and drew contexts by
seeded resets), ``/1`` also has no fingerprint (it is matched on its history's seed, samples and env).
This module is the only one that knows them: :func:`open_checkpoint` checks a checkpoint as its format
was written and upgrades an older one, once, to the current form (``stop_reason`` and ``log_crc`` from
its history, which it keeps as ``state["held_history"]``, a :class:`~creps_gym.runner.history.History`;
``best_policy`` None where a checkpoint was written before runs kept one), so the loop and the recovery of
a history read one form.

**Checkpoints.** A checkpoint records the :func:`config_fingerprint` of its run; :func:`check_checkpoint`
refuses one written under another configuration, and runner state that no run can have written.

**Sizes.** :func:`check_run_memory` refuses, before the optimiser or the batch is allocated, a run whose
arrays would not fit in memory (:func:`creps_gym._validation.check_fits_in_memory`).
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable
from typing import Any

from creps_gym._validation import check_fits_in_memory, config_field
from creps_gym.errors import RunDirError
from creps_gym.runner.config import RunConfig
from creps_gym.runner.history import History
from creps_gym.runner.protocol import CRITERION
from creps_gym.runner.rundir.log_chain import entry_crc, history_crc

__all__ = [
    "CHECKPOINT_FORMAT",
    "FINGERPRINT_FIELDS",
    "FINGERPRINT_FIELDS_IF_SET",
    "LEGACY_FORMATS",
    "check_checkpoint",
    "check_run_memory",
    "checkpoint_document",
    "config_fingerprint",
    "open_checkpoint",
    "possible_stop_reason",
]

CHECKPOINT_FORMAT = "creps_gym.run/3"
#: Formats still read: ``/2`` holds the whole history (and drew contexts by seeded resets), ``/1`` also has
#: no fingerprint (matched on the history's seed, samples and env).
LEGACY_FORMATS = ("creps_gym.run/2", "creps_gym.run/1")
#: The configuration fields that define a run's results (the others only say where and how it runs).
FINGERPRINT_FIELDS = (
    "env",
    "env_kwargs",
    "optimizer",
    "optimizer_options",
    "seed",
    "samples",
    "iterations",
    "eval_every",
    "eval_contexts",
    "context_draws",
    "initial_mean",
    "initial_std",
    "max_episodes",
    "target_regret",
    "max_time",
)
#: Fields fingerprinted only when set (``context_selector`` not None): runs without a selector keep the
#: fingerprint they had before the fields existed, so their checkpoints still load.
FINGERPRINT_FIELDS_IF_SET = ("context_selector", "context_selector_options")
#: ``divergence`` is fingerprinted only when it is not the default, for the same reason.
DEFAULT_DIVERGENCE = RunConfig.divergence
#: A checkpoint's own keys around the loop's state; the optimiser's state keys start with ``optimizer.``.
_CHECKPOINT_KEYS = ("format", "fingerprint", "state_crc")
_OPTIMIZER = "optimizer."
#: The fields format ``creps_gym.run/2`` fingerprinted (it had no ``context_draws``: always ``"reset"``).
FINGERPRINT_FIELDS_2 = tuple(name for name in FINGERPRINT_FIELDS if name != "context_draws")


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


def checkpoint_document(
    state: dict[str, Any], optimizer_state: dict[str, Any], config: RunConfig
) -> dict[str, Any]:
    """What a checkpoint holds (``save_state`` content): the loop's ``state`` and its checksum, the
    optimiser's state (keys prefixed ``optimizer.``), the format and ``config``'s fingerprint."""
    flat = {"format": CHECKPOINT_FORMAT, "fingerprint": config_fingerprint(config), **state}
    flat["state_crc"] = entry_crc(state, sort_keys=True)  # the loop's state is checked as a whole
    flat.update({f"{_OPTIMIZER}{key}": value for key, value in optimizer_state.items()})
    return flat


def _loop_state(flat: dict[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in flat.items() if not k.startswith(_OPTIMIZER) and k not in _CHECKPOINT_KEYS}


def open_checkpoint(
    flat: dict[str, Any],
    config: RunConfig | None,
    path: str,
    advice: str,
    damaged: Callable[[Any], RunDirError],
) -> tuple[dict[str, Any], dict[str, Any]]:
    """``(loop state, optimiser state)`` of the checkpoint ``flat`` (``load_state`` content), upgraded.

    Checked as its format was written (the loop state's checksum; with ``config``,
    :func:`check_checkpoint`), then an older format is upgraded to the current form (see the module
    docstring). ``damaged(why)`` is the error for a damaged checkpoint (it names the file ``path`` and
    what to do, ``advice``).
    """
    found = flat.get("format")
    if found not in (CHECKPOINT_FORMAT, *LEGACY_FORMATS):
        raise damaged(f"format {found!r}, expected {CHECKPOINT_FORMAT!r}")
    state = _loop_state(flat)
    if found == CHECKPOINT_FORMAT:
        try:
            intact = flat.get("state_crc") == entry_crc(state, sort_keys=True)
        except (TypeError, ValueError):
            intact = False
        if not intact:
            raise damaged("the loop state does not match its checksum")
    if config is not None:
        check_checkpoint(flat, config, path, advice)
    optimizer_state = {k[len(_OPTIMIZER) :]: v for k, v in flat.items() if k.startswith(_OPTIMIZER)}
    if found != CHECKPOINT_FORMAT:
        try:
            held = History.from_dict(state.pop("history"))
        except (KeyError, TypeError, ValueError, AttributeError) as exc:
            raise damaged(exc) from None
        state.update(stop_reason=held.stop_reason, log_crc=history_crc(held.records), held_history=held)
    state.setdefault("best_policy", None)  # none in checkpoints written before runs kept their best policy
    return state, optimizer_state
