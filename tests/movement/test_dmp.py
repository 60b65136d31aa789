"""Discrete DMPs: convergence, start state, forcing shape and decay, batch exactness, errors."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from creps_gym.movement import DiscreteDMP, DMPConfig, step_spectral_radius

START = np.array([1.0, -0.5, 0.0])
GOAL = np.array([0.0, 0.5, 0.0])


def test_zero_weights_follow_the_critically_damped_spring_to_the_goal():
    dmp = DiscreteDMP(3)
    traj = dmp.rollout(np.zeros((1, 15)), START, GOAL, n_steps=400, dt=0.0025, tau=1.0)
    # Unforced, critically damped: e(t) = e0 (1 + ω t) exp(−ω t) with ω = α_z / (2 τ).
    omega = dmp.config.alpha_z / 2.0
    t = np.arange(401) * 0.0025
    expected = GOAL + (START - GOAL) * ((1.0 + omega * t) * np.exp(-omega * t))[:, None]
    np.testing.assert_allclose(traj.positions[0], expected, atol=0.01)
    np.testing.assert_allclose(traj.positions[0, -1], GOAL, atol=1e-4)
    np.testing.assert_array_equal(traj.forcing, 0.0)


def test_any_weights_converge_to_the_goal_once_the_phase_has_decayed():
    rng = np.random.default_rng(0)
    dmp = DiscreteDMP(3, DMPConfig(weight_scale=150.0))
    traj = dmp.rollout(rng.normal(size=(4, 3, 5)), START, GOAL, n_steps=1000, dt=0.01, tau=1.0)
    np.testing.assert_allclose(traj.positions[:, -1], np.broadcast_to(GOAL, (4, 3)), atol=1e-8)
    np.testing.assert_allclose(traj.velocities[:, -1], 0.0, atol=1e-8)


def test_forcing_term_vanishes_as_the_phase_decays():
    dmp = DiscreteDMP(2, DMPConfig(weight_scale=10.0))
    weights = np.array([[[1.0, -2.0, 3.0, -4.0, 5.0], [5.0, 4.0, 3.0, 2.0, 1.0]]])
    traj = dmp.rollout(weights, [0.0, 0.0], [1.0, 1.0], n_steps=500, dt=0.01, tau=1.0)
    np.testing.assert_allclose(traj.phase, np.exp(-dmp.config.alpha_x * np.arange(501) * 0.01))
    # |f| <= s · x · max|w| because the normalised basis is a convex combination.
    bound = 10.0 * traj.phase[:, None] * np.abs(weights[0]).max(axis=1)
    assert np.all(np.abs(traj.forcing[0]) <= bound + 1e-12)
    assert np.abs(traj.forcing[0, -1]).max() < 1e-5 * np.abs(traj.forcing[0, :10]).max()


def test_start_state_is_respected():
    rng = np.random.default_rng(1)
    dmp = DiscreteDMP(3)
    starts = rng.normal(size=(5, 3))
    traj = dmp.rollout(rng.normal(size=(5, 15)), starts, GOAL, n_steps=50, dt=0.01)
    np.testing.assert_array_equal(traj.positions[:, 0], starts)
    np.testing.assert_array_equal(traj.velocities[:, 0], 0.0)
    assert traj.positions.shape == traj.velocities.shape == traj.accelerations.shape == (5, 51, 3)


def test_normalised_basis_sums_to_one_and_peaks_in_time_order():
    dmp = DiscreteDMP(1, DMPConfig(n_basis=6))
    values = dmp.basis(dmp.centres)
    np.testing.assert_allclose(values.sum(axis=1), 1.0)
    np.testing.assert_array_equal(values.argmax(axis=1), np.arange(6))
    phase = np.exp(-dmp.config.alpha_x * np.linspace(0.0, 1.0, 101))
    peaks = dmp.basis(phase).argmax(axis=0)
    assert np.all(np.diff(peaks) > 0)


def test_basis_stays_normalised_far_from_every_centre():
    dmp = DiscreteDMP(1, DMPConfig(n_basis=20, alpha_x=25.0))
    values = dmp.basis([0.0, 1e-300, 1.0, 50.0])
    assert np.isfinite(values).all()
    np.testing.assert_allclose(values.sum(axis=1), 1.0)
    assert values[3].argmax() == 0  # far beyond x = 1 the first (widest, largest-centre) basis wins
    with pytest.raises(ValueError, match=r"phase: expected shape \(n,\)"):
        dmp.basis(np.ones((2, 2)))


def test_known_weights_match_an_independent_ode_solution():
    """Constant weights w give f = s x w; compare with scipy's RK45 on the continuous system."""
    cfg_scale = 25.0 * 6.25
    cfg = DMPConfig(weight_scale=cfg_scale)
    dmp = DiscreteDMP(1, cfg)
    w, tau = 0.8, 1.0

    def rhs(t, state):
        y, z = state
        x = np.exp(-cfg.alpha_x * t / tau)
        return [z / tau, (cfg.alpha_z * (cfg.beta_z * (0.0 - y) - z) + cfg_scale * x * w) / tau]

    t_eval = np.linspace(0.0, 1.0, 2001)
    reference = solve_ivp(rhs, (0.0, 1.0), [1.0, 0.0], t_eval=t_eval, rtol=1e-10, atol=1e-12).y[0]
    traj = dmp.rollout(np.full((1, 5), w), [1.0], [0.0], n_steps=2000, dt=0.0005)
    np.testing.assert_allclose(traj.positions[0, :, 0], reference, atol=2e-3)
    # The shape: the joint falls monotonically and lags above the moving set point g + x w.
    y = traj.positions[0, :, 0]
    assert np.all(np.diff(y) <= 0.0)
    assert np.all(y[1:] > w * traj.phase[1:])


