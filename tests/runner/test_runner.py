"""The runner: loop, seeds, backends, stop conditions, failures, history, run directory, export, plots."""

from __future__ import annotations

import csv
import io
import json
import math
import re
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from helpers import EXTRAS, SPHERE, marked, python_blocks

from creps_gym import registered_ids
from creps_gym.envs.base import ContextualEpisodicEnv, SupportsRegret
from creps_gym.envs.evaluation import contextual_model
from creps_gym.errors import EpisodeError
from creps_gym.optimizers import CREPSCMA, minimum_samples
from creps_gym.runner import (
    Callback,
    History,
    IterationRecord,
    ProgressBar,
    RunConfig,
    RunDir,
    Runner,
    default_initial_distribution,
    plot_histories,
    resume,
    run,
    split_seed,
    write_iohanalyzer,
)
from creps_gym.runner.rundir.log_chain import history_crc

SMALL = {"env_kwargs": {"dim": 4}}


class Target(ContextualEpisodicEnv):
    """theta*(s) = (s, -s): return -|theta - theta*(s)|^2. ``fail`` makes chosen evaluations raise."""

    def __init__(self, fail=None):
        super().__init__([0.0], [1.0], [-2.0, -2.0], [2.0, 2.0])
        self.fail = fail  # callable(params (n, p)) -> bool, called once per evaluate call

    def evaluate(self, contexts, params):
        if self.fail is not None and self.fail(params):
            raise RuntimeError("simulated crash")
        best = np.concatenate([contexts, -contexts], axis=1)
        return -np.sum((params - best) ** 2, axis=1), {}


class PlainEnv(gym.Env):
    """A one-step env that is not a creps_gym model: the runner evaluates it with seeded episodes."""

    observation_space = gym.spaces.Box(0.0, 1.0, (1,), np.float64)
    action_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float64)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.s = self.np_random.uniform(0.0, 1.0, size=1)
        return self.s.copy(), {}

    def step(self, action):
        return self.s.copy(), -float((action[0] - self.s[0]) ** 2), True, False, {}


def test_same_seed_gives_a_bit_identical_history_and_another_seed_does_not():
    a = run("creps-cma-old", SPHERE, 6, 10, 7, **SMALL)
    b = run("creps-cma-old", SPHERE, 6, 10, 7, **SMALL)
    c = run("creps-cma-old", SPHERE, 6, 10, 8, **SMALL)
    assert a.equals(b) and not a.equals(c)


@pytest.mark.parametrize(
    "backend",
    [
        {"backend": "vector"},
        {"backend": "vector", "vector_mode": "sync", "workers": 3},
        {"backend": "vector", "vector_mode": "async", "workers": 2},
    ],
    ids=["native", "sync", "async"],
)
def test_every_vector_backend_matches_serial_bit_for_bit(backend):
    serial = run("creps-cma-old", SPHERE, 4, 10, 1, backend="serial", **SMALL)
    other = run("creps-cma-old", SPHERE, 4, 10, 1, **SMALL, **backend)
    assert other.equals(serial)


@pytest.mark.parametrize("env_id", marked(registered_ids()))
@pytest.mark.slow
def test_every_registered_env_runs_and_a_chunked_vector_backend_matches_serial(env_id):
    space = gym.make(env_id)
    n = minimum_samples("creps-cma-old", space.action_space.shape[0], space.observation_space.shape[0])
    # One iteration: the episodes, an update and an evaluation (later iterations' streams are the subject of
    # test_every_vector_backend_matches_serial_bit_for_bit, on the sphere).
    serial = run("creps-cma-old", env_id, 1, n, 0, eval_contexts=2, backend="serial")
    vector = {"backend": "vector", "workers": 3}  # chunks of 3 + ... + a padded last one
    chunked = run("creps-cma-old", env_id, 1, n, 0, eval_contexts=2, **vector)
    assert chunked.equals(serial) and len(serial) == 1
    assert np.isfinite(serial.column("eval_return")).all()
    knows_optimum = isinstance(contextual_model(gym.make(env_id)), SupportsRegret)
    assert np.isfinite(serial.column("eval_regret")).all() == knows_optimum
    assert serial.meta["metric"] == ("regret" if knows_optimum else "return")


