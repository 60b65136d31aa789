"""The Ray backend joins a running cluster (issue 14, item 5).

The cheap tests check the chunk planner, the address rules and the configuration without Ray. The
cluster tests start a real 2-node cluster on this machine: ``ray start --head --num-cpus=1`` and a worker
node ``ray start --address=HEAD --num-cpus=1``, both with ``--block`` in sessions of their own, every port
chosen free, and a temporary ``--temp-dir`` (so Ray's "latest cluster" file, which a bare ``ray.init()``
elsewhere on the machine would read, is never written to ``/tmp/ray``). Token authentication is off for
this private cluster (``RAY_AUTH_MODE=disabled``), so the test needs no token; the test process is set to
the same mode while the cluster runs (a local ``ray.init`` of an earlier test turns token mode on).

Clean-up never uses ``ray stop``, which stops every Ray on the machine: the fixture stops exactly the
process trees of the two ``ray start`` processes it launched
(:func:`creps_gym.runner.backends.watchdog.process_tree` and
:func:`~creps_gym.runner.backends.watchdog.terminate`), backed by a
:class:`~creps_gym.runner.backends.watchdog.Watchdog` that does the same if the test process itself is
killed. Ray's worker processes lead process groups of their own, so killing the ``ray start`` process
groups would not be enough.
"""

from __future__ import annotations

import itertools
import json
import os
import shutil
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from helpers import EXTRAS, cli_in_process

from creps_gym.cli import main
from creps_gym.envs.base import ContextualEpisodicEnv
from creps_gym.optimizers import CREPSCMA
from creps_gym.runner import RunDir, resume, run
from creps_gym.runner.backends.ray import cluster_cpus, plan_chunks, resolve_address
from creps_gym.runner.backends.watchdog import Watchdog, process_tree, terminate
from creps_gym.runner.config import RunConfig, check_ray_address
from creps_gym.runner.rundir.checkpoint import config_fingerprint

ROOT = Path(__file__).resolve().parents[3]
# A killed node is declared dead after 3 refused health checks 1 s apart (Ray's default: 5 checks 3 s apart);
# a live but slow node still gets 5 s per check, so a loaded machine does not lose one.
FAST_NODE_DEATH = {
    "RAY_health_check_period_ms": "1000",
    "RAY_health_check_timeout_ms": "5000",
    "RAY_health_check_failure_threshold": "3",
}
NODE = "CREPS_GYM_TEST_NODE"  # which node a Ray worker process belongs to (inherited from `ray start`)


# -- without Ray -----------------------------------------------------------------------------------------
def test_chunks_cover_every_episode_once_in_balanced_contiguous_spans():
    for episodes in range(1, 40):
        for chunks in range(1, 45):
            spans = plan_chunks(episodes, chunks)
            assert len(spans) == min(episodes, chunks)
            assert spans[0][0] == 0 and spans[-1][1] == episodes
            assert all(b == a for (_, b), (a, _) in itertools.pairwise(spans))
            sizes = [b - a for a, b in spans]
            assert min(sizes) >= 1 and max(sizes) - min(sizes) <= 1


def test_the_chunks_follow_the_clusters_total_cpus():
    two_nodes = {"CPU": 2.0, "node:192.0.2.2": 2.0, "memory": 1e9, "node:__internal_head__": 1.0}
    assert cluster_cpus(two_nodes) == 2 and len(plan_chunks(50, cluster_cpus(two_nodes))) == 2
    assert cluster_cpus({"CPU": 64.0}) == 64 and len(plan_chunks(50, 64)) == 50
    assert cluster_cpus({"CPU": 3.5}) == 3 and cluster_cpus({"CPU": 0.0}) == 1 == cluster_cpus({})


