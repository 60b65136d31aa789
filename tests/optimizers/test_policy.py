"""The Policy object and its file: every optimiser gives one equal to recommend(), files round-trip bit for
bit, hostile files are refused, and loading needs neither MuJoCo nor Ray."""

from __future__ import annotations

import dataclasses
import io
import json
import os
import subprocess
import sys
import zipfile

import numpy as np
import pytest
from helpers import marked

from creps_gym.optimizers import CCMAES, Policy, RBFFeatures
from creps_gym.optimizers.policy_io import JSON_ENTRY, MAX_POLICY_BYTES
from creps_gym.optimizers.registry import make_optimizer, optimizer_class, optimizer_names


def _trained(name: str, p: int = 4, z: int = 2, iterations: int = 3):
    optimizer = make_optimizer(name, p, z, 0, initial_mean=0.5)
    rng = np.random.default_rng(1)
    for _ in range(iterations):
        contexts = rng.uniform(-1, 1, (20, z))
        params = optimizer.ask(contexts)
        optimizer.tell(contexts, params, -((params - contexts.sum(1, keepdims=True)) ** 2).sum(1))
    return optimizer


@pytest.mark.parametrize("name", marked(optimizer_names()))
@pytest.mark.slow
def test_every_optimizer_gives_a_policy_equal_to_recommend(name, tmp_path):
    """Or, for an optimiser whose policy distils ``recommend`` (``distilled_policy``, c-bo: a GP's
    maximisers), equal to the least-squares fit of ``recommend`` on its distillation grid."""
    optimizer = _trained(name)
    policy = optimizer.mean_policy()
    contexts = np.random.default_rng(2).uniform(-1, 1, (9, 2))
    expected = optimizer.recommend(contexts)
    single = optimizer.recommend(contexts[3:4])[0]  # (BLAS may round a batch of one differently)
    if getattr(optimizer, "distilled_policy", False):
        grid = optimizer.distillation_contexts()
        features = policy.features(grid)
        fitted = np.linalg.lstsq(features, optimizer.recommend(grid), rcond=None)[0]
        assert policy.coefficients.tobytes() == fitted.tobytes()
        expected, single = policy(contexts), policy(contexts[3:4])[0]  # for the file round trips below
    assert policy(contexts).tobytes() == expected.tobytes()
    assert policy(contexts[3]).tobytes() == single.tobytes()  # one context (z,) -> (p,)
    loaded = Policy.load(policy.save(tmp_path / "policy.npz"))
    assert loaded.equals(policy) and loaded(contexts).tobytes() == expected.tobytes()
    again = Policy.from_dict(json.loads(json.dumps(policy.to_dict())))
    assert again.equals(policy)
    if getattr(optimizer, "close", None):
        optimizer.close()


@pytest.mark.parametrize("name", marked(["cma", "nevergrad", "optuna"]))
def test_adapters_give_a_constant_policy(name):
    policy = _trained(name).mean_policy()
    rows = policy(np.array([[-1.0, 0.0], [0.3, 0.9]]))
    assert rows[0].tobytes() == rows[1].tobytes() and policy.coefficients.shape == (1, 4)


def test_the_mean_policy_is_a_copy_that_the_optimizer_does_not_change():
    optimizer = _trained("c-cma-es")
    policy = optimizer.mean_policy()
    before = policy.coefficients.copy()
    contexts = np.zeros((24, 2))
    optimizer.tell(contexts, optimizer.ask(contexts), np.arange(24.0))
    assert np.array_equal(policy.coefficients, before) and not policy.coefficients.flags.writeable


def test_rbf_features_boxes_and_source_round_trip(tmp_path):
    features = RBFFeatures.grid([0.0, -1.0], [1.0, 1.0], 3)
    coefficients = np.random.default_rng(0).normal(size=(9, 3))
    box = ([0.0, -1.0], [1.0, 1.0])
    policy = Policy(
        features,
        coefficients,
        context_box=box,
        param_box=([-np.inf] * 3, [np.inf] * 3),
        env="creps_gym/Sphere-v0",
        env_kwargs={"dim": 3, "nested": {"a": [1, 2]}},
        source={"iteration": 7, "eval_return": -0.5, "which": "best"},
    )
    loaded = Policy.load(policy.save(tmp_path / "p.npz"))
    assert loaded.equals(policy) and loaded.env_kwargs == {"dim": 3, "nested": {"a": [1, 2]}}
    assert np.isinf(loaded.param_box[0]).all() and loaded.source["iteration"] == 7
    assert Policy.from_dict(json.loads(json.dumps(policy.to_dict()))).equals(policy)