def test_seed_streams_are_independent_and_deterministic():
    rng_a, opt_a, eval_a = split_seed(5)
    rng_b, opt_b, eval_b = split_seed(5)
    assert (opt_a, eval_a) == (opt_b, eval_b) and len({opt_a, eval_a, split_seed(6)[1]}) == 3
    assert np.array_equal(rng_a.integers(0, 2**63 - 1, 4), rng_b.integers(0, 2**63 - 1, 4))


def test_default_initial_distribution_is_the_box_centre_and_a_quarter_width():
    box = gym.spaces.Box(np.array([-1.0, 0.0, -np.inf]), np.array([3.0, 2.0, np.inf]), dtype=np.float64)
    mean, std = default_initial_distribution(box)
    assert np.array_equal(mean, [1.0, 1.0, 0.0]) and np.array_equal(std, [1.0, 0.5, 1.0])


def test_uniform_initial_mean_is_drawn_in_the_box_from_the_seed_without_touching_other_streams():
    def runner(seed, **options):
        return Runner(RunConfig(SPHERE, "creps", 1, 10, seed, env_kwargs={"dim": 4}, **options))

    a, b, c = (runner(seed, initial_mean="uniform") for seed in (3, 3, 4))
    means = [r.optimizer.recommend(np.zeros((1, 1)))[0] for r in (a, b, c)]
    box = a.env.action_space
    assert np.array_equal(means[0], means[1]) and not np.array_equal(means[0], means[2])
    assert np.all((box.low <= means[0]) & (means[0] <= box.high))
    assert not np.allclose(means[0], default_initial_distribution(box)[0])
    default = runner(3)
    assert np.array_equal(a.test_contexts, default.test_contexts)
    assert a.env_rng.integers(2**62) == default.env_rng.integers(2**62)


def test_learning_and_the_record_fields():
    history = run("creps-cma-old", SPHERE, 25, 20, 0, eval_every=5, **SMALL)
    assert [r.iteration for r in history] == list(range(1, 26))
    assert [r.episodes for r in history] == [20 * i for i in range(1, 26)]
    evaluated = np.isfinite(history.column("eval_regret"))
    assert np.array_equal(np.flatnonzero(evaluated) + 1, [5, 10, 15, 20, 25])
    regrets = history.column("eval_regret")[evaluated]
    assert regrets[-1] < 0.1 * regrets[0] and np.all(history.column("eval_return")[evaluated] == -regrets)
    assert history.stop_reason == "iterations" and np.all(np.diff(history.column("wall_time")) >= 0)
    assert history.column("diag.kl").shape == (25,) and history.meta["metric"] == "regret"


def test_envs_that_are_not_contextual_episodic_are_rejected_clearly():
    with pytest.raises(TypeError, match=r"env: expected a Box action_space .* got Discrete\(2\)"):
        run("creps", "CartPole-v1", 2, 4, 0)


def test_env_without_regret_reports_returns_and_rejects_a_regret_target():
    history = run("creps-cma-old", "creps_gym/Plane-v0", 3, 10, 0, **SMALL)
    assert np.isnan(history.column("eval_regret")).all() and np.isfinite(history.column("eval_return")).all()
    assert history.meta["metric"] == "return"
    with pytest.raises(ValueError, match="target_regret: expected None for creps_gym/Plane-v0"):
        run("creps-cma-old", "creps_gym/Plane-v0", 3, 10, 0, target_regret=1e-3, **SMALL)


@pytest.mark.parametrize(
    ("options", "reason"),
    [
        ({"max_episodes": 35}, "max_episodes"),
        ({"target_regret": 5.0}, "target_regret"),
        ({"max_time": 1e-9}, "max_time"),
        ({"optimizer_options": {"min_std": 10.0}}, "optimizer: min_std"),
    ],
)
def test_stop_conditions(options, reason):
    history = run("creps-cma-old", SPHERE, 50, 10, 0, **SMALL, **options)
    assert history.stop_reason == reason and len(history) < 50
    last = history.records[-1]
    assert np.isfinite(last.eval_regret)  # the last iteration is always evaluated
    if reason == "max_episodes":
        assert last.episodes == 30  # a fourth iteration would exceed 35 episodes
    if reason == "target_regret":
        assert last.eval_regret <= 5.0 and np.all(history.column("eval_regret")[:-1] > 5.0)


