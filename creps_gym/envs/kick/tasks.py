"""The two humanoid kick tasks of Abdolmaleki et al. (2019), section 5.3: precision and flexibility."""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from creps_gym._validation import check_bool, check_real
from creps_gym.envs.kick.env import KickEnv, KickVectorEnv
from creps_gym.envs.kick.simulation import SimulationResult

__all__ = [
    "FLEXIBILITY_HIGH",
    "FLEXIBILITY_LOW",
    "PRECISION_BALL",
    "KickFlexibilityEnv",
    "KickFlexibilityVectorEnv",
    "KickPrecisionEnv",
    "KickPrecisionVectorEnv",
]

Array = NDArray[np.float64]

PRECISION_BALL: Array = np.array([0.16, -0.05])
"""Ball start (m) of the precision task, relative to the torso: in front of the right foot."""
FLEXIBILITY_LOW: Array = np.array([0.15, -0.15])
FLEXIBILITY_HIGH: Array = np.array([0.30, 0.15])

_MANUAL = """{summary}

    ## Description
{description}

    ## Context Space
{context}

    ## Parameter Space
    ``Box(-1, 1, (25,), float64)``, normalised: θ = (12 initial joint angles, 12 final joint angles,
    duration t). The 12 joints are the right leg's then the left leg's (hip yaw-pitch, hip roll, hip pitch,
    knee, ankle pitch, ankle roll); each maps linearly from [-1, 1] onto its joint range (NAO H25 figures,
    rad) and t onto [0.05, 0.6] s. ``env.unwrapped.physical_low``/``physical_high``/``to_physical`` give
    the physical units and ``param_names`` the names. Values outside [-1, 1] are clipped. The motion is the
    paper's linear interpolator: from the settled standing pose to the initial pose in 0.4 s, hold 0.1 s,
    linear to the final pose over t, hold. ``env.unwrapped.reference_params()`` is a right-leg kick that
    ships as the recommended initial mean. ``env.unwrapped.initial_distribution()`` (the runner's default
    start) is the reference kick with σ = 0.02 per parameter, at which few sampled kicks fall. Fall rates
    of 200 kicks sampled around the reference (seed 0, uniform contexts): precision 2.5 % at σ = 0.02,
    16 % at 0.03, 54 % at 0.05, 81 % at 0.08; flexibility 3.5 % at σ = 0.02, 21 % at 0.03, 55 % at 0.05,
    84 % at 0.08. From this start ``creps-gym run --optimizer c-cma-es --iterations 20 --samples 20 --seed
    0`` raises the mean policy's evaluation return from -5.64 (the reference kick) to -3.78.

    ## Return
{returns}

    ## Episode End
    One step per episode (``terminated=True``). The simulation (MuJoCo, 2 ms, implicitfast) runs until 1 s
    after the swing ends and the ball is 0.8 m away or at rest; the ball's roll is then finished on a
    ball-only model until it is slower than 0.02 m/s (at most 16 s). The robot has *fallen* if its torso
    drops below 0.6 of its standing height or tilts over 60° before that: a fall scores as "ball not moved"
    minus ``fall_penalty`` and minus ``fall_grading`` times its severity (a falling body can pinch the ball
    and launch it, which is not a kick).
    ``info`` holds ``context``, ``fell``, ``ball_displacement`` (x, y in m), ``kick_distance``,
    ``min_foot_ball_distance`` (m, during the kick), ``launch_speed`` (m/s), ``uprightness`` and
    ``mirrored``.

    ## Arguments
    * ``rolling_friction`` (0.003): the ball's rolling friction, which sets the distance scale (calibrated
      so that a strong kick, launched at about 4.5 m/s, rolls 12-14 m; pinned by a test).
    * ``fall_penalty`` (1.0): subtracted from the "ball not moved" return when the robot falls.
    * ``fall_grading`` (0.0; 30.0 in ``KickPrecision-v1``): a fall's return is also lowered by this times
      its severity ``1 - uprightness`` (in [0, 2]; ``info["uprightness"]`` is the lowest min(torso height /
      standing height, cosine of the tilt) while watched), so that a search can tell a stumble from a
      collapse where every sample falls.
    * ``forward_only``, ``miss_weight`` (flexibility only): see Return and Version History.
    * ``num_threads`` (0 = all CPUs): threads of the batched simulation; results do not depend on it.
    * ``fixed_base`` (False): debug option that welds the torso to the world; not a benchmark setting.
    * ``render_mode`` (None, ``"rgb_array"``, ``"rgb_array_list"``), ``width`` (480), ``height`` (360):
      ``rgb_array`` renders the last kick at the end of its swing, ``rgb_array_list`` the whole last
      episode at 25 frames/s from a camera tracking robot and ball; the precision target is a red disc on
      the pitch. Headless: set ``MUJOCO_GL=egl`` or ``osmesa`` before importing mujoco. To record a whole
      one-step episode to video, make the env with ``rgb_array_list`` and pass ``env.render()`` after the
      step to :func:`creps_gym.envs.kick.rendering.save_video`, which writes a GIF/MP4 (the documented
      alternative to Gymnasium's ``RecordVideo``, which needs moviepy), or use ``creps-gym evaluate RUN
      --video FILE``. ``env.unwrapped.episode_frames()`` gives the same frames, each rendered when read
      (an 8 s episode has 200; ``rgb_array_list`` draws them without shadows or reflections, which halves
      the software rendering time, about 0.07 s a frame).

    ## Version History
{version_history}
"""


