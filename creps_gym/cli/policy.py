"""``creps-gym policy`` and ``creps-gym evaluate``: the learned policy of a run, out of the run folder.

``policy RUN`` prints the policy of a run folder (or of a policy file) as JSON: its parameters for the
``--context`` values given, else its coefficients; ``--save FILE`` writes it as a policy file.
An ask/tell run (``creps-gym ask``) has no evaluations: its default is its final policy, and
``evaluate`` needs one started with ``--env``. ``evaluate RUN`` runs it on fresh, seeded test
contexts of the run's env and prints the mean return and regret as JSON (``--run-contexts``: the
run's own test contexts, which reproduce its evaluation); ``--video FILE`` records the episodes it
evaluates, one test context unless ``--contexts`` says more, where the env renders (needs the
``video`` extra), saying on stderr what it renders. Exit codes are the CLI's
(:mod:`creps_gym.cli`): 2 for a bad ``--context`` or option, 3 for a missing or damaged run folder or
policy file, 4 for a missing extra, 1 when the env fails.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from pathlib import Path
from typing import Any

from creps_gym.cli.types import add_import, import_user_modules, integer
from creps_gym.errors import UsageError

__all__ = ["COMMANDS", "VIDEO_SUFFIXES", "add_commands", "check_video_file"]


def add_commands(commands: Any) -> None:
    """Register the ``policy`` and ``evaluate`` subcommands on the CLI's subparsers."""
    policy = commands.add_parser(
        "policy",
        help="print the learned policy of a run (or a policy file) as JSON",
        description="Print the learned policy of a run folder or a policy file as JSON: its parameters for "
        "each --context, else its coefficients.",
    )
    evaluate = commands.add_parser(
        "evaluate",
        help="evaluate the learned policy of a run on fresh test contexts",
        description="Run the learned policy on fresh, seeded test contexts of the run's env and print the "
        "mean return and regret as JSON.",
    )
    for parser in (policy, evaluate):
        parser.add_argument("run", metavar="RUN", help="run folder, or a policy file (.npz)")
        parser.add_argument(
            "--which",
            choices=("best", "final"),
            default=None,
            help="the best evaluated mean policy (default) or the final one (the default of an ask/tell "
            "run, which evaluates none)",
        )
        add_import(parser)
    policy.add_argument(
        "--context",
        action="append",
        nargs="+",
        type=float,
        default=[],
        metavar="S",
        help="one context: z numbers (repeat --context for more contexts)",
    )
    policy.add_argument("--extrapolate", action="store_true", help="accept contexts outside the context box")
    policy.add_argument("--save", metavar="FILE", help="also write the policy as a policy file (.npz)")
    evaluate.add_argument(
        "--contexts",
        type=integer(1),
        default=None,
        metavar="N",
        help="test contexts (100; with --video 1: the video records each)",
    )
    evaluate.add_argument("--seed", type=integer(0), default=0, help="seed of the test contexts (0)")
    evaluate.add_argument(
        "--run-contexts",
        action="store_true",
        help="use the run's own test contexts instead (reproduces the run's evaluation)",
    )
    evaluate.add_argument(
        "--video",
        metavar="FILE",
        help="record the evaluated episodes, the motion through each (.mp4 or .gif; extra 'video')",
    )


def _load(args: argparse.Namespace) -> Any:
    """The policy asked for (a damaged or foreign file is a run-folder error, exit 3)."""
    from creps_gym.errors import RunDirError
    from creps_gym.runner.rundir.policies import load_policy

    import_user_modules(args.imports)  # the current directory is searched too, as for `run`
    if args.which is None:
        args.which = "final" if _ask_tell(args.run) else "best"
    try:
        return load_policy(args.run, args.which)
    except RunDirError:
        raise
    except FileNotFoundError as exc:  # no such folder or file, or a run folder without that policy
        raise FileNotFoundError(f"RUN: {str(exc).removeprefix('path: ')}") from None
    except ValueError as exc:
        raise RunDirError(f"RUN: {exc}") from None


def _ask_tell(path: str) -> bool:
    """Whether ``path`` is an ask/tell run folder (False for anything else, which ``load_policy`` judges)."""
    from creps_gym.runner.manual import is_ask_tell
    from creps_gym.runner.rundir import RunDir

    try:
        return Path(path).is_dir() and is_ask_tell(RunDir.open(path))
    except (OSError, ValueError):
        return False


