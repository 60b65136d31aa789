"""The Ray backend: one chunk of episodes per Ray task (``pip install creps-gym[ray]``).

Ray is imported only when a :class:`RayBackend` is built. Which Ray it uses, in this order:

1. **A Ray already initialised in this process** (e.g. your own ``ray.init(address=...)``) is used as is
   and left running. With ``ray_address`` set, it must be that cluster (``RuntimeError`` otherwise).
2. **A running cluster**, at ``ray_address`` (:class:`~creps_gym.runner.config.RunConfig`, ``--ray-address``)
   or else at the ``RAY_ADDRESS`` environment variable (Ray's convention; ``"local"`` or empty means
   unset): ``"HOST:PORT"`` as ``ray start --head`` prints it, or ``"auto"``. The run joins it as a
   driver and, at its end, only disconnects: the cluster keeps running for the next run. An address
   where nothing answers, or where a server that is not Ray's does, raises ``ValueError`` within seconds
   (:func:`check_reachable`; Ray itself would retry for minutes, or wait for ever). A new run checks it
   before it creates its run directory.
3. **Otherwise a local Ray** (``ray.init(address="local")``, so a cluster that ``ray start`` left on
   this machine is never joined by accident). Its start-up (seconds) is paid once per process: the Ray
   stays up for the next run of the process with the same ``workers`` (another ``workers`` or a
   ``ray_address`` restarts or leaves it), and is shut down when the process exits, or by
   :func:`shutdown_local_ray` (call it before your own ``ray.init``).

Each iteration's episodes are split into one chunk per CPU of the cluster, counted when the iteration
starts (``ray.cluster_resources()``), so nodes that join or leave mid-run are taken into account; each
task asks for one CPU, so the chunks spread over every node. ``workers`` fixes the number of chunks
instead. The history does not depend on the chunks (each episode replays its own seeded reset).

**Losing a node.** A task whose worker process or node dies is re-submitted by Ray (``retries`` times)
on the nodes still alive, so no sample is lost and the history stays bit-identical; a run whose head
node dies stops with an :class:`~creps_gym.errors.EpisodeError`.

**A hard kill of the run.** ``ray.init`` starts its services (GCS server, raylet, log monitor, and the
raylet's dashboard and runtime-env agents and workers) as processes of their own. After a ``kill -9`` of
the run's process, the GCS server, raylet and workers exit by themselves, but Ray's agents stay alive. So
a run that starts its own Ray also starts a small watchdog process (:mod:`creps_gym.runner.backends.watchdog`,
Linux ``/proc`` only). It records the processes Ray started and their descendants, and when the run's
process dies without shutting Ray down it terminates them (SIGTERM, then SIGKILL after 2 s) and exits.
Ray's session files under its temporary directory (``/tmp/ray/session_*``) are left, as after any Ray
session. A Ray the user initialised, or a cluster the run joined, is never watched or stopped. The
watchdog of a local Ray kept for later runs watches until the process exits or shuts that Ray down.
"""

from __future__ import annotations

import atexit
import itertools
import os
import socket
from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from creps_gym._validation import config_field
from creps_gym.errors import EpisodeError
from creps_gym.optimizers.adapters.base import import_optional
from creps_gym.runner.backends.episodes import Array, Backend, EnvSource, run_episodes
from creps_gym.runner.backends.watchdog import Watchdog, child_pids
from creps_gym.runner.config import check_ray_address

__all__ = [
    "RayBackend",
    "check_ray_cluster",
    "check_reachable",
    "cluster_cpus",
    "plan_chunks",
    "resolve_address",
    "shutdown_local_ray",
]

_RAY_ENVS: dict[str, gym.Env] = {}
#: The local Ray a RayBackend started in this process and keeps for later runs: the ``ray`` module, its
#: ``num_cpus``, ``watchdog`` and GCS ``address`` (empty when there is none).
_LOCAL_RAY: dict[str, Any] = {}
CONNECT_TIMEOUT = 5.0  # seconds to wait for a cluster's GCS port to answer before ray.init


def resolve_address(ray_address: str | None, environ: Mapping[str, str]) -> tuple[str | None, str]:
    """The cluster to join and where its address came from: ``ray_address``, else ``RAY_ADDRESS``.

    Returns ``(None, "")`` when neither names a cluster (``RAY_ADDRESS`` unset, empty or ``"local"``).
    ``ValueError`` (naming ``ray_address`` or ``RAY_ADDRESS``) for an address that is not ``"auto"`` or
    ``"HOST:PORT"``.
    """
    if ray_address is not None:
        return check_ray_address(ray_address, "ray_address"), "ray_address"
    value = environ.get("RAY_ADDRESS", "").strip()
    if value in ("", "local"):
        return None, ""
    return check_ray_address(value, "RAY_ADDRESS"), "RAY_ADDRESS"


def cluster_cpus(resources: Mapping[str, float]) -> int:
    """The CPUs of a cluster (``ray.cluster_resources()``: the total over its live nodes); at least 1."""
    return max(1, int(resources.get("CPU", 0)))