@pytest.mark.parametrize(
    ("contexts", "match"),
    [
        ([[0.5, 2.0]], "context box"),
        ([[np.nan, 0.0]], "finite"),
        ([0.5], r"expected shape \(n, 2\)"),
        ([[0.5, 0.5, 0.5]], r"expected shape \(n, 2\)"),
        (np.zeros((0, 2)), "n >= 1"),
    ],
)
def test_contexts_are_checked_like_the_env_checks_them(contexts, match):
    policy = Policy("affine", np.ones((3, 2)), context_dim=2, context_box=([0, 0], [1, 1]))
    with pytest.raises(ValueError, match=match):
        policy(contexts)
    assert policy([[0.5, 2.0]], extrapolate=True).shape == (1, 2)


def test_a_policy_without_a_box_refuses_contexts_beyond_the_optimizers_range():
    policy = Policy("quadratic", np.full((3, 1), 1e200), context_dim=1)
    with pytest.raises(ValueError, match=r"\|s\| <= 1e\+100"):
        policy([[1e101]])
    with pytest.raises(ValueError, match="non-finite"):
        policy([[1e99]])  # 1e200 s² overflows


def _npz(entries: dict[str, np.ndarray]) -> bytes:
    buffer = io.BytesIO()
    np.savez(buffer, **entries)
    return buffer.getvalue()


def _good_entries() -> dict[str, np.ndarray]:
    document = Policy("affine", np.ones((2, 3)), context_dim=1).to_dict(arrays=False)
    return {
        "coefficients": np.ones((2, 3)),
        JSON_ENTRY: np.frombuffer(json.dumps(document).encode(), np.uint8),
    }


def _with_document(**changes) -> dict[str, np.ndarray]:
    entries = _good_entries()
    document = json.loads(entries[JSON_ENTRY].tobytes())
    document.update(changes)
    entries[JSON_ENTRY] = np.frombuffer(json.dumps(document).encode(), np.uint8)
    return entries


HOSTILE = {
    "not a zip": b"hello",
    "empty": b"",
    "unknown entry": _npz({**_good_entries(), "extra": np.ones(2)}),
    "no document": _npz({"coefficients": np.ones((2, 3))}),
    "object array": _npz({**_good_entries(), "coefficients": np.array([[1, None]], dtype=object)}),
    "int coefficients": _npz({**_good_entries(), "coefficients": np.ones((2, 3), dtype=np.int64)}),
    "wrong shape": _npz({**_good_entries(), "coefficients": np.ones((5, 3))}),
    "nan coefficients": _npz({**_good_entries(), "coefficients": np.full((2, 3), np.nan)}),
    "3-d coefficients": _npz({**_good_entries(), "coefficients": np.ones((2, 3, 1))}),
    "not JSON": _npz({**_good_entries(), JSON_ENTRY: np.frombuffer(b"{nope", np.uint8)}),
    "NaN in JSON": _npz({**_good_entries(), JSON_ENTRY: np.frombuffer(b'{"a": NaN}', np.uint8)}),
    "JSON list": _npz({**_good_entries(), JSON_ENTRY: np.frombuffer(b"[1]", np.uint8)}),
    "other format": _npz(_with_document(format="creps_gym.policy/99")),
    "unknown key": _npz(_with_document(extra=1)),
    "unknown features": _npz(_with_document(features={"name": "os.system", "context_dim": 1})),
    "huge degree": _npz(_with_document(features={"name": "polynomial", "context_dim": 1, "degree": 10**9})),
    "bad source": _npz(_with_document(source={"x": {"nested": 1}})),
    "bad env": _npz(_with_document(env=3)),
    "bad n_params": _npz(_with_document(n_params=4)),
    "huge context_dim": _npz(_with_document(context_dim=10**9)),
    "deep JSON": _npz(
        {**_good_entries(), JSON_ENTRY: np.frombuffer(b"[" * 100000 + b"]" * 100000, np.uint8)}
    ),
}