def test_the_address_comes_from_the_argument_then_ray_address():
    assert resolve_address("10.0.0.1:6379", {"RAY_ADDRESS": "10.0.0.2:6379"}) == (
        "10.0.0.1:6379",
        "ray_address",
    )
    assert resolve_address(None, {"RAY_ADDRESS": " head:6379 "}) == ("head:6379", "RAY_ADDRESS")
    assert resolve_address(None, {"RAY_ADDRESS": "auto"}) == ("auto", "RAY_ADDRESS")
    for unset in ({}, {"RAY_ADDRESS": ""}, {"RAY_ADDRESS": "local"}):
        assert resolve_address(None, unset) == (None, "")
    with pytest.raises(ValueError, match=r"^RAY_ADDRESS: expected 'HOST:PORT' .* got 'ray://head:10001'"):
        resolve_address(None, {"RAY_ADDRESS": "ray://head:10001"})


@pytest.mark.parametrize(
    "address",
    [
        "head",
        "head:",
        ":6379",
        "head:0",
        "head:65536",
        "head:6379x",
        "a b:1",
        "ray://head:10001",
        "head:６３７９",
        "",
        "local",
    ],
)
def test_bad_addresses_are_refused_with_their_name(address):
    with pytest.raises(ValueError, match=rf"^ray_address: expected 'HOST:PORT' .*, got {address!r}$"):
        check_ray_address(address)
    with pytest.raises(ValueError, match=r"^ray_address: expected 'HOST:PORT'"):
        RunConfig("creps_gym/Sphere-v0", "creps", 2, 12, 0, backend="ray", ray_address=address)
    for good in ("10.0.0.1:6379", "head.example.org:6379", "[::1]:6379", "auto"):
        assert check_ray_address(good) == good
    with pytest.raises(TypeError, match=r"^ray_address: expected a str 'HOST:PORT' or 'auto', got int 6379$"):
        RunConfig("creps_gym/Sphere-v0", "creps", 2, 12, 0, backend="ray", ray_address=6379)


def test_an_address_needs_the_ray_backend(tmp_path, capsys):
    with pytest.raises(
        ValueError, match=r"^ray_address: expected None unless backend='ray' \(backend is 'auto'"
    ):
        RunConfig("creps_gym/Sphere-v0", "creps", 2, 12, 0, ray_address="10.0.0.1:6379")
    base = ["run", "--env", "creps_gym/Sphere-v0", "--optimizer", "creps", "--iterations", "2", "--seed", "0"]
    for flags, expected in (
        (["--ray-address", "10.0.0.1:6379"], "argument --ray-address: expected None unless backend='ray'"),
        (["--backend", "ray", "--ray-address", "head"], "argument --ray-address: expected 'HOST:PORT'"),
    ):
        assert main([*base, "--out", str(tmp_path / "run"), *flags]) == 2
        assert expected in capsys.readouterr().err
    assert not (tmp_path / "run").exists()


def test_config_json_records_the_address_but_a_resume_never_joins_it(tmp_path):
    config = RunConfig("creps_gym/Sphere-v0", "creps", 2, 12, 0, backend="ray", ray_address="10.0.0.1:6379")
    RunDir.create(tmp_path / "run", config, {}).lock.release()
    recorded = json.loads((tmp_path / "run" / RunDir.CONFIG).read_text())["config"]
    assert recorded["ray_address"] == "10.0.0.1:6379" and recorded["backend"] == "ray"
    read = RunDir.open(tmp_path / "run").config()
    assert read.ray_address is None and read.backend == "ray"
    assert config_fingerprint(read) == config_fingerprint(config)  # the same run: its checkpoints resume
    del recorded["ray_address"]  # a run directory written before the field existed
    assert RunConfig.from_dict(recorded).ray_address is None