def plan_chunks(episodes: int, chunks: int) -> list[tuple[int, int]]:
    """Split ``range(episodes)`` into ``min(chunks, episodes)`` contiguous spans ``(a, b)``.

    The spans cover every episode once, in order, and their sizes differ by at most one.
    """
    count = max(1, min(chunks, episodes))
    bounds = np.linspace(0, episodes, count + 1).astype(int)
    return list(itertools.pairwise(int(b) for b in bounds))


#: What an HTTP/2 client sends first (RFC 9113, 3.4), then an empty SETTINGS frame; a gRPC server such as
#: Ray's GCS answers with a SETTINGS frame (type 4), any other listener with something else or nothing.
_HTTP2_HELLO = b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n" + bytes([0, 0, 0, 4, 0, 0, 0, 0, 0])


def shutdown_local_ray() -> None:
    """Shut down the local Ray that runs of this process started and kept (nothing if there is none).

    Called at exit; a Ray the user initialised, or a cluster a run joined, is never touched.
    """
    if not _LOCAL_RAY:
        return
    ray, watchdog = _LOCAL_RAY["ray"], _LOCAL_RAY["watchdog"]
    if _own_local_ray(ray):
        ray.shutdown()
    _LOCAL_RAY.clear()
    if watchdog is not None:
        watchdog.release()


def _start_local_ray(ray: Any, workers: int | None) -> None:
    """``ray.init`` a local Ray of ``workers`` CPUs (all if None), watched, and kept for later runs."""
    shutdown_local_ray()  # a Ray we started and someone else shut down: release its watchdog
    before = child_pids(os.getpid())
    ray.init(address="local", num_cpus=workers, include_dashboard=False, logging_level="ERROR")
    watchdog = Watchdog.start(sorted(child_pids(os.getpid()) - before))
    address = ray.get_runtime_context().gcs_address
    _LOCAL_RAY.update(ray=ray, num_cpus=workers, watchdog=watchdog, address=address)


def _own_local_ray(ray: Any) -> bool:
    """Whether the Ray initialised in this process is the local one a run started (not the user's)."""
    return (
        bool(_LOCAL_RAY)
        and ray.is_initialized()
        and ray.get_runtime_context().gcs_address == _LOCAL_RAY["address"]
    )


atexit.register(shutdown_local_ray)


def check_reachable(address: str, name: str, timeout: float = CONNECT_TIMEOUT) -> None:
    """``ValueError`` naming ``name`` unless a gRPC server (a Ray GCS) answers at ``HOST:PORT``.

    Fast, unlike ``ray.init``, which retries for minutes where nothing answers and waits for ever on a
    listener that is not Ray (``python -m http.server``): at most ``timeout`` seconds to connect and as
    many for the first HTTP/2 frame.
    """
    host, _, port = address.rpartition(":")
    try:
        with socket.create_connection((host.strip("[]"), int(port)), timeout=timeout) as sock:
            reply = b""
            try:
                sock.sendall(_HTTP2_HELLO)
                while len(reply) < 9:
                    chunk = sock.recv(9 - len(reply))
                    if not chunk:
                        break
                    reply += chunk
            except OSError:  # a reset or no answer in time: not a gRPC server
                pass
    except OSError as exc:
        raise ValueError(
            f"{name}: expected the address of a running Ray cluster (`ray start --head` prints it), got "
            f"{address!r}, where nothing answers ({type(exc).__name__}: {exc})"
        ) from None
    if len(reply) < 9 or reply[3] != 4:
        raise ValueError(
            f"{name}: expected the address of a running Ray cluster (`ray start --head` prints it), got "
            f"{address!r}, where a server that is not Ray's answers (first bytes {reply[:9]!r}, not an "
            "HTTP/2 SETTINGS frame)"
        )


def _canonical(address: str, local_ip: str) -> tuple[str, str]:
    """``(ip, port)`` of ``HOST:PORT``, this machine's loopback names mapped to ``local_ip``."""
    host, _, port = address.rpartition(":")
    try:
        ip = socket.gethostbyname(host.strip("[]"))
    except OSError:
        ip = host
    return (local_ip if ip.startswith("127.") or ip in ("::1", "localhost") else ip), port


def _ray_chunk(
    key: str, source: EnvSource, seeds: Any, contexts: Array, params: Array, first: int, label: str, n: int
) -> Array:
    """Body of a Ray task: the worker keeps one env per source."""
    if key not in _RAY_ENVS:
        _RAY_ENVS[key] = source.make()
    env, batched = _RAY_ENVS[key], source.set_context
    return run_episodes(
        env, seeds, contexts, params, first=first, label=label, retries=n, set_context=batched
    )