#: The file names ``--video`` writes (imageio picks the format by the name).
VIDEO_SUFFIXES = (".mp4", ".gif")


def _output(path: str | None, flag: str, suffixes: tuple[str, ...] | None = None) -> Any:
    """The file ``flag`` will write, checked like ``-o`` before anything is computed (exit 2 if refused)."""
    from creps_gym.runner.results.outputs import check_output_path

    if path is None:
        return None
    try:
        return check_output_path(path, flag, suffixes)
    except ValueError as exc:
        raise UsageError(f"argument {exc}") from None


def _written(flag: str, path: str, write: Any) -> str:
    """``write()``'s file as printed (a link's target named); a failed write is exit 2 naming the file."""
    try:
        written = Path(write())
    except ValueError as exc:
        message = str(exc).removeprefix("path: ").removeprefix(f"{flag}: ")
        raise UsageError(f"argument {flag}: {message}") from None
    except OSError as exc:
        cause = exc.strerror or type(exc).__name__
        raise UsageError(f"argument {flag}: cannot write {exc.filename or path}: {cause}") from None
    return path if Path(os.path.abspath(path)) == written else f"{written} (through the link {path})"


def _numbers(array: Any) -> Any:
    return [[float(v) for v in row] for row in array]


def _cmd_policy(args: argparse.Namespace) -> int:
    import numpy as np

    target = _output(args.save, "--save")
    policy = _load(args)
    out: dict[str, Any] = {"env": policy.env, "which": args.which, "source": policy.source}
    if args.context:
        if any(len(row) != policy.context_dim for row in args.context):
            lengths = sorted({len(row) for row in args.context})
            raise UsageError(f"argument --context: expected {policy.context_dim} numbers (z), got {lengths}")
        try:
            params = policy(np.array(args.context, dtype=np.float64), extrapolate=args.extrapolate)
        except ValueError as exc:
            message = str(exc).removeprefix("contexts: ").replace("extrapolate=True", "--extrapolate")
            raise UsageError(f"argument --context: {message}") from None
        out.update(contexts=_numbers(args.context), params=_numbers(params))
    else:
        out.update(features=policy.features.spec(), coefficients=_numbers(policy.coefficients))
    if target is not None:
        out["saved"] = _written("--save", args.save, lambda: policy.save(target))
    print(json.dumps(out, allow_nan=False))
    return 0


def _environment(args: argparse.Namespace, policy: Any) -> tuple[str, dict[str, Any], Any]:
    """The env id and keywords to evaluate on, and the run's config (None for a policy file)."""
    from creps_gym.errors import RunDirError
    from creps_gym.runner.rundir import RunDir
    from creps_gym.runner.rundir.references import unimported_module

    if Path(args.run).is_dir():
        config = RunDir.open(args.run).config()  # checked: names no module that is not imported
        if config.env is None and _ask_tell(args.run):
            raise UsageError(
                f"RUN: expected a run that names an env id, got {args.run}, an ask/tell run without --env "
                "(its returns came from `creps-gym tell`: there is no env to evaluate its policy on; "
                "`creps-gym policy` prints it)"
            )
        if config.env is None:
            raise UsageError(f"RUN: expected a run of an env id, got {args.run} (an env object's run)")
        return config.env, dict(config.env_kwargs), config
    if policy.env is None:
        raise UsageError(f"RUN: expected a policy file that names its env, got {args.run}")
    found = unimported_module([policy.env, policy.env_kwargs], "policy")
    if found is not None:
        _, text, module = found
        raise RunDirError(
            f"RUN: {args.run} names the module {module!r} ({text!r}), which is not imported; a policy "
            "file never makes creps-gym import code: pass --import MODULE if you trust it"
        )
    return policy.env, dict(policy.env_kwargs), None


def _cmd_evaluate(args: argparse.Namespace) -> int:

    from creps_gym.runner.rundir.policies import evaluate_on_env
    from creps_gym.runner.seeds import split_seed

    _output(args.video, "--video", VIDEO_SUFFIXES)
    policy = _load(args)
    env_id, kwargs, config = _environment(args, policy)
    n, seed = args.contexts if args.contexts is not None else (1 if args.video else 100), args.seed
    if args.run_contexts:
        if config is None:
            raise UsageError("argument --run-contexts: expected a run folder as RUN, got a policy file")
        n, seed = config.eval_contexts, split_seed(config.seed)[2]
    try:
        policy.check_batch(n, "argument --run-contexts" if args.run_contexts else "argument --contexts")
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    env = _make(args.run, env_id, kwargs)
    if args.video:
        mode = _render_mode(env, env_id)
    try:
        mean_return, mean_regret = evaluate_on_env(policy, env, n, seed)
    finally:
        env.close()
    out = {"env": env_id, "which": args.which, "source": policy.source, "contexts": n, "seed": seed}
    out.update(mean_return=mean_return, mean_regret=None if math.isnan(mean_regret) else mean_regret)
    if args.video:
        out["video"] = _record(_make(args.run, env_id, kwargs, mode), policy, n, seed, args.video)
    print(json.dumps(out, allow_nan=False))
    return 0


