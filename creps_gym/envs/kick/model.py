"""The kick's MuJoCo models and the mapping from normalised parameters to joint targets.

The MJCF (``assets/nao_kick.xml``) documents the robot: a NAO-like humanoid, 6 joints per leg, position
servos, and a RoboCup 3D ball. This module loads it by absolute path, makes the ball-only model used to finish
the ball's roll, and defines the parameter layout:

``theta = (12 initial joint angles, 12 final joint angles, duration t)``, each in ``[-1, 1]`` (the
action box). Joint ``j`` maps to ``mid_j + half_j * u`` over its joint range, and the duration to
``DURATION_RANGE`` linearly. The 12 joints are the right leg's 6 then the left leg's 6, each in the order of
``LEG_JOINTS``; mirroring a kick swaps the two blocks (the legs' axes are mirror images).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from creps_gym.envs.opengl import import_mujoco

import_mujoco()  # chooses the GL backend first (MuJoCo reads MUJOCO_GL once); a clear error
import mujoco  # noqa: E402
import numpy as np  # noqa: E402
from numpy.typing import NDArray  # noqa: E402

__all__ = [
    "ASSET_PATH",
    "BALL_RADIUS",
    "BALL_TIMESTEP",
    "DURATION_RANGE",
    "JOINT_HIGH",
    "JOINT_LOW",
    "JOINT_NAMES",
    "LEG_JOINTS",
    "REFERENCE_KICK",
    "STAND_POSE",
    "KickModels",
    "load_models",
    "mirror_params",
    "rest_qpos",
    "to_normalised",
    "to_physical",
]

Array = NDArray[np.float64]

ASSET_PATH = Path(__file__).resolve().parent / "assets" / "nao_kick.xml"
LEG_JOINTS = ("hip_yawpitch", "hip_roll", "hip_pitch", "knee", "ankle_pitch", "ankle_roll")
JOINT_NAMES = tuple(f"{side}_{joint}" for side in ("r", "l") for joint in LEG_JOINTS)
# Joint ranges (rad) of the MJCF, NAO H25 figures; the same for both legs thanks to the mirrored axes.
_LEG_LOW = np.array([-1.1453, -0.7904, -1.5359, -0.0923, -1.1895, -0.7690])
_LEG_HIGH = np.array([0.7408, 0.3794, 0.4840, 2.1125, 0.9227, 0.3978])
JOINT_LOW: Array = np.concatenate([_LEG_LOW, _LEG_LOW])
JOINT_HIGH: Array = np.concatenate([_LEG_HIGH, _LEG_HIGH])
DURATION_RANGE = (0.05, 0.6)
"""Bounds (s) of the swing duration t from the initial to the final pose."""
STAND_POSE: Array = np.tile([0.0, 0.0, -0.45, 0.9, -0.45, 0.0], 2)
"""Crouched standing pose (rad), 12 joints; every episode starts from it, settled."""
BALL_RADIUS = 0.042
BALL_TIMESTEP = 0.004
"""Timestep (s) of the ball-only model: twice the full model's; the roll differs from 2 ms by < 5 mm."""
SETTLE_STEPS = 500  # the standing robot settles for 1 s before any episode starts

# A right-leg kick for the precision task's ball (about 8 m): CMA-ES from a hand-made swing, then CMA-ES on
# the mean return under N(0, 0.03^2) perturbations for robustness (see benchmarks/kick/README.md).
# Normalised units; the recommended initial mean.
REFERENCE_KICK: Array = np.concatenate(
    [
        [0.2240, 0.4762, 0.0473, 0.2843, 0.0426, 0.6308],  # the initial pose: right leg (LEG_JOINTS)
        [0.5542, 0.1158, -0.0344, -0.2869, -0.1746, 0.1892],  # ... left leg
        [-0.4231, -0.0201, -0.5163, -0.5637, 0.2372, 0.2611],  # the final pose: right leg
        [0.6974, -0.0027, 0.5251, -0.1084, -0.4773, 0.0645],  # ... left leg
        [-1.0000],  # the swing duration
    ]
)
REFERENCE_KICK.flags.writeable = False


def _mid_half() -> tuple[Array, Array]:
    low = np.concatenate([JOINT_LOW, JOINT_LOW, [DURATION_RANGE[0]]])
    high = np.concatenate([JOINT_HIGH, JOINT_HIGH, [DURATION_RANGE[1]]])
    return (low + high) / 2.0, (high - low) / 2.0


def to_physical(params: Array) -> tuple[Array, Array, Array]:
    """Map normalised parameters to joint targets and durations.

    Parameters
    ----------
    params : ndarray, shape (n, 25)
        Normalised parameters; values outside ``[-1, 1]`` are clipped.

    Returns
    -------
    initial, final : ndarray, shape (n, 12)
        Joint angles (rad) of the initial and final poses.
    duration : ndarray, shape (n,)
        Swing durations (s).
    """
    mid, half = _mid_half()
    physical = mid + half * np.clip(params, -1.0, 1.0)
    return physical[:, :12], physical[:, 12:24], physical[:, 24]


def to_normalised(initial: Array, final: Array, duration: Array) -> Array:
    """Inverse of :func:`to_physical`: angles (n, 12), (n, 12) and durations (n,) to params (n, 25)."""
    mid, half = _mid_half()
    physical = np.concatenate([initial, final, np.asarray(duration)[:, None]], axis=1)
    return (physical - mid) / half


def mirror_params(params: Array) -> Array:
    """Swap the right- and left-leg 6-joint blocks of both poses: the mirror-image kick, shape (n, 25)."""
    out = np.array(params, dtype=np.float64, copy=True)
    for start in (0, 12):
        out[:, start : start + 6] = params[:, start + 6 : start + 12]
        out[:, start + 6 : start + 12] = params[:, start : start + 6]
    return out