@pytest.mark.parametrize("name", sorted(HOSTILE))
def test_hostile_policy_files_are_refused_with_a_value_error(tmp_path, name):
    path = tmp_path / "p.npz"
    path.write_bytes(HOSTILE[name])
    with pytest.raises(ValueError, match="policy file"):
        Policy.load(path)


@pytest.mark.parametrize(
    ("centres", "path"),
    [
        ([[0.0]] * 5 + [[10**30]], r"features\['centres'\]\[5\]\[0\]"),
        ([[0.0, 1.0], [2.0, -(10**30)]], r"features\['centres'\]\[1\]\[1\]"),
        ([[0.5]] * 3 + [10**30], r"features\['centres'\]\[3\]"),
    ],
)
def test_a_huge_int_anywhere_in_a_spec_is_refused_naming_its_place(centres, path):
    """Lists of floats, or of rows of floats, are checked in one pass; any other list is walked, so an int
    among floats is still found and named."""
    z = len(centres[0])
    spec = {"name": "rbf", "context_dim": z, "centres": centres, "bandwidth": 1.0}
    with pytest.raises(ValueError, match=path + ": expected an int of at most 1000 in magnitude"):
        Policy(spec, np.zeros((len(centres), 1)), context_dim=z)
    rows = {"name": "rbf", "context_dim": 2, "centres": [[0.0, 1.0]] * 4, "bandwidth": 1.0}
    assert Policy(rows, np.zeros((4, 1)), context_dim=2).features.n_features == 4


def test_a_header_that_claims_a_huge_array_is_refused_before_allocating(tmp_path):
    good = _npz(_good_entries())
    with zipfile.ZipFile(io.BytesIO(good)) as archive:
        raw = archive.read("coefficients.npy")
    forged = raw.replace(b"(2, 3)", b"(10000000000, 3)", 1)
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w") as archive:
        archive.writestr("coefficients.npy", forged)
        archive.writestr(f"{JSON_ENTRY}.npy", zipfile.ZipFile(io.BytesIO(good)).read(f"{JSON_ENTRY}.npy"))
    (tmp_path / "p.npz").write_bytes(buffer.getvalue())
    with pytest.raises(ValueError, match="bytes of data"):
        Policy.load(tmp_path / "p.npz")


def test_a_compressed_entry_that_inflates_beyond_the_limit_is_refused(tmp_path):
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", compression=zipfile.ZIP_DEFLATED) as archive:
        archive.writestr(f"{JSON_ENTRY}.npy", b"\0" * (9 * 2**20))  # over MAX_JSON_BYTES once inflated
    (tmp_path / "p.npz").write_bytes(buffer.getvalue())
    with pytest.raises(ValueError, match="expected an uncompressed array"):  # policy files are stored
        Policy.load(tmp_path / "p.npz")


def test_links_fifos_and_oversized_files_are_refused(tmp_path):
    target = Policy("affine", np.ones((2, 1)), context_dim=1).save(tmp_path / "real.npz")
    (tmp_path / "link.npz").symlink_to(target)
    with pytest.raises(ValueError, match="symbolic link"):
        Policy.load(tmp_path / "link.npz")
    os.mkfifo(tmp_path / "fifo.npz")
    with pytest.raises(ValueError, match="not a regular file"):
        Policy.load(tmp_path / "fifo.npz")  # never blocks waiting for a writer
    with open(tmp_path / "big.npz", "wb") as stream:
        stream.truncate(MAX_POLICY_BYTES + 1)
    with pytest.raises(ValueError, match="at most"):
        Policy.load(tmp_path / "big.npz")
    with pytest.raises(FileNotFoundError):
        Policy.load(tmp_path / "missing.npz")