def _manual(
    summary: str,
    description: str,
    context: str,
    returns: str,
    version_history: str = "    * v0: initial version.",
) -> str:
    """The class docstring: the task's sections and the shared ones, in Gymnasium's order."""
    return _MANUAL.format(
        summary=summary,
        description=description,
        context=context,
        returns=returns,
        version_history=version_history,
    )


class KickPrecisionEnv(KickEnv):
    __doc__ = _manual(
        "Humanoid kick, precision task: kick a fixed ball to a target distance.",
        """    A NAO-like humanoid (0.57 m, 5.25 kg, 6 position-controlled joints per leg, free-floating
    torso) stands behind a RoboCup 3D ball (radius 0.042 m, 0.026 kg) placed at (0.16, -0.05) m relative
    to its torso, in front of the right foot. It must kick the ball to the target distance ``s`` straight
    ahead (paper, section 5.3, Fig. 5). The motion is open-loop; the robot must keep its balance.""",
        """    ``Box(3, 12, (1,), float64)``: the target distance ``s`` in metres, uniform by default;
    ``reset(options={"context": [s]})`` sets it. The context is the observation and ``info["context"]``.""",
        """    ``-(x - s)² - y²``, with x, y the ball's displacement (m) forward and to the left.
    A fall returns ``-s² - fall_penalty`` (v0), minus ``fall_grading`` times the fall's severity in [0, 2]
    (v1: ``fall_grading=30``, which outweighs the ``-s²`` term's change of about 24 per metre at 12 m).""",
        version_history="""    * v1: a fall's return is graded by its severity (``fall_grading=30``). Where
      every sample falls, as near the 12 m target, v0 gives them all the same return and a search has no
      direction back to a kick that stands (``benchmarks/kick/README.md``).
    * v0: initial version.""",
    )

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(np.array([3.0]), np.array([12.0]), **kwargs)

    def ball_positions(self, contexts: Array) -> tuple[Array, NDArray[np.bool_]]:
        """The fixed ball (n, 2); never mirrored."""
        n = contexts.shape[0]
        return np.tile(PRECISION_BALL, (n, 1)), np.zeros(n, dtype=bool)

    def target_offset(self, context: Array) -> Array:
        """The target: ``s`` metres straight ahead of the ball's start."""
        return np.array([context[0], 0.0])

    def task_returns(self, contexts: Array, displacement: Array) -> Array:
        """``-(x - s)² - y²``, shape (n,)."""
        return -((displacement[:, 0] - contexts[:, 0]) ** 2) - displacement[:, 1] ** 2


