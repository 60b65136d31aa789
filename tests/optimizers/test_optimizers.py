"""CREPS and CREPS-CMA: convergence, the paper's qualitative claims, determinism, checkpoints, bad input."""

from __future__ import annotations

import numpy as np
import pytest

from creps_gym.optimizers import (
    CREPS,
    CREPSCMA,
    RBFFeatures,
    interpolation_factor,
    make_optimizer,
    optimizer_names,
    regularised_covariance,
)
from creps_gym.optimizers.creps import spd_factor, weighted_ml_fit, weighted_sample_covariance
from creps_gym.optimizers.registry import optimizer_class


def _native(name: str):
    def build(n_params, n_context_dims, seed=None, initial_mean=0.0, initial_cov=1.0, **options):
        return make_optimizer(name, n_params, n_context_dims, seed, initial_mean, initial_cov, **options)

    return build


#: Every registered optimiser of this package (the adapters have their own tests), by registry name.
OPTIMIZERS = {
    name: _native(name) for name in optimizer_names() if ".adapters." not in optimizer_class(name).__module__
}


class ContextualSphere:
    """The paper's construction x = θ + A·s on the sphere; θ*(s) = −A·s and the regret is |x|²."""

    def __init__(self, dim: int, context_dim: int, seed: int = 0) -> None:
        self.matrix = np.random.default_rng(seed).uniform(-1, 1, (dim, context_dim))
        self.dim, self.context_dim = dim, context_dim

    def contexts(self, rng: np.random.Generator, n: int) -> np.ndarray:
        return rng.uniform(0, 3, (n, self.context_dim))

    def regret(self, contexts: np.ndarray, params: np.ndarray) -> np.ndarray:
        return ((params + contexts @ self.matrix.T) ** 2).sum(axis=1)


def learn(name: str, problem: ContextualSphere, iterations: int, samples: int, seed: int = 0) -> float:
    rng = np.random.default_rng(seed + 100)
    optimizer = OPTIMIZERS[name](
        n_params=problem.dim, n_context_dims=problem.context_dim, initial_mean=3.0, initial_cov=4.0, seed=seed
    )
    for _ in range(iterations):
        contexts = problem.contexts(rng, samples)
        params = optimizer.ask(contexts)
        optimizer.tell(contexts, params, -problem.regret(contexts, params))
    test = problem.contexts(np.random.default_rng(7), 50)
    return float(problem.regret(test, optimizer.recommend(test)).mean())


@pytest.mark.slow
def test_creps_cma_old_solves_a_contextual_sphere_and_creps_stalls():
    problem = ContextualSphere(dim=6, context_dim=2)
    assert learn("creps-cma-old", problem, iterations=350, samples=40) < 1e-5
    assert learn("creps", problem, iterations=350, samples=40) > 1e-2  # premature convergence (paper, Fig. 1)


@pytest.mark.slow
def test_current_mean_variant_also_converges_on_the_sphere():
    assert (
        learn("creps-cma-current", ContextualSphere(dim=6, context_dim=2), iterations=350, samples=40) < 1e-5
    )


#: A smaller budget, (iterations, samples), for optimisers whose every ask optimises an acquisition per row
#: (a GP): the contract does not depend on the budget, and the model is in use from the second batch on
#: (2 (5 + 1) = 12 initial episodes).
BUDGETS = {"c-bo": (4, 8)}


@pytest.mark.parametrize("name", sorted(OPTIMIZERS))
@pytest.mark.slow
def test_same_seed_gives_bit_identical_runs(name):
    problem = ContextualSphere(dim=5, context_dim=1)
    iterations, samples = BUDGETS.get(name, (30, 20))
    first = learn(name, problem, iterations, samples, seed=3)
    assert first == learn(name, problem, iterations, samples, seed=3)
    assert first != learn(name, problem, iterations, samples, seed=4)


# The checkpoint round trip of every optimiser: tests/optimizers/test_contract_checkpoint.py.


