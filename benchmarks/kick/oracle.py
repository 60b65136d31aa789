"""The kick study's oracle: CMA-ES learning one context alone, with IPOP restarts, as an upper yardstick.

At one evaluation point (a precision target or a flexibility ball position) a registry optimiser (pycma's
``cma`` by default) searches from the env-declared start N(0, I) of :class:`~creps_gym.wrappers.OffsetParams`
at its default population λ. Near the reference kick most samples of a far ball never touch it, so the
returns are flat and CMA-ES stops within a few iterations. A one-start oracle would then report a
position as out of reach after 13 episodes of a 3,000-episode budget. The oracle restarts instead, as
IPOP-CMA-ES does (Auger and Hansen, CEC 2005): each time a start meets a stop criterion, a new start from
the same initial distribution with twice the population and a new seed, until the next iteration no longer
fits in the budget. Its ``value`` is the best final mean over the starts: the oracle keeps its best
attempt, as a user with that budget would.

A start's seed is child ``r`` of ``SeedSequence([seed, crc32(experiment), index])``; the first start's
seed is the one a one-start oracle used, so a start that ran the whole budget without stopping gives the
same record as before.
"""

from __future__ import annotations

import time
import zlib
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.kick.study import (
    ENV_IDS,
    LEGACY_ENV_IDS,
    PACKAGES,
    TARGETS,
    episode_metric,
    evaluate,
    grid_contexts,
    read_json,
    write_json,
)
from benchmarks.provenance import provenance
from creps_gym.envs.base import initial_distribution
from creps_gym.optimizers.registry import make_optimizer, recommended_samples
from creps_gym.wrappers import OffsetParams

__all__ = ["SIGN", "ipop_starts", "oracle_point", "read_oracle"]

SIGN = {"precision": -1.0, "flexibility": 1.0}  # better metric: smaller error, farther kick


def read_oracle(path: Path, experiment: str) -> dict[str, Any]:
    """An oracle record of ``experiment``; a record without ``starts`` (written by a single start that ran
    its whole budget) gets its one start listed, and one without ``env`` the legacy env it ran on."""
    record = {"env": LEGACY_ENV_IDS[experiment], **read_json(path)}
    if "starts" not in record:
        start = {key: record[key] for key in ("population", "episodes", "value")}
        record["starts"] = [{**start, "stop": {}}]
    return record


def _reusable(record: dict[str, Any], experiment: str, episodes: int) -> bool:
    """Same env and budget, and either written with restarts or a single start that never stopped early
    (the restarting oracle would reproduce it)."""
    if (
        record["budget_episodes"] != episodes
        or record.get("env", LEGACY_ENV_IDS[experiment]) != ENV_IDS[experiment]
    ):
        return False
    return "starts" in record or record["episodes"] == episodes // record["population"] * record["population"]


def _one_start(
    env: OffsetParams,
    experiment: str,
    context: np.ndarray,
    population: int,
    budget: int,
    seed: int,
    name: str,
) -> tuple[dict[str, Any], np.ndarray]:
    """One CMA-ES start at ``population`` until it stops or the next iteration exceeds ``budget``: its
    record and its final mean's offsets (1, p)."""
    p, z = env.action_space.shape[0], env.unwrapped.context_dim
    mean, std = initial_distribution(env)
    opt = make_optimizer(name, p, z, seed, initial_mean=mean, initial_cov=std**2)
    contexts = np.tile(context, (population, 1))
    sign = SIGN[experiment]
    best = -np.inf
    stop: dict[str, Any] = {}
    while opt.evaluations + population <= budget and not stop:
        offsets = opt.ask(contexts)
        returns, info = evaluate(env, contexts, offsets)
        opt.tell(contexts, offsets, returns)
        metric = episode_metric(experiment, contexts, info)
        best = max(best, float(np.max(np.where(info["fell"], -np.inf, sign * metric))))
        stop = opt.stop()
    final = opt.recommend(context[None])
    _, info = evaluate(env, context[None], final)
    value = float(episode_metric(experiment, context[None], info)[0])
    record = {
        "population": population,
        "episodes": opt.evaluations,
        "value": value,
        "stop": stop,
        "best": best,
    }
    return record, final


def _start_seed(sequence: np.random.SeedSequence, start: int) -> int:
    """Seed of start ``start``: the sequence's own for the first (the one-start oracle's), then its
    ``start``-th child."""
    child = sequence if start == 0 else np.random.SeedSequence(sequence.entropy, spawn_key=(start,))
    return int(child.generate_state(1)[0])


def ipop_starts(
    env: OffsetParams,
    experiment: str,
    context: np.ndarray,
    episodes: int,
    seed_of: Callable[[int, int], int],
    name: str = "cma",
) -> list[tuple[dict[str, Any], np.ndarray]]:
    """IPOP starts of ``name`` at ``context``: the registry's population first, each next start twice the
    last one's, while a start's first iteration fits in the ``episodes`` left. Start k's seed is
    ``seed_of(k, used)`` (``used``: the episodes spent before it). Each start's record and final mean's
    offsets (:func:`_one_start`)."""
    population, used, starts = recommended_samples(name, env.action_space.shape[0], 0), 0, []
    while used + population <= episodes:
        seed = seed_of(len(starts), used)
        starts.append(_one_start(env, experiment, context, population, episodes - used, seed, name))
        used += starts[-1][0]["episodes"]
        population *= 2
    return starts


def oracle_point(
    env: OffsetParams,
    experiment: str,
    index: int,
    episodes: int,
    seed: int,
    folder: Path,
    name: str = "cma",
    fresh: bool = False,
) -> dict[str, Any]:
    """The oracle at one evaluation point (target ``TARGETS[index]`` or ball position
    ``grid_contexts()[index]``): ``name`` learning that context alone with IPOP restarts, ``episodes`` in all.

    Cached as ``oracle-<index>.json`` under ``folder`` (``fresh``: computed again all the same). ``value``
    is the best final mean's metric over the starts (error to the target, or forward distance with 0 for a
    fall), ``best`` the best metric of any sample that did not fall, ``starts`` each start's population,
    episodes, value and stop criteria, ``provenance`` where it was computed
    (:func:`benchmarks.provenance.provenance`).
    """
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"oracle-{index:02d}.json"
    if path.exists() and not fresh and _reusable(read_json(path), experiment, episodes):
        return read_oracle(path, experiment)
    context = TARGETS[index : index + 1] if experiment == "precision" else grid_contexts()[index]
    sequence = np.random.SeedSequence([seed, zlib.crc32(experiment.encode()), index])
    sign, begin = SIGN[experiment], time.perf_counter()

    def seed_of(start: int, used: int) -> int:
        return _start_seed(sequence, start)

    starts = [record for record, _ in ipop_starts(env, experiment, context, episodes, seed_of, name)]
    used = sum(s["episodes"] for s in starts)
    best = max(s.pop("best") for s in starts)
    result = {
        "index": index,
        "env": ENV_IDS[experiment],
        "context": context.tolist(),
        "optimizer": name,
        "population": starts[0]["population"],
        "budget_episodes": episodes,
        "episodes": used,
        "value": sign * max(sign * s["value"] for s in starts),
        "best": sign * best if np.isfinite(best) else None,
        "starts": starts,
        "seconds": time.perf_counter() - begin,
        "provenance": provenance(PACKAGES),
    }
    write_json(path, result)
    return result