@EXTRAS
def test_callbacks_see_every_record_and_can_stop_the_run():
    seen = []

    class Recorder(Callback):
        def on_start(self, history, total_iterations):
            seen.append(("start", total_iterations))

        def on_end(self, history):
            seen.append(("end", len(history)))

    def stop_at_three(record, history):
        seen.append(record.iteration)
        return record.iteration == 3

    history = run("cma", SPHERE, 10, 8, 0, callbacks=[Recorder(), stop_at_three], **SMALL)
    assert history.stop_reason == "callback" and seen == [("start", 10), 1, 2, 3, ("end", 3)]
    with pytest.raises(TypeError, match="callbacks: expected Callback instances or callables"):
        run("cma", SPHERE, 2, 8, 0, callbacks=[42], **SMALL)


def test_env_and_optimizer_objects_and_generic_env_evaluation():
    history = run(CREPSCMA(2, 1, seed=0, initial_cov=0.5), Target(), 15, 12, 0)
    assert history.meta["optimizer"] == "CREPSCMA" and history.meta["metric"] == "return"
    # The return is −|θ − θ*(s)|²: learning must cut the mean policy's error by far more than noise could.
    assert history.records[-1].eval_return > 0.1 * history.records[0].eval_return
    with pytest.raises(ValueError, match="optimizer: expected n_params = 2 for Target, got 3"):
        run(CREPSCMA(3, 1, seed=0), Target(), 2, 10, 0)
    plain = run(CREPSCMA(1, 1, seed=0), PlainEnv(), 10, 10, 0)
    assert np.isnan(plain.column("eval_regret")).all()
    assert plain.records[-1].eval_return > 0.1 * plain.records[0].eval_return
    assert plain.equals(run(CREPSCMA(1, 1, seed=0), PlainEnv(), 10, 10, 0))


def _failing_target(**kwargs):
    return Target(fail=lambda params: bool((params[:, 0] > 0.5).any()))


@pytest.mark.parametrize("backend", [{"backend": "serial"}, {"backend": "vector", "vector_mode": "sync"}])
def test_a_failing_episode_stops_the_run_with_an_error_naming_it(backend):
    if "test/FailingTarget-v0" not in gym.registry:
        gym.register("test/FailingTarget-v0", entry_point=_failing_target)
    env = gym.make("test/FailingTarget-v0", disable_env_checker=True)  # a spec, so vector envs can be made
    pattern = (
        r"iteration 1, episode \d+ \(reset seed \d+, context \[.*\]\) "
        r"failed (3|1) time\(s\); last error: RuntimeError: simulated crash"
    )
    with pytest.raises(EpisodeError, match=pattern):
        run(CREPSCMA(2, 1, seed=0), env, 2, 10, 0, **backend)


def test_flaky_episodes_are_retried_and_change_nothing():
    calls = {"n": 0}

    def flaky(params):
        calls["n"] += 1
        return calls["n"] % 7 == 0  # every 7th evaluate call crashes; its retry succeeds

    steady = run(CREPSCMA(2, 1, seed=0), Target(), 5, 10, 0)
    retried = run(CREPSCMA(2, 1, seed=0), Target(fail=flaky), 5, 10, 0, retries=1)
    assert calls["n"] > 50 and retried.equals(steady)
    with pytest.raises(EpisodeError, match="failed 1 time"):
        calls["n"] = 0
        run(CREPSCMA(2, 1, seed=0), Target(fail=lambda p: flaky(p) or calls["n"] > 3), 5, 10, 0, retries=0)


def test_a_non_finite_return_is_an_error_not_a_silent_nan():
    class NaNEnv(Target):
        def evaluate(self, contexts, params):
            returns, info = super().evaluate(contexts, params)
            return np.where(params[:, 0] > 1.0, np.nan, returns), info

    with pytest.raises(EpisodeError, match="expected a finite return, got nan"):
        run(CREPSCMA(2, 1, seed=0, initial_mean=1.5, initial_cov=0.01), NaNEnv(), 2, 10, 0)