def test_checkpoint_keeps_rbf_features_and_variant(tmp_path):
    features = RBFFeatures.grid([0.0], [3.0], per_dim=4)
    optimizer = CREPSCMA(3, 1, variant="current", mean_features=features, seed=1)
    optimizer.save(tmp_path / "rbf.npz")
    restored = CREPSCMA.load(tmp_path / "rbf.npz")
    assert restored.config.variant == "current"
    np.testing.assert_array_equal(restored.config.mean_map.centres, features.centres)
    with pytest.raises(ValueError, match="expected a 'creps' checkpoint, got 'creps-cma'"):
        CREPS.load(tmp_path / "rbf.npz")


def test_interpolation_factor_and_regularised_covariance_follow_eq_13_14():
    weights = np.full(50, 1 / 50)
    assert interpolation_factor(weights, 15) == pytest.approx(50 / 225)
    assert interpolation_factor(weights, 5) == 1.0  # min(1, φ_eff/n²)
    old, sample = np.eye(2), np.diag([4.0, 0.0])
    np.testing.assert_allclose(regularised_covariance(old, sample, 0.25), np.diag([1.75, 0.75]))


def test_max_interpolation_caps_lambda_only_where_eq_14_exceeds_it():
    weights = np.full(50, 1 / 50)
    assert interpolation_factor(weights, 5, maximum=0.2) == 0.2
    assert interpolation_factor(weights, 16, maximum=0.2) == pytest.approx(50 / 256)  # below the cap
    rng = np.random.default_rng(0)
    contexts, params = rng.uniform(0, 3, (50, 1)), rng.normal(size=(50, 4))
    returns = -(params**2).sum(axis=1)
    lambdas = []
    for cap in (1.0, 0.2):
        optimizer = CREPSCMA(4, 1, max_interpolation=cap, seed=0)
        optimizer.tell(contexts, params, returns, allow_external=True)
        lambdas.append(optimizer.diagnostics["interpolation"])
    assert lambdas == [1.0, 0.2]  # φ_eff ≥ 16 = n², so Eq. (14) alone gives λ = 1


@pytest.mark.parametrize("bad", [0.0, -0.1, 1.5, float("nan"), float("inf")])
def test_max_interpolation_outside_the_unit_interval_is_rejected(bad):
    with pytest.raises(ValueError, match=r"max_interpolation: expected a finite value in \(0.0, 1.0\]"):
        CREPSCMA(4, 1, max_interpolation=bad)
    with pytest.raises(TypeError, match="max_interpolation: expected a real number"):
        CREPSCMA(4, 1, max_interpolation="0.2")


@pytest.mark.parametrize("variant", ["old", "current"])
def test_sample_covariance_is_centred_on_the_old_or_the_new_mean(variant):
    """Equal returns give exactly uniform weights; then Eqs. (12)-(16) can be checked by hand."""
    rng = np.random.default_rng(0)
    n_params, n = 25, 400
    initial_mean = rng.normal(size=n_params)
    optimizer = CREPSCMA(n_params, 1, variant=variant, initial_mean=initial_mean, initial_cov=0.5, seed=0)
    contexts = rng.uniform(0, 1, (n, 1))
    params = optimizer.ask(contexts)
    old_cov = optimizer.cov.copy()
    optimizer.tell(contexts, params, np.full(n, 3.0))
    if variant == "old":
        centre = initial_mean
    else:
        phi = np.column_stack([np.ones(n), contexts])
        centre = phi @ np.linalg.lstsq(phi, params, rcond=None)[0]
    deviations = params - centre
    expected_s = deviations.T @ deviations / n / (1 - 1 / n)  # Z = 1 - Σ d² with d = 1/N
    lam = n / n_params**2  # φ_eff = N for uniform weights
    assert optimizer.diagnostics["interpolation"] == pytest.approx(lam, rel=1e-12)
    np.testing.assert_allclose(optimizer.cov, (1 - lam) * old_cov + lam * expected_s, rtol=1e-7, atol=1e-12)