# -- a real Ray ------------------------------------------------------------------------------------------
class Probe(ContextualEpisodicEnv):
    """theta*(s) = (s, -s). In a Ray worker of the test cluster, it can log its node and pin chunks to nodes.

    ``log``: every evaluation on a node appends the node's name to this file. ``meet``: an evaluation on a
    node creates ``meet + ".<node>"`` and waits until both nodes' files exist, so the first iteration holds
    the head's only CPU until the worker node has taken a chunk. ``hang``: once ``hang + ".armed"`` exists,
    an evaluation on the worker node writes ``hang`` and blocks until its node is killed, and one on the
    head waits for ``hang`` first (so the worker node gets a chunk to die in).
    """

    def __init__(self, log: str | None = None, meet: str | None = None, hang: str | None = None):
        super().__init__([0.0], [1.0], [-2.0, -2.0], [2.0, 2.0])
        self.log, self.meet, self.hang = log, meet, hang

    def evaluate(self, contexts, params):
        node = os.environ.get(NODE)
        if node is not None:  # in a Ray worker of the test cluster (never in the test process)
            self._pin(node)
        best = np.concatenate([contexts, -contexts], axis=1)
        return -np.sum((params - best) ** 2, axis=1), {}

    def _pin(self, node: str) -> None:
        if self.log is not None:
            with open(self.log, "a") as file:
                file.write(node + "\n")
        if self.meet is not None:
            Path(f"{self.meet}.{node}").touch()
            _wait_for([f"{self.meet}.head", f"{self.meet}.worker"])
        if self.hang is not None and os.path.exists(self.hang + ".armed"):
            if node == "worker":
                Path(self.hang).write_text(str(os.getpid()))
                time.sleep(300)  # the test kills this node long before
            _wait_for([self.hang])


def _wait_for(paths: list[str], seconds: float = 20.0) -> None:
    """Wait until every file in ``paths`` exists (at most ``seconds``: the test then fails, never hangs)."""
    deadline = time.monotonic() + seconds
    while not all(os.path.exists(path) for path in paths) and time.monotonic() < deadline:
        time.sleep(0.02)


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def _ray_start(directory: Path, role: str, *args: str) -> subprocess.Popen:
    """``ray start --block`` of one node, in a session of its own, every port free; output in a file."""
    ports = [
        "--dashboard-agent-listen-port",
        "--dashboard-agent-grpc-port",
        "--metrics-export-port",
        "--runtime-env-agent-port",
        "--node-manager-port",
        "--object-manager-port",
    ]
    command = [sys.executable, "-m", "ray.scripts.scripts", "start", "--block", "--num-cpus=1", *args]
    command += ["--disable-usage-stats", *(f"{flag}={_free_port()}" for flag in ports)]
    path = os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))  # this checkout's code
    env = {**os.environ, "PYTHONPATH": path, "RAY_AUTH_MODE": "disabled", NODE: role, **FAST_NODE_DEATH}
    env.pop("RAY_ADDRESS", None)
    with open(directory / f"{role}.out", "w") as out:
        return subprocess.Popen(
            command,
            stdout=out,
            stderr=subprocess.STDOUT,
            stdin=subprocess.DEVNULL,
            env=env,
            start_new_session=True,
        )


def _wait(condition, seconds: float, what: str, process: subprocess.Popen, log: Path) -> None:
    deadline = time.monotonic() + seconds
    while not condition():
        if process.poll() is not None or time.monotonic() > deadline:
            pytest.fail(f"{what} (exit code {process.poll()}):\n{log.read_text()[-3000:]}")
        time.sleep(0.2)


