"""The runner keeps the best evaluated policy (across restarts and resumes), load_policy reads it from a run
folder, and `creps-gym policy` / `creps-gym evaluate` use it."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys

import gymnasium as gym
import numpy as np
import pytest
from helpers import SPHERE, cli_in_process

import creps_gym
from creps_gym.optimizers import Policy
from creps_gym.runner import History, RunDir, resume, run
from creps_gym.runner.rundir.policies import evaluate_on_env
from creps_gym.runner.seeds import split_seed

# c-cma-es restarts at iteration 24 with these options (its stagnation criterion after 5 iterations), and
# its evaluations get worse after that (``keep_best=False``: its recommendation restarts with the search): the
# best policy is iteration 22's, the final one much worse. ``budget=None``: the restart is made although the
# 6 iterations left could not carry a search as far as the first one went (Eq. C12's rule would decline it).
RESTARTING = {
    "env_kwargs": {"dim": 3},
    "optimizer_options": {"tolstagnation": 5, "restarts": 3, "keep_best": False, "budget": None},
}


def _run(path, **options):
    return run("c-cma-es", SPHERE, 30, None, 0, run_dir=path, checkpoint_every=4, **RESTARTING, **options)


def _run_value(policy: Policy, seed: int = 0) -> tuple[float, float]:
    """The policy's evaluation on the test contexts of a run with master seed ``seed``."""
    return evaluate_on_env(policy, gym.make(SPHERE, dim=3), 16, split_seed(seed)[2])


def test_the_best_policy_survives_a_restart_and_reproduces_its_evaluation(tmp_path):
    history = _run(tmp_path / "run")
    assert history.column("diag.restarts")[-1] >= 1
    best_iteration = history.best_iteration
    record = history.records[best_iteration - 1]
    assert record.eval_return == np.nanmax(history.column("eval_return")) > history.records[-1].eval_return
    best, final = (creps_gym.load_policy(tmp_path / "run", which) for which in ("best", "final"))
    assert best.source["iteration"] == best_iteration and final.source["iteration"] == 30
    assert _run_value(best) == (record.eval_return, record.eval_regret)  # bit for bit
    assert _run_value(final) == (history.records[-1].eval_return, history.records[-1].eval_regret)
    assert best.env == SPHERE and best.env_kwargs == {"dim": 3} and best.context_box is not None
    document = json.loads((tmp_path / "run" / RunDir.HISTORY_JSON).read_text())
    assert document["best_iteration"] == best_iteration
    assert History.from_json(tmp_path / "run" / RunDir.HISTORY_JSON).equals(history)


def test_the_final_policy_is_the_recommendation_after_a_restart_that_kept_the_best(tmp_path):
    """Issue 42, item 1: with ``keep_best`` (the default) a restarted c-cma-es recommends the best search's
    policy, and the run's evaluation measures that; ``policy.npz`` held the restarted search's mean instead
    (evaluated −0.58 where the run recorded −2e−6 on these options)."""
    restart = {"tolx": 1e-3, "budget": None}  # restart even where the budget left could not repay it (C12)
    options = {"env_kwargs": {"dim": 2}, "optimizer_options": restart, "eval_every": 5}
    history = run("c-cma-es", SPHERE, 85, None, 0, run_dir=tmp_path / "run", **options)
    assert history.column("diag.restarts")[-1] >= 1  # the search restarted; the kept best is in force
    last = history.records[-1]
    final = creps_gym.load_policy(tmp_path / "run", "final")
    assert final.source["iteration"] == 85
    value = evaluate_on_env(final, gym.make(SPHERE, dim=2), 16, split_seed(0)[2])
    assert value == (last.eval_return, last.eval_regret)  # bit for bit
    assert last.eval_regret < 1e-4


@pytest.mark.parametrize("name", ["c-cma-es", "c-bo"])
@pytest.mark.slow
def test_a_policy_files_evaluation_is_its_own(name, tmp_path):
    """What the runner evaluates is the policy it keeps, also where that policy distils ``recommend``
    (c-bo): ``creps-gym evaluate RUN --run-contexts`` reproduces the recorded ``eval_return``."""
    options = {"env_kwargs": {"dim": 2}, "eval_every": 2}
    history = run(name, SPHERE, 4, None, 0, run_dir=tmp_path / "run", **options)
    for which in ("best", "final"):
        policy = creps_gym.load_policy(tmp_path / "run", which)
        record = history.records[policy.source["iteration"] - 1]
        value = evaluate_on_env(policy, gym.make(SPHERE, dim=2), 16, split_seed(0)[2])
        assert value == (record.eval_return, record.eval_regret), which


class _Crash(Exception):
    pass


def _crash_at(iteration: int):
    def callback(record, history):
        if record.iteration == iteration:
            raise _Crash

    return callback


