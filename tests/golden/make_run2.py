"""Writes ``tests/golden/run2/``: a run directory of format ``creps_gym.run/2`` (creps_gym before issue 14).

Run it with the code of commit bfedeb5 (the last one that writes format 2), e.g.::

    mkdir /tmp/base && git archive bfedeb5 | tar -x -C /tmp/base
    PYTHONPATH=/tmp/base python tests/golden/make_run2.py tests/golden/run2

It leaves an unfinished run (checkpoint at iteration 4, iterations 5 and 6 logged after it) and writes
``expected_history.json``, the history of the same run uninterrupted, next to it. ``test_resume.py`` resumes
the directory with today's code and checks it gives that history bit for bit.
"""

from __future__ import annotations

import sys
from pathlib import Path

from creps_gym.runner import RunDir, run

SETTINGS = {"env_kwargs": {"dim": 3}, "checkpoint_every": 4, "eval_every": 2}


class Stop(Exception):
    """Leaves the run unfinished, as a crash would."""


def stop_at_6(record, history):
    if record.iteration == 6:
        raise Stop


def main(folder: str) -> None:
    out = Path(folder)
    try:
        run(
            "creps-cma-old",
            "creps_gym/Sphere-v0",
            9,
            6,
            3,
            run_dir=out / "run",
            callbacks=[stop_at_6],
            **SETTINGS,
        )
    except Stop:
        pass
    (out / "run" / RunDir.LOCK).unlink(missing_ok=True)
    run("creps-cma-old", "creps_gym/Sphere-v0", 9, 6, 3, **SETTINGS).to_json(out / "expected_history.json")


if __name__ == "__main__":
    main(sys.argv[1])
