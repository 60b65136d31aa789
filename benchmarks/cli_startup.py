"""Start-up time of the command line: ``creps-gym --help`` and ``creps-gym list`` against ``python -c pass``.

Each command runs in a fresh interpreter (``python -m creps_gym.cli ...``, what the console script runs,
without the launcher of a Python version manager); the three commands alternate in ``--rounds`` rounds and
the script reports the median wall time of each, its ratio to ``python -c pass`` measured in the same
rounds, and the time it adds to it. ``--root DIR`` measures the checkout in DIR instead of this one (e.g.
an older commit unpacked with ``git archive``), for a before/after comparison on one machine.

Usage::

    python benchmarks/cli_startup.py              # 15 rounds
    python benchmarks/cli_startup.py --rounds 5 --root /tmp/old-checkout

Target (issue 31): ``--help`` and ``list`` in at most 0.5 s on the 2-core development machine.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
COMMANDS = {
    "python -c pass": ["-c", "pass"],
    "creps-gym --help": ["-m", "creps_gym.cli", "--help"],
    "creps-gym list": ["-m", "creps_gym.cli", "list"],
}


def time_once(args: list[str], root: Path) -> float:
    """Wall time (s) of one fresh interpreter running ``args`` with ``root`` first on its path."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(root), os.environ.get("PYTHONPATH", "")])}
    start = time.perf_counter()
    subprocess.run([sys.executable, *args], env=env, cwd=root, stdout=subprocess.DEVNULL, check=True)
    return time.perf_counter() - start


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=15, help="alternating rounds (default 15)")
    parser.add_argument("--root", type=Path, default=ROOT, help="the checkout to measure (default: this)")
    args = parser.parse_args(argv)
    times: dict[str, list[float]] = {name: [] for name in COMMANDS}
    for command in COMMANDS.values():  # one warm-up each (file system caches)
        time_once(command, args.root)
    for _ in range(args.rounds):
        for name, command in COMMANDS.items():
            times[name].append(time_once(command, args.root))
    base = statistics.median(times["python -c pass"])
    print(f"{args.root} ({args.rounds} rounds, median wall time; load average {os.getloadavg()[0]:.1f})")
    print(f"{'command':<20} {'seconds':>8} {'ratio':>6} {'added s':>8}")
    for name, values in times.items():
        median = statistics.median(values)
        print(f"{name:<20} {median:8.3f} {median / base:6.2f} {median - base:8.3f}")


if __name__ == "__main__":
    main()