@pytest.mark.slow
def test_the_best_policy_is_bit_identical_after_a_resume(tmp_path):
    _run(tmp_path / "whole")
    with pytest.raises(_Crash):  # killed after iteration 26's record: the checkpoint is iteration 24's
        _run(tmp_path / "cut", callbacks=[_crash_at(26)])
    assert RunDir.open(tmp_path / "cut").load_checkpoint()[0]["best_policy"]["source"]["iteration"] == 22
    (tmp_path / "cut" / RunDir.BEST_POLICY).unlink()  # the checkpoint holds the best policy
    resume(tmp_path / "cut")
    for name in (RunDir.BEST_POLICY, RunDir.POLICY):
        assert (tmp_path / "cut" / name).read_bytes() == (tmp_path / "whole" / name).read_bytes()


def test_a_finished_run_rewrites_a_missing_or_damaged_policy_file(tmp_path):
    _run(tmp_path / "run")
    expected = (tmp_path / "run" / RunDir.BEST_POLICY).read_bytes()
    (tmp_path / "run" / RunDir.BEST_POLICY).write_bytes(b"damaged")
    (tmp_path / "run" / RunDir.POLICY).unlink()
    resume(tmp_path / "run")
    assert (tmp_path / "run" / RunDir.BEST_POLICY).read_bytes() == expected
    assert creps_gym.load_policy(tmp_path / "run", "final").source["iteration"] == 30


def test_load_policy_of_an_old_or_unfinished_run_folder(tmp_path):
    _run(tmp_path / "run")
    final = creps_gym.load_policy(tmp_path / "run", "final")
    for name in (RunDir.BEST_POLICY, RunDir.POLICY):  # a folder written before policy files existed
        (tmp_path / "run" / name).unlink()
    from_checkpoint = creps_gym.load_policy(tmp_path / "run", "final")
    contexts = np.linspace(0, 3, 7)[:, None]
    assert from_checkpoint(contexts).tobytes() == final(contexts).tobytes()
    with pytest.raises(FileNotFoundError, match=r"best_policy\.npz"):
        creps_gym.load_policy(tmp_path / "run", "best")
    with pytest.raises(ValueError, match="which"):
        creps_gym.load_policy(tmp_path / "run", "last")


def test_a_damaged_or_linked_policy_file_in_a_run_folder_is_a_run_dir_error(tmp_path):
    _run(tmp_path / "run")
    best = tmp_path / "run" / RunDir.BEST_POLICY
    best.write_bytes(b"PK\x03\x04 not a zip")
    with pytest.raises(creps_gym.errors.RunDirError, match=r"best_policy\.npz"):
        creps_gym.load_policy(tmp_path / "run")
    best.unlink()
    best.symlink_to(tmp_path / "run" / RunDir.POLICY)
    with pytest.raises(creps_gym.errors.RunDirError, match="symbolic link"):
        creps_gym.load_policy(tmp_path / "run")


def test_overwrite_deletes_the_policy_files_of_the_old_run(tmp_path):
    _run(tmp_path / "run")
    with pytest.raises(_Crash):  # the new run writes nothing before its first checkpoint
        run("creps", SPHERE, 9, 12, 0, run_dir=tmp_path / "run", overwrite=True, callbacks=[_crash_at(1)])
    assert not (tmp_path / "run" / RunDir.BEST_POLICY).exists()
    assert not (tmp_path / "run" / RunDir.POLICY).exists()


# -- the command line ------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def cli_run(tmp_path_factory):
    path = tmp_path_factory.mktemp("cli") / "run"
    _run(path)
    return path


_cli = cli_in_process  # the commands' behaviour, in this process


def test_policy_prints_the_parameters_for_each_context(cli_run, tmp_path):
    result = _cli("policy", cli_run, "--context", "1.5", "--context", "0", "--save", tmp_path / "p.npz")
    assert result.returncode == 0, result.stderr
    out = json.loads(result.stdout)
    best = creps_gym.load_policy(cli_run)
    assert np.array(out["params"]).tobytes() == best([[1.5], [0.0]]).tobytes()
    assert out["source"]["iteration"] == best.source["iteration"] and out["which"] == "best"
    assert Policy.load(tmp_path / "p.npz").equals(best)
    final = json.loads(_cli("policy", cli_run, "--which", "final").stdout)
    assert (
        np.array(final["coefficients"]).tobytes()
        == creps_gym.load_policy(cli_run, "final").coefficients.tobytes()
    )


@pytest.mark.parametrize(
    ("args", "code", "message"),
    [
        (["--context", "1", "2"], 2, "expected 1 numbers"),
        (["--context", "3.5"], 2, "context box"),
        (["--context", "nan"], 2, "finite"),
        (["--context", "x"], 2, "invalid float"),
        (["--which", "last"], 2, "invalid choice"),
    ],
)
def test_policy_refuses_bad_contexts_with_exit_2(cli_run, args, code, message):
    result = _cli("policy", cli_run, *args)
    assert result.returncode == code and message in result.stderr and "Traceback" not in result.stderr