def test_a_reset_that_ignores_its_seed_is_reported():
    class Drifting(PlainEnv):
        def reset(self, *, seed=None, options=None):
            obs, info = super().reset(seed=None)
            return obs, info

    with pytest.raises(EpisodeError, match="must be deterministic under reset"):
        run(CREPSCMA(1, 1, seed=0), Drifting(), 2, 10, 0)


def test_history_round_trips_through_json_and_csv_bit_for_bit(tmp_path):
    history = run("creps-cma-current", SPHERE, 5, 10, 2, eval_every=2, **SMALL)
    history.records[0].diagnostics["odd"] = -math.inf
    loaded = History.from_json(history.to_json(tmp_path / "h.json"))
    assert loaded.equals(history, include_time=True) and loaded.meta == history.meta
    assert json.loads((tmp_path / "h.json").read_text())["records"][0]["eval_regret"] is None  # NaN -> null
    from_csv = History.from_csv(history.to_csv(tmp_path / "h.csv"))
    from_csv.stop_reason = history.stop_reason
    assert from_csv.equals(history, include_time=True)
    other = History.from_dict(history.to_dict())
    other.records[2].mean_return = np.nextafter(other.records[2].mean_return, 0)
    assert not other.equals(history)


def test_run_directory_contents(tmp_path):
    out = tmp_path / "run"
    history = run("creps-cma-old", SPHERE, 7, 10, 4, run_dir=out, checkpoint_every=3, **SMALL)
    directory = RunDir.open(out)
    expected = RunConfig(SPHERE, "creps-cma-old", 7, 10, 4, checkpoint_every=3, env_kwargs={"dim": 4})
    assert directory.config() == expected
    versions = json.loads(directory.file(RunDir.VERSIONS).read_text())
    assert {"gymnasium", "numpy", "mujoco", "creps-gym", "python"} <= set(versions)
    records, events = directory.read_log()
    assert History(records).equals(History(history.records), include_time=True)
    assert [e["event"] for e in events] == ["start", "end"]
    state, optimizer_state = directory.load_checkpoint()
    assert state["iteration"] == 7 and state["stop_reason"] == "iterations" and "history" not in state
    assert state["log_crc"] == history_crc(history.records)  # the history itself is in the log
    assert optimizer_state["kind"] == "creps-cma"
    assert History.from_json(directory.file(RunDir.HISTORY_JSON)).equals(history, include_time=True)
    with pytest.raises(FileExistsError, match="holds a run"):
        run("creps-cma-old", SPHERE, 7, 10, 4, run_dir=out, **SMALL)


def test_resume_continues_exactly_with_objects(tmp_path):
    uninterrupted = run(CREPSCMA(2, 1, seed=3), Target(), 9, 10, 1, checkpoint_every=4)

    def crash(record, history):
        if record.iteration == 6:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run(
            CREPSCMA(2, 1, seed=3),
            Target(),
            9,
            10,
            1,
            run_dir=tmp_path,
            checkpoint_every=4,
            callbacks=[crash],
        )
    assert RunDir.open(tmp_path).load_checkpoint()[0]["iteration"] == 4
    (tmp_path / "checkpoint.npz1234.tmp").write_bytes(b"half-written")  # as left by a kill during a write
    resumed = resume(tmp_path, env=Target(), optimizer_class=CREPSCMA)
    assert resumed.equals(uninterrupted)
    assert not list(tmp_path.glob("*.tmp"))
    records, events = RunDir.open(tmp_path).read_log()
    assert History(records, stop_reason="iterations").equals(uninterrupted)
    log = (tmp_path / RunDir.LOG).read_text()
    redone = [log.count(f'{{"iteration": {i},') for i in (4, 5, 6, 7)]
    assert redone == [1, 2, 2, 1]  # 5 and 6 ran again after the resume from checkpoint 4
    assert [e["event"] for e in events] == ["start", "resume", "end"]
    finished = resume(tmp_path, env=Target(), optimizer_class=CREPSCMA)  # a finished run is returned as is
    assert finished.equals(uninterrupted)
    with pytest.raises(ValueError, match="env: expected the env object"):
        resume(tmp_path)