@pytest.fixture(scope="module")
def cluster():
    """A 2-node Ray cluster on this machine (see the module docstring); yields its address and nodes."""
    ray = pytest.importorskip("ray")
    if not os.path.isdir("/proc"):
        pytest.skip("the cluster's clean-up needs Linux's /proc")
    ray.cloudpickle.register_pickle_by_value(sys.modules[__name__])  # the workers cannot import this file
    if ray.is_initialized():
        pytest.skip("a Ray is initialised in this process: the runner would use it instead of the cluster")
    auth_mode = os.environ.get("RAY_AUTH_MODE")
    directory = Path(tempfile.mkdtemp(prefix="crg"))  # short: Ray's socket paths must fit in 107 bytes
    nodes, watchdog = {}, None
    try:
        _set_auth_mode(
            ray, "disabled"
        )  # the cluster's (a local ray.init earlier in this process set "token")
        head_args = [
            "--head",
            f"--port={_free_port()}",
            f"--temp-dir={directory}",
            "--include-dashboard=false",
        ]
        nodes["head"] = head = _ray_start(directory, "head", *head_args, f"--dashboard-port={_free_port()}")
        address_file = directory / "ray_current_cluster"
        _wait(address_file.exists, 120, "the head node did not start", head, directory / "head.out")
        address = address_file.read_text().strip()
        nodes["worker"] = worker = _ray_start(directory, "worker", f"--address={address}")
        watchdog = Watchdog.start([head.pid, worker.pid])  # stops both if this test process is killed
        ray.init(address=address, logging_level="ERROR", log_to_driver=False)
        try:
            cpus = lambda: ray.cluster_resources().get("CPU", 0) >= 2  # noqa: E731
            _wait(cpus, 120, "the worker node did not join", worker, directory / "worker.out")
        finally:
            ray.shutdown()
        yield {"address": address, "directory": directory, **nodes}
    finally:
        terminate(process_tree([p.pid for p in nodes.values()]))
        for process in nodes.values():
            process.wait(timeout=30)
        if watchdog is not None:
            watchdog.stop_watched()  # anything the trees lost on the way (nothing, normally)
        shutil.rmtree(directory, ignore_errors=True)
        _set_auth_mode(ray, auth_mode)


def _set_auth_mode(ray, mode: str | None) -> None:
    """Set this process's Ray token-authentication mode (None: unset), as Ray's own tests do.

    A driver whose mode differs from the cluster's reaches the cluster, but the cluster's workers cannot
    call back into it (a task then fails to fetch its ``ray.put`` arguments: "the object's owner has
    exited"). The C++ side caches the mode, so it is re-read explicitly.
    """
    if mode is None:
        os.environ.pop("RAY_AUTH_MODE", None)
    else:
        os.environ["RAY_AUTH_MODE"] = mode
    ray._raylet.Config.initialize("")
    ray._raylet.AuthenticationTokenLoader.instance().reset_cache()


def _crash_at(iteration: int):
    def crash(record, history):
        if record.iteration == iteration:
            raise RuntimeError("simulated crash of the driver")

    return crash


@EXTRAS
def test_unreachable_addresses_fail_at_once_with_their_name(monkeypatch):
    ray = pytest.importorskip("ray")
    if ray.is_initialized():
        pytest.skip("a Ray is initialised in this process: it would be used as is")
    dead = f"127.0.0.1:{_free_port()}"
    env = Probe()
    started = time.monotonic()
    with pytest.raises(
        ValueError, match=rf"^ray_address: expected the address of a running Ray .* got '{dead}'"
    ):
        run(CREPSCMA(2, 1, seed=0), env, 2, 10, 0, backend="ray", ray_address=dead)
    monkeypatch.setenv("RAY_ADDRESS", dead)
    with pytest.raises(
        ValueError, match=rf"^RAY_ADDRESS: expected the address of a running Ray .* got '{dead}'"
    ):
        run(CREPSCMA(2, 1, seed=0), env, 2, 10, 0, backend="ray")
    assert time.monotonic() - started < 60 and not ray.is_initialized()  # (Ray itself retries for minutes)


@EXTRAS
@pytest.mark.slow
def test_a_2_node_cluster_gives_the_serial_history_and_is_left_running(cluster, tmp_path, monkeypatch):
    """Run on the cluster, crash the driver, resume there through RAY_ADDRESS: the serial history."""
    import ray

    monkeypatch.delenv("RAY_ADDRESS", raising=False)
    serial = run(CREPSCMA(2, 1, seed=0), Probe(), 5, 10, 0)
    log = tmp_path / "nodes.log"
    out = tmp_path / "run"
    with pytest.raises(RuntimeError, match="simulated crash"):
        env = Probe(str(log), meet=str(tmp_path / "meet"))
        run(
            CREPSCMA(2, 1, seed=0),
            env,
            5,
            10,
            0,
            backend="ray",
            ray_address=cluster["address"],
            run_dir=out,
            checkpoint_every=2,
            callbacks=[_crash_at(3)],
        )
    assert not ray.is_initialized()  # the driver disconnected ...
    assert all(node.poll() is None for node in (cluster["head"], cluster["worker"]))  # ... the cluster runs
    document = json.loads((out / RunDir.CONFIG).read_text())
    assert document["config"]["ray_address"] == cluster["address"]
    document["config"]["ray_address"] = f"127.0.0.1:{_free_port()}"  # a resume never joins it
    (out / RunDir.CONFIG).write_text(json.dumps(document))
    monkeypatch.setenv("RAY_ADDRESS", cluster["address"])
    resumed = resume(out, env=Probe(str(log)), optimizer_class=CREPSCMA)
    assert resumed.equals(serial)
    events = [e for e in RunDir.open(out).read_log()[1] if e["event"] == "ray"]
    expected = {"event": "ray", "ray": "joined", "address": cluster["address"], "nodes": 2, "cpus": 2}
    assert events == [expected, expected]  # the run and its resume, both on the 2 nodes
    assert set(log.read_text().split()) == {"head", "worker"}  # the chunks spread over both nodes
    assert not ray.is_initialized() and cluster["worker"].poll() is None and cluster["head"].poll() is None


