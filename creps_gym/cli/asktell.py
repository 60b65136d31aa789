"""``creps-gym ask`` and ``creps-gym tell``: a run driven episode by episode from the shell (a real robot).

``ask RUN --new --optimizer NAME --seed N --param-low ... --param-high ... --context-low ...
--context-high ...`` starts an ask/tell run in the folder RUN (or ``--env ID`` takes the spaces of a
registered env, to rehearse on a simulated task); ``ask RUN --context S...`` prints the parameters to try
(``--json``: with the episode's id) and keeps the episode pending; ``tell RUN --return R [--episode ID]``
records its return (``--failed``: it gave none; another episode takes its place). ``ask RUN --pending``
prints the pending episodes again. See :mod:`creps_gym.runner.manual` for the run folder, crash safety and
the checks. Exit codes are the CLI's (:mod:`creps_gym.cli`): 2 for a bad flag or a request the run cannot
take (a full batch, a finished run, an unknown episode), 3 for a missing, damaged or locked run folder.
"""

from __future__ import annotations

import argparse
import json
import math
import shlex
import sys
from typing import Any

from creps_gym.cli.types import (
    add_import,
    add_key_value,
    add_search_start,
    import_modules_and_check_names,
    integer,
)
from creps_gym.errors import RunDirError, UsageError

__all__ = ["COMMANDS", "add_commands"]

_BOXES = ("--param-low", "--param-high", "--context-low", "--context-high")