class KickFlexibilityEnv(KickEnv):
    __doc__ = _manual(
        "Humanoid kick, flexibility task: kick the ball as far as possible from wherever it lies.",
        """    The NAO-like humanoid of ``KickPrecision-v0`` finds the ball at a context-dependent position in
    front of it and must kick it as far as possible straight ahead (paper, section 5.3, Fig. 6 and 7).
    θ describes a right-leg kick. As in the paper ("mirror the joints"), for balls on the left
    (``y_B > 0``) the env swaps the right- and left-leg blocks of θ, so the left leg performs the
    mirror-image kick; ``info["mirrored"]`` says when. The legs' joint axes are mirror images, so a ball
    at (x_B, y_B) and θ give the mirror image of the kick of the ball at (x_B, -y_B), and the same return:
    the return is even in y_B, which a model of it may use (c-bo's ``symmetric_contexts=(1,)``).""",
        """    ``Box([0.15, -0.15], [0.30, 0.15], (2,), float64)``: the ball position (x_B, y_B) in metres
    relative to the torso (x forward, y left), the paper's box; uniform by default. The reference kick
    reaches balls up to x_B = 0.20 m; how far a search from it reaches is measured per ball position by
    the kick study's oracle (``benchmarks/kick``), not assumed.""",
        """    v1 (``forward_only=True``): ``sign(x) x² - y²``, with x, y the ball's displacement (m) forward
    and to the left, so only forward distance pays and a backward kick is penalised.
    v0 (``forward_only=False``): the paper's ``x² - y²``, which pays a backward kick as much as the
    mirrored forward one.
    A fall returns ``-fall_penalty`` (minus ``fall_grading`` times its severity if given).
    v2 (``miss_weight=1``) subtracts ``miss_weight · d`` from the v1 return, with d in [0, 1] the smallest
    distance (m) between a foot and the ball during the kick (``info["min_foot_ball_distance"]`` clipped to
    [0, 1]: the info is MuJoCo's signed distance, negative while a foot presses into the ball), and
    ``miss_weight`` more from a fall. A kick that misses the ball thus scores how close it came instead of a
    flat 0, which is what tells a search how to reach a far ball, and a fall stays below every kick that
    stands.""",
        version_history="""    * v2: a kick that misses the ball scores ``-miss_weight · d`` (d: its closest
      foot-ball distance, m) instead of 0, and a fall ``-fall_penalty - miss_weight`` (``miss_weight=1``).
    * v1: the return is ``sign(x) x² - y²`` (forward distance only;
      ``forward_only=True``).
    * v0: initial version, the paper's ``x² - y²``.""",
    )

    def __init__(self, *, forward_only: bool = False, miss_weight: float = 0.0, **kwargs: Any) -> None:
        self.forward_only = check_bool(forward_only, "forward_only")
        self.miss_weight = check_real(miss_weight, "miss_weight")
        super().__init__(FLEXIBILITY_LOW, FLEXIBILITY_HIGH, **kwargs)

    def episode_returns(self, contexts: Array, result: SimulationResult) -> Array:
        """The v0/v1 return minus ``miss_weight`` times the closest foot-ball distance (m, in [0, 1]; 1 for
        a fall), shape (n,)."""
        returns = super().episode_returns(contexts, result)
        if self.miss_weight == 0.0:
            return returns
        miss = np.where(result.fell, 1.0, np.clip(result.min_foot_ball_distance, 0.0, 1.0))
        return returns - self.miss_weight * miss

    def ball_positions(self, contexts: Array) -> tuple[Array, NDArray[np.bool_]]:
        """The ball at the context (n, 2); mirrored when ``y_B > 0``."""
        return contexts.copy(), contexts[:, 1] > 0.0

    def task_returns(self, contexts: Array, displacement: Array) -> Array:
        """``sign(x) x² - y²`` (v1, ``forward_only``) or ``x² - y²`` (v0), shape (n,)."""
        x, y = displacement[:, 0], displacement[:, 1]
        forward = np.sign(x) * x**2 if self.forward_only else x**2
        return forward - y**2


class KickPrecisionVectorEnv(KickVectorEnv):
    """Native vector env of ``creps_gym/KickPrecision-v0`` and ``-v1`` (batched, multi-threaded)."""

    single_env_class: ClassVar[type[KickEnv]] = KickPrecisionEnv


class KickFlexibilityVectorEnv(KickVectorEnv):
    """Native vector env of ``creps_gym/KickFlexibility-v0`` (batched, multi-threaded)."""

    single_env_class: ClassVar[type[KickEnv]] = KickFlexibilityEnv