@EXTRAS
@pytest.mark.slow
def test_killing_the_worker_node_mid_run_loses_no_sample(cluster, tmp_path):
    """The worker node's processes are killed while it evaluates a chunk: Ray re-runs it on the head."""
    import ray

    serial = run(CREPSCMA(2, 1, seed=1), Probe(), 4, 10, 1)
    hang = str(tmp_path / "hang")
    killed = []

    def kill_the_worker_node():
        _wait_for([hang], 120)
        if os.path.exists(hang):
            tree = process_tree([cluster["worker"].pid])
            killed.append(int(Path(hang).read_text()) in tree)  # the evaluating worker is in the node's tree
            terminate(tree, grace=0)  # SIGKILL, as when the machine is lost

    def arm(record, history):
        if record.iteration == 1:
            Path(hang + ".armed").touch()  # iteration 2's chunk on the worker node hangs there

    killer = threading.Thread(target=kill_the_worker_node, daemon=True)
    killer.start()
    history = run(
        CREPSCMA(2, 1, seed=1),
        Probe(hang=hang),
        4,
        10,
        1,
        backend="ray",
        ray_address=cluster["address"],
        callbacks=[arm],
    )
    killer.join(timeout=10)
    assert killed == [True] and cluster["worker"].wait(timeout=30) is not None
    assert history.equals(serial) and len(history) == 4 and history.records[-1].episodes == 40
    assert not ray.is_initialized() and cluster["head"].poll() is None  # the runner left the head running
    ray.init(address=cluster["address"], logging_level="ERROR", log_to_driver=False)
    try:
        assert ray.get(ray.remote(lambda: os.getpid()).remote()) > 0  # the head node still serves tasks ...
        deadline = time.monotonic() + 60
        while ray.cluster_resources().get("CPU") != 1.0 and time.monotonic() < deadline:
            time.sleep(0.2)  # ... and the cluster's view drops the lost node (it may lag the run's end)
        assert ray.cluster_resources().get("CPU") == 1.0
    finally:
        ray.shutdown()


def test_the_cli_documents_ray_address(capsys):
    with pytest.raises(SystemExit):
        main(["run", "--help"])
    help_text = " ".join(capsys.readouterr().out.split())
    assert "--ray-address HOST:PORT" in help_text and "$RAY_ADDRESS" in help_text


# -- an address where something that is not Ray answers (issue 30, item 5) ---------------------------------
@pytest.fixture
def http_server():
    """``python -m http.server`` on a free loopback port, in a thread; yields its ``HOST:PORT``."""
    import http.server

    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), http.server.SimpleHTTPRequestHandler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"127.0.0.1:{server.server_address[1]}"
    finally:
        server.shutdown()
        server.server_close()
        thread.join(timeout=5)


def _listener(reply: bytes | None):
    """A loopback listener that answers each connection with ``reply`` (None: accepts and stays silent)."""
    sock = socket.socket()
    sock.bind(("127.0.0.1", 0))
    sock.listen()
    held = []

    def serve():
        while True:
            try:
                connection, _ = sock.accept()
            except OSError:
                return
            held.append(connection)
            if reply is not None:
                connection.sendall(reply)

    threading.Thread(target=serve, daemon=True).start()
    return sock, held