@EXTRAS
def test_progress_bar_shows_the_regret_only_when_asked():
    stream = io.StringIO()
    run("creps-cma-old", SPHERE, 3, 10, 0, callbacks=[ProgressBar(True, stream)], **SMALL)
    text = stream.getvalue()
    assert "3/3" in text and "regret=" in text
    quiet = io.StringIO()
    run("creps-cma-old", SPHERE, 3, 10, 0, callbacks=[ProgressBar(None, quiet)], **SMALL)  # not a terminal
    assert quiet.getvalue() == ""


@EXTRAS
def test_progress_bar_of_an_early_stop_ends_at_100_percent_with_its_reason():
    """Issue 31: a run that met its target after 2 of 40 iterations left its bar at "5%"."""
    stream = io.StringIO()
    history = run(
        "creps-cma-old", SPHERE, 40, 10, 0, callbacks=[ProgressBar(True, stream)], target_regret=1e3, **SMALL
    )
    last = stream.getvalue().split("\r")[-1]
    assert history.stop_reason == "target_regret" and len(history) < 40
    assert "100%" in last and f"{len(history)}/{len(history)}" in last and "stop=target_regret" in last


def test_iohanalyzer_export(tmp_path):
    histories = [run("creps-cma-old", SPHERE, 4, 10, seed, eval_every=2, **SMALL) for seed in (0, 1)]
    path = write_iohanalyzer(histories, tmp_path / "ioh.csv")
    rows = list(csv.DictReader(path.open()))
    assert list(rows[0]) == ["evaluations", "value", "function_id", "algorithm_id", "dimension", "run_id"]
    assert [(r["evaluations"], r["run_id"]) for r in rows] == [
        ("20", "0"),
        ("40", "0"),
        ("20", "1"),
        ("40", "1"),
    ]
    assert float(rows[1]["value"]) == histories[0].records[3].eval_regret
    assert {(r["function_id"], r["algorithm_id"], r["dimension"]) for r in rows} == {
        (SPHERE, "creps-cma-old", "4")
    }
    plane = run("creps", "creps_gym/Plane-v0", 2, 10, 0, **SMALL)  # no regret: the (maximised) return
    rows = list(csv.DictReader(write_iohanalyzer([plane], tmp_path / "plane.csv").open()))
    assert [float(r["value"]) for r in rows] == plane.column("eval_return").tolist()


@pytest.mark.slow
def test_plot_median_and_band_over_seeds_with_a_log_regret_axis(tmp_path):
    pytest.importorskip("matplotlib")
    runs = {
        name: [run(name, SPHERE, 4, 10, s, **SMALL) for s in (0, 1, 2)] for name in ("creps", "creps-cma-old")
    }
    figure = plot_histories(runs, tmp_path / "curves.png", title="test")
    assert (tmp_path / "curves.png").stat().st_size > 0
    left, right = figure.axes
    assert right.get_yscale() == "log" and left.get_yscale() == "symlog"
    line = right.get_lines()[1]
    expected = np.median([h.column("eval_regret") for h in runs["creps-cma-old"]], axis=0)
    assert line.get_label() == "creps-cma-old (n=3; stop: iterations ×3)"
    assert np.allclose(line.get_ydata(), expected)
    assert len(right.collections) == 2  # one band per group
    with pytest.raises(ValueError, match="band"):
        plot_histories(runs, band=(0.9, 0.1))


BACKEND_ERROR = r"backend: expected one of \['auto', 'serial', 'vector', 'ray'\], got 'gpu'"


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        ({"samples": 1}, ValueError, "samples: expected an integer >= 2, got 1"),
        ({"backend": "gpu"}, ValueError, BACKEND_ERROR),
        ({"max_episodes": 5}, ValueError, "max_episodes: expected at least one iteration's samples"),
        ({"initial_std": [1.0, -1.0]}, ValueError, "initial_std: expected a number or a list of positive"),
        ({"initial_std": 1e-320}, ValueError, "initial_std: .* with a finite variance > 0, got 1e-320"),
        ({"initial_std": 1e308}, ValueError, "initial_std: .* with a finite variance > 0, got 1e[+]308"),
        ({"initial_mean": np.zeros((2, 2))}, ValueError, r"initial_mean: expected .* 1-D list .* \(2, 2\)"),
        (
            {"initial_mean": "centre"},
            ValueError,
            "initial_mean: expected a number or a list of finite numbers",
        ),
        ({"target_regret": math.nan}, ValueError, "target_regret: expected a positive finite number"),
        ({"seed": -1}, ValueError, "seed: expected an integer >= 0"),
    ],
)
def test_bad_configuration_is_named(kwargs, error, match):
    base = {"env": SPHERE, "optimizer": "creps", "iterations": 2, "samples": 10, "seed": 0}
    with pytest.raises(error, match=match):
        RunConfig(**{**base, **kwargs})
    with pytest.raises(ValueError, match="config: expected keys"):
        RunConfig.from_dict({**base, "sample": 3})


