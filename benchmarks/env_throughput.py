"""Episodes per second of the contextual function envs, against a raw numpy evaluation of the same batch.

Four ways to run n one-step episodes of one function, at n = 1, 50 and 1000 by default, in one run:

* ``raw``: the physical limit, one numpy evaluation of the batch with the textbook formula
  ``f(R (theta + contexts @ A.T - o))`` (a BLAS product for ``A s``), no env at all;
* ``native``: ``gymnasium.make_vec(id, num_envs=n)`` (the registered ``vector_entry_point``, SAME_STEP
  autoreset: every ``step`` is n complete episodes, new contexts included);
* ``sync``: ``gymnasium.make_vec(id, num_envs=n, vectorization_mode="sync")`` with SAME_STEP autoreset;
* ``loop``: ``env = gymnasium.make(id)`` and ``reset()`` + ``step()`` per episode.

The target is native >= 50 % of raw at n = 1000. ``--all`` adds that ratio for each of the 15 functions.

Usage::

    python benchmarks/env_throughput.py [--id creps_gym/Rosenbrock-v0] [--sizes 1 50 1000] [--all]
"""

from __future__ import annotations

import argparse
import ctypes
import ctypes.util
import time
from collections.abc import Callable

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode

import creps_gym  # noqa: F401  (registers the ids)
from creps_gym.envs.functions import REGISTRATIONS

TARGET = 0.5
M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3  # glibc's mallopt parameters


def pin_glibc_malloc(threshold: int = 64 << 20) -> bool:
    """Stop glibc from returning freed heap memory to the OS after every large temporary.

    A batch of n = 1000 rows of p = 15 float64 is 120 kB, just under glibc's default 128 kB trim and mmap
    thresholds: depending on the heap's layout, each fresh temporary can then be page-faulted in again, and
    the same numpy expression (raw or env) runs 2-5x slower from one process to the next. Raising both
    thresholds (like ``MALLOC_TRIM_THRESHOLD_``/``MALLOC_MMAP_THRESHOLD_``) makes the figures reproducible.
    Returns False where glibc's ``mallopt`` is not available.
    """
    name = ctypes.util.find_library("c")
    try:
        libc = ctypes.CDLL(name)
        mallopt = libc.mallopt
    except (OSError, AttributeError, TypeError):
        return False
    return bool(mallopt(M_TRIM_THRESHOLD, threshold)) and bool(mallopt(M_MMAP_THRESHOLD, threshold))


def _block_size(call: Callable[[], object], block_time: float) -> tuple[int, float]:
    """Number of calls that take about ``block_time`` seconds, and the time of one call (after a warm-up)."""
    call()
    number = 1
    while True:
        start = time.perf_counter()
        for _ in range(number):
            call()
        elapsed = time.perf_counter() - start
        if elapsed >= block_time or number >= 1 << 20:
            return number, elapsed / number
        number *= 2


def interleaved_seconds(
    calls: dict[str, Callable[[], object]], rounds: int, budget: float, block_time: float = 0.002
) -> dict[str, float]:
    """Best time of one call of each path over short timed blocks that alternate between the paths.

    Short blocks (about 2 ms, under a scheduler time slice) and the best of many rounds estimate the
    uncontended time even on a loaded machine; alternating the paths exposes them to the same load. A slow
    path gets fewer rounds, at most ``budget`` seconds.
    """
    sizes = {name: _block_size(call, block_time) for name, call in calls.items()}
    best = dict.fromkeys(calls, float("inf"))
    for round_index in range(rounds):
        for name, call in calls.items():
            number, estimate = sizes[name]
            if round_index > 3 and round_index * number * estimate > budget:
                continue
            start = time.perf_counter()
            for _ in range(number):
                call()
            best[name] = min(best[name], (time.perf_counter() - start) / number)
    return best


