"""Feature maps: values, shapes, specs and errors."""

from __future__ import annotations

import json
import math
import time

import numpy as np
import pytest

from creps_gym.optimizers import (
    AffineFeatures,
    BaselineFeatures,
    FeatureMap,
    QuadraticFeatures,
    RBFFeatures,
    make_features,
    register_feature_map,
)

CONTEXTS = np.array([[1.0, 2.0], [-0.5, 3.0]])


def test_affine_quadratic_and_baseline_values():
    np.testing.assert_array_equal(AffineFeatures(2)(CONTEXTS), [[1, 1, 2], [1, -0.5, 3]])
    np.testing.assert_array_equal(QuadraticFeatures(2)(CONTEXTS), [[1, 1, 2, 1, 4], [1, -0.5, 3, 0.25, 9]])
    np.testing.assert_array_equal(BaselineFeatures(2)(CONTEXTS), [[1, 2, 1, 4], [-0.5, 3, 0.25, 9]])


def test_rbf_features_are_normalised_and_peak_at_their_centre():
    rbf = RBFFeatures.grid([0.0, 0.0], [3.0, 3.0], per_dim=3)
    assert rbf.n_features == 9
    values = rbf(np.array([[1.5, 1.5], [100.0, -100.0]]))  # far away: still finite and normalised
    np.testing.assert_allclose(values.sum(axis=1), 1.0)
    assert np.argmax(values[0]) == 4  # the grid's centre point (1.5, 1.5)
    expected = np.exp(-((rbf.centres - 1.5) ** 2).sum(1) / (2 * 1.5**2))
    np.testing.assert_allclose(values[0], expected / expected.sum())


@pytest.mark.parametrize(
    "feature_map", [AffineFeatures(2), QuadraticFeatures(2), RBFFeatures.grid([0, 0], [1, 1], 2)]
)
def test_spec_round_trips_through_json(feature_map):
    rebuilt = make_features(json.loads(json.dumps(feature_map.spec())), 2)
    np.testing.assert_array_equal(rebuilt(CONTEXTS), feature_map(CONTEXTS))


def test_constant_coefficients_give_a_constant_mean():
    for feature_map in (AffineFeatures(2), QuadraticFeatures(2), RBFFeatures.grid([0, 0], [3, 3], 3)):
        coefficients = feature_map.constant_coefficients(np.array([1.0, -2.0]))
        np.testing.assert_allclose(feature_map(CONTEXTS) @ coefficients, [[1, -2], [1, -2]])


def test_user_feature_maps_can_be_registered(monkeypatch):
    from creps_gym.optimizers import features

    monkeypatch.setattr(features, "_REGISTRY", dict(features._REGISTRY))  # leave the global registry clean

    class Cubic(FeatureMap):
        name = "cubic-test"

        @property
        def n_features(self):
            return 1 + self.context_dim

        def __call__(self, contexts):
            return np.column_stack([np.ones(len(contexts)), contexts**3])

    register_feature_map(Cubic)
    np.testing.assert_array_equal(make_features("cubic-test", 2)(CONTEXTS)[0], [1, 1, 8])
    with pytest.raises(TypeError, match="expected a FeatureMap subclass"):
        register_feature_map(dict)
    register_feature_map(Cubic)  # the same class again: allowed

    class Impostor(FeatureMap):
        name = "affine"

    with pytest.raises(ValueError, match="cls: expected a feature map name not yet registered, got 'affine'"):
        register_feature_map(Impostor)
    assert make_features("affine", 1).__class__.__name__ == "AffineFeatures"