@pytest.mark.slow
def test_a_policy_file_loads_without_mujoco_ray_or_gymnasium_envs(tmp_path):
    path = _trained("creps").mean_policy().save(tmp_path / "p.npz")
    code = (
        "import sys\n"
        "for name in ('mujoco', 'ray', 'gymnasium_robotics'):\n"
        "    sys.modules[name] = None\n"
        "import creps_gym\n"
        f"policy = creps_gym.Policy.load({str(path)!r})\n"
        "print(policy([[0.1, 0.2]]).shape)\n"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "(1, 4)"


def test_an_optimizer_loads_from_a_run_checkpoint(tmp_path):
    from creps_gym.runner import run

    run("c-cma-es", "creps_gym/Sphere-v0", 3, None, 0, run_dir=tmp_path / "run", env_kwargs={"dim": 3})
    optimizer = CCMAES.load(tmp_path / "run" / "checkpoint.npz")
    assert optimizer.iteration == 3
    state = {"kind": None}
    with pytest.raises(ValueError, match="load_policy"):
        CCMAES.from_state_dict({k: v for k, v in state.items() if k != "kind"})


@pytest.mark.slow
def test_creps_gym_exposes_policy_and_load_policy_lazily():
    code = "import sys, creps_gym; assert 'creps_gym.runner' not in sys.modules; creps_gym.load_policy"
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    import creps_gym

    assert creps_gym.Policy is Policy and callable(creps_gym.load_policy)
    with pytest.raises(AttributeError):
        creps_gym.no_such_name  # noqa: B018


def _kept_best(name: str):
    """A C-CMA-ES-family optimiser whose search converged, then restarted: its recommendation is the kept
    best (C10), not the restarted search's initial mean. None for optimisers without ``keep_best``."""
    config_class = getattr(optimizer_class(name), "config_class", None)
    if config_class is None or "keep_best" not in {field.name for field in dataclasses.fields(config_class)}:
        return None
    optimizer = make_optimizer(name, 2, 1, 0, initial_mean=3.0, tolx=1e-6)
    rng = np.random.default_rng(0)
    while optimizer.restarts_done == 0:
        contexts = rng.uniform(0.0, 1.0, (16, 1))
        params = optimizer.ask(contexts)
        optimizer.tell(contexts, params, -((params - contexts) ** 2).sum(axis=1))
        assert optimizer.iteration < 600, "no restart"
    return optimizer


def _same_policy(optimizer, contexts) -> None:
    policy = optimizer.mean_policy()
    if getattr(optimizer, "distilled_policy", False):  # a fit of recommend (checked above), and the runner
        assert policy.equals(optimizer.mean_policy())  # evaluates it: the same policy at each call
        return
    assert policy(contexts).tobytes() == optimizer.recommend(contexts).tobytes()
    if hasattr(optimizer, "recommended_coefficients"):  # the adapters' constant policy has one row
        assert policy.coefficients.tobytes() == optimizer.recommended_coefficients().tobytes()


@pytest.mark.parametrize("name", marked(optimizer_names()))
@pytest.mark.slow
def test_the_mean_policy_is_recommend_after_a_restart_a_resume_and_a_kept_best(name, tmp_path):
    """Issue 42, item 1: ``mean_policy()`` (what ``policy.npz`` holds) ignored C-CMA-ES's kept best while
    ``recommend`` applied it, so the "final" policy of a restarted run was the restarted search's."""
    contexts = np.random.default_rng(2).uniform(-1, 1, (9, 2))
    optimizer = _trained(name, iterations=4)
    _same_policy(optimizer, contexts)
    optimizer.restart()  # a forced restart (the runner's divergence rule); False and no change without one
    _same_policy(optimizer, contexts)
    restored = type(optimizer).load(optimizer.save(tmp_path / "resumed.npz"))
    _same_policy(restored, contexts)
    assert restored.recommend(contexts).tobytes() == optimizer.recommend(contexts).tobytes()
    assert restored.mean_policy().coefficients.tobytes() == optimizer.mean_policy().coefficients.tobytes()
    kept = _kept_best(name)
    if kept is not None:
        tests = np.linspace(0.0, 1.0, 5)[:, None]
        assert kept.recommended_coefficients() is kept.best_coefficients  # the kept best is in force
        assert not np.array_equal(kept.best_coefficients, kept.coefficients)
        _same_policy(kept, tests)
        assert ((kept.mean_policy()(tests) - tests) ** 2).sum(axis=1).max() < 1e-2  # the converged one
        _same_policy(type(kept).load(kept.save(tmp_path / "kept.npz")), tests)
    for each in (optimizer, restored):
        if getattr(each, "close", None):
            each.close()