def raw_evaluation(model, contexts: np.ndarray, params: np.ndarray) -> Callable[[], np.ndarray]:
    """One plain numpy evaluation of the batch: the textbook formula, no env."""
    matrix, kernel = model.problem.matrix, model.function.kernel
    shift, rotation = model.problem.shift, model.problem.rotation
    if rotation is not None:
        return lambda: kernel((params + contexts @ matrix.T - shift) @ rotation.T)
    if model.function.shifted:
        return lambda: kernel(params + contexts @ matrix.T - shift)
    return lambda: kernel(params + contexts @ matrix.T)


def measure(env_id: str, n: int, kwargs: dict, rounds: int, paths: tuple[str, ...]) -> dict[str, float]:
    """Episodes per second of each path for a batch of n episodes."""
    single = gym.make(env_id, **kwargs)
    model = single.unwrapped
    rng = np.random.default_rng(0)
    contexts = model.sample_contexts(rng, n)
    params = rng.uniform(model.action_space.low, model.action_space.high, size=(n, model.param_dim))
    calls: dict[str, Callable[[], object]] = {"raw": raw_evaluation(model, contexts, params)}
    native = gym.make_vec(env_id, num_envs=n, **kwargs)
    native.reset(seed=0, options={"context": contexts})
    calls["native"] = lambda: native.step(params)
    if "sync" in paths:
        sync = gym.make_vec(
            env_id,
            num_envs=n,
            vectorization_mode="sync",
            vector_kwargs={"autoreset_mode": AutoresetMode.SAME_STEP},
            **kwargs,
        )
        sync.reset(seed=0)
        calls["sync"] = lambda: sync.step(params)
    if "loop" in paths:
        single.reset(seed=0)

        def loop() -> None:
            for k in range(n):
                single.reset()
                single.step(params[k])

        calls["loop"] = loop
    seconds = interleaved_seconds(calls, rounds, budget=2.0)
    return {name: n / value for name, value in seconds.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--id", default="creps_gym/Rosenbrock-v0", help="function id (default: Rosenbrock)")
    parser.add_argument("--dim", type=int, default=15)
    parser.add_argument("--context-dim", type=int, default=1)
    parser.add_argument("--sizes", type=int, nargs="+", default=[1, 50, 1000])
    parser.add_argument("--rounds", type=int, default=300, help="timed rounds per measurement (best kept)")
    parser.add_argument("--all", action="store_true", help="native/raw at the largest n for every function")
    parser.add_argument(
        "--default-malloc", action="store_true", help="keep glibc's default malloc thresholds"
    )
    args = parser.parse_args()
    kwargs = {"dim": args.dim, "context_dim": args.context_dim}
    pinned = False if args.default_malloc else pin_glibc_malloc()
    print(f"glibc malloc trim/mmap thresholds pinned to 64 MiB: {'yes' if pinned else 'no (defaults)'}")

    print(f"{args.id}, p = {args.dim}, z = {args.context_dim}: episodes per second")
    header = f"{'n':>6} {'raw numpy':>12} {'native':>12} {'sync':>12} {'loop':>12} {'native/raw':>11}"
    print(header + "\n" + "-" * len(header))
    ratios = {}
    for n in args.sizes:
        rates = measure(args.id, n, kwargs, args.rounds, ("sync", "loop"))
        ratios[n] = rates["native"] / rates["raw"]
        cells = " ".join(f"{rates[name]:12.4g}" for name in ("raw", "native", "sync", "loop"))
        print(f"{n:>6} {cells} {ratios[n]:10.0%}")
    largest = max(args.sizes)
    verdict = "meets" if ratios[largest] >= TARGET else "misses"
    print(f"\nnative/raw at n = {largest}: {ratios[largest]:.0%} ({verdict} the {TARGET:.0%} target)")

    if args.all:
        print(f"\nEvery function at n = {largest} (native/raw, episodes per second):")
        for entry in REGISTRATIONS:
            rates = measure(entry["id"], largest, kwargs, args.rounds, ())
            share = rates["native"] / rates["raw"]
            print(
                f"  {entry['id']:40s} {share:5.0%}  raw {rates['raw']:10.4g}  native {rates['native']:10.4g}"
            )


if __name__ == "__main__":
    main()