def test_weighted_ml_fit_recovers_a_linear_mean_and_covariance_helper_is_unbiased():
    rng = np.random.default_rng(1)
    contexts = rng.uniform(0, 3, (200, 2))
    phi = np.column_stack([np.ones(200), contexts])
    truth = rng.normal(size=(3, 4))
    params = phi @ truth
    weights = rng.uniform(0.5, 1.5, 200)
    weights /= weights.sum()
    np.testing.assert_allclose(weighted_ml_fit(phi, params, weights, ridge=1e-12), truth, atol=1e-8)
    noise = rng.normal(size=(200, 4))
    uniform = np.full(200, 1 / 200)
    np.testing.assert_allclose(
        weighted_sample_covariance(noise, np.zeros((200, 4)), uniform), noise.T @ noise / 199
    )


@pytest.mark.parametrize("constant_column", [None, 0])
def test_weighted_ml_fit_is_scipys_positive_definite_solve_bit_for_bit(constant_column):
    """The fit calls LAPACK ``posv`` directly; twin: the same normal equations through ``scipy.linalg.solve``,
    over shapes the optimisers use (a 1 × 1 system is a division, as in the scipy the committed studies ran
    on, 1.17; older ones factorise it), and a singular Gram matrix still raises ``LinAlgError``."""
    from scipy import linalg

    from creps_gym.optimizers import mean_fit

    def twin(gram, rhs):
        return rhs / gram if gram.size == 1 else linalg.solve(gram, rhs, assume_a="pos", check_finite=False)

    rng = np.random.default_rng(3)
    systems = []
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(mean_fit, "_solve_pos", lambda a, b: systems.append((a, b)) or np.zeros(b.shape))
        for n, k, p in [(8, 2, 1), (24, 3, 6), (40, 4, 3), (100, 6, 20), (10, 2, 5)]:
            phi = np.column_stack([np.ones(n), rng.uniform(-2, 2, (n, k - 1))])
            params, weights = rng.standard_normal((n, p)), rng.uniform(0, 1, n)
            mean_fit.weighted_ml_fit(phi, params, weights / weights.sum(), 1e-8, constant_column)
    assert len(systems) == 5
    grams, rights = rng.uniform(0.1, 10, (200, 1, 1)), rng.standard_normal((200, 1, 3))
    for gram, rhs in [*systems, *zip(grams, rights, strict=True)]:
        direct = mean_fit._solve_pos(gram, rhs)
        assert np.array_equal(direct, twin(gram, rhs))
        assert direct.strides == (8 * direct.shape[1], 8)  # later products' bits depend on the strides
    assert mean_fit._solve_pos(np.eye(2), np.ones((2, 0))).shape == (2, 0)
    assert mean_fit._solve_pos(np.zeros((0, 0)), np.ones((0, 3))).shape == (0, 3)
    with pytest.raises(np.linalg.LinAlgError, match="gram: expected a positive definite matrix"):
        mean_fit._solve_pos(np.zeros((2, 2)), np.ones((2, 1)))


def test_spd_factor_repairs_a_singular_covariance():
    singular = np.outer([1.0, 2.0, 3.0], [1.0, 2.0, 3.0])
    cov, chol, repaired = spd_factor(singular)
    assert repaired
    np.testing.assert_allclose(chol @ chol.T, cov)
    assert np.linalg.eigvalsh(cov).min() > 0


def test_covariance_stays_spd_through_a_long_run_with_few_samples():
    """p > N makes every CREPS sample covariance singular; the documented repair keeps Σ SPD."""
    problem = ContextualSphere(dim=12, context_dim=1)
    rng = np.random.default_rng(0)
    optimizer = CREPS(12, 1, initial_mean=2.0, seed=0)
    for _ in range(60):
        contexts = problem.contexts(rng, 8)
        params = optimizer.ask(contexts)
        optimizer.tell(contexts, params, -problem.regret(contexts, params))
        np.linalg.cholesky(optimizer.cov)
    assert optimizer.diagnostics["cov_repaired"] == 1.0