def test_policy_and_evaluate_exit_3_for_a_missing_or_damaged_run(tmp_path, cli_run):
    damaged = tmp_path / "run"
    shutil.copytree(cli_run, damaged)
    (damaged / RunDir.BEST_POLICY).write_bytes(b"junk")
    (tmp_path / "junk.npz").write_bytes(b"junk")
    for command in ("policy", "evaluate"):
        for target in (tmp_path / "missing", damaged, tmp_path / "junk.npz"):
            result = _cli(command, target)
            assert result.returncode == 3, (command, target, result.stderr)
            assert result.stderr.count("\n") == 1 and "Traceback" not in result.stderr


def test_evaluate_reproduces_the_run_on_its_own_contexts_and_uses_fresh_ones_by_default(cli_run):
    history = History.from_json(cli_run / RunDir.HISTORY_JSON)
    record = history.records[history.best_iteration - 1]
    own = json.loads(_cli("evaluate", cli_run, "--run-contexts").stdout)
    assert (own["mean_return"], own["mean_regret"], own["contexts"]) == (
        record.eval_return,
        record.eval_regret,
        16,
    )
    fresh = json.loads(_cli("evaluate", cli_run, "--contexts", "50", "--seed", "7").stdout)
    expected = evaluate_on_env(creps_gym.load_policy(cli_run), gym.make(SPHERE, dim=3), 50, 7)
    assert (fresh["mean_return"], fresh["mean_regret"]) == expected and fresh["contexts"] == 50
    assert fresh["mean_return"] != own["mean_return"]


def test_evaluate_a_policy_file_refuses_a_module_it_names(tmp_path, cli_run):
    policy = creps_gym.load_policy(cli_run)
    odd = Policy(policy.features, policy.coefficients, env="no_such_module_x:Env-v0", source=policy.source)
    odd.save(tmp_path / "p.npz")
    result = _cli("evaluate", tmp_path / "p.npz")
    assert result.returncode == 3 and "never makes creps-gym import" in result.stderr
    assert _cli("evaluate", tmp_path / "p.npz", "--run-contexts").returncode in (2, 3)


def test_evaluate_video_of_an_env_that_does_not_render_is_a_usage_error(cli_run, tmp_path):
    result = _cli("evaluate", cli_run, "--video", tmp_path / "v.gif")
    assert result.returncode == 2 and "renders" in result.stderr


@pytest.fixture(scope="module")
def reacher_run(tmp_path_factory):
    path = tmp_path_factory.mktemp("reacher") / "run"
    run("creps", "creps_gym/PlanarReacher-v0", 2, 30, 0, run_dir=path, eval_contexts=2)
    return path


@pytest.mark.slow
def test_evaluate_video_without_the_extra_exits_4(reacher_run, tmp_path):
    code = (
        "import sys\nsys.modules['imageio'] = None\nfrom creps_gym.cli import main\n"
        f"sys.exit(main(['evaluate', {str(reacher_run)!r}, '--contexts', '2', '--video', 'v.gif']))"
    )
    result = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=180, cwd=tmp_path
    )
    assert result.returncode == 4 and "creps-gym[video]" in result.stderr
    assert not (tmp_path / "v.gif").exists()


def test_the_policy_files_temporaries_are_the_runs_own():
    assert RunDir.TEMPORARY.match(f".{RunDir.BEST_POLICY}.123.tmp")
    assert RunDir.TEMPORARY.match(f".{RunDir.POLICY}.123.tmp")


class _NoPolicy:
    """An optimiser object without mean_policy(): the run keeps no policy file."""

    def __init__(self):
        from creps_gym.optimizers import CREPS

        self.inner = CREPS(3, 1, seed=0)
        self.n_params, self.n_context_dims = 3, 1

    def ask(self, contexts):
        return self.inner.ask(contexts)

    def tell(self, contexts, params, returns):
        self.inner.tell(contexts, params, returns)

    def recommend(self, contexts):
        return self.inner.recommend(contexts)

    def stop(self):
        return {}

    def state_dict(self):
        return self.inner.state_dict()

    @property
    def diagnostics(self):
        return self.inner.diagnostics


def test_an_optimizer_without_mean_policy_runs_without_policy_files(tmp_path):
    history = run(_NoPolicy(), SPHERE, 3, 12, 0, run_dir=tmp_path / "run", env_kwargs={"dim": 3})
    assert history.best_iteration is not None
    assert not (tmp_path / "run" / RunDir.BEST_POLICY).exists()
    assert not (tmp_path / "run" / RunDir.POLICY).exists()