def test_record_round_trip_and_column_errors():
    record = IterationRecord(1, 10, -1.5, diagnostics={"a": 1.0})
    assert IterationRecord.from_dict(record.to_dict()).equals(record, include_time=True)
    with pytest.raises(ValueError, match="name: expected one of"):
        History([record]).column("nope")


@pytest.mark.slow
def test_the_runner_guide_examples_run_and_print_what_their_comment_says(tmp_path, monkeypatch, capsys):
    pytest.importorskip("matplotlib")
    guide = Path(__file__).resolve().parents[2] / "docs" / "runner.md"
    blocks = python_blocks(guide)
    monkeypatch.chdir(tmp_path)
    namespace: dict = {"__name__": "runner_guide"}
    for block in blocks:
        exec(compile(block, str(guide), "exec"), namespace)
    assert namespace["history"].stop_reason == "target_regret"
    quoted = re.search(r"print\(history\.stop_reason, .*\)  # (\S+ \d+ [0-9.]+)\.\.\.\n", "\n".join(blocks))
    assert quoted is not None and capsys.readouterr().out.startswith(quoted.group(1))
    assert (tmp_path / "comparison.png").exists() and (
        tmp_path / "runs" / "api-demo" / "history.json"
    ).exists()


def test_wrapped_action_spaces_are_evaluated_through_episodes_not_the_raw_model():
    """Regression: under NormalizeParams the raw model would read normalised parameters as physical ones."""
    import gymnasium as gym

    from creps_gym.wrappers import NormalizeParams

    env = NormalizeParams(gym.make(SPHERE, dim=3))
    history = run(CREPSCMA(3, 1, seed=0), env, 3, 10, 0)
    assert history.meta["metric"] == "return"


def test_numpy_initial_distributions_are_accepted_as_numbers():
    base = {"env": SPHERE, "optimizer": "creps", "iterations": 2, "samples": 10, "seed": 0}
    config = RunConfig(**base, initial_mean=np.arange(3.0), initial_std=np.float32(0.5))
    assert config.initial_mean == [0.0, 1.0, 2.0] and config.initial_std == 0.5
    assert RunConfig.from_dict(json.loads(json.dumps(config.to_dict()))) == config


def test_an_env_declared_std_whose_variance_overflows_is_named():
    import gymnasium as gym

    class Huge(gym.Wrapper):
        def initial_distribution(self):
            return np.zeros(3), np.full(3, 1e200)

    with pytest.raises(ValueError, match="initial_std: expected standard deviations with finite variances"):
        run("creps", Huge(gym.make(SPHERE, dim=3)), 2, 10, 0)


def test_a_module_prefixed_id_runs_as_gymnasium_make_takes_it():
    """``"module:Env-v0"`` works with the auto (native vector) and serial backends."""
    for backend in ("auto", "serial"):
        history = run("creps", "creps_gym:" + SPHERE, 2, 10, 0, env_kwargs={"dim": 3}, backend=backend)
        plain = run("creps", SPHERE, 2, 10, 0, env_kwargs={"dim": 3}, backend=backend)
        assert history.column("eval_regret").tolist() == plain.column("eval_regret").tolist()