def test_diagnostics_report_the_documented_quantities():
    problem = ContextualSphere(dim=4, context_dim=1)
    optimizer = CREPSCMA(4, 1, seed=0)
    contexts = problem.contexts(np.random.default_rng(0), 30)
    params = optimizer.ask(contexts)
    returns = -problem.regret(contexts, params)
    optimizer.tell(contexts, params, returns)
    d = optimizer.diagnostics
    assert d["kl"] == pytest.approx(0.5, abs=1e-8)
    assert 1 <= d["ess"] <= 30
    assert d["interpolation"] == pytest.approx(min(1, d["ess"] / 16))
    assert d["mean_return"] == pytest.approx(returns.mean())
    assert d["logdet_cov"] == pytest.approx(np.linalg.slogdet(optimizer.cov)[1])
    assert d["cond_cov"] == pytest.approx(np.linalg.cond(optimizer.cov))
    assert d["eta"] > 0 and d["external_samples"] == 0


def test_stop_reports_a_collapsed_distribution():
    optimizer = CREPSCMA(3, 1, initial_cov=1e-30, min_std=1e-12, seed=0)
    assert optimizer.stop() == {}
    contexts = np.linspace(0, 1, 10)[:, None]
    params = optimizer.ask(contexts)
    optimizer.tell(contexts, params, -np.abs(params).sum(1))
    assert "min_std" in optimizer.stop()


# -- protocol misuse and bad input ---------------------------------------------------------------------------
def fresh(**kw):
    return CREPSCMA(3, 2, **{"seed": 0, **kw})


def test_tell_without_ask_and_twice_raise_runtime_error():
    optimizer = fresh()
    contexts = np.random.default_rng(0).uniform(size=(8, 2))
    with pytest.raises(RuntimeError, match="without a pending ask"):
        optimizer.tell(contexts, np.zeros((8, 3)), np.zeros(8))
    params = optimizer.ask(contexts)
    optimizer.tell(contexts, params, np.arange(8.0))
    with pytest.raises(RuntimeError, match="without a pending ask"):
        optimizer.tell(contexts, params, np.arange(8.0))


def test_rows_that_were_not_asked_are_rejected_unless_external_is_allowed():
    optimizer = fresh()
    contexts = np.random.default_rng(0).uniform(size=(8, 2))
    params = optimizer.ask(contexts)
    forged = params.copy()
    forged[2, 0] += 1e-9
    with pytest.raises(RuntimeError, match=r"row 2 .* was not returned by the last ask"):
        optimizer.tell(contexts, forged, np.arange(8.0))
    rows = [0, 1, 2, 3, 4, 5, 0]
    with pytest.raises(RuntimeError, match="row 6 repeats asked sample 0"):
        optimizer.tell(contexts[rows], params[rows], np.arange(7.0))
    optimizer.tell(contexts, forged, np.arange(8.0), allow_external=True)
    assert optimizer.diagnostics["external_samples"] == 1.0


def test_a_subset_of_the_asked_rows_in_any_order_may_be_told():
    optimizer = fresh()
    contexts = np.random.default_rng(0).uniform(size=(10, 2))
    params = optimizer.ask(contexts)
    order = [4, 0, 3, 9, 7, 1]
    optimizer.tell(contexts[order], params[order], np.arange(6.0))
    assert optimizer.evaluations == 6


def snapshot(optimizer):
    return {k: (v.copy() if isinstance(v, np.ndarray) else v) for k, v in optimizer.state_dict().items()}


def assert_unchanged(before, optimizer):
    after = optimizer.state_dict()
    assert before.keys() == after.keys()
    for key, value in before.items():
        if isinstance(value, np.ndarray):
            np.testing.assert_array_equal(value, after[key])
        else:
            assert value == after[key], key


#: Bad tells of a batch of 4 to ``fresh()`` (p = 3, z = 2): the entries that differ from a valid tell.
BAD_TELLS = [
    ({"contexts": np.zeros((4, 3))}, ValueError, r"contexts: expected shape \(n, 2\), got \(4, 3\)"),
    ({"params": np.zeros((4, 2))}, ValueError, r"params: expected shape \(4, 3\), got \(4, 2\)"),
    ({"returns": np.zeros(3)}, ValueError, r"returns: expected shape \(4,\), got \(3,\)"),
    ({"returns": [0, 1, np.nan, 2]}, ValueError, "returns: expected finite values, got nan"),
    ({"params": np.full((4, 3), np.inf)}, ValueError, "params: expected finite values"),
    (
        {"contexts": np.zeros((1, 2)), "params": np.zeros((1, 3)), "returns": np.zeros(1)},
        ValueError,
        "at least 2 samples per tell, got 1",
    ),
    ({"returns": "bad"}, TypeError, "returns: expected an array of real numbers, got str"),
]


