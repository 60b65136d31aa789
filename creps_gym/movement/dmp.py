"""Discrete Dynamic Movement Primitives (DMPs), integrated for a whole batch of weight vectors at once.

A discrete DMP (Ijspeert, Nakanishi, Hoffmann, Pastor and Schaal, "Dynamical Movement Primitives: Learning
Attractor Models for Motor Behaviors", Neural Computation 25(2), 2013, doi:10.1162/NECO_a_00393) drives
each degree of freedom ("joint") ``y`` towards a known, fixed goal ``g`` with a critically damped spring
whose set point is shaped by a learned forcing term. With ``τ`` the duration and ``t`` the time:

* canonical system (their section 2.1)::

      τ ẋ = −α_x x,          x(0) = 1,   so   x(t) = exp(−α_x t / τ)

* transformation system (their section 2.1)::

      τ ż = α_z (β_z (g − y) − z) + f(x),     τ ẏ = z

* forcing term with normalised Gaussian basis functions in phase (their section 2.1)::

      f(x) = s · x · Σ_i ψ_i(x) w_i / Σ_i ψ_i(x),     ψ_i(x) = exp(−h_i (x − c_i)²)

  The centres ``c_i = exp(−α_x t_i / τ)`` sit at times ``t_i`` equally spaced over ``[0, τ]`` (spacing
  ``Δ = τ / (B − 1)`` for ``B`` basis functions, ``Δ = τ`` if ``B = 1``). The widths
  ``h_i = 1 / (2 (σ α_x c_i / τ)²)`` with ``σ = Δ / 2`` make each ``ψ_i``, to first order in ``t − t_i``, a
  Gaussian in *time* of standard deviation ``σ``, so every basis function covers the same stretch of time.
  Ijspeert et al. multiply ``f`` by the amplitude ``(g − y_0)``; that factor vanishes when a joint starts at
  its goal (the planar reacher's joints 2 to 5 do), so here the forcing is scaled by the constant
  ``s = weight_scale`` instead, or by ``weight_scale · (g − y_0)`` with ``amplitude_scaling=True``.
  With ``weight_scale = α_z β_z`` a weight is measured in the joint's own unit: ``x · Σψw/Σψ`` is then
  the shift of the spring's set point away from ``g``.

``α_z = 25`` and ``β_z = α_z / 4`` (critical damping) are the values Ijspeert et al. use; ``α_x = 3`` makes
the phase fall to ``exp(−3) ≈ 0.05`` at ``t = τ``, so the last basis function still acts. As ``x → 0``
(``t ≫ τ``) the forcing vanishes and ``y`` converges to ``g`` for any weights.

Integrator
----------
The phase is evaluated in closed form, ``x_k = exp(−α_x k Δt / τ)``. The transformation system is
integrated with the semi-implicit (symplectic) Euler scheme with step ``Δt``::

    ż_k     = (α_z (β_z (g − y_k) − z_k) + f(x_k)) / τ
    z_{k+1} = z_k + Δt ż_k
    y_{k+1} = y_k + Δt z_{k+1} / τ

Velocities are ``ẏ_k = z_k / τ`` and accelerations ``ÿ_k = ż_k / τ``. :func:`step_spectral_radius`
gives the spectral radius of the unforced step map; ``rollout`` rejects steps where it is ``>= 1``. With
the default gains, ``Δt α_z / τ`` up to about 1.6 is stable (100 steps over ``τ`` give 0.25).

Vectorisation and exactness
---------------------------
Every time step is a handful of element-wise numpy operations on ``(n, joints)`` arrays, for any batch size
``n``. No matrix product is used, so a batched rollout equals ``n`` single rollouts bit for bit (BLAS
kernels may round differently for different batch sizes).

Public API
----------
``DMPConfig``
    Frozen, self-validating constants (``n_basis``, ``alpha_z``, ``beta_z``, ``alpha_x``, ``weight_scale``,
    ``amplitude_scaling``).
``DiscreteDMP(n_joints, config)``
    ``rollout(weights, start, goal, n_steps, dt, tau=None) -> DMPTrajectory`` with ``weights`` of shape
    ``(n, joints, basis)`` or ``(n, joints * basis)`` (joint-major: joint ``j`` owns entries
    ``j*basis .. (j+1)*basis - 1``), ``start`` and ``goal`` of shape ``(joints,)`` or ``(n, joints)``.
    ``DMPTrajectory`` holds ``positions``, ``velocities``, ``accelerations`` (each ``(n, n_steps + 1,
    joints)``, index ``k`` is time ``k Δt``, index 0 the start), ``phase`` (``(n_steps + 1,)``) and
    ``forcing`` (``(n, n_steps + 1, joints)``). ``basis(phase)`` gives the normalised basis values.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from creps_gym._validation import as_float_array, check_bool, check_positive_int, check_real

__all__ = ["DMPConfig", "DMPTrajectory", "DiscreteDMP", "step_spectral_radius"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class DMPConfig:
    """Constants of a discrete DMP (see the module docstring for the equations).

    Parameters
    ----------
    n_basis : int
        Basis functions per joint (the paper's planar reacher uses 5).
    alpha_z, beta_z : float
        Spring gains of the transformation system; ``beta_z = alpha_z / 4`` is critically damped.
    alpha_x : float
        Decay rate of the canonical system.
    weight_scale : float
        Constant factor ``s`` of the forcing term.
    amplitude_scaling : bool
        Also multiply the forcing by ``(g − y_0)`` as in Ijspeert et al. (2013).
    """

    n_basis: int = 5
    alpha_z: float = 25.0
    beta_z: float = 6.25
    alpha_x: float = 3.0
    weight_scale: float = 1.0
    amplitude_scaling: bool = False

    def __post_init__(self) -> None:
        object.__setattr__(self, "n_basis", check_positive_int(self.n_basis, "n_basis"))
        for name in ("alpha_z", "beta_z", "alpha_x", "weight_scale"):
            object.__setattr__(self, name, check_real(getattr(self, name), name, strict=True))
        object.__setattr__(self, "amplitude_scaling", check_bool(self.amplitude_scaling, "amplitude_scaling"))


def step_spectral_radius(config: DMPConfig, step: float) -> float:
    """Spectral radius of one unforced semi-implicit Euler step, with ``step = Δt / τ``.

    The error ``e = y − g`` and ``z`` evolve as ``[e, z] ← B A [e, z]`` with
    ``A = [[1, 0], [−h α_z β_z, 1 − h α_z]]`` (velocity update), ``B = [[1, h], [0, 1]]`` (position
    update) and ``h = Δt / τ``. The integration is stable when the returned value is below 1.
    """
    h = float(step)
    velocity = np.array([[1.0, 0.0], [-h * config.alpha_z * config.beta_z, 1.0 - h * config.alpha_z]])
    position = np.array([[1.0, h], [0.0, 1.0]])
    return float(np.max(np.abs(np.linalg.eigvals(position @ velocity))))


@dataclass(frozen=True)
class DMPTrajectory:
    """A batch of integrated DMP trajectories; index ``k`` of the time axis is time ``k Δt``.

    Attributes
    ----------
    positions, velocities, accelerations : ndarray, shape (n, n_steps + 1, joints)
    forcing : ndarray, shape (n, n_steps + 1, joints)
        The forcing term ``f(x_k)`` that entered the step.
    phase : ndarray, shape (n_steps + 1,)
        The canonical state ``x_k``.
    dt : float
        The integration step.
    """

    positions: Array
    velocities: Array
    accelerations: Array
    forcing: Array
    phase: Array
    dt: float


class DiscreteDMP:
    """Discrete DMPs for ``n_joints`` degrees of freedom, integrated for a batch of weight vectors.

    Parameters
    ----------
    n_joints : int
        Degrees of freedom, each with its own ``config.n_basis`` weights.
    config : DMPConfig, optional
        The DMP constants (default ``DMPConfig()``).

    Examples
    --------
    >>> dmp = DiscreteDMP(2, DMPConfig(n_basis=3))
    >>> traj = dmp.rollout(np.zeros((4, 6)), start=[1.0, -1.0], goal=[0.0, 0.0], n_steps=100, dt=0.01)
    >>> traj.positions.shape
    (4, 101, 2)
    """

    def __init__(self, n_joints: int, config: DMPConfig | None = None) -> None:
        self.n_joints = check_positive_int(n_joints, "n_joints")
        if config is None:
            config = DMPConfig()
        if not isinstance(config, DMPConfig):
            raise TypeError(f"config: expected a DMPConfig or None, got {type(config).__name__}")
        self.config = config
        times = np.linspace(0.0, 1.0, config.n_basis)  # t_i / τ
        sigma = 0.5 / max(config.n_basis - 1, 1)  # half the spacing, in units of τ
        self.centres: Array = np.exp(-config.alpha_x * times)
        self.widths: Array = 1.0 / (2.0 * (sigma * config.alpha_x * self.centres) ** 2)

    @property
    def n_params(self) -> int:
        """Number of weights, ``n_joints * n_basis``."""
        return self.n_joints * self.config.n_basis

    def basis(self, phase: Any) -> Array:
        """Normalised basis values ``ψ_i(x) / Σ_j ψ_j(x)`` for phases of shape (m,): shape (m, n_basis)."""
        phase = as_float_array(phase, "phase", (None,))
        exponents = -self.widths * (phase[:, None] - self.centres) ** 2
        # Shifting by the row maximum leaves the ratio unchanged and keeps the sum >= 1 (no 0/0 far out).
        psi = np.exp(exponents - exponents.max(axis=1, keepdims=True))
        return psi / psi.sum(axis=1, keepdims=True)

    def _check_weights(self, weights: Any) -> Array:
        basis = self.config.n_basis
        weights = as_float_array(weights, "weights")
        if weights.ndim == 2 and weights.shape[1] == self.n_params:
            return weights.reshape(weights.shape[0], self.n_joints, basis)
        if weights.ndim == 3 and weights.shape[1:] == (self.n_joints, basis):
            return weights
        raise ValueError(
            f"weights: expected shape (n, {self.n_joints}, {basis}) or (n, {self.n_params}), "
            f"got {weights.shape}"
        )

    def _check_state(self, value: Any, name: str, n: int) -> Array:
        array = as_float_array(value, name)
        if array.shape == (self.n_joints,):
            return np.broadcast_to(array, (n, self.n_joints))
        if array.shape == (n, self.n_joints):
            return array
        raise ValueError(
            f"{name}: expected shape ({self.n_joints},) or ({n}, {self.n_joints}), got {array.shape}"
        )

    def _forcing_term(self, weights: Array, phase: Array, amplitude: Array) -> Array:
        """Forcing term for weights (n, joints, basis), phases (T,), amplitudes (n, joints): (n, T, joints).

        Element-wise products summed over the basis axis one term at a time, so that every row is computed
        exactly as it would be alone.
        """
        values = self.basis(phase) * phase[:, None]  # (T, basis): x ψ_i / Σψ
        total = np.zeros((weights.shape[0], phase.shape[0], self.n_joints))
        for i in range(self.config.n_basis):
            total += weights[:, None, :, i] * values[None, :, i, None]
        return (self.config.weight_scale * amplitude)[:, None, :] * total

    def rollout(
        self,
        weights: Any,
        start: Any,
        goal: Any,
        n_steps: int,
        dt: float,
        tau: float | None = None,
    ) -> DMPTrajectory:
        """Integrate a batch of DMPs from rest at ``start``.

        Parameters
        ----------
        weights : array_like, shape (n, joints, basis) or (n, joints * basis)
            Forcing weights, joint-major in the flat form.
        start, goal : array_like, shape (joints,) or (n, joints)
            Initial positions (the initial velocity is zero) and the goal attractor.
        n_steps : int
            Number of integration steps; the trajectory has ``n_steps + 1`` samples.
        dt : float
            Integration step (s).
        tau : float, optional
            Duration ``τ`` (s); default ``n_steps * dt``.

        Returns
        -------
        DMPTrajectory
            Positions, velocities, accelerations and forcing of shape (n, n_steps + 1, joints).
        """
        weights = self._check_weights(weights)
        n = weights.shape[0]
        start = self._check_state(start, "start", n)
        goal = self._check_state(goal, "goal", n)
        n_steps = check_positive_int(n_steps, "n_steps")
        dt = check_real(dt, "dt", strict=True)
        tau = n_steps * dt if tau is None else check_real(tau, "tau", strict=True)
        cfg = self.config
        radius = step_spectral_radius(cfg, dt / tau)
        if radius >= 1.0:
            raise ValueError(
                f"dt: expected a step for which the integration is stable (spectral radius < 1), got dt={dt} "
                f"with tau={tau}: radius {radius:.3g}; use a smaller dt"
            )
        phase = np.exp(-cfg.alpha_x * dt * np.arange(n_steps + 1) / tau)
        amplitude = goal - start if cfg.amplitude_scaling else np.ones((n, self.n_joints))
        forcing = self._forcing_term(weights, phase, amplitude)
        positions, velocities, accelerations = self._integrate(forcing, start, goal, dt, tau)
        return DMPTrajectory(positions, velocities, accelerations, forcing, phase, dt)

    def _integrate(
        self, forcing: Array, start: Array, goal: Array, dt: float, tau: float
    ) -> tuple[Array, Array, Array]:
        """Semi-implicit Euler integration of the transformation system (see the module docstring)."""
        cfg = self.config
        n, samples, joints = forcing.shape
        positions = np.empty((n, samples, joints))
        velocities = np.empty((n, samples, joints))
        accelerations = np.empty((n, samples, joints))
        y = np.array(start, dtype=np.float64)
        z = np.zeros((n, joints))
        for k in range(samples):
            z_dot = (cfg.alpha_z * (cfg.beta_z * (goal - y) - z) + forcing[:, k]) / tau
            positions[:, k] = y
            velocities[:, k] = z / tau
            accelerations[:, k] = z_dot / tau
            z = z + dt * z_dot
            y = y + dt * z / tau
        return positions, velocities, accelerations