def test_positive_weight_raises_the_trajectory_and_effects_add_up():
    dmp = DiscreteDMP(1, DMPConfig(weight_scale=100.0))
    base = dmp.rollout(np.zeros((1, 5)), [0.0], [1.0], 100, 0.01).positions
    single = [dmp.rollout(np.eye(5)[[i]], [0.0], [1.0], 100, 0.01).positions - base for i in range(5)]
    for effect in single:  # the critically damped impulse response t exp(−ωt) is non-negative
        assert np.all(effect >= -1e-12) and effect.max() > 0
    both = dmp.rollout(np.ones((1, 5)), [0.0], [1.0], 100, 0.01).positions - base
    np.testing.assert_allclose(both, sum(single), atol=1e-12)  # the system is linear in the weights
    peaks = [int(effect[0, :, 0].argmax()) for effect in single]
    assert peaks == sorted(peaks)  # later basis functions act later


def test_batched_rollout_equals_sequential_rollouts_exactly():
    rng = np.random.default_rng(2)
    dmp = DiscreteDMP(5, DMPConfig(weight_scale=156.25, amplitude_scaling=False))
    weights = rng.normal(size=(100, 25)) * 5
    starts = rng.normal(size=(100, 5))
    batch = dmp.rollout(weights, starts, np.zeros(5), 100, 0.01)
    for i in (0, 1, 37, 99):
        one = dmp.rollout(weights[i : i + 1], starts[i], np.zeros(5), 100, 0.01)
        np.testing.assert_array_equal(batch.positions[i], one.positions[0])
        np.testing.assert_array_equal(batch.accelerations[i], one.accelerations[0])
        np.testing.assert_array_equal(batch.velocities[i], one.velocities[0])


def test_flat_and_per_joint_weights_are_the_same_layout():
    rng = np.random.default_rng(3)
    dmp = DiscreteDMP(2, DMPConfig(n_basis=4))
    weights = rng.normal(size=(3, 2, 4))
    a = dmp.rollout(weights, [0.0, 1.0], [1.0, 0.0], 30, 0.01)
    b = dmp.rollout(weights.reshape(3, 8), [0.0, 1.0], [1.0, 0.0], 30, 0.01)
    np.testing.assert_array_equal(a.positions, b.positions)


def test_amplitude_scaling_switches_off_joints_that_start_at_their_goal():
    dmp = DiscreteDMP(2, DMPConfig(amplitude_scaling=True, weight_scale=50.0))
    traj = dmp.rollout(np.ones((1, 10)), [0.0, 2.0], [0.0, 0.0], 100, 0.01)
    np.testing.assert_array_equal(traj.positions[0, :, 0], 0.0)
    np.testing.assert_allclose(traj.forcing[0, :, 1], 50.0 * -2.0 * traj.phase)


def test_spectral_radius_marks_the_stability_limit():
    cfg = DMPConfig()
    assert step_spectral_radius(cfg, 0.01) < 1.0
    assert step_spectral_radius(cfg, 2.0 / cfg.alpha_z) > 1.0
    with pytest.raises(ValueError, match="dt: expected a step for which the integration is stable"):
        DiscreteDMP(1, cfg).rollout(np.zeros((1, 5)), [0.0], [1.0], n_steps=10, dt=0.1, tau=1.0)


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        ({"weights": np.zeros((2, 7))}, ValueError, r"weights: expected shape \(n, 2, 5\) or \(n, 10\)"),
        ({"weights": np.full((1, 10), np.nan)}, ValueError, "weights: expected finite"),
        ({"weights": "abc"}, TypeError, "weights"),
        ({"start": [0.0, 0.0, 0.0]}, ValueError, r"start: expected shape \(2,\) or \(1, 2\)"),
        ({"goal": np.zeros((3, 2))}, ValueError, r"goal: expected shape \(2,\) or \(1, 2\)"),
        ({"n_steps": 0}, ValueError, "n_steps"),
        ({"n_steps": 2.5}, TypeError, "n_steps"),
        ({"dt": -0.01}, ValueError, "dt: expected a finite value > 0"),
        ({"tau": float("inf")}, ValueError, "tau"),
    ],
)
def test_rollout_rejects_bad_input(kwargs, error, match):
    call = {"weights": np.zeros((1, 10)), "start": [0.0, 1.0], "goal": [1.0, 0.0], "n_steps": 10, "dt": 0.01}
    call.update(kwargs)
    with pytest.raises(error, match=match):
        DiscreteDMP(2).rollout(**call)


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        ({"n_basis": 0}, ValueError, "n_basis"),
        ({"alpha_z": -1.0}, ValueError, "alpha_z: expected a finite value > 0"),
        ({"alpha_x": "3"}, TypeError, "alpha_x"),
        ({"weight_scale": float("nan")}, ValueError, "weight_scale"),
        ({"amplitude_scaling": 1}, TypeError, "amplitude_scaling: expected a bool"),
    ],
)
def test_config_rejects_bad_values(kwargs, error, match):
    with pytest.raises(error, match=match):
        DMPConfig(**kwargs)


def test_dmp_rejects_bad_construction():
    with pytest.raises(ValueError, match="n_joints"):
        DiscreteDMP(0)
    with pytest.raises(TypeError, match="config: expected a DMPConfig"):
        DiscreteDMP(2, {"n_basis": 5})
