"""Parametric controllers that run a whole inner episode for one parameter vector θ.

The episodic conversion (:class:`~creps_gym.wrappers.episodic.EpisodicEnv`) calls ``start(θ, o_0)`` once
per episode and then ``act(t, o_t)`` at every inner step; observations are the inner env's observations
flattened to float64 vectors (``gymnasium.spaces.flatten``; a goal env's Dict is flattened in sorted key
order: achieved_goal, desired_goal, observation). The env clips actions into the inner action box.

Controllers
-----------
Controller
    The protocol users implement for their own controllers.
DMPController
    Open loop: each action dimension follows a discrete DMP (:class:`creps_gym.movement.DiscreteDMP`)
    from ``start`` to ``goal`` shaped by θ, the DMP weights.
TrackingDMPController
    A DMP reference from the observed start to a learned goal, tracked by a PD law on the observation.
LinearFeedbackController
    Closed loop: ``a_t = K [o_t; 1]`` with the gain matrix ``K`` = θ reshaped.

Functions
---------
make_controller
    Build a controller from a JSON-able spec (``{"type": "dmp", "n_basis": 5}``) and the inner spaces;
    used by registered ids.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from creps_gym._validation import as_float_array, check_positive_int
from creps_gym.movement import DiscreteDMP, DMPConfig, step_spectral_radius

__all__ = [
    "Controller",
    "DMPController",
    "LinearFeedbackController",
    "TrackingDMPController",
    "make_controller",
]

Array = NDArray[np.float64]


@runtime_checkable
class Controller(Protocol):
    """A parametric controller: θ (p,) fixes the behaviour of a whole inner episode.

    Attributes
    ----------
    action_dim : int
        Size of the (flat) action it outputs; must equal the inner env's action size.
    observation_dim : int or None
        Size of the flat observation it needs, or None if it ignores observations.
    param_low, param_high : ndarray, shape (p,)
        The search box of θ; it becomes the episodic env's action space.
    """

    action_dim: int
    observation_dim: int | None
    param_low: Array
    param_high: Array

    def start(self, params: Array, observation: Array) -> None:
        """Begin an episode with parameters (p,) and the first flat observation (d,)."""

    def act(self, step: int, observation: Array) -> Array:
        """Action (action_dim,) at inner step ``step`` (0-based) for the flat observation (d,)."""


def _bound(value: Any, name: str, *, allow_zero: bool = False) -> float:
    """A finite real number > 0 (or >= 0 with ``allow_zero``)."""
    value = float(as_float_array(value, name, ()))
    if value < 0 or (value == 0 and not allow_zero):
        raise ValueError(f"{name}: expected a value {'>=' if allow_zero else '>'} 0, got {value}")
    return value


def _indices(value: Any, size: int, name: str) -> NDArray[np.int64]:
    """Observation indices as an int array (k,), each in ``[0, size)``."""
    chosen = np.asarray(value)
    if chosen.ndim != 1 or chosen.dtype.kind not in "iu" or chosen.size == 0:
        raise TypeError(f"{name}: expected a non-empty sequence of ints, got {value!r}")
    if chosen.min() < 0 or chosen.max() >= size:
        raise ValueError(
            f"{name}: expected values in [0, {size - 1}] (the flat observation), got {chosen.tolist()}"
        )
    return chosen.astype(np.int64)


def _per_dimension(value: Any, name: str, dim: int) -> Array:
    """A scalar or a (dim,) array as a (dim,) float64 array."""
    array = as_float_array(value, name)
    if array.shape not in ((), (dim,)):
        raise ValueError(f"{name}: expected a scalar or shape ({dim},), got shape {array.shape}")
    return np.broadcast_to(array, (dim,)).copy()


def _dmp_config(n_basis: int, config: dict[str, Any]) -> DMPConfig:
    """DMP constants with ``weight_scale = α_z β_z`` by default (weights in the DMP's own unit)."""
    config.setdefault("weight_scale", config.get("alpha_z", 25.0) * config.get("beta_z", 6.25))
    return DMPConfig(n_basis=n_basis, **config)


def _stable_horizon(horizon: Any, config: DMPConfig) -> int:
    """``horizon`` as an int if the DMP integration with Δt/τ = 1/horizon is stable, else a ValueError
    naming the shortest stable horizon (the radius falls as the horizon grows: bisection)."""
    horizon = check_positive_int(horizon, "horizon")

    def stable(steps: int) -> bool:
        return step_spectral_radius(config, 1.0 / steps) < 1.0

    if stable(horizon):
        return horizon
    unstable, enough = horizon, 2 * horizon
    while not stable(enough):
        unstable, enough = enough, 2 * enough
    while enough - unstable > 1:
        middle = (unstable + enough) // 2
        unstable, enough = (unstable, middle) if stable(middle) else (middle, enough)
    raise ValueError(
        f"horizon: expected at least {enough} inner steps for a stable DMP integration with these gains "
        f"(the inner episode length: EpisodicEnv's max_inner_steps or the inner time limit), got {horizon}"
    )


class DMPController:
    """Open-loop actions from discrete DMPs, one per action dimension; θ are the DMP weights.

    Every episode integrates ``DiscreteDMP(action_dim, config).rollout(θ, start, goal, horizon, 1/horizon)``
    once and plays its positions: the action at inner step ``t`` is ``y(t / horizon)``; after the horizon the
    last position is held. With the default ``weight_scale = α_z β_z`` a weight is the shift, in action
    units, of the spring's set point while its basis function is active.

    Parameters
    ----------
    action_dim : int
        Action dimensions (DMP joints).
    horizon : int
        Inner steps the DMP spans (the DMP integration needs ``horizon >= 16`` with the default gains).
    n_basis : int
        Basis functions per action dimension; ``p = action_dim * n_basis`` (joint-major).
    weight_bound : float
        The search box of θ is ``[-weight_bound, weight_bound]^p``.
    start, goal : float or array_like, shape (action_dim,)
        Action at the start and the rest action the DMP converges to (default 0).
    **config : Any
        Other :class:`~creps_gym.movement.DMPConfig` fields (``alpha_z``, ``alpha_x``, ``weight_scale``...).
    """

    observation_dim: int | None = None

    def __init__(
        self,
        action_dim: int,
        horizon: int,
        n_basis: int = 5,
        weight_bound: float = 1.0,
        start: Any = 0.0,
        goal: Any = 0.0,
        **config: Any,
    ) -> None:
        self.action_dim = check_positive_int(action_dim, "action_dim")
        self.dmp = DiscreteDMP(self.action_dim, _dmp_config(n_basis, config))
        self.horizon = _stable_horizon(horizon, self.dmp.config)
        bound = _bound(weight_bound, "weight_bound")
        self.param_low = np.full(self.dmp.n_params, -bound)
        self.param_high = np.full(self.dmp.n_params, bound)
        self.start_action = _per_dimension(start, "start", self.action_dim)
        self.goal_action = _per_dimension(goal, "goal", self.action_dim)
        self._actions: Array | None = None

    def trajectory(self, params: Any) -> Array:
        """The action sequences for a batch of weights (n, p): shape (n, horizon + 1, action_dim)."""
        step = 1.0 / self.horizon
        return self.dmp.rollout(params, self.start_action, self.goal_action, self.horizon, step).positions

    def start(self, params: Array, observation: Array) -> None:
        """Integrate the DMP for weights (p,); the observation is ignored (open loop)."""
        self._actions = self.trajectory(np.asarray(params, dtype=np.float64)[None, :])[0]

    def act(self, step: int, observation: Array) -> Array:
        """The DMP position at inner step ``step`` (held after the horizon): shape (action_dim,)."""
        if self._actions is None:
            raise RuntimeError("DMPController.act() called before start(): start an episode first")
        return self._actions[min(step, self.horizon)]


class TrackingDMPController:
    """A DMP reference from the observed start to a learned goal, tracked by a PD law on the observation.

    At the start of an episode the DMP is integrated from the observed positions ``o_0[position_indices]``
    to the goal ``g`` with weights ``w``; at inner step ``t`` the action is
    ``kp (y(t / horizon) - o_t[position_indices]) - kd o_t[velocity_indices]``. θ = ``[g, w]`` with ``g``
    (j,) first, then the ``j * n_basis`` weights (joint-major); ``p = j (1 + n_basis)``. Learning ``g`` as a
    function of the context (a reaching goal) is what CREPS's linear mean does well.

    Parameters
    ----------
    observation_dim : int
        Size of the flat inner observation.
    position_indices, velocity_indices : sequence of int, length j
        Where the tracked positions and their velocities are in the flat observation; ``j`` is the
        action size.
    horizon : int
        Inner steps the DMP spans (``>= 16`` with the default gains).
    goal_low, goal_high : array_like, shape (j,)
        Search box of the goal part of θ.
    n_basis : int
        Basis functions per dimension.
    weight_bound : float
        Search box ``[-weight_bound, weight_bound]`` of the weights (in position units).
    kp, kd : float
        Proportional (> 0) and damping (>= 0) gains.
    **config : Any
        Other :class:`~creps_gym.movement.DMPConfig` fields.
    """

    def __init__(
        self,
        observation_dim: int,
        position_indices: Sequence[int],
        velocity_indices: Sequence[int],
        horizon: int,
        goal_low: Any,
        goal_high: Any,
        n_basis: int = 3,
        weight_bound: float = 1.0,
        kp: float = 5.0,
        kd: float = 1.0,
        **config: Any,
    ) -> None:
        self.observation_dim = check_positive_int(observation_dim, "observation_dim")
        self.positions = _indices(position_indices, self.observation_dim, "position_indices")
        self.velocities = _indices(velocity_indices, self.observation_dim, "velocity_indices")
        if self.velocities.shape != self.positions.shape:
            raise ValueError(
                f"velocity_indices: expected {self.positions.size} indices (one per position), "
                f"got {self.velocities.size}"
            )
        self.action_dim = int(self.positions.size)
        goal_low = as_float_array(goal_low, "goal_low", (self.action_dim,))
        goal_high = as_float_array(goal_high, "goal_high", (self.action_dim,))
        self.kp, self.kd = _bound(kp, "kp"), _bound(kd, "kd", allow_zero=True)
        self.dmp = DiscreteDMP(self.action_dim, _dmp_config(n_basis, config))
        self.horizon = _stable_horizon(horizon, self.dmp.config)
        bound = _bound(weight_bound, "weight_bound")
        self.param_low = np.r_[goal_low, np.full(self.dmp.n_params, -bound)]
        self.param_high = np.r_[goal_high, np.full(self.dmp.n_params, bound)]
        self._reference: Array | None = None

    def reference(self, params: Any, start: Any) -> Array:
        """Reference positions for θ (n, p) from ``start`` (j,) or (n, j): shape (n, horizon + 1, j)."""
        params = as_float_array(params, "params", (None, self.param_low.shape[0]))
        goal, weights = params[:, : self.action_dim], params[:, self.action_dim :]
        rollout = self.dmp.rollout(weights, start, goal, self.horizon, 1.0 / self.horizon)
        return rollout.positions

    def start(self, params: Array, observation: Array) -> None:
        """Integrate the reference from the observed positions to the goal in θ (p,)."""
        self._reference = self.reference(np.asarray(params)[None, :], observation[self.positions])[0]

    def act(self, step: int, observation: Array) -> Array:
        """PD action towards the reference at ``step`` (held after the horizon): shape (j,)."""
        if self._reference is None:
            raise RuntimeError("TrackingDMPController.act() called before start(): start an episode first")
        error = self._reference[min(step, self.horizon)] - observation[self.positions]
        return self.kp * error - self.kd * observation[self.velocities]


class LinearFeedbackController:
    """Linear state feedback ``a_t = K [o_t[indices]; 1]``, with θ the gain matrix K flattened row-major.

    Parameters
    ----------
    observation_dim : int
        Size of the flat inner observation.
    action_dim : int
        Size of the action.
    indices : sequence of int, optional
        Observation entries fed back (default: all); ``p = action_dim * (len(indices) + 1)``.
    gain_bound : float
        The search box of θ is ``[-gain_bound, gain_bound]^p``.
    """

    def __init__(
        self,
        observation_dim: int,
        action_dim: int,
        indices: Sequence[int] | None = None,
        gain_bound: float = 1.0,
    ) -> None:
        self.observation_dim = check_positive_int(observation_dim, "observation_dim")
        self.action_dim = check_positive_int(action_dim, "action_dim")
        everything = list(range(self.observation_dim))
        self.indices = _indices(everything if indices is None else indices, self.observation_dim, "indices")
        bound = _bound(gain_bound, "gain_bound")
        n_params = self.action_dim * (self.indices.size + 1)
        self.param_low, self.param_high = np.full(n_params, -bound), np.full(n_params, bound)
        self._gains: Array | None = None

    def start(self, params: Array, observation: Array) -> None:
        """Set the gains from θ (p,), shape (action_dim, len(indices) + 1) row-major."""
        self._gains = np.asarray(params, dtype=np.float64).reshape(self.action_dim, self.indices.size + 1)

    def act(self, step: int, observation: Array) -> Array:
        """``K [o[indices]; 1]``, shape (action_dim,)."""
        if self._gains is None:
            raise RuntimeError("LinearFeedbackController.act() called before start(): start an episode first")
        return self._gains[:, :-1] @ observation[self.indices] + self._gains[:, -1]


def make_controller(
    spec: Mapping[str, Any], observation_dim: int, action_dim: int, horizon: int
) -> Controller:
    """Build a controller from a JSON-able spec and the inner env's sizes.

    Parameters
    ----------
    spec : mapping
        ``{"type": "dmp", ...}`` (:class:`DMPController`), ``{"type": "tracking_dmp", ...}``
        (:class:`TrackingDMPController`) or ``{"type": "linear", ...}`` (:class:`LinearFeedbackController`),
        with the class's options besides the sizes.
    observation_dim, action_dim : int
        Flat sizes of the inner observation and action.
    horizon : int
        Inner episode length (the DMP's span).
    """
    if not isinstance(spec, Mapping) or "type" not in spec:
        raise TypeError(f"controller: expected a Controller or a mapping with a 'type' key, got {spec!r}")
    options = {key: value for key, value in spec.items() if key != "type"}
    if spec["type"] == "dmp":
        return DMPController(action_dim, horizon, **options)
    if spec["type"] == "tracking_dmp":
        return TrackingDMPController(observation_dim, horizon=horizon, **options)
    if spec["type"] == "linear":
        return LinearFeedbackController(observation_dim, action_dim, **options)
    raise ValueError(f"controller['type']: expected 'dmp', 'tracking_dmp' or 'linear', got {spec['type']!r}")