@pytest.mark.parametrize(("bad", "error", "match"), BAD_TELLS)
def test_bad_tell_input_raises_and_leaves_the_optimizer_unchanged(bad, error, match):
    optimizer = fresh()
    optimizer.ask(np.zeros((4, 2)))
    before = snapshot(optimizer)
    tell = {"contexts": np.zeros((4, 2)), "params": np.zeros((4, 3)), "returns": np.zeros(4), **bad}
    with pytest.raises(error, match=match):
        optimizer.tell(**tell)
    assert_unchanged(before, optimizer)


def test_epsilon_must_stay_below_log_n_at_tell_time():
    optimizer = fresh(epsilon=2.0)
    contexts = np.random.default_rng(0).uniform(size=(7, 2))
    params = optimizer.ask(contexts)
    before = snapshot(optimizer)
    with pytest.raises(
        ValueError, match=r"epsilon: expected < log\(N\) = 1.9459 for a batch of N=7 samples, got 2.0"
    ):
        optimizer.tell(contexts, params, np.arange(7.0))
    assert_unchanged(before, optimizer)


def test_batches_the_baseline_interpolates_are_rejected():
    """With N <= k + 1 the baseline [s, s²] explains any returns: no information, so a clear error."""
    optimizer = fresh()  # z = 2, so k = 4 baseline features
    contexts = np.random.default_rng(0).uniform(size=(5, 2))
    params = optimizer.ask(contexts)
    before = snapshot(optimizer)
    with pytest.raises(ValueError, match=r"returns: expected more than k \+ 1 = 5 samples.*got N = 5"):
        optimizer.tell(contexts, params, np.arange(5.0))
    assert_unchanged(before, optimizer)


def test_ask_rejects_bad_contexts():
    optimizer = fresh()
    with pytest.raises(ValueError, match=r"contexts: expected shape \(n, 2\), got \(2,\)"):
        optimizer.ask(np.zeros(2))
    with pytest.raises(ValueError, match="contexts: expected finite values"):
        optimizer.ask([[0.0, np.nan]])
    with pytest.raises(ValueError, match="at least one row"):
        optimizer.ask(np.zeros((0, 2)))


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        (
            {"initial_cov": np.eye(2)},
            ValueError,
            r"initial_cov: expected a scalar, shape \(3,\) or \(3, 3\), got \(2, 2\)",
        ),
        ({"initial_cov": -1.0}, ValueError, "initial_cov: expected variances > 0, got min -1.0"),
        (
            {"initial_mean": np.zeros(4)},
            ValueError,
            r"initial_mean: expected a scalar, shape \(3,\) or \(3, 3\)",
        ),
        ({"epsilon": 0.0}, ValueError, r"epsilon: expected a finite value in \(0.0, 50.0\], got 0.0"),
        ({"variant": "newest"}, ValueError, "variant: expected one of .*'old', 'current'.*got 'newest'"),
        ({"seed": 1.5}, TypeError, "seed: expected an int >= 0 or None, got float"),
        ({"mean_features": "cubic"}, ValueError, "mean_features: expected one of .*got 'cubic'"),
        ({"ridge": -1.0}, ValueError, r"ridge: expected a finite value in \[0.0, 1.0\], got -1.0"),
    ],
)
def test_config_validation(kwargs, error, match):
    with pytest.raises(error, match=match):
        fresh(**kwargs)


def test_non_spd_initial_covariance_is_rejected():
    with pytest.raises(ValueError, match="initial_cov: expected a symmetric positive-definite matrix"):
        CREPS(2, 1, initial_cov=np.array([[1.0, 2.0], [2.0, 1.0]]))
    with pytest.raises(ValueError, match="initial_cov: expected a symmetric matrix"):
        CREPS(2, 1, initial_cov=np.array([[1.0, 0.5], [0.0, 1.0]]))