class RayBackend(Backend):
    """Ray tasks, one chunk of episodes per cluster CPU (``workers`` chunks if given); see the module.

    Attributes
    ----------
    cluster : dict
        What the run used: ``ray`` (``"joined"`` a running cluster, ``"in-process"`` a Ray already
        initialised, ``"local"`` one started for the run), ``address`` (the cluster's GCS address),
        ``nodes`` and ``cpus`` (alive when the backend was built). The runner logs it.
    """

    name = "ray"

    def __init__(
        self, source: EnvSource, retries: int, workers: int | None, address: str | None = None
    ) -> None:
        super().__init__(source, retries)
        self._ray = ray = import_optional("ray", "ray")
        address, origin = resolve_address(address, os.environ)
        self._shutdown = False  # whether close() calls ray.shutdown() (never stopping a cluster)
        ours = _own_local_ray(ray)
        if ours and (address is not None or _LOCAL_RAY["num_cpus"] != workers):
            shutdown_local_ray()  # another cluster, or another size: our local Ray gives way
            ours = False
        if ours:
            kind = "local"  # started by an earlier run of this process, kept for this one
        elif ray.is_initialized():
            self._check_same_cluster(address, origin)
            kind = "in-process"
        elif address is not None:
            self._join(address, origin)
            kind = "joined"
        else:
            _start_local_ray(ray, workers)
            kind = "local"
        self.workers = workers
        try:
            nodes = sum(1 for node in ray.nodes() if node.get("Alive"))
            address = ray.get_runtime_context().gcs_address
            self.cluster = {"ray": kind, "address": address, "nodes": nodes, "cpus": self._cpus()}
            self._source_ref = ray.put(source)
        except BaseException:
            self.close()
            raise
        self._key = self._source_ref.hex()
        self._task = ray.remote(num_cpus=1, max_retries=retries)(_ray_chunk)

    def log_entry(self) -> dict[str, Any]:
        return {"event": "ray", **self.cluster}

    def _join(self, address: str, origin: str) -> None:
        """Connect this process to the running cluster at ``address`` as a driver."""
        if address != "auto":
            check_reachable(address, origin)
        try:
            self._ray.init(address=address, logging_level="ERROR")
        except Exception as exc:  # Ray raises ConnectionError, AuthenticationError, RuntimeError, ...
            raise RuntimeError(
                f"{origin}: could not join the Ray cluster at {address!r} ({type(exc).__name__}: "
                f"{str(exc).splitlines()[0] if str(exc) else ''}); a cluster with token authentication "
                "needs RAY_AUTH_MODE=token and its token here (see docs/runner.md)"
            ) from None
        self._shutdown = True  # disconnects this driver only; the cluster keeps running

    def _check_same_cluster(self, address: str | None, origin: str) -> None:
        """``RuntimeError`` if the Ray initialised in this process is not the cluster at ``address``."""
        if address is None or address == "auto" or origin != "ray_address":
            return
        joined = self._ray.get_runtime_context().gcs_address
        local_ip = joined.rpartition(":")[0]
        if _canonical(address, local_ip) != _canonical(joined, local_ip):
            raise RuntimeError(
                f"ray_address: expected the cluster this process already joined ({joined!r}), got "
                f"{address!r}; call ray.shutdown() first to join another cluster"
            )

    def _cpus(self) -> int:
        return cluster_cpus(self._ray.cluster_resources())

    def evaluate(self, seeds: NDArray[np.int64], contexts: Array, params: Array, label: str) -> Array:
        ray = self._ray
        spans = plan_chunks(len(seeds), self.workers or self._cpus())
        key, ref, tries = self._key, self._source_ref, self.retries
        task = self._task.remote
        refs = [task(key, ref, seeds[a:b], contexts[a:b], params[a:b], a, label, tries) for a, b in spans]
        returns = []
        for (a, b), ref in zip(spans, refs, strict=True):
            try:
                returns.append(ray.get(ref))
            except ray.exceptions.RayTaskError as exc:
                cause = exc.cause if isinstance(exc.cause, Exception) else exc
                raise EpisodeError(str(cause).splitlines()[-1] if cause is exc else str(cause)) from None
            except ray.exceptions.RayError as exc:
                raise EpisodeError(
                    f"{label}, episodes {a}..{b - 1}: the Ray task failed {self.retries + 1} time(s) "
                    f"({type(exc).__name__}: {str(exc).splitlines()[0]})"
                ) from None
        return np.concatenate(returns)

    def close(self) -> None:
        """Disconnect from a joined cluster; a local Ray stays up for the next run (see the module)."""
        if self._shutdown and self._ray.is_initialized():
            self._ray.shutdown()
        self._shutdown = False


def check_ray_cluster(config: Any) -> None:
    """For the Ray backend: ``ImportError`` without Ray, and, joining a cluster, ``ValueError`` naming the
    address unless Ray answers there.

    Called before a new run directory is created, so a wrong address leaves nothing behind.
    """
    if config.backend != "ray":
        return
    import_optional("ray", "ray")  # a missing Ray (exit 4) leaves no run folder behind either

    address, origin = resolve_address(config.ray_address, os.environ)
    if address is not None and address != "auto":
        with config_field("ray_address" if origin == "ray_address" else None):
            check_reachable(address, origin)
