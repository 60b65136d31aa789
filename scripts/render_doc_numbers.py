"""Regenerate the numbers the docs quote, from the code, so they cannot drift.

* README.md and docs/runner.md: the iterations (and episodes) the README's main job needs to reach its
  target regret. The job is the README's own ``creps-gym run`` command, parsed by the CLI's parser.
* docs/wrappers.md: the Reacher learning table, from running the document's own Reacher example.

Run ``python scripts/render_doc_numbers.py`` after a change that moves these numbers and commit the diff;
``--check`` only compares (exit code 1 on a difference), ``--only quickstart|reacher`` limits the work.
The Reacher example takes about two minutes on 2 cores; ``tests/docs/test_doc_numbers.py`` recomputes the
main job and the Reacher table's first column in CI.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import re
import shlex
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
README, RUNNER_DOC, WRAPPERS_DOC = (
    ROOT / "README.md",
    ROOT / "docs" / "runner.md",
    ROOT / "docs" / "wrappers.md",
)
_MAIN_JOB = re.compile(r"^pip install .*? && (creps-gym run .*)$", re.MULTILINE)
_README_PHRASE = re.compile(r"in about [\d,]+ iterations")
_RUNNER_PHRASE = re.compile(r"in about [\d,]+ iterations \([\d,]+ episodes")
_REACHER_TABLE = re.compile(r"^\| iteration \(× 40 episodes\) \|.*\n(?:\|.*\n){3}", re.MULTILINE)
_REACHER_LINE = re.compile(r"it +(\d+): return +(-?[\d.]+), final distance ([\d.]+)")


def main_job_argv() -> list[str]:
    """The README's main job as ``creps-gym`` arguments (without the program name)."""
    return shlex.split(_MAIN_JOB.search(README.read_text(encoding="utf-8")).group(1))[1:]


def main_job() -> tuple[int, int]:
    """Iterations and episodes of the README's main job (run without a run directory)."""
    from creps_gym.cli import build_parser
    from creps_gym.runner import run

    args = build_parser().parse_args(main_job_argv())
    history = run(
        args.optimizer,
        args.env,
        args.iterations,
        args.samples,
        args.seed,
        target_regret=args.target_regret,
        env_kwargs=dict(args.env_kwarg),
    )
    last = history.records[-1]
    return last.iteration, last.episodes


def _about(value: int, digits: int) -> str:
    return f"{round(value, -digits):,}"


def quickstart_docs(iterations: int, episodes: int) -> dict[Path, str]:
    """README.md and docs/runner.md with the main job's numbers (rounded to tens and hundreds)."""
    readme = _README_PHRASE.sub(f"in about {_about(iterations, 1)} iterations", README.read_text("utf-8"))
    phrase = f"in about {_about(iterations, 1)} iterations ({_about(episodes, 2)} episodes"
    runner = _RUNNER_PHRASE.sub(phrase, RUNNER_DOC.read_text("utf-8"))
    return {README: readme, RUNNER_DOC: runner}


def reacher_block() -> str:
    """The Reacher example of docs/wrappers.md (its last Python block)."""
    blocks = re.findall(r"```python\n(.*?)```", WRAPPERS_DOC.read_text("utf-8"), flags=re.DOTALL)
    return blocks[-1]


def reacher_rows(iterations: int | None = None) -> list[tuple[int, float, float]]:
    """(iteration, mean return, final distance) printed by the Reacher example, optionally shortened."""
    code = reacher_block()
    if iterations is not None:
        code = code.replace("for it in range(161):", f"for it in range({iterations}):")
    output = io.StringIO()
    with contextlib.redirect_stdout(output):
        exec(compile(code, f"{WRAPPERS_DOC}:reacher", "exec"), {"__name__": "reacher_doc"})
    return [(int(i), float(r), float(d)) for i, r, d in _REACHER_LINE.findall(output.getvalue())]


def reacher_table(rows: list[tuple[int, float, float]]) -> str:
    """The Markdown table of docs/wrappers.md (minus signs as U+2212)."""

    def line(cells: list[str]) -> str:
        return "| " + " | ".join(cells) + " |\n"

    return (
        line(["iteration (× 40 episodes)", *(str(i) for i, _, _ in rows)])
        + "|---" * (len(rows) + 1)
        + "|\n"
        + line(["mean return", *(f"{r:.2f}".replace("-", "−") for _, r, _ in rows)])
        + line(["final fingertip–target distance", *(f"{d:.3f}" for _, _, d in rows)])
    )


def committed_reacher_table() -> str:
    return _REACHER_TABLE.search(WRAPPERS_DOC.read_text("utf-8")).group(0)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="compare only; exit 1 on a difference")
    parser.add_argument("--only", choices=("quickstart", "reacher"))
    args = parser.parse_args(argv)
    rendered: dict[Path, str] = {}
    if args.only in (None, "quickstart"):
        rendered.update(quickstart_docs(*main_job()))
    if args.only in (None, "reacher"):
        text = WRAPPERS_DOC.read_text("utf-8")
        rendered[WRAPPERS_DOC] = text.replace(committed_reacher_table(), reacher_table(reacher_rows()))
    stale = [path for path, text in rendered.items() if path.read_text("utf-8") != text]
    for path in stale:
        print(f"{'differs' if args.check else 'rewritten'}: {path.relative_to(ROOT)}")
        if not args.check:
            path.write_text(rendered[path], encoding="utf-8")
    return 1 if args.check and stale else 0


if __name__ == "__main__":
    sys.exit(main())