@pytest.mark.slow
def test_a_listener_that_is_not_ray_is_refused_within_seconds(http_server):
    from creps_gym.runner.backends.ray import check_reachable

    start = time.monotonic()
    with pytest.raises(
        ValueError, match=r"ray_address: expected the address of a running Ray cluster .* not Ray's"
    ):
        check_reachable(http_server, "ray_address")
    silent, held = _listener(None)
    address = f"127.0.0.1:{silent.getsockname()[1]}"
    with pytest.raises(
        ValueError,
        match=r"got '127\.0\.0\.1:\d+', where a server that is not Ray's answers \(first bytes b''",
    ):
        check_reachable(address, "ray_address", timeout=1.0)
    grpc_like, _ = _listener(bytes([0, 0, 0, 4, 0, 0, 0, 0, 0]))  # an HTTP/2 server's first frame: SETTINGS
    check_reachable(f"127.0.0.1:{grpc_like.getsockname()[1]}", "ray_address", timeout=5.0)
    for sock in (silent, grpc_like, *held):
        sock.close()
    assert time.monotonic() - start < 30


@EXTRAS  # the Ray backend checks that Ray is installed first
def test_run_with_a_ray_address_that_is_not_ray_exits_2_and_leaves_no_run_folder(
    http_server, tmp_path, capsys
):
    """Before: ``--ray-address`` of an http.server waited for ever, after creating the run folder."""
    argv = ["run", "--env", "creps_gym/Sphere-v0", "--optimizer", "creps", "--iterations", "1", "--seed", "0"]
    argv += [
        "--backend",
        "ray",
        "--ray-address",
        http_server,
        "--out",
        str(tmp_path / "run"),
        "--no-progress",
    ]
    start = time.monotonic()
    assert main(argv) == 2
    assert time.monotonic() - start < 30
    err = capsys.readouterr().err
    assert (
        "argument --ray-address: expected the address of a running Ray cluster" in err and http_server in err
    )
    assert not (tmp_path / "run").exists()


@EXTRAS  # the Ray backend checks that Ray is installed first
def test_resume_with_a_ray_address_that_is_not_ray_exits_2_at_once(
    http_server, tmp_path, capsys, monkeypatch
):
    """Before: a resume on the Ray backend with RAY_ADDRESS at a non-Ray listener failed with exit 1."""
    import json

    from creps_gym.runner import run

    out = tmp_path / "run"
    run("creps", "creps_gym/Sphere-v0", 3, 10, 0, env_kwargs={"dim": 2}, run_dir=out, checkpoint_every=1)
    (out / "history.json").unlink()
    document = json.loads((out / "config.json").read_text())
    document["config"]["backend"] = "ray"  # where it runs is not part of the run (not fingerprinted)
    (out / "config.json").write_text(json.dumps(document))
    monkeypatch.setenv("RAY_ADDRESS", http_server)
    start = time.monotonic()
    assert main(["resume", str(out), "--no-progress", "--no-plot"]) == 2
    assert time.monotonic() - start < 30
    err = capsys.readouterr().err
    assert "RAY_ADDRESS: expected the address of a running Ray cluster" in err and http_server in err


def test_a_ray_run_without_ray_installed_exits_4_and_leaves_no_run_folder(tmp_path, monkeypatch):
    """Before: the run folder was created before the Ray backend found Ray missing."""
    monkeypatch.setitem(sys.modules, "ray", None)  # as if Ray were not installed: `import ray` raises
    out = tmp_path / "run"
    argv = ["--env", "creps_gym/Sphere-v0", "--optimizer", "creps", "--iterations", "1", "--seed", "0"]
    result = cli_in_process("run", *argv, "--backend", "ray", "--out", out, "--no-progress")
    assert result.returncode == 4, result.stderr
    assert "pip install creps-gym[ray]" in result.stderr and not out.exists()