def test_initial_mean_accepts_full_coefficients_and_rbf_constant_mean():
    coefficients = np.arange(6.0).reshape(2, 3)
    optimizer = CREPS(3, 1, initial_mean=coefficients)
    np.testing.assert_array_equal(optimizer.recommend([[2.0]]), [[0.0 + 2 * 3, 1 + 2 * 4, 2 + 2 * 5]])
    rbf = CREPS(3, 1, initial_mean=[1.0, 2.0, 3.0], mean_features=RBFFeatures.grid([0], [3], 5))
    np.testing.assert_allclose(rbf.recommend([[0.3], [2.9]]), [[1, 2, 3], [1, 2, 3]])


def test_non_contextual_problems_use_zero_context_dimensions():
    """z = 0 turns CREPS-CMA into episodic REPS with a regularised covariance (a plain optimiser)."""
    optimizer = CREPSCMA(4, 0, initial_mean=3.0, seed=0)
    for _ in range(300):
        contexts = np.zeros((20, 0))
        params = optimizer.ask(contexts)
        optimizer.tell(contexts, params, -(params**2).sum(axis=1))
    assert np.abs(optimizer.recommend(np.zeros((1, 0)))).max() < 1e-8


@pytest.mark.parametrize(
    "make_contexts",
    [
        lambda rng, n: np.full((n, 2), 1.3),  # a constant context
        lambda rng, n: np.column_stack([rng.uniform(0, 3, n), np.full(n, 1.3)]),  # one dimension fixed
        lambda rng, n: 1e5 + rng.uniform(0, 3, (n, 2)),  # a far-offset context box
        lambda rng, n: rng.uniform(0, 3e7, (n, 2)),  # a huge context scale
    ],
    ids=["constant", "one-fixed-dimension", "offset-1e5", "scale-3e7"],
)
def test_learning_does_not_depend_on_where_or_how_large_the_context_box_is(make_contexts):
    """Regression: constant or offset contexts once gave uniform weights (no learning) and a biased ridge."""
    rng = np.random.default_rng(0)
    optimizer = CREPSCMA(4, 2, initial_mean=3.0, initial_cov=1.0, seed=0)
    for _ in range(200):
        contexts = make_contexts(rng, 20)
        params = optimizer.ask(contexts)
        optimizer.tell(contexts, params, -(params**2).sum(axis=1))
        assert optimizer.diagnostics["kl"] == pytest.approx(0.5, abs=1e-8)
    test = make_contexts(np.random.default_rng(1), 10)
    assert np.abs(optimizer.recommend(test)).max() < 1e-6


def test_ridge_fit_is_invariant_to_offsetting_the_contexts():
    rng = np.random.default_rng(3)
    contexts = rng.uniform(0, 3, (30, 2))
    params = rng.normal(size=(30, 4))
    weights = rng.uniform(0.5, 1.5, 30)
    weights /= weights.sum()
    for offset in (0.0, 30.0, 1e3, 1e5):
        phi = np.column_stack([np.ones(30), contexts + offset])
        coefficients = weighted_ml_fit(phi, params, weights, ridge=1e-8, constant_column=0)
        np.testing.assert_allclose(
            phi @ coefficients, phi @ weighted_ml_fit(phi, params, weights, 0.0, 0), rtol=1e-6
        )
    reference = np.column_stack([np.ones(30), contexts])
    shifted = np.column_stack([np.ones(30), contexts + 1e5])
    np.testing.assert_allclose(
        shifted @ weighted_ml_fit(shifted, params, weights, 1e-8, 0),
        reference @ weighted_ml_fit(reference, params, weights, 1e-8, 0),
        rtol=1e-6,
        atol=1e-9,
    )


def test_identical_asked_rows_can_all_be_told():
    """A collapsed distribution (σ below one ulp) asks identical rows; each may be told once."""
    optimizer = CREPSCMA(3, 0, initial_mean=1.0, initial_cov=1e-40, seed=0)
    contexts = np.zeros((10, 0))
    params = optimizer.ask(contexts)
    assert len({row.tobytes() for row in params}) == 1
    optimizer.tell(contexts, params, np.arange(10.0))
    params = optimizer.ask(contexts)
    with pytest.raises(RuntimeError, match="row 10 repeats asked sample 0"):
        optimizer.tell(np.zeros((11, 0)), np.vstack([params, params[:1]]), np.arange(11.0))