@dataclass(frozen=True)
class KickModels:
    """The compiled models and the settled initial state shared by every episode.

    Attributes
    ----------
    full : mujoco.MjModel
        Robot, ball and floor.
    ball : mujoco.MjModel
        Ball and floor only, with the same contact parameters and a ``BALL_TIMESTEP`` timestep.
    initial_state : ndarray, shape (nstate,)
        ``mjSTATE_INTEGRATION`` state of ``full`` after the robot settled in ``STAND_POSE`` (time 0).
    ball_qpos_address : int
        Index of the ball's free joint in ``full``'s qpos (its qvel index is ``ball_qvel_address``).
    ball_qvel_address : int
    stand_height : float
        Torso height (m) of the settled robot.
    sensor_slices : dict of str to slice
        Where each named sensor sits in ``sensordata``.
    rolling_friction : float
        The ball's rolling friction coefficient.
    """

    full: mujoco.MjModel
    ball: mujoco.MjModel
    initial_state: Array
    ball_qpos_address: int
    ball_qvel_address: int
    stand_height: float
    sensor_slices: dict[str, slice]
    rolling_friction: float


def _ball_only_spec(spec: mujoco.MjSpec) -> mujoco.MjSpec:
    """Remove the robot (body, actuators, sensors) from a copy of the full spec."""
    ball_spec = spec.copy()
    for sensor in list(ball_spec.sensors):
        ball_spec.delete(sensor)
    for actuator in list(ball_spec.actuators):
        ball_spec.delete(actuator)
    ball_spec.delete(ball_spec.body("torso"))
    return ball_spec


def _sensor_slices(model: mujoco.MjModel) -> dict[str, slice]:
    slices = {}
    for i in range(model.nsensor):
        start, size = int(model.sensor_adr[i]), int(model.sensor_dim[i])
        slices[mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_SENSOR, i)] = slice(start, start + size)
    return slices


def _settled_state(model: mujoco.MjModel) -> tuple[Array, float]:
    """Stand the robot on the floor in STAND_POSE (ball parked), let it settle; return state, height."""
    data = mujoco.MjData(model)
    ball_adr = int(model.jnt_qposadr[model.joint("ball").id])
    data.qpos[7:19] = STAND_POSE
    data.ctrl[:] = STAND_POSE
    data.qpos[ball_adr : ball_adr + 3] = (-3.0, 0.0, BALL_RADIUS)
    mujoco.mj_forward(model, data)
    data.qpos[2] -= min(data.site("r_sole").xpos[2], data.site("l_sole").xpos[2])
    mujoco.mj_forward(model, data)
    for _ in range(SETTLE_STEPS):
        mujoco.mj_step(model, data)
    data.time = 0.0
    state = np.empty(mujoco.mj_stateSize(model, mujoco.mjtState.mjSTATE_INTEGRATION))
    mujoco.mj_getState(model, data, state, mujoco.mjtState.mjSTATE_INTEGRATION)
    return state, float(data.qpos[2])


def load_models(rolling_friction: float = 0.003, fixed_base: bool = False) -> KickModels:
    """Compile the full and the ball-only model.

    Parameters
    ----------
    rolling_friction : float
        The ball's rolling friction coefficient (the calibrated distance scale).
    fixed_base : bool
        Debug option: weld the torso to the world (no balance needed). Not a benchmark setting.

    Returns
    -------
    KickModels
    """
    spec = mujoco.MjSpec.from_file(str(ASSET_PATH))
    spec.geom("ball").friction[2] = rolling_friction
    if fixed_base:
        spec.delete(spec.joint("root"))
    ball_spec = _ball_only_spec(spec)
    ball_spec.option.timestep = BALL_TIMESTEP
    full = spec.compile()
    ball = ball_spec.compile()
    state, height = _settled_state(full) if not fixed_base else _settled_fixed(full)
    ball_joint = full.joint("ball").id
    return KickModels(
        full=full,
        ball=ball,
        initial_state=state,
        ball_qpos_address=int(full.jnt_qposadr[ball_joint]),
        ball_qvel_address=int(full.jnt_dofadr[ball_joint]),
        stand_height=height,
        sensor_slices=_sensor_slices(full),
        rolling_friction=float(rolling_friction),
    )


def _settled_fixed(model: mujoco.MjModel) -> tuple[Array, float]:
    """Initial state of the welded-torso debug model (joints in STAND_POSE, ball parked)."""
    data = mujoco.MjData(model)
    data.qpos[:12] = STAND_POSE
    data.ctrl[:] = STAND_POSE
    ball_adr = int(model.jnt_qposadr[model.joint("ball").id])
    data.qpos[ball_adr : ball_adr + 3] = (-3.0, 0.0, BALL_RADIUS)
    mujoco.mj_forward(model, data)
    state = np.empty(mujoco.mj_stateSize(model, mujoco.mjtState.mjSTATE_INTEGRATION))
    mujoco.mj_getState(model, data, state, mujoco.mjtState.mjSTATE_INTEGRATION)
    return state, float(data.site("torso").xpos[2])


def rest_qpos(models: KickModels, ball_xy: Array) -> Array:
    """Full-model qpos (nq,) of the settled robot with the ball at rest at ``ball_xy`` (2,)."""
    nq = models.full.nq
    qpos = np.array(models.initial_state[1 : 1 + nq])  # mjSTATE_INTEGRATION starts with time, then qpos
    adr = models.ball_qpos_address
    qpos[adr : adr + 7] = (ball_xy[0], ball_xy[1], BALL_RADIUS, 1.0, 0.0, 0.0, 0.0)
    return qpos
