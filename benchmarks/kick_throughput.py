"""Kick throughput: episodes per second of the kick env against raw ``mj_step`` of the same models.

Measured in one run:

* sequential: ``env.evaluate`` one episode at a time, one thread;
* batched on 1 thread: one ``evaluate`` call for the whole batch;
* batched on all cores;
* raw ``mj_step``: the C loop ``mujoco.mj_step(model, data, nstep=k)`` on the full model (robot standing,
  ball at its feet) and on the ball-only model (ball rolling), in steps per second.

The episodes' simulated steps (full-model steps of phase 1, ball-only steps of phase 2) priced at the raw
step costs give the time raw ``mj_step`` would need for the same episodes; its ratio to the measured time is
the fraction of raw throughput the env achieves per core. "cores busy" is the process's CPU time over the
wall time: on a machine shared with other jobs, a low figure for the threaded batch means the threads
waited for a core, not that they were idle. Episode parameters are the reference kick plus
Gaussian noise (sigma 0.02 in normalised units, the recommended initial step), as an optimiser samples them.

Usage::

    python benchmarks/kick_throughput.py            # 200 episodes per batch (about a minute on 2 cores)
    python benchmarks/kick_throughput.py --episodes 1000
"""

from __future__ import annotations

import argparse
import os
import time

import gymnasium as gym
import mujoco
import mujoco.rollout as rollout
import numpy as np

import creps_gym  # noqa: F401  (registers the ids)
from creps_gym.envs.kick.model import BALL_TIMESTEP, REFERENCE_KICK, to_physical
from creps_gym.envs.kick.simulation import controls
from creps_gym.envs.kick.tasks import PRECISION_BALL

DT = 0.002  # the full model's timestep


def raw_seconds(models, params: np.ndarray, phase1_steps: np.ndarray, phase2_steps: np.ndarray) -> float:
    """Time raw ``mj_step`` (one thread) takes for the same episodes: no checks, no chunks, no Python.

    Phase 1 replays each episode's servo targets for its number of full-model steps with
    ``mujoco.rollout.rollout`` (a C loop of ``mj_step``); phase 2 prices its ball-only steps at the cost of
    ``mj_step(ball_model, data, nstep=k)`` for a rolling ball.
    """
    data = mujoco.MjData(models.full)
    mujoco.mj_setState(models.full, data, models.initial_state, mujoco.mjtState.mjSTATE_INTEGRATION)
    adr = models.ball_qpos_address
    data.qpos[adr : adr + 3] = (*PRECISION_BALL, 0.042)
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    state = np.empty((1, mujoco.mj_stateSize(models.full, spec)))
    mujoco.mj_getState(models.full, data, state[0], spec)
    initial, final, duration = to_physical(params)
    total = 0.0
    for i in range(params.shape[0]):
        steps = round(float(phase1_steps[i]))
        ctrl = controls(initial[i : i + 1], final[i : i + 1], duration[i : i + 1], np.arange(steps) * DT)
        start = time.perf_counter()
        rollout.rollout(models.full, data, state, ctrl)
        total += time.perf_counter() - start
    ball = mujoco.MjData(models.ball)
    ball.qpos[:4] = (0.0, 0.0, 0.042, 1.0)
    ball.qvel[0] = 3.0
    nstep = 20000
    start = time.perf_counter()
    mujoco.mj_step(models.ball, ball, nstep=nstep)
    ball_step = (time.perf_counter() - start) / nstep
    return total + float(phase2_steps.sum()) * ball_step


def episodes(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """n precision-task contexts (n, 1) and noisy reference kicks (n, 25)."""
    rng = np.random.default_rng(seed)
    contexts = rng.uniform(3.0, 12.0, (n, 1))
    params = np.clip(REFERENCE_KICK + rng.normal(0.0, 0.02, (n, 25)), -1.0, 1.0)
    return contexts, params


def timed(env, contexts: np.ndarray, params: np.ndarray, batch: int) -> tuple[float, float, np.ndarray]:
    """Wall time and process CPU time of evaluating all episodes in batches of ``batch``, and the returns."""
    returns = []
    start, cpu = time.perf_counter(), time.process_time()
    for i in range(0, contexts.shape[0], batch):
        returns.append(env.evaluate(contexts[i : i + batch], params[i : i + batch])[0])
    return time.perf_counter() - start, time.process_time() - cpu, np.concatenate(returns)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--episodes", type=int, default=200, help="episodes per measurement")
    parser.add_argument("--sequential", type=int, default=50, help="episodes of the sequential measurement")
    args = parser.parse_args()
    cores = os.cpu_count() or 1
    contexts, params = episodes(args.episodes)
    one = gym.make("creps_gym/KickPrecision-v0", num_threads=1).unwrapped
    every = gym.make("creps_gym/KickPrecision-v0", num_threads=0).unwrapped
    result = one.simulate(contexts, params)
    phase1_steps = result.phase1_time / DT
    phase2_steps = (result.sim_time - result.phase1_time) / BALL_TIMESTEP
    raw = raw_seconds(one.models, params, phase1_steps, phase2_steps)
    print(
        f"episodes: {phase1_steps.mean():.0f} full-model + {phase2_steps.mean():.0f} ball-only steps on "
        f"average, {result.fell.mean():.0%} falls; raw mj_step takes {raw / args.episodes * 1e3:.2f} ms each"
    )

    seq_time, seq_cpu, seq_returns = timed(one, contexts[: args.sequential], params[: args.sequential], 1)
    one_time, one_cpu, one_returns = timed(one, contexts, params, args.episodes)
    all_time, all_cpu, all_returns = timed(every, contexts, params, args.episodes)
    identical = np.array_equal(one_returns, all_returns) and np.array_equal(
        seq_returns, one_returns[: args.sequential]
    )
    raw_rate = args.episodes / raw
    rows = [
        ("sequential, 1 thread", args.sequential / seq_time, 1, seq_cpu / seq_time),
        ("batched, 1 thread", args.episodes / one_time, 1, one_cpu / one_time),
        (f"batched, {cores} threads", args.episodes / all_time, cores, all_cpu / all_time),
    ]
    print(f"{'mode':<24}{'episodes/s':>12}{'vs raw mj_step per core':>26}{'cores busy':>12}")
    for name, rate, threads, busy in rows:
        print(f"{name:<24}{rate:>12.1f}{rate / threads / raw_rate:>25.0%}{busy:>12.2f}")
    load = os.getloadavg()[0]
    print(f"raw mj_step equivalent: {raw_rate:.1f} episodes/s per core (load average {load:.1f})")
    print(f"speed-up on {cores} cores: {rows[2][1] / rows[1][1]:.2f}x")
    print(f"sequential, 1-thread and {cores}-thread results bit-identical: {identical}")
    print(f"70,000 episodes on {cores} cores: {70000 / rows[2][1] / 60:.1f} min")


if __name__ == "__main__":
    main()
