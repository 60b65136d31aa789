"""Ray start-up per run: several short ``backend="ray"`` runs in one process against the same runs serially.

Each run is ``creps-cma-old`` on the contextual Sphere (p = 3, N = 8, 2 iterations, 2 Ray workers), so its
wall time is almost all start-up: the first run starts a local Ray; the later ones show what a run pays
when the process already ran one (issue 31: Ray's start-up is paid once per process, not per run). The
serial runs of the same configuration, timed in the same process, are the baseline.

Usage::

    python benchmarks/ray_startup.py              # 3 Ray runs, 3 serial runs
    python benchmarks/ray_startup.py --runs 2
"""

from __future__ import annotations

import argparse
import os
import time

from creps_gym.runner import run

CONFIG = {"env_kwargs": {"dim": 3}, "eval_contexts": 4}


def timed(backend: str, **extra: object) -> float:
    start = time.perf_counter()
    run("creps-cma-old", "creps_gym/Sphere-v0", 2, 8, 0, backend=backend, **CONFIG, **extra)
    return time.perf_counter() - start


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=3, help="runs per backend (default 3)")
    args = parser.parse_args(argv)
    serial = [timed("serial") for _ in range(args.runs)]
    ray = [timed("ray", workers=2) for _ in range(args.runs)]
    print(f"load average {os.getloadavg()[0]:.1f}")
    print(f"{'run':>4} {'ray s':>8} {'serial s':>9}")
    for k, (a, b) in enumerate(zip(ray, serial, strict=True), 1):
        print(f"{k:>4} {a:8.2f} {b:9.3f}")


if __name__ == "__main__":
    main()