def test_a_registered_feature_map_with_fields_of_its_own_round_trips(tmp_path, monkeypatch):
    """Through a checkpoint: its spec holds every constructor field."""
    from dataclasses import dataclass

    from creps_gym.optimizers import CREPS, features

    monkeypatch.setattr(features, "_REGISTRY", dict(features._REGISTRY))

    @dataclass(frozen=True)
    class Scaled(FeatureMap):
        name = "scaled-test"
        constant_column = 0
        scale: float = 1.0

        @property
        def n_features(self):
            return 1 + self.context_dim

        def __call__(self, contexts):
            return np.column_stack([np.ones(len(contexts)), self.scale * contexts])

    register_feature_map(Scaled)
    optimizer = CREPS(2, 1, seed=0, mean_features=Scaled(1, scale=10.0), initial_mean=np.ones((2, 2)))
    restored = CREPS.load(optimizer.save(tmp_path / "ckpt.npz"))
    assert restored.config.mean_map == Scaled(1, scale=10.0)
    np.testing.assert_array_equal(restored.recommend([[1.0]]), optimizer.recommend([[1.0]]))


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: make_features("nope", 1), "features: expected one of .*got 'nope'"),
        (lambda: make_features(AffineFeatures(3), 1), "expected a map for context_dim=1, got one for 3"),
        (lambda: RBFFeatures(2, centres=np.zeros((3, 1))), r"centres: expected shape \(k, 2\)"),
        (
            lambda: RBFFeatures(1, centres=[[0.0]], bandwidth=0.0),
            "bandwidth: expected a finite number > 0 whose 2 h² is too, got 0.0",
        ),
        (
            lambda: RBFFeatures(1, centres=[[0.0]], bandwidth=1e-170),  # 2 h² underflows to 0
            "bandwidth: expected a finite number > 0 whose 2 h² is too, got 1e-170",
        ),
        (
            lambda: RBFFeatures(1, centres=[[0.0]], bandwidth=10**400),
            "bandwidth: expected a finite number > 0 whose 2 h² is too, got 1000",
        ),
        (lambda: AffineFeatures(-1), "context_dim: expected an int >= 0, got -1"),
        (
            lambda: BaselineFeatures(1).constant_coefficients(np.ones(2)),
            r"initial_mean: expected full coefficients of shape \(2, p\) for the 'baseline' feature map",
        ),
    ],
)
def test_feature_errors(call, match):
    with pytest.raises(ValueError, match=match):
        call()


@pytest.mark.parametrize("spec", [3, None, 1.5])
def test_a_feature_spec_of_the_wrong_type_is_named(spec):
    with pytest.raises(TypeError, match="features: expected a name, a spec dict or a FeatureMap, got"):
        make_features(spec, 1)


def test_rbf_features_compare_and_hash_by_value():
    rbf = RBFFeatures.grid([0.0], [1.0], per_dim=3)
    assert rbf == RBFFeatures.grid([0.0], [1.0], per_dim=3) and hash(rbf) == hash(
        RBFFeatures.grid([0], [1], 3)
    )
    assert rbf != RBFFeatures.grid([0.0], [1.0], per_dim=4) and rbf != AffineFeatures(1)
    with pytest.raises(TypeError, match="bandwidth: expected a finite number > 0, got bool"):
        RBFFeatures(1, centres=[[0.0]], bandwidth=True)


# -- feature counts are checked before anything is enumerated (issue 30, item 6) -----------------------------
def test_the_monomial_count_is_the_binomial_coefficient_and_the_enumerated_count():
    from creps_gym.optimizers.features import PolynomialFeatures, count_monomials

    for z, degree in [(0, 0), (0, 5), (1, 0), (1, 7), (3, 4), (5, 2), (2, 9)]:
        count = count_monomials(z, degree)
        assert count == math.comb(z + degree, degree) == len(PolynomialFeatures(z, degree).monomials)
    assert count_monomials(10**6, 10**6, limit=1000) > 1000  # stops early: no huge product


@pytest.mark.parametrize(
    ("z", "degree", "message"),
    [
        (1, 100_000, r"mean_features: degree: expected a size whose arrays fit in memory .*100001 monomials"),
        (
            3,
            10**12,
            r"mean_features: degree: expected a degree whose monomials of 3 context dimensions number",
        ),
    ],
)
def test_a_polynomial_degree_whose_features_cannot_fit_is_refused_at_once_naming_the_option(
    z, degree, message
):
    """Before: the monomials were enumerated until the OOM killer stopped the process."""
    from creps_gym.optimizers import make_optimizer

    for name in ("creps", "c-cma-es"):
        start = time.perf_counter()
        with pytest.raises(ValueError, match=message):
            make_optimizer(name, 2, z, 0, mean_features={"name": "polynomial", "degree": degree})
        assert time.perf_counter() - start < 5.0


def test_the_cli_refuses_a_huge_polynomial_degree_with_exit_2_before_writing(tmp_path, capsys):
    from creps_gym.cli import main

    option = 'mean_features={"name": "polynomial", "degree": 100000}'
    argv = ["run", "--env", "creps_gym/Sphere-v0", "--optimizer", "creps", "--iterations", "1", "--seed", "0"]
    assert main([*argv, "--out", str(tmp_path / "run"), "--opt", option, "--no-progress", "--no-plot"]) == 2
    assert "argument --opt: mean_features: degree: expected" in capsys.readouterr().err
    assert not (tmp_path / "run").exists()
