"""MuJoCo humanoid ball kick (the paper's section 5.3): precision and flexibility tasks.

Importing this package is cheap and does not import mujoco: the env modules (``tasks``, ``env``,
``simulation``, ``model``, ``rendering``) are loaded by the registered entry points when a kick env is made.

Registered ids
--------------
``creps_gym/KickPrecision-v0``
    Kick a fixed ball to a target distance s in [3, 12] m; return -(x - s)² - y², a fall -s² - 1.
``creps_gym/KickPrecision-v1``
    As v0, and a fall's return is lowered by 30 times its severity (1 - the robot's lowest uprightness).
``creps_gym/KickFlexibility-v0``
    Kick a ball placed at (x_B, y_B) as far as possible; return x² - y² (the paper's).
``creps_gym/KickFlexibility-v1``
    As v0 with a return for forward distance only: sign(x) x² - y².
``creps_gym/KickFlexibility-v2``
    As v1, and a kick that misses the ball scores minus its closest foot-ball distance (m) instead of 0.
``creps_gym/KickPrecisionLowDim-v0``, ``creps_gym/KickFlexibilityLowDim-v0``
    KickPrecision-v1 and KickFlexibility-v2 searched over six metaparameters around the reference kick
    (swing amplitude, hip, ankle, duration, aim, lean: :mod:`creps_gym.envs.kick.subspace`, through
    :class:`creps_gym.envs.subspace.AffineSubspaceEnv`). They kick no farther than 9.68 m and reach no
    ball at x_B = 0.30 m.
``creps_gym/KickPrecisionLowDim-v1``, ``creps_gym/KickFlexibilityLowDim-v1``
    As v0, with ``power`` (towards a standing 12 m kick) and, for the flexibility, ``reach`` (towards a
    standing kick of a ball at x_B = 0.30 m) as a seventh and eighth metaparameter.
``creps_gym/KickPrecisionLowDim-v2``
    KickPrecision-v1 searched over three of those, ``duration``, ``aim`` and ``power``: a kick's timing,
    direction and strength, the few metaparameters a real robot's engineer would expose.
``creps_gym/KickFlexibilityLowDim-v2``
    KickFlexibility-v2 searched over four: ``aim``, ``lean``, ``power`` and ``reach``, the kick's sideways
    direction and body shift (for a ball off the centre line) and its strength for a near and a far ball.
"""

from __future__ import annotations

from typing import Any

__all__ = ["REGISTRATIONS"]

_TASKS = "creps_gym.envs.kick.tasks"
_SIX = ("amplitude", "hip", "ankle", "duration", "aim", "lean")  # subspace.METAPARAMETERS (a test compares)

REGISTRATIONS: list[dict[str, Any]] = [
    {
        "id": "creps_gym/KickPrecision-v0",
        "entry_point": f"{_TASKS}:KickPrecisionEnv",
        "vector_entry_point": f"{_TASKS}:KickPrecisionVectorEnv",
        "kwargs": {"rolling_friction": 0.003, "fall_penalty": 1.0},
    },
    {
        "id": "creps_gym/KickPrecision-v1",
        "entry_point": f"{_TASKS}:KickPrecisionEnv",
        "vector_entry_point": f"{_TASKS}:KickPrecisionVectorEnv",
        "kwargs": {"rolling_friction": 0.003, "fall_penalty": 1.0, "fall_grading": 30.0},
    },
    {
        "id": "creps_gym/KickFlexibility-v0",
        "entry_point": f"{_TASKS}:KickFlexibilityEnv",
        "vector_entry_point": f"{_TASKS}:KickFlexibilityVectorEnv",
        "kwargs": {"rolling_friction": 0.003, "fall_penalty": 1.0},
    },
    {
        "id": "creps_gym/KickFlexibility-v1",
        "entry_point": f"{_TASKS}:KickFlexibilityEnv",
        "vector_entry_point": f"{_TASKS}:KickFlexibilityVectorEnv",
        "kwargs": {"rolling_friction": 0.003, "fall_penalty": 1.0, "forward_only": True},
    },
    {
        "id": "creps_gym/KickFlexibility-v2",
        "entry_point": f"{_TASKS}:KickFlexibilityEnv",
        "vector_entry_point": f"{_TASKS}:KickFlexibilityVectorEnv",
        "kwargs": {"rolling_friction": 0.003, "fall_penalty": 1.0, "forward_only": True, "miss_weight": 1.0},
    },
    *(
        {
            "id": f"creps_gym/Kick{task}LowDim-v0",
            "entry_point": "creps_gym.envs.kick.subspace:make_low_dimensional_kick",
            "kwargs": {"full_id": f"creps_gym/Kick{task}-{version}", "initial_std": 0.3},
        }
        for task, version in (("Precision", "v1"), ("Flexibility", "v2"))
    ),
    *(
        {
            "id": f"creps_gym/Kick{task}LowDim-v1",
            "entry_point": "creps_gym.envs.kick.subspace:make_low_dimensional_kick",
            "kwargs": {"full_id": f"creps_gym/Kick{task}-{version}", "initial_std": 0.3, "names": names},
        }
        for task, version, names in (
            ("Precision", "v1", (*_SIX, "power")),
            ("Flexibility", "v2", (*_SIX, "power", "reach")),
        )
    ),
    {
        "id": "creps_gym/KickPrecisionLowDim-v2",
        "entry_point": "creps_gym.envs.kick.subspace:make_low_dimensional_kick",
        "kwargs": {
            "full_id": "creps_gym/KickPrecision-v1",
            "initial_std": 0.3,
            "names": ("duration", "aim", "power"),
        },
    },
    {
        "id": "creps_gym/KickFlexibilityLowDim-v2",
        "entry_point": "creps_gym.envs.kick.subspace:make_low_dimensional_kick",
        "kwargs": {
            "full_id": "creps_gym/KickFlexibility-v2",
            "initial_std": 0.3,
            "names": ("aim", "lean", "power", "reach"),
        },
    },
]