def _make(run: str, env_id: str, kwargs: dict[str, Any], render_mode: str | None = None) -> Any:
    """``gymnasium.make`` of the env a run folder or policy file names; an env that cannot be made is
    the file's fault (exit 3), its text escaped (a file may hold terminal control characters)."""
    import gymnasium as gym

    from creps_gym.errors import RunDirError
    from creps_gym.runner.rundir.references import escape_text

    extra = {} if render_mode is None else {"render_mode": render_mode}
    try:
        return gym.make(env_id, **extra, **kwargs)
    except (gym.error.Error, TypeError, ValueError) as exc:
        cause = escape_text(f"{type(exc).__name__}: {exc}")
        raise RunDirError(f"RUN: {run} names an env that cannot be made ({cause})") from None


def _render_mode(env: Any, env_id: str) -> str:
    """The render mode that records an episode (the whole of it where the env can); checks the extra."""
    from creps_gym.optimizers.adapters.base import import_optional
    from creps_gym.runner.rundir.references import escape_text

    modes = list(env.metadata.get("render_modes", []))
    mode = next((m for m in ("rgb_array_list", "rgb_array") if m in modes), None)
    if mode is None:
        raise UsageError(
            f"argument --video: expected an env that renders (rgb_array), got {escape_text(env_id)} {modes}"
        )
    import_optional("imageio", extra="video")
    import_optional("imageio_ffmpeg", extra="video")
    return mode


def _record(env: Any, policy: Any, n: int, seed: int, path: str) -> str:
    """Record the ``n`` episodes evaluated for ``seed`` (the same test contexts and reset seeds) of ``env``
    to ``path``, each frame rendered as it is written, with progress on stderr, through a temporary that is
    checked whole before it is renamed (exit 2 naming the file if it cannot be written, see
    :func:`write_output_with`); returns the path as printed."""
    from creps_gym.runner.results.outputs import write_output_with
    from creps_gym.runner.results.video import EpisodeVideo, write_video
    from creps_gym.runner.rundir.policies import evaluation_draws

    try:
        _, contexts, seeds = evaluation_draws(env, n, seed)
    except BaseException:
        env.close()
        raise
    video = EpisodeVideo(env, policy, contexts, seeds, progress=sys.stderr)  # write_video closes the env

    def frames_to(tmp: Path) -> None:
        write_video(tmp, video)
        check_video_file(tmp)

    return _written("--video", path, lambda: write_output_with(path, frames_to, "--video", VIDEO_SUFFIXES))


def check_video_file(path: str | os.PathLike[str]) -> None:
    """``OSError`` unless ``path`` is a whole video file: a GIF that ends with its trailer, or an MP4 whose
    top-level boxes fill it exactly and include its index (``moov``) and data (``mdat``). ffmpeg's exit
    status is not checked by imageio, so a full disk or ``ulimit -f`` would otherwise leave a cut file."""
    import errno

    with open(path, "rb") as stream:
        data = stream.read()
    if Path(path).suffix.lower() == ".gif":
        whole = data.startswith(b"GIF8") and data.endswith(b";")
    else:
        boxes, offset = set(), 0
        while offset + 8 <= len(data):
            size, kind = int.from_bytes(data[offset : offset + 4], "big"), data[offset + 4 : offset + 8]
            if size == 1 and offset + 16 <= len(data):  # a 64-bit size follows
                size = int.from_bytes(data[offset + 8 : offset + 16], "big")
            if size < 8:
                break
            boxes.add(kind)
            offset += size
        whole = offset == len(data) and {b"ftyp", b"moov", b"mdat"} <= boxes
    if not whole:
        raise OSError(errno.EIO, f"the video written is incomplete ({len(data)} bytes)")


COMMANDS = {"policy": _cmd_policy, "evaluate": _cmd_evaluate}