def test_a_start_no_batch_size_can_learn_from_names_the_initial_distribution():
    """check_batch_size blames ``samples`` only if a batch four times as large is learnt from."""
    from creps_gym.runner.protocol import check_batch_size

    class Refusing:
        def __init__(self, smallest):
            self.smallest = smallest

        def ask(self, contexts):
            return np.zeros((contexts.shape[0], 2))

        def tell(self, contexts, params, returns):
            if contexts.shape[0] < self.smallest:
                raise ValueError("Eigenvalues did not converge")

    contexts = np.zeros((5, 1))
    check_batch_size(lambda: Refusing(5), contexts, {}, "'x'")  # accepted: no error
    with pytest.raises(ValueError, match=r"samples: expected a batch size that 'x' can learn from, got 5"):
        check_batch_size(lambda: Refusing(12), contexts, {}, "'x'")
    with pytest.raises(ValueError, match="initial_mean, initial_std: expected a start 'x' can learn from"):
        check_batch_size(lambda: Refusing(10**9), contexts, {}, "'x'")


def test_more_workers_than_samples_are_capped_at_the_samples():
    runner = Runner(RunConfig(SPHERE, "creps", 2, 12, 0, backend="vector", workers=10**11))
    backend = runner.make_backend()
    try:
        assert backend.num_envs == 12
    finally:
        backend.close()


class _Misbehaving(CREPSCMA):
    """CREPS-CMA whose ``ask`` or ``stop`` output breaks the protocol as ``fault`` says."""

    fault = ""

    def ask(self, contexts):
        params = super().ask(contexts)
        return params + 0j if self.fault == "complex ask" else params

    def recommend(self, contexts):
        params = super().recommend(contexts)
        return params.astype(np.complex128) if self.fault == "complex recommend" else params

    def stop(self):
        return {"str": "bye", "list": ["tolx"], "name": {"$\\frac{$": 1}, "key": {1: 1}}.get(self.fault, {})


@pytest.mark.parametrize(
    ("fault", "error", "message"),
    [
        (
            "complex ask",
            TypeError,
            r"optimizer\.ask\(\) output: expected an array of real numbers, got a complex",
        ),
        ("str", TypeError, r"optimizer\.stop\(\): expected a dict of the met stop criteria .* got str 'bye'"),
        ("list", TypeError, r"optimizer\.stop\(\): expected a dict .* got list"),
        ("name", ValueError, r"optimizer\.stop\(\): expected criterion names of letters"),
        ("key", TypeError, r"optimizer\.stop\(\): expected str criterion names, got int 1"),
    ],
)
def test_optimizer_output_that_breaks_the_protocol_is_refused_not_converted(fault, error, message):
    optimizer = _Misbehaving(4, 1, seed=0)
    optimizer.fault = fault
    with pytest.raises(error, match=message):
        run(optimizer, SPHERE, 2, 10, 0, env_kwargs={"dim": 4}, eval_every=1)


def test_complex_recommendations_are_refused_in_episodes_of_a_plain_env():
    optimizer = _Misbehaving(1, 1, seed=0)
    optimizer.fault = "complex recommend"
    message = r"TypeError: optimizer\.recommend\(\) output: expected an array of real numbers, got a complex"
    with pytest.raises(EpisodeError, match=message):
        run(optimizer, PlainEnv(), 2, 10, 0, eval_every=1)


def test_finite_mean_never_overflows_and_keeps_the_bits_of_ordinary_means():
    from creps_gym.envs.evaluation import finite_mean

    values = np.full(14, -1.4283e308)
    with np.errstate(over="ignore"):
        assert np.isinf(values.mean())  # what the runner recorded before
    assert finite_mean(values) == pytest.approx(-1.4283e308, rel=1e-12)
    ordinary = np.random.default_rng(0).normal(size=101) * 1e3
    assert finite_mean(ordinary) == float(ordinary.mean())  # bit for bit
    assert finite_mean([1.0, -np.inf]) == -np.inf and math.isnan(finite_mean([np.nan, 1.0]))


def test_returns_near_the_float_limit_give_finite_summaries_history_and_export(tmp_path):
    """Before: every return was finite, but the mean overflowed to -inf in history.json and the export."""
    history = run(
        "creps",
        SPHERE,
        2,
        14,
        0,
        env_kwargs={"dim": 3},
        initial_mean=6.9e153,
        initial_std=1e140,
        run_dir=tmp_path,
    )
    for column in ("mean_return", "eval_return", "eval_regret"):
        values = history.column(column)
        assert np.isfinite(values).all() and np.abs(values).max() > 1e308, column
    for name in ("history.json", "history.csv", "iohanalyzer.csv"):
        assert "inf" not in (tmp_path / name).read_text().lower(), name