def test_state_dict_is_a_snapshot_not_a_view():
    optimizer = fresh()
    contexts = np.random.default_rng(0).uniform(size=(8, 2))
    params = optimizer.ask(contexts)
    optimizer.tell(contexts, params, np.arange(8.0))
    state = optimizer.state_dict()
    state["cov"][0, 0] = 99.0
    state["coefficients"][:] = 0.0
    assert optimizer.cov[0, 0] != 99.0 and optimizer.coefficients.any()
    keys = set(state["diagnostics"])
    assert "cond_cov" in optimizer.diagnostics  # computes the lazy entries
    assert set(state["diagnostics"]) == keys


def test_numpy_scalars_in_the_config_still_save(tmp_path):
    optimizer = CREPSCMA(np.int64(3), np.int64(1), epsilon=np.float32(0.5), seed=np.int64(3))
    optimizer.save(tmp_path / "numpy.npz")
    assert CREPSCMA.load(tmp_path / "numpy.npz").config.seed == 3


def test_eta_diagnostic_is_the_temperature_in_return_units():
    """Plugging the reported η into the raw dual (w fitted at that η) gives back KL = ε."""
    from scipy.optimize import minimize

    rng = np.random.default_rng(0)
    optimizer = CREPSCMA(4, 1, initial_mean=2.0, seed=0)
    for _ in range(30):
        contexts = rng.uniform(0, 3, (40, 1))
        params = optimizer.ask(contexts)
        returns = -((params - contexts) ** 2).sum(axis=1) * 1e3
        optimizer.tell(contexts, params, returns)
    eta = optimizer.diagnostics["eta"]
    phi = np.column_stack([contexts, contexts**2])
    phi = phi - phi.mean(axis=0)

    def objective(w):
        scaled = (returns - phi @ w) / eta
        return eta * (np.log(np.mean(np.exp(scaled - scaled.max()))) + scaled.max())

    w = minimize(objective, np.zeros(2), method="BFGS", options={"gtol": 1e-12}).x
    scaled = (returns - phi @ w) / eta
    weights = np.exp(scaled - scaled.max())
    weights /= weights.sum()
    # The η reported before a fix (scaled by std R instead of the residual's spread) gave 0.41 here.
    assert np.log(40) + weights @ np.log(weights) == pytest.approx(0.5, abs=1e-3)


@pytest.mark.slow
def test_eq_14_collapses_on_a_small_rosenbrock_and_the_cap_prevents_it():
    """With 50 samples and p = 4, Eq. (14) gives λ = 1 (no regularisation): CREPS-CMA-old's covariance
    collapses before the target, as in ``benchmarks/scaling``. Capping λ at 0.2 reaches it."""
    from creps_gym.runner import run

    def final(cap: float) -> tuple[str | None, float]:
        history = run(
            "creps-cma-old",
            "creps_gym/Rosenbrock-v0",
            iterations=400,
            samples_per_iteration=50,
            seed=0,
            env_kwargs={"dim": 4, "context_dim": 1, "instance": 0},
            optimizer_options={"max_interpolation": cap},
            target_regret=1e-5,
            backend="vector",
        )
        return history.stop_reason, float(history.column("eval_regret")[-1])

    reason, regret = final(1.0)  # the stall is caught by stagnation before the condition number explodes
    assert reason in ("optimizer: tolstagnation", "optimizer: max_condition") and regret > 0.1
    reason, regret = final(0.2)
    assert reason == "target_regret" and regret <= 1e-5