def finite(text: str) -> float:
    """A finite number (a return, a context value, a box bound)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return value


def add_commands(commands: Any) -> None:
    """Add ``ask`` and ``tell`` to the sub-command parsers ``commands``."""
    ask = _run_command(
        commands,
        "ask",
        "print the parameters to try for a context (a run driven from outside, e.g. a real robot)",
        "Print the parameters of the next episode for a context and keep it pending until "
        "`creps-gym tell` records its return. --new starts the run.",
    )
    ask.add_argument(
        "--context", nargs="+", type=finite, metavar="S", help="the episode's context: z numbers"
    )
    ask.add_argument("--extrapolate", action="store_true", help="accept a context outside the context box")
    ask.add_argument("--pending", action="store_true", help="print the pending episodes (asks nothing)")
    ask.add_argument("--json", action="store_true", help="print JSON (with the episode's id)")
    _add_new(ask)
    add_import(ask)
    tell = _run_command(
        commands,
        "tell",
        "record the return of an episode that `ask` printed",
        "Record the return of a pending episode; a full batch updates the optimiser, "
        "checkpoints and rewrites policy.npz.",
    )
    outcome = tell.add_mutually_exclusive_group(required=True)
    outcome.add_argument("--return", dest="value", type=finite, metavar="R", help="the episode's return")
    outcome.add_argument("--failed", action="store_true", help="the episode gave no return (drop it)")
    tell.add_argument("--episode", type=integer(1), metavar="ID", help="its id (needed if several pending)")
    tell.add_argument("--json", action="store_true", help="print JSON")


def _run_command(commands: Any, name: str, summary: str, description: str) -> argparse.ArgumentParser:
    """A command on one ask/tell run folder (``RUN``)."""
    command = commands.add_parser(name, help=summary, description=description)
    command.add_argument("run", metavar="RUN", help="the ask/tell run folder")
    return command


def _add_new(ask: argparse.ArgumentParser) -> None:
    new = ask.add_argument_group("a new run (--new)")
    new.add_argument("--new", action="store_true", help="start a new ask/tell run in RUN")
    new.add_argument("--optimizer", "--optimiser", dest="optimizer", help="optimiser name (e.g. c-bo, creps)")
    new.add_argument("--seed", type=integer(0), help="master seed (>= 0)")
    new.add_argument(
        "--env", help="take the spaces of this registered env id (rehearsal; `evaluate` uses it)"
    )
    add_key_value(new, "--env-kwarg", "with --env: e.g. dim=5")
    new.add_argument(
        "--params", type=integer(1), metavar="P", help="p, if each parameter bound is one number"
    )
    new.add_argument(
        "--context-dims", type=integer(1), metavar="Z", help="z, if each context bound is one number"
    )
    for flag in _BOXES:
        new.add_argument(flag, nargs="+", type=finite, metavar="X", help="the box's bound (1 or p/z numbers)")
    new.add_argument("--samples", type=integer(2), help="episodes per batch (default: the optimiser's)")
    new.add_argument("--iterations", type=integer(1), default=1_000_000, help="batches (default: no limit)")
    new.add_argument("--max-episodes", type=integer(2), help="episode budget (default: no limit)")
    add_search_start(new)
    add_key_value(new, "--opt", "optimiser option")
    new.add_argument("--overwrite", action="store_true", help="replace a run already in RUN (deletes it)")


# -- handlers -----------------------------------------------------------------------------------------------
def _spaces(args: argparse.Namespace) -> Any:
    """The boxes the flags give (each bound 1 number, broadcast to --params/--context-dims, or p/z)."""
    from creps_gym.runner.manual import Spaces

    given = {flag: getattr(args, flag[2:].replace("-", "_")) for flag in _BOXES}
    if args.env is not None:
        if any(v is not None for v in given.values()) or args.params or args.context_dims:
            raise UsageError("argument --env: expected either --env or the boxes, got both")
        return None
    missing = [flag for flag, value in given.items() if value is None]
    if missing:
        raise UsageError(f"argument {missing[0]}: expected with --new (or --env ID), got none")
    boxes = {}
    for flag, value in given.items():
        size = args.params if flag.startswith("--param") else args.context_dims
        if size is not None and len(value) == 1:
            value = value * size
        elif size is not None and len(value) != size:
            raise UsageError(f"argument {flag}: expected 1 or {size} numbers, got {len(value)}")
        boxes[flag[2:].replace("-", "_")] = value
    try:
        return Spaces.of(**boxes)
    except ValueError as exc:
        raise UsageError(f"argument --{str(exc).replace('_', '-')}") from None


def _create(args: argparse.Namespace) -> Any:
    from creps_gym.cli.run import _as_usage_error
    from creps_gym.errors import RunDirError
    from creps_gym.runner.config import RunConfig
    from creps_gym.runner.manual import AskTellRun

    for flag in ("optimizer", "seed"):
        if getattr(args, flag) is None:
            raise UsageError(f"argument --{flag}: expected with --new, got none")
    import_modules_and_check_names(args)
    spaces = _spaces(args)
    options = {"env": args.env, "optimizer": args.optimizer, "seed": args.seed, "samples": args.samples}
    options.update(
        iterations=args.iterations, max_episodes=args.max_episodes, env_kwargs=dict(args.env_kwarg)
    )
    options.update(
        initial_mean=args.initial_mean, initial_std=args.initial_std, optimizer_options=dict(args.opt)
    )
    try:
        return AskTellRun.create(args.run, RunConfig(**options), spaces, overwrite=args.overwrite)
    except RunDirError:
        raise
    except (ValueError, TypeError) as exc:
        raise _as_usage_error(exc) from None


def _open(args: argparse.Namespace) -> Any:
    from creps_gym.runner.manual import AskTellRun

    if getattr(args, "new", False):
        return _create(args)
    import_modules_and_check_names(argparse.Namespace(imports=getattr(args, "imports", [])))
    try:
        return AskTellRun.open(args.run)
    except FileNotFoundError as exc:
        raise FileNotFoundError(f"{exc} (start one with `creps-gym ask RUN --new ...`)") from None


def _numbers(array: Any) -> list[float]:
    return [float(v) for v in array]


def _plain(values: Any) -> str:
    return " ".join(repr(float(v)) for v in values)


def _episode(episode: Any) -> dict[str, Any]:
    return {
        "episode": episode.episode,
        "context": _numbers(episode.context),
        "params": _numbers(episode.params),
    }


def _status(run: Any) -> dict[str, Any]:
    asked = sum(not e.failed for e in run.batch)
    return {"iteration": run.iteration + 1, "asked": asked, "samples": run.config.samples}


def _cmd_ask(args: argparse.Namespace) -> int:
    if args.pending and args.context:
        raise UsageError("argument --pending: expected no --context with it (it asks nothing)")
    if not args.new and not args.pending and not args.context:
        raise UsageError("argument --context: expected the episode's context (z numbers), got none")
    with _open(args) as run:
        if args.pending or not args.context:  # --pending, or --new without a context: nothing asked
            return _print_pending(run, args)
        try:
            episode = run.ask(args.context, extrapolate=args.extrapolate)
        except RunDirError:  # a file of the folder (exit 3)
            raise
        except ValueError as exc:
            message = str(exc).removeprefix("context: ").replace("pass extrapolate", "pass --extrapolate")
            raise UsageError(f"argument --context: {message}") from None
        except RuntimeError as exc:
            raise UsageError(str(exc)) from None
        out = {**_episode(episode), "clipped": bool((episode.params != episode.asked).any()), **_status(run)}
        out["pending"] = [e.episode for e in run.pending]
    if args.json:
        print(json.dumps(out, allow_nan=False))
    else:
        print(_plain(episode.params))
        print(
            f"creps-gym ask: episode {episode.episode} (iteration {out['iteration']}: {out['asked']} of "
            f"{out['samples']} asked{', clipped to the parameter box' if out['clipped'] else ''}); then "
            f"`creps-gym tell {shlex.quote(args.run)} --episode {episode.episode} --return R`",
            file=sys.stderr,
        )
    return 0


def _print_pending(run: Any, args: argparse.Namespace) -> int:
    pending = [_episode(e) for e in run.pending]
    if args.json:
        out = {"pending": pending, **_status(run), "stop_reason": run.stop_reason}
        print(json.dumps(out, allow_nan=False))
        return 0
    for entry in pending:
        print(f"{entry['episode']}: {_plain(entry['params'])}")
    status = _status(run)
    state = f"{status['asked']} of {status['samples']} asked"
    if run.stop_reason:
        state = f"finished (stop: {run.stop_reason})"
    print(f"creps-gym ask: {len(pending)} pending; iteration {status['iteration']}: {state}", file=sys.stderr)
    return 0


def _cmd_tell(args: argparse.Namespace) -> int:
    with _open(args) as run:
        try:
            done = run.tell(args.value, args.episode, failed=args.failed)
        except RunDirError:  # a file of the folder (exit 3)
            raise
        except (ValueError, RuntimeError) as exc:
            raise _tell_error(exc) from None
        record, status = done["iteration"], _status(run)
        out: dict[str, Any] = {"episode": done["episode"], "failed": args.failed, "return": args.value}
        out["batch_told"] = record is not None
        if record is not None:
            out.update(iteration=record.iteration, episodes=record.episodes, mean_return=record.mean_return)
            out.update(stop_reason=run.stop_reason, policy=str(run.run_dir.file("policy.npz")))
        else:
            told = sum(e.value is not None for e in run.batch)
            out.update(iteration=status["iteration"], told=told, samples=status["samples"])
    if args.json:
        print(json.dumps(out, allow_nan=False))
    elif record is not None:
        stop = f"; the run has finished (stop: {out['stop_reason']})" if out["stop_reason"] else ""
        print(
            f"iteration {record.iteration} told: episodes {record.episodes}, mean return "
            f"{record.mean_return:.6g}; policy: {out['policy']}{stop}"
        )
    else:
        told = f"{out['told']} of {out['samples']} told in iteration {out['iteration']}"
        print(f"episode {done['episode']} recorded ({told})")
    return 0


def _tell_error(exc: Exception) -> UsageError:
    """A refused tell as a usage error naming its flag (the episode's, or the return's: the optimiser
    refuses returns whose spread overflows)."""
    field, _, message = str(exc).partition(": ")
    flag = {"episode": "--episode", "value": "--return", "returns": "--return"}.get(field)
    return UsageError(f"argument {flag}: {message}" if flag else str(exc))


COMMANDS = {"ask": _cmd_ask, "tell": _cmd_tell}