def test_max_std_growth_stops_a_diverging_search():
    """Returns that ignore θ (pure noise) do not steer Σ: with λ = 1 its eigenvalues take a multiplicative
    random walk (and the old-mean S divided by Z = 1 − Σd² grows by 1/Z in expectation), so the search
    spreads out; ``max_std_growth`` stops it, like pycma's tolupsigma."""
    rng = np.random.default_rng(0)
    optimizer = CREPSCMA(4, 1, initial_cov=1.0, max_std_growth=3.0, seed=0)
    met: dict = {}
    iterations = 0
    while not met and iterations < 500:
        contexts = rng.uniform(0, 3, (50, 1))
        optimizer.tell(contexts, optimizer.ask(contexts), rng.normal(size=50))
        iterations += 1
        met = optimizer.stop()
    assert set(met) == {"max_std_growth"} and met["max_std_growth"] > 3.0 and 10 < iterations < 500
    with pytest.raises(ValueError, match=r"max_std_growth: expected a finite value in \(1.0, 1e\+300\]"):
        CREPSCMA(4, 1, max_std_growth=0.5)


@pytest.mark.slow
def test_old_mean_sample_covariance_is_unbiased_without_z_under_random_selection():
    """Weights that ignore θ: around the true (old) mean, E[Σ d_k ε_k ε_kᵀ] = Σ, so dividing by Z biases S
    up by 1/Z; around a mean fitted to the same samples, Z is what removes the bias (Eqs. 12 and 15)."""
    rng = np.random.default_rng(0)
    cov = np.array([[2.0, 0.5, 0.0], [0.5, 1.0, 0.2], [0.0, 0.2, 0.5]])
    weights = rng.dirichlet(np.ones(50))  # fixed, independent of the samples
    z = 1.0 - weights @ weights
    batches = rng.multivariate_normal(np.zeros(3), cov, size=(20_000, 50))  # around the true mean 0
    plain = np.mean([weighted_sample_covariance(b, np.zeros(3), weights, False) for b in batches], axis=0)
    with_z = np.mean([weighted_sample_covariance(b, np.zeros(3), weights) for b in batches], axis=0)
    np.testing.assert_allclose(plain, cov, atol=0.02)
    np.testing.assert_allclose(with_z, cov / z, atol=0.02)
    assert np.all(np.diag(with_z) - np.diag(cov) > 0.5 * (1 / z - 1) * np.diag(cov))  # the bias is resolved
    fitted = np.mean(  # the weighted mean of each batch as the centre: now Z corrects
        [weighted_sample_covariance(b, weights @ b, weights) for b in batches[:5000]], axis=0
    )
    np.testing.assert_allclose(fitted, cov, atol=0.04)


def test_divide_by_z_reaches_the_covariance_update():
    rng = np.random.default_rng(3)
    contexts = rng.uniform(0, 3, (60, 1))
    covs = []
    for divide in (True, False):
        optimizer = CREPSCMA(25, 1, initial_mean=1.0, initial_cov=0.5, divide_by_z=divide, seed=0)
        optimizer.tell(contexts, optimizer.ask(contexts), np.full(60, 1.0))  # uniform weights: Z = 1 − 1/60
        covs.append(optimizer.cov)
    lam = 60 / 25**2
    np.testing.assert_allclose(
        (covs[0] - (1 - lam) * 0.5 * np.eye(25)) * (1 - 1 / 60),
        covs[1] - (1 - lam) * 0.5 * np.eye(25),
        atol=1e-12,
    )
    with pytest.raises(TypeError, match="divide_by_z: expected a bool, got int 0"):
        CREPSCMA(4, 1, divide_by_z=0)


@pytest.mark.parametrize("function", ["Sphere", "Rosenbrock", "ShiftedRotatedElliptic"])
def test_the_documented_effective_sample_size_and_interpolation_of_eq_14(function):
    """docs/algorithms.md: with ε = 0.5, N = 50 and n = 15, φ_eff is about 20–26 and λ = φ_eff/n² about
    0.09–0.12 (medians over the first 40 iterations; every iteration within 19–27)."""
    from creps_gym.runner import run

    history = run("creps-cma-old", f"creps_gym/{function}-v0", 40, 50, 0, eval_every=40)
    ess = np.array([record.diagnostics["ess"] for record in history.records])
    interpolation = np.median([record.diagnostics["interpolation"] for record in history.records])
    assert 20.0 <= np.median(ess) <= 26.0 and ((ess > 19.0) & (ess < 27.0)).all(), ess
    assert 0.09 <= interpolation <= 0.12
